"""Differentiable weighted essential-matrix estimation and pose recovery, batched, in torch.

Beyond the paper: the geometric head of :class:`~strl_pyg.StrLPose` predicts a weight per
correspondence and this module turns the weights into a pose with the exact two-view geometry
of the inputs, instead of a global regression.

Convention: normalised camera coordinates ``x = K^-1 p`` (first two components), ``T_0to1``
maps camera-0 points into camera 1 (``X1 = R X0 + t``), the epipolar constraint is
``x1^T E x0 = 0`` with ``E = [t]_x R``.

Pipeline of :func:`weighted_essential`:

1. weighted isotropic (Hartley) conditioning of both point sets;
2. weighted eight-point: the eigenvector of the smallest eigenvalue of
   ``A^T diag(w) A`` (``A`` the ``N x 9`` Kronecker rows), in float64;
3. ``iterations`` rounds of iteratively reweighted least squares: ``w_i <- w0_i / (1 +
   r_i^2 / tau^2)`` with the Sampson residual ``r_i`` of the current estimate (a Cauchy
   kernel), then step 2 again.

The returned ``E`` is the algebraic solution (unit Frobenius norm, not projected onto the
essential manifold, so that its gradient stays well defined: the SVD projection has a
singular gradient at ``s1 = s2``); :func:`decompose_essential` projects it and picks the pose
whose triangulated points lie in front of both cameras.

Degenerate inputs are reported, never returned as NaN: a pair whose weights leave fewer than
``min_effective`` effective correspondences (``(sum w)^2 / sum w^2``) or whose weighted system
has a null space of dimension > 1 (second-smallest eigenvalue below ``rank_tol`` times the
largest) gets ``status = DEGENERATE`` and a fixed finite ``E`` with zero gradient.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from strl_pyg.geometry import pose_sampson, sampson_error, so3_exp, tangent_basis

__all__ = [
    "OK",
    "DEGENERATE",
    "EssentialEstimate",
    "weighted_essential",
    "sampson_sq",
    "decompose_essential",
    "refine_pose",
    "smallest_eigenvector",
]

OK = 0
DEGENERATE = 1


@dataclass
class EssentialEstimate:
    """Output of :func:`weighted_essential`.

    Attributes:
        E: ``[B, 3, 3]`` algebraic essential matrices (unit Frobenius norm) in the input dtype.
        status: ``[B]`` long, :data:`OK` or :data:`DEGENERATE`.
        weights: ``[B, N]`` final IRLS weights (normalised to sum 1 per pair).
        num_effective: ``[B]`` effective number of correspondences of the input weights.
    """

    E: Tensor
    status: Tensor
    weights: Tensor
    num_effective: Tensor

    @property
    def ok(self) -> Tensor:
        return self.status == OK


def _batched(x0: Tensor, x1: Tensor, weights: Tensor, mask: Tensor | None):
    if x0.dim() == 2:
        x0, x1, weights = x0[None], x1[None], weights[None]
        mask = None if mask is None else mask[None]
    if x0.dim() != 3 or x0.shape[-1] != 2 or x1.shape != x0.shape:
        raise ValueError(f"Expected x0, x1 of shape [B, N, 2] or [N, 2] (got {tuple(x0.shape)} "
                         f"and {tuple(x1.shape)})")
    if weights.shape != x0.shape[:2]:
        raise ValueError(f"Expected weights of shape {tuple(x0.shape[:2])} "
                         f"(got {tuple(weights.shape)})")
    if mask is not None:
        if mask.shape != x0.shape[:2]:
            raise ValueError(f"Expected a mask of shape {tuple(x0.shape[:2])} "
                             f"(got {tuple(mask.shape)})")
        weights = weights * mask.to(weights.dtype)
    return x0, x1, weights


def sampson_sq(E: Tensor, x0: Tensor, x1: Tensor) -> Tensor:
    """Squared Sampson distances ``[B, N]`` of normalised matches ``x0``, ``x1`` ``[B, N, 2]``
    under ``E`` ``[B, 3, 3]`` (``x1^T E x0 = 0``); invariant to the scale of ``E``. The same
    as :func:`strl_pyg.geometry.sampson_error` (``eps = 1e-30``), computed in float64 whatever
    the inputs' dtype and returned in theirs: the division's backward squares ``eps``, which
    float32 cannot hold (1e-60 is 0), so a match on both epipoles (denominator 0) gave
    ``0 * r^2 / 0`` = NaN in the gradient even where the caller passes none (issue 30)."""
    dtype = torch.promote_types(E.dtype, x0.dtype)
    return sampson_error(E.double(), x0.double(), x1.double(), eps=1e-30).to(dtype)


def _conditioning(x: Tensor, w: Tensor) -> Tensor:
    """Weighted Hartley transform ``[B, 3, 3]``: weighted centroid to 0, mean distance
    ``sqrt(2)``."""
    c = (w[..., None] * x).sum(1)  # w sums to 1
    d = ((x - c[:, None]).square().sum(-1) + 1e-24).sqrt()
    s = 2.0**0.5 / (w * d).sum(1).clamp_min(1e-12)
    T = torch.zeros(x.shape[0], 3, 3, dtype=x.dtype, device=x.device)
    T[:, 0, 0] = s
    T[:, 1, 1] = s
    T[:, 0, 2] = -s * c[:, 0]
    T[:, 1, 2] = -s * c[:, 1]
    T[:, 2, 2] = 1.0
    return T


def _apply(T: Tensor, x: Tensor) -> Tensor:
    return x @ T[:, :2, :2].transpose(-1, -2) + T[:, None, :2, 2]


class _SmallestEigenvector(torch.autograd.Function):
    """The eigenvector of the smallest eigenvalue of symmetric ``M`` ``[B, n, n]``, with a
    backward that reads only the gaps ``l_0 - l_j`` to the other eigenvalues, each kept at
    least ``gap_tol * max |l|`` away from zero."""

    @staticmethod
    def forward(ctx, M: Tensor, gap_tol: float) -> Tensor:
        evals, vecs = torch.linalg.eigh(M)
        ctx.save_for_backward(evals, vecs)
        ctx.gap_tol = gap_tol
        return vecs[..., 0]

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad: Tensor) -> tuple[Tensor, None]:
        evals, vecs = ctx.saved_tensors
        # dv_0 = sum_{j > 0} v_j (v_j^T dM v_0) / (l_0 - l_j); l_0 - l_j <= 0 (ascending)
        scale = evals.abs().amax(-1, keepdim=True).clamp_min(torch.finfo(evals.dtype).tiny)
        gap = torch.minimum(evals[..., :1] - evals[..., 1:], -ctx.gap_tol * scale)
        rest = vecs[..., 1:]
        coef = (rest.transpose(-1, -2) @ grad[..., None])[..., 0] / gap  # [B, n - 1]
        G = (rest @ coef[..., None]) @ vecs[..., None, :, 0]  # [B, n, n]
        return 0.5 * (G + G.transpose(-1, -2)), None


def smallest_eigenvector(M: Tensor, gap_tol: float = 1e-12) -> Tensor:
    """Unit eigenvector ``[B, n]`` of the smallest eigenvalue of each symmetric ``M``
    ``[B, n, n]`` (``torch.linalg.eigh``, sign as it returns it), differentiable.

    ``torch.linalg.eigh``'s own backward divides by the gaps between *all* pairs of
    eigenvalues, so two equal eigenvalues that the smallest eigenvector does not depend on
    still give a NaN gradient (``0 / 0``). This backward forms only the gaps to the smallest
    eigenvalue (the derivative of that eigenvector), each at least ``gap_tol`` times the largest
    eigenvalue's magnitude away from zero, so a near-repeated smallest eigenvalue gives a large
    but finite gradient; elsewhere it equals ``eigh``'s (tested).
    """
    return _SmallestEigenvector.apply(M, gap_tol)


_FALLBACK = torch.diag(torch.arange(1.0, 10.0, dtype=torch.float64))


def _eight_point(x0: Tensor, x1: Tensor, w: Tensor, rank_tol: float) -> tuple[Tensor, Tensor]:
    """One weighted eight-point solve; ``w`` sums to 1 per pair. Returns ``E`` and a
    ``[B]`` bool of rank-deficient systems."""
    T0, T1 = _conditioning(x0, w), _conditioning(x1, w)
    y0, y1 = _apply(T0, x0), _apply(T1, x1)
    a0 = torch.cat([y0, torch.ones_like(y0[..., :1])], dim=-1)
    a1 = torch.cat([y1, torch.ones_like(y1[..., :1])], dim=-1)
    A = (a1[..., :, None] * a0[..., None, :]).flatten(-2)  # [B, N, 9], row-major E
    M = A.transpose(-1, -2) @ (w[..., None] * A)  # [B, 9, 9]
    with torch.no_grad():
        ev = torch.linalg.eigvalsh(M)
        bad = ev[:, 1] <= rank_tol * ev[:, -1].clamp_min(1e-300)
        bad |= ~torch.isfinite(ev).all(-1)
    # A rank-deficient M has tied eigenvalues and an undefined eigenvector gradient: solve a
    # fixed, well-conditioned system instead and report the pair.
    M = torch.where(bad[:, None, None], _FALLBACK.to(M), M)
    En = smallest_eigenvector(M, rank_tol).reshape(-1, 3, 3)
    E = T1.transpose(-1, -2) @ En @ T0
    E = E / E.flatten(-2).norm(dim=-1).clamp_min(1e-300)[:, None, None]
    return E, bad


def weighted_essential(
    x0: Tensor, x1: Tensor, weights: Tensor, mask: Tensor | None = None,
    iterations: int = 2, tau: float = 1e-3, min_effective: float = 8.0,
    rank_tol: float = 1e-12,
) -> EssentialEstimate:
    """Weighted eight-point + IRLS essential matrix (module docstring), differentiable with
    respect to ``x0``, ``x1`` and ``weights``.

    Args:
        x0, x1: normalised coordinates ``[B, N, 2]`` (or ``[N, 2]``).
        weights: non-negative weights ``[B, N]`` (e.g. inlier probabilities); the scale of
            each pair's weights does not matter.
        mask: optional ``[B, N]`` bool of valid entries (padding is ``False``).
        iterations: IRLS rounds after the first solve (default 2; 0 = plain weighted 8-point).
        tau: Cauchy scale of the IRLS kernel, normalised units (``~ px / focal``).
        min_effective: fewest effective correspondences for a non-degenerate solve.
        rank_tol: relative eigenvalue gap below which the system is under-determined.

    Returns:
        :class:`EssentialEstimate`; the solve runs in float64 and ``E`` is cast back.
    """
    x0, x1, weights = _batched(x0, x1, weights, mask)
    if iterations < 0:
        raise ValueError(f"Expected iterations >= 0 (got {iterations})")
    dtype = x0.dtype
    x0, x1, w0 = x0.double(), x1.double(), weights.double()
    finite = torch.isfinite(x0).all(-1) & torch.isfinite(x1).all(-1) & torch.isfinite(w0)
    w0 = torch.where(finite, w0.clamp_min(0.0), torch.zeros_like(w0))
    x0 = torch.where(finite[..., None], x0, torch.zeros_like(x0))
    x1 = torch.where(finite[..., None], x1, torch.zeros_like(x1))
    total = w0.sum(1)
    with torch.no_grad():
        n_eff = total.square() / w0.square().sum(1).clamp_min(1e-300)
        few = (n_eff < min_effective) | (total <= 0)
    # Degenerate pairs get uniform weights so that every op below stays finite.
    w0 = torch.where(few[:, None], torch.ones_like(w0), w0)
    w0 = w0 / w0.sum(1, keepdim=True)
    E, bad = _eight_point(x0, x1, w0, rank_tol)
    w = w0
    for _ in range(iterations):
        r2 = sampson_sq(E, x0, x1)
        w = w0 / (1.0 + r2 / tau**2)
        w = w / w.sum(1, keepdim=True).clamp_min(1e-300)
        E, bad_i = _eight_point(x0, x1, w, rank_tol)
        bad = bad | bad_i
    status = torch.where(few | bad, DEGENERATE, OK).long()
    E = torch.where(status[:, None, None] == OK, E, torch.zeros_like(E))
    return EssentialEstimate(E.to(dtype), status, w.to(dtype), n_eff.to(dtype))


def triangulated_depths(R: Tensor, t: Tensor, x0: Tensor, x1: Tensor) -> tuple[Tensor, Tensor]:
    """Depths of the midpoint-free linear triangulation of each match in both cameras:
    solve ``z1 h1 = z0 R h0 + t`` in least squares for ``(z0, z1)``."""
    h0 = torch.cat([x0, torch.ones_like(x0[..., :1])], dim=-1)
    h1 = torch.cat([x1, torch.ones_like(x1[..., :1])], dim=-1)
    a = h0 @ R.transpose(-1, -2)  # R h0, [B, N, 3]
    # z0 a - z1 h1 = -t  ->  2x2 normal equations
    aa = (a * a).sum(-1)
    ab = (a * h1).sum(-1)
    bb = (h1 * h1).sum(-1)
    at = (a * t[:, None]).sum(-1)
    bt = (h1 * t[:, None]).sum(-1)
    det = aa * bb - ab * ab
    det = torch.where(det.abs() < 1e-18, torch.full_like(det, 1e-18), det)
    z0 = (-at * bb + ab * bt) / det
    z1 = (aa * bt - ab * at) / det
    return z0, z1


@torch.no_grad()
def decompose_essential(E: Tensor, x0: Tensor, x1: Tensor,
                        weights: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """``T_0to1`` from essential matrices: the SVD projection onto the essential manifold, the
    four ``(R, +-t)`` candidates, and the one with the largest weight of matches in front of
    both cameras (cheirality).

    Args:
        E: ``[B, 3, 3]``.
        x0, x1: normalised coordinates ``[B, N, 2]``.
        weights: ``[B, N]`` (default: uniform).

    Returns:
        ``R`` ``[B, 3, 3]``, unit ``t`` ``[B, 3]``, and the weighted fraction ``[B]`` of matches
        with positive depths in both views for the chosen candidate (in ``[0, 1]``).
    """
    E = E.double()
    x0, x1 = x0.double(), x1.double()
    w = torch.ones(x0.shape[:2], dtype=torch.float64, device=x0.device) if weights is None \
        else weights.double()
    w = w / w.sum(1, keepdim=True).clamp_min(1e-300)
    U, _, Vh = torch.linalg.svd(E)
    U = U * torch.sign(torch.det(U))[:, None, None]
    Vh = Vh * torch.sign(torch.det(Vh))[:, None, None]
    W = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=E.dtype,
                     device=E.device)
    t = U[..., 2]
    best_score = torch.full(E.shape[:1], -1.0, dtype=E.dtype, device=E.device)
    best_R = torch.eye(3, dtype=E.dtype, device=E.device).expand_as(E).clone()
    best_t = torch.zeros_like(t)
    for Wm in (W, W.T):
        R = U @ Wm @ Vh
        for sign in (1.0, -1.0):
            tc = sign * t
            z0, z1 = triangulated_depths(R, tc, x0, x1)
            score = (w * ((z0 > 0) & (z1 > 0)).double()).sum(1)
            better = score > best_score
            best_score = torch.where(better, score, best_score)
            best_R = torch.where(better[:, None, None], R, best_R)
            best_t = torch.where(better[:, None], tc, best_t)
    return best_R, best_t, best_score


@torch.no_grad()
def refine_pose(R: Tensor, t: Tensor, x0: Tensor, x1: Tensor, weights: Tensor,
                iterations: int = 10, tau: float | None = None) -> tuple[Tensor, Tensor]:
    """Weighted Gauss-Newton (Levenberg-damped) refinement of ``(R, t)`` on the signed Sampson
    residuals, over the 5 degrees of freedom ``R <- exp([w]_x) R``, ``t <- normalise(t + B d)``.

    Args:
        R: ``[B, 3, 3]``; t: ``[B, 3]`` (normalised to unit length).
        x0, x1: normalised coordinates ``[B, N, 2]``; weights: ``[B, N]`` (zero = ignored).
        iterations: Gauss-Newton steps (default 10).
        tau: optional Cauchy scale (normalised units) that down-weights large residuals
            at every step; ``None`` keeps the given weights.

    Returns:
        refined ``R`` ``[B, 3, 3]`` and unit ``t`` ``[B, 3]`` (float64); a step that does not
        lower the weighted cost is rejected, so the cost never increases.
    """
    R, t = R.double().clone(), t.double().clone()
    t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    x0, x1, w = x0.double(), x1.double(), weights.double().clamp_min(0.0)
    lam = torch.full(R.shape[:1], 1e-4, dtype=R.dtype, device=R.device)
    eps = 1e-7

    def cost(Rc, tc):
        r = pose_sampson(Rc, tc, x0, x1)
        if tau is None:
            return (w * r.square()).sum(1), r, w
        rho = tau**2 * torch.log1p(r.square() / tau**2)  # Cauchy
        return (w * rho).sum(1), r, w / (1.0 + r.square() / tau**2)

    for _ in range(iterations):
        c0, r, ww = cost(R, t)
        B = tangent_basis(t)
        # numerical Jacobian (5 columns) in float64: cheap for N of a few thousand
        cols = []
        for k in range(5):
            dx = torch.zeros(R.shape[0], 5, dtype=R.dtype, device=R.device)
            dx[:, k] = eps
            Rk = so3_exp(dx[:, :3]) @ R
            tk = t + (B @ dx[:, 3:, None])[..., 0]
            tk = tk / tk.norm(dim=-1, keepdim=True)
            cols.append((pose_sampson(Rk, tk, x0, x1) - r) / eps)
        J = torch.stack(cols, dim=-1)  # [B, N, 5]
        H = J.transpose(-1, -2) @ (ww[..., None] * J)
        g = J.transpose(-1, -2) @ (ww * r)[..., None]
        eye = torch.eye(5, dtype=R.dtype, device=R.device)
        Hd = H + lam[:, None, None] * (torch.diagonal(H, dim1=-2, dim2=-1)[..., None] * eye
                                       + 1e-12 * eye)
        step = -torch.linalg.solve(Hd, g)[..., 0]
        Rn = so3_exp(step[:, :3]) @ R
        tn = t + (B @ step[:, 3:, None])[..., 0]
        tn = tn / tn.norm(dim=-1, keepdim=True)
        c1, _, _ = cost(Rn, tn)
        better = torch.isfinite(c1) & (c1 <= c0)
        R = torch.where(better[:, None, None], Rn, R)
        t = torch.where(better[:, None], tn, t)
        lam = torch.where(better, lam * 0.3, lam * 10.0).clamp(1e-9, 1e6)
    return R, t
