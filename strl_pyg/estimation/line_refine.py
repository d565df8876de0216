"""The joint refinement of a relative pose on few point matches and the lines of vanishing
directions (:func:`refine_with_lines`), and the one line residual of the vanishing-point solver
(:mod:`strl_pyg.estimation.vanishing`): a segment's distance to the line through its midpoint
and a vanishing point."""

from __future__ import annotations

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import normalised_matches
from strl_pyg.geometry import check_rotation, pose_sampson
from strl_pyg.geometry.manifold import so3_exp, sphere_exp, tangent_basis

__all__ = ["refine_with_lines", "line_sigmas", "VP_LINE_SIGMA_PX", "LINE_NOISE_REF_PX",
           "LINE_COUNT_REF", "JACOBIANS", "segment_geometry", "vp_residual_px"]

#: The lines' weight in the joint refinement (:func:`refine_with_lines`): the pixel distance of
#: a segment's endpoint to its vanishing line counts like a point's Sampson distance times
#: ``1 / VP_LINE_SIGMA_PX``; read at every call by the method ``vp``
#: (:class:`~strl_pyg.inference.PoseEstimator`). Fitted on the calibration split of
#: ``benchmarks/studies/bench_vanishing.py`` (point-poor pairs of other seeds than ``point_poor``).
VP_LINE_SIGMA_PX = 0.03
#: The line noise and the lines per direction of the calibration split (medians over its
#: directions: the median endpoint distance of a direction's lines to its vanishing line, in
#: image 0; the lines it holds). A direction whose lines are noisier, or more, than these gets
#: a larger sigma (:func:`line_sigmas`).
LINE_NOISE_REF_PX = 0.1
LINE_COUNT_REF = 10
#: The Jacobians :func:`refine_with_lines` can take.
JACOBIANS = ("central", "autodiff")
#: The central-difference step (the unknowns are radians and tangent coordinates, ~1e-2 to 1):
#: truncation ~h^2 and rounding ~1e-16 / h, both ~1e-10 of the derivative.
_CENTRAL_STEP = 1e-6


def _jacobian(batched, single, p: torch.Tensor, how: str) -> torch.Tensor:
    """``d residuals / d p`` ``[M, P]``: central differences through ``batched`` (``[B, P] ->
    [B, M]``, one call for every column) or ``torch.func.jacfwd`` of ``single``."""
    if how == "autodiff":
        return torch.func.jacfwd(single)(p)
    h = _CENTRAL_STEP
    steps = h * torch.eye(len(p), dtype=p.dtype)
    r = batched(torch.cat([p + steps, p - steps]))
    return ((r[:len(p)] - r[len(p):]) / (2 * h)).T


def _homogeneous(x: np.ndarray) -> np.ndarray:
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


def segment_geometry(lines: np.ndarray, K: np.ndarray):
    """Pixel endpoints ``[M, 2, 3]``, midpoints ``[M, 3]`` and unit interpretation-plane
    normals (normalised camera coordinates) ``[M, 3]`` of ``[M, 2, 2]`` pixel segments."""
    ph = _homogeneous(lines)
    Kinv = np.linalg.inv(K)
    rays = ph @ Kinv.T
    n = np.cross(rays[:, 0], rays[:, 1])
    n /= np.linalg.norm(n, axis=1, keepdims=True).clip(1e-300)
    return ph, ph.mean(axis=1), n


def _vp_residuals(d: torch.Tensor, K: torch.Tensor, ends: torch.Tensor,
                  mids: torch.Tensor) -> torch.Tensor:
    """Signed pixel distance ``[H, M]`` of each segment's first endpoint to the line through
    its midpoint and the vanishing point ``K d`` (``d`` ``[H, 3]``); the second endpoint's is
    its negative (the line passes through the midpoint): the consensus of
    :func:`~strl_pyg.estimation.vanishing.vanishing_directions` and the refinement's residual."""
    v = (d @ K.T)[:, None].expand(-1, len(mids), -1)  # [H, M, 3], third coordinate 0 at inf.
    l = torch.cross(mids[None].expand_as(v), v, dim=-1)
    return (l * ends[None, :, 0]).sum(-1) / l[..., :2].norm(dim=-1).clamp_min(1e-300)


def vp_residual_px(d: np.ndarray, K: np.ndarray, ends: np.ndarray, mids: np.ndarray):
    """:func:`_vp_residuals`' distance ``[H, M]`` (unsigned) of numpy arrays, in closed form
    (the fast path of the vanishing-point consensus; :func:`_vp_residuals` is its reference).

    With the vanishing point ``v = K d``, a midpoint ``(m_x, m_y, 1)`` and a first endpoint
    ``(e_x, e_y, 1)``, the line ``l = m x v`` gives ``l . e = v . (e_y - m_y, m_x - e_x,
    m_y e_x - m_x e_y)``, ``l_x = v . (0, -1, m_y)`` and ``l_y = v . (1, 0, -m_x)``: three
    ``[H, 3] @ [3, M]`` products instead of ``[H, M, 3]`` cross products."""
    v = np.asarray(d, float) @ np.asarray(K, float).T  # [H, 3]
    e = np.asarray(ends, float)[:, 0, :2]
    m = np.asarray(mids, float)[:, :2]
    ex, ey, mx, my = e[:, 0], e[:, 1], m[:, 0], m[:, 1]
    ones, zeros = np.ones_like(mx), np.zeros_like(mx)
    num = v @ np.stack([ey - my, mx - ex, my * ex - mx * ey])
    lx = v @ np.stack([zeros, -ones, my])
    ly = v @ np.stack([ones, zeros, -mx])
    return np.abs(num) / np.maximum(np.hypot(lx, ly), 1e-300)


def line_sigmas(matches: PairMatches, directions: list, line_sigma_px: float) -> np.ndarray:
    """Each direction's sigma in :func:`refine_with_lines`: ``line_sigma_px`` times
    ``max(1, s / LINE_NOISE_REF_PX)`` times ``sqrt(max(1, n / LINE_COUNT_REF))``, ``s`` the
    median distance (px) of the direction's ``n`` lines to its vanishing line in image 0.

    Why: the constant was fitted on generated pairs, whose segments are near-exact projections
    of parallel edges (``s`` ~0.1 px, ~10 lines per direction). Real segments are noisier
    (KITTI 06: ~0.27 px) and many more (~70 per direction), and the lines of one direction
    share its errors (edges not quite parallel, lens residuals), so they are not independent
    evidence: with the sigma scaled so, a direction's lines weigh on the rotation like ten
    lines of the calibration split's precision, however many and however noisy
    (``benchmarks/studies/results_vanishing.md``).
    """
    if not 0 < line_sigma_px < np.inf:  # NaN too; inf would silently drop the lines
        raise ValueError(f"Expected a finite line_sigma_px > 0 (got {line_sigma_px})")
    K0 = np.asarray(matches.K0, float)
    ends, mids, _ = segment_geometry(np.asarray(matches.lines0, float), K0)
    out = []
    for d0, _, mk in directions:
        mk = np.asarray(mk, bool)
        s = float(np.median(vp_residual_px(np.asarray(d0, float)[None], K0, ends[mk],
                                            mids[mk])[0])) if mk.any() else 0.0
        out.append(line_sigma_px * max(1.0, s / LINE_NOISE_REF_PX)
                   * max(1.0, mk.sum() / LINE_COUNT_REF) ** 0.5)
    return np.array(out)


def refine_with_lines(matches: PairMatches, R: np.ndarray, t: np.ndarray, directions: list,
                      point_mask: np.ndarray, line_sigma_px: float | None = None,
                      scale_px: float = 1.0, iterations: int = 15,
                      return_cost: bool = False, jacobian: str = "central") -> tuple:
    """Joint Levenberg-Marquardt refinement of ``(R, t)`` and the vanishing directions on the
    point matches and the lines of those directions.

    Unknowns: ``R <- exp([w]_x) R`` (3), the unit ``t`` (2) and each direction ``d_i`` in camera
    0 (2 each). Residuals (pixels): the Sampson distance of every point in ``point_mask``; for
    every line of direction ``i``, the distance of its endpoint to the line through its
    midpoint and the vanishing point, ``K0 d_i`` in image 0 and ``K1 R d_i`` in image 1
    (divided by direction ``i``'s sigma, :func:`line_sigmas` of ``line_sigma_px``). A Cauchy
    loss of scale ``scale_px`` (iteratively reweighted) bounds every residual's pull. With few
    points and small baselines the translation is only as good as the rotation (a 1 deg
    rotation error moved the translation by ~9 deg on the point-poor pairs); the lines, many
    and in both images, pin the rotation, the points fix ``t``.

    Args:
        matches: the pair (``K0``, ``K1``, points, lines).
        R, t: the starting pose (``X1 = R X0 + t``).
        directions: :func:`~strl_pyg.estimation.vanishing.vanishing_directions` of
            ``matches`` (``(d0, d1, mask)``).
        point_mask: boolean ``[N]``, the point matches to use (``vanishing_point_pose``
            passes every point: the Cauchy loss bounds the outliers' pull).
        line_sigma_px: the lines' weight (finite, > 0); ``None``: :data:`VP_LINE_SIGMA_PX`
            as it is at the call.
        scale_px, iterations: the Cauchy scale (pixels, finite, > 0), the most iterations.
        return_cost: also return the final robust cost (comparable between starts on the
            same ``directions`` and ``point_mask``).
        jacobian: ``"central"`` (default): central differences, all ``2 P`` evaluations in
            one batched call of the residuals; ``"autodiff"``: ``torch.func.jacfwd``, the
            exact reference (the same refinement to ~1e-11; slower: functorch's per-operation
            overhead dominates on these small problems).

    Returns:
        ``R`` ``(3, 3)`` and unit ``t`` ``(3,)`` (float64 numpy), and the cost if asked; a step
        that does not lower the robust cost is rejected, so the result is never worse than the
        start on that cost.
    """
    n, R, t = matches.num_points, np.asarray(R, float), np.asarray(t, float)
    if R.shape != (3, 3) or t.shape != (3,) or not (np.isfinite(R).all() and 0 < t @ t < np.inf):
        raise ValueError(f"Expected a finite R (3, 3) and a finite nonzero t (3,) (got shapes "
                         f"{R.shape}, {t.shape})")
    check_rotation(R)
    point_mask = np.asarray(point_mask)
    if point_mask.dtype != bool or point_mask.shape != (n,):
        raise ValueError(f"Expected point_mask as a boolean array of length {n} (got "
                         f"{point_mask.dtype} of shape {point_mask.shape})")
    if line_sigma_px is None:
        line_sigma_px = VP_LINE_SIGMA_PX
    if jacobian not in JACOBIANS:
        raise ValueError(f"Expected jacobian in {JACOBIANS} (got {jacobian!r})")
    if not (0 < scale_px < np.inf) or int(iterations) != iterations or iterations < 0:
        raise ValueError(f"Expected a finite scale_px > 0 and an integer iterations >= 0 (got "
                         f"{scale_px}, {iterations})")
    dt = torch.float64
    K0 = torch.as_tensor(np.asarray(matches.K0, float), dtype=dt)
    K1 = torch.as_tensor(np.asarray(matches.K1, float), dtype=dt)
    x0, x1, focal = normalised_matches(matches)
    keep = torch.as_tensor(np.asarray(point_mask, bool))
    x0, x1 = x0[keep], x1[keep]
    segs = []
    for lines, K in ((matches.lines0, K0), (matches.lines1, K1)):
        e, m, _ = segment_geometry(np.asarray(lines, float), K.numpy())
        segs.append((torch.from_numpy(e), torch.from_numpy(m)))
    R0 = torch.as_tensor(R, dtype=dt)
    t0 = torch.as_tensor(t, dtype=dt)
    t0 = t0 / t0.norm()
    Bt = tangent_basis(t0)
    d0 = [torch.as_tensor(d[0], dtype=dt) for d in directions]
    Bd = [tangent_basis(d) for d in d0]
    masks = [torch.as_tensor(np.asarray(d[2], bool)) for d in directions]
    sigmas = line_sigmas(matches, directions, line_sigma_px)

    def unpack(p):  # p [B, P] -> R [B, 3, 3], t [B, 3], directions [B, 3] each
        Rp = so3_exp(p[:, :3]) @ R0
        tp = sphere_exp(t0, Bt, p[:, 3:5])
        ds = [sphere_exp(d, B, p[:, 5 + 2 * i:7 + 2 * i])
              for i, (d, B) in enumerate(zip(d0, Bd, strict=True))]
        return Rp, tp, ds

    def batched(p):  # p [B, P] -> residuals [B, M]
        Rp, tp, ds = unpack(p)
        r = [pose_sampson(Rp, tp, x0, x1) * focal]
        for d, mk, sig in zip(ds, masks, sigmas, strict=True):
            for Kc, dc, (e, mid) in ((K0, d, segs[0]), (K1, (Rp @ d[..., None])[..., 0], segs[1])):
                r.append(_vp_residuals(dc, Kc, e[mk], mid[mk]) / float(sig))
        return torch.cat(r, dim=1)

    def residuals(p):
        return batched(p[None])[0]

    def cost(r):
        return float((scale_px ** 2 * torch.log1p((r / scale_px) ** 2)).sum())

    p = torch.zeros(5 + 2 * len(d0), dtype=dt)
    r = residuals(p)
    c, lam = cost(r), 1e-3
    for _ in range(iterations):
        J = _jacobian(batched, residuals, p, jacobian)
        w = 1.0 / (1.0 + (r / scale_px) ** 2)  # the Cauchy loss's IRLS weights
        H, g = J.T @ (w[:, None] * J), J.T @ (w * r)
        improved = False
        while lam <= 1e6:
            step = -torch.linalg.solve(H + lam * torch.diag(H.diagonal().clamp_min(1e-12)), g)
            r_new = residuals(p + step)
            c_new = cost(r_new)
            if c_new < c:
                p, r, c, lam, improved = p + step, r_new, c_new, lam / 3, True
                break
            lam *= 5
        if not improved or float(step.norm()) < 1e-10:
            break
    Rp, tp, _ = unpack(p[None])
    Rp, tp = Rp[0], tp[0]
    return (Rp.numpy(), tp.numpy(), c) if return_cost else (Rp.numpy(), tp.numpy())
