"""Relative pose from few points and many lines: vanishing-point rotation, 2-point translation.

A line match alone does not constrain the relative pose (two image lines always back-project
to intersecting planes), but a family of parallel scene lines does: its vanishing direction
``d0`` in camera 0 and ``d1`` in camera 1 satisfy ``d1 = +-R d0``. Two such families give the
rotation; with ``R`` known, every point match gives one linear constraint on the translation
direction (``t . (x1 x R x0) = 0``), so two point matches fix it. That is the solver of this
module (:func:`vanishing_point_pose`), for the regime where the 5-point solvers have too few
point matches to find or support a pose:

1. **Vanishing directions of the matched lines**, found jointly in both images: RANSAC over
   pairs of line matches (each pair, if parallel in the scene, gives ``d0`` and ``d1``), the
   consensus being the line matches whose segments point at the vanishing point within
   ``line_threshold_px`` in *both* images; up to three directions, greedily, each refined on
   its lines (the null vector of their interpretation-plane normals).
2. **Rotation hypotheses** from every pair of directions at least
   :data:`VP_MIN_SEPARATION_DEG` apart (no such pair: no answer) and every sign assignment that
   keeps their angle (``R`` preserves ``d0a . d0b``), by orthogonal Procrustes.
3. **Translation** for each rotation by 2-point RANSAC over the point matches (every pair
   when there are few), scored by MSAC on the Sampson distance, its sign by cheirality.
4. The best hypothesis and any given start (``starts``: the 5-point solver's, from
   :class:`~strl_pyg.inference.PoseEstimator`) are refined jointly on all the points and the
   lines of the vanishing directions (:func:`refine_with_lines`); the lowest cost wins (the
   lines pin the rotation the translation needs). ``line_sigma_px=None``: the inlier points.

The result is a :class:`~strl_pyg.estimation.classical.BaselineResult` (method ``"vp"``), and
:class:`~strl_pyg.inference.PoseEstimator` checks its support on the point matches like every
solver's (:func:`~strl_pyg.inference.support.check_support`).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation import line_refine
from strl_pyg.estimation.classical import BaselineResult, _failed, normalised_matches
from strl_pyg.estimation.line_refine import (
    _homogeneous,
    refine_with_lines,
    segment_geometry,
    vp_residual_px,
)
from strl_pyg.geometry import Pose, check_rotation, pose_sampson

__all__ = ["vanishing_directions", "vanishing_point_pose", "VP_MIN_LINES", "VP_MIN_POINTS",
           "VP_MIN_SEPARATION_DEG"]

#: Line matches a vanishing direction needs (in both images) to be used.
VP_MIN_LINES = 4
#: Point matches the translation needs at the least (two fix it; the rest check it).
VP_MIN_POINTS = 5
#: The lines inform the pose only when two of their shared vanishing directions are at least
#: this far apart (deg): the rotation of two nearly parallel directions is ill-conditioned about
#: the axis between them, and one direction leaves a rotation free. A conditioning bound, not a
#: fit: on the calibration split 30, 45 and 60 deg score alike; on the dino's curved outlines the
#: directions found lay 10-13 deg apart (``benchmarks/studies/results_vanishing.md``).
VP_MIN_SEPARATION_DEG = 30.0


def _directions_text(n: int, separation: float | None) -> str:
    """What the matched lines share, in words (``vp``'s reason for failing)."""
    if n == 0:
        return "the matched lines of both images share no vanishing direction"
    if n == 1:
        return "the matched lines of both images share only one vanishing direction"
    apart = f", only {separation:.0f} deg apart" if separation is not None and \
        np.isfinite(separation) else ""
    return f"the matched lines of both images share {n} vanishing directions{apart}"


def vanishing_directions(matches: PairMatches, line_threshold_px: float = 2.0,
                         max_directions: int = 3, min_lines: int = VP_MIN_LINES,
                         max_hypotheses: int = 3000, min_angle_deg: float = 10.0,
                         seed: int = 0) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Vanishing directions shared by the matched lines of both images (module docstring).

    Returns:
        up to ``max_directions`` tuples ``(d0, d1, inliers)``: unit directions in camera 0 and
        camera 1 coordinates (``d1 = +-R d0``; the sign is not known) and the boolean mask of
        the line matches that point at them in both images, strongest first.
    """
    if matches.num_lines < 2 or not matches.has_intrinsics:
        return []
    K0, K1 = np.asarray(matches.K0, float), np.asarray(matches.K1, float)
    e0, m0, n0 = segment_geometry(np.asarray(matches.lines0, float), K0)
    e1, m1, n1 = segment_geometry(np.asarray(matches.lines1, float), K1)
    M = len(n0)
    rng = np.random.default_rng(seed)
    pairs = np.array(np.triu_indices(M, 1)).T
    if len(pairs) > max_hypotheses:
        pairs = pairs[rng.choice(len(pairs), max_hypotheses, replace=False)]
    free = np.ones(M, dtype=bool)
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    cos_min = np.cos(np.radians(min_angle_deg))
    for _ in range(max_directions):
        ok = free[pairs[:, 0]] & free[pairs[:, 1]]
        hyp = pairs[ok]
        if len(hyp) == 0:
            break
        d0 = np.cross(n0[hyp[:, 0]], n0[hyp[:, 1]])
        d1 = np.cross(n1[hyp[:, 0]], n1[hyp[:, 1]])
        good = (np.linalg.norm(d0, axis=1) > 1e-6) & (np.linalg.norm(d1, axis=1) > 1e-6)
        d0, d1 = d0[good], d1[good]
        if len(d0) == 0:
            break
        d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
        d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
        if found:  # not (nearly) a direction already found
            prev = np.stack([f[0] for f in found])
            keep = (np.abs(d0 @ prev.T) < cos_min).all(axis=1)
            d0, d1 = d0[keep], d1[keep]
            if len(d0) == 0:
                break
        inl = ((vp_residual_px(d0, K0, e0, m0) < line_threshold_px)
               & (vp_residual_px(d1, K1, e1, m1) < line_threshold_px) & free[None])
        best = int(inl.sum(axis=1).argmax())
        mask = inl[best]
        if mask.sum() < min_lines:
            break
        # refine on the inlier lines: the direction closest to every interpretation plane,
        # its consensus again (twice), and the direction of the last consensus
        for i in range(3):
            d0b = np.linalg.svd(n0[mask], full_matrices=False)[2][-1]
            d1b = np.linalg.svd(n1[mask], full_matrices=False)[2][-1]
            if i == 2:
                break
            new = ((vp_residual_px(d0b[None], K0, e0, m0)[0] < line_threshold_px)
                   & (vp_residual_px(d1b[None], K1, e1, m1)[0] < line_threshold_px) & free)
            if new.sum() < min_lines:
                break
            mask = new
        if found and (np.abs(np.stack([f[0] for f in found]) @ d0b) >= cos_min).any():
            break
        found.append((d0b, d1b, mask))
        free &= ~mask
    return found


def _procrustes(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation ``R`` minimising ``sum |b_i - R a_i|^2`` (``a``, ``b`` ``[k, 3]``)."""
    U, _, Vt = np.linalg.svd(b.T @ a)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def _separation_deg(dirs) -> float:
    """The widest angle (deg, at most 90) between two of the directions in camera 0; 0 for
    fewer than two."""
    D = np.array([d[0] for d in dirs]).reshape(-1, 3)
    c = np.abs(D @ D.T)[np.triu_indices(len(D), 1)]
    return float(np.degrees(np.arccos(np.clip(c.min(), 0.0, 1.0)))) if len(c) else 0.0


def _rotations(dirs, max_angle_error_deg: float) -> list[np.ndarray]:
    """Rotation hypotheses of every pair of directions at least :data:`VP_MIN_SEPARATION_DEG`
    apart and every sign assignment (module step 2)."""
    out = []
    tol = np.sin(np.radians(max_angle_error_deg))
    for i in range(len(dirs)):
        for j in range(i + 1, len(dirs)):
            a0, a1 = dirs[i][0], dirs[i][1]
            b0, b1 = dirs[j][0], dirs[j][1]
            if _separation_deg([dirs[i], dirs[j]]) < VP_MIN_SEPARATION_DEG:
                continue
            for sa in (1.0, -1.0):
                for sb in (1.0, -1.0):
                    u1, v1 = sa * a1, sb * b1
                    if abs(a0 @ b0 - u1 @ v1) > tol:
                        continue  # R keeps the angle between two directions
                    c0 = np.cross(a0, b0)
                    c1 = np.cross(u1, v1)
                    out.append(_procrustes(np.stack([a0, b0, c0 / np.linalg.norm(c0)]),
                                           np.stack([u1, v1, c1 / np.linalg.norm(c1)])))
    return out


def _sampson(R: np.ndarray, T: np.ndarray, x0: torch.Tensor, x1: torch.Tensor) -> np.ndarray:
    """Sampson distances ``[P, N]`` of the matches (normalised ``[N, 2]``) under ``R`` and the
    translations ``T`` ``[P, 3]``, in closed form (the fast path; :func:`_sampson_reference`,
    the package's one Sampson under a pose, is its reference).

    With ``r = R h0`` and ``E = [t]_x R``, every term is linear in ``t``: ``h1 . E h0 = t . (r x
    h1)``, ``(E h0)_{x,y} = t . (0, r_z, -r_y), t . (-r_z, 0, r_x)`` and ``(E^T h1)_j = t .
    (R_j x h1)`` (``R_j`` the ``j``-th column): five ``[P, 3] @ [3, N]`` products instead of
    ``P`` essential matrices applied to every match."""
    R, T = np.asarray(R, float), np.asarray(T, float)
    h0, h1 = _homogeneous(x0.numpy()), _homogeneous(x1.numpy())
    r = h0 @ R.T
    zero = np.zeros(len(r))
    num = T @ np.cross(r, h1).T
    den = ((T @ np.stack([zero, r[:, 2], -r[:, 1]])) ** 2
           + (T @ np.stack([-r[:, 2], zero, r[:, 0]])) ** 2
           + (T @ np.cross(R[:, 0], h1).T) ** 2 + (T @ np.cross(R[:, 1], h1).T) ** 2)
    return np.abs(num) / np.sqrt(den + 1e-300)


def _sampson_reference(R: np.ndarray, T: np.ndarray, x0: torch.Tensor,
                       x1: torch.Tensor) -> np.ndarray:
    """:func:`_sampson` through :func:`~strl_pyg.geometry.pose_sampson`, batched over the
    hypotheses."""
    P = len(T)
    r = pose_sampson(torch.from_numpy(R).expand(P, 3, 3), torch.from_numpy(T),
                     x0.expand(P, -1, -1), x1.expand(P, -1, -1))
    return r.abs().numpy()


def _in_front(R: np.ndarray, t: np.ndarray, h0: np.ndarray, h1: np.ndarray) -> np.ndarray:
    """Whether each match triangulates in front of both cameras (midpoint of the rays)."""
    from strl_pyg.geometry.essential import triangulated_depths

    z0, z1 = triangulated_depths(torch.from_numpy(R)[None], torch.from_numpy(t)[None],
                                 torch.from_numpy(h0[:, :2])[None],
                                 torch.from_numpy(h1[:, :2])[None])
    return ((z0[0] > 0) & (z1[0] > 0)).numpy()


def _as_Rt(pose) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` float64 numpy of a ``Pose`` or a ``(4, 4)`` / ``(3, 4)`` ``T_0to1``."""
    T = pose.matrix().numpy() if isinstance(pose, Pose) else np.asarray(pose, float)
    if T.shape not in ((4, 4), (3, 4)) or not np.isfinite(T).all():
        raise ValueError(f"Expected a start as a Pose or a finite (4, 4) / (3, 4) T_0to1 "
                         f"(got {type(pose).__name__} of shape {getattr(T, 'shape', None)})")
    if np.linalg.norm(T[:3, 3]) < 1e-12:
        raise ValueError("Expected a start with a nonzero translation (got t = 0)")
    check_rotation(T[:3, :3], "a start's rotation")
    return T[:3, :3], T[:3, 3]


def _best_translation(rotations: list, pairs: np.ndarray, h0: np.ndarray, h1: np.ndarray,
                      x0, x1, thr: float) -> tuple | None:
    """For each rotation, the translation of a point pair (``t . a_k = 0`` for both) that
    explains the most matches (MSAC), refit on its inliers, its sign by cheirality; the best
    ``(in front, -cost, R, t, inliers)`` over the rotations (``None``: no pair gave one)."""
    best = None
    for R in rotations:
        a = np.cross(h1, h0 @ R.T)  # t . a_k = 0 for every match
        T = np.cross(a[pairs[:, 0]], a[pairs[:, 1]])
        norm = np.linalg.norm(T, axis=1)
        keep = norm > 1e-12
        if not keep.any():
            continue
        T = T[keep] / norm[keep, None]
        r = _sampson(R, T, x0, x1)
        cost = np.minimum(r, thr) ** 2
        k = int(cost.sum(axis=1).argmin())
        t = T[k]
        inl = r[k] < thr
        if inl.sum() >= 2:  # least squares on the inliers, then the sign by cheirality
            t = np.linalg.svd(a[inl], full_matrices=False)[2][-1]
        front_p, front_m = _in_front(R, t, h0, h1), _in_front(R, -t, h0, h1)
        if (front_m & inl).sum() > (front_p & inl).sum():
            t, front_p = -t, front_m
        score = (int((front_p & inl).sum()), -float(cost[k].sum()))
        if best is None or score > best[:2]:
            best = (*score, R, t, inl & front_p)
    return best


def _refine_jointly(matches: PairMatches, cands: list, dirs: list,
                    line_sigma_px: float) -> list:
    """The points and the lines of the directions together, from each candidate ``(name, R,
    t)``; all on one cost (every point, Cauchy-robust; the sign of t does not change it), so
    the lowest is the pose that explains the points and the lines best. Returns ``[(cost,
    name, R, t)]`` of the finite refinements."""
    every = np.ones(matches.num_points, dtype=bool)
    out = []
    for name, Rs, ts in cands:
        Rr, tr, c = refine_with_lines(matches, Rs, ts, dirs, every, line_sigma_px,
                                      return_cost=True)
        if np.isfinite(c) and np.isfinite(Rr).all() and np.isfinite(tr).all():
            out.append((c, name, Rr, tr))
    return out


def vanishing_point_pose(matches: PairMatches, threshold_px: float = 1.0,
                         line_threshold_px: float = 2.0, max_pairs: int = 500,
                         max_angle_error_deg: float = 3.0, max_refine_deg: float = 5.0,
                         seed: int = 0, directions: list | None = None,
                         line_sigma_px: float | None = line_refine.VP_LINE_SIGMA_PX,
                         starts: list | None = None) -> BaselineResult:
    """``T_0to1`` from the vanishing directions of the matched lines and the point matches
    (module docstring).

    Args:
        matches: a :class:`~strl_pyg.data.PairMatches` with ``K0``, ``K1``, at least
            :data:`VP_MIN_POINTS` point matches and line matches.
        threshold_px: inlier threshold on the points' Sampson distance (pixels).
        line_threshold_px: how far (pixels) a segment's endpoints may lie from the line through
            its midpoint and a vanishing point.
        max_pairs: point pairs tried per rotation (all pairs when there are fewer).
        max_angle_error_deg: how far the angle between two directions may differ between the
            images for the pair to give a rotation.
        max_refine_deg: with ``line_sigma_px=None``, the points-only refinement is kept only
            within this rotation of the vanishing-point rotation.
        seed: the RANSAC samples.
        directions: :func:`vanishing_directions` of ``matches`` (with ``line_threshold_px`` and
            ``seed``) when the caller has them already; computed here when ``None``.
        line_sigma_px: the lines' weight in the final refinement (:func:`refine_with_lines`);
            ``None`` refines on the inlier points alone (at least 5), as before. The default
            is :data:`~strl_pyg.estimation.line_refine.VP_LINE_SIGMA_PX` as it was when this
            module was imported; the method ``vp`` passes the constant's value at each call.
        starts: other poses (``Pose`` or ``(4, 4)`` / ``(3, 4)`` arrays ``T_0to1``, e.g. the
            5-point solver's) refined like the vanishing-point hypothesis; the refined pose
            of lowest robust cost on all the points and the directions' lines is returned
            (``info["start"]``: ``"vp"`` or the index in ``starts``). Needs ``line_sigma_px``.

    Returns:
        a :class:`BaselineResult` (``success=False`` with ``info["reason"]`` when no two shared
        vanishing directions are :data:`VP_MIN_SEPARATION_DEG` apart, when no translation has
        two point matches in front of both cameras and no start is given, or when the refined
        pose keeps fewer than two); ``info`` holds ``directions`` (how many),
        ``direction_lines`` (their line counts), ``separation_deg`` (the widest two's angle),
        ``refined`` and, with ``line_sigma_px``, ``start``.
    """
    if not isinstance(matches, PairMatches):
        raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
    if not matches.has_intrinsics:
        raise ValueError("Expected intrinsics K0 and K1 in the PairMatches (got none)")
    if matches.num_points < VP_MIN_POINTS:
        raise ValueError(f"Expected at least {VP_MIN_POINTS} point matches "
                         f"(got {matches.num_points})")
    if not (threshold_px > 0 < line_threshold_px
            and (line_sigma_px is None or 0 < line_sigma_px < np.inf)):
        raise ValueError(f"Expected threshold_px, line_threshold_px, line_sigma_px > 0 (the "
                         f"last finite, or None)"
                         f" (got {threshold_px}, {line_threshold_px}, {line_sigma_px})")
    if starts and line_sigma_px is None:
        raise ValueError("Expected line_sigma_px with starts (the starts are compared on the "
                         "joint refinement's cost; got line_sigma_px=None)")
    given = [_as_Rt(s) for s in (starts or ())]
    start = time.perf_counter()
    n = matches.num_points
    dirs = (vanishing_directions(matches, line_threshold_px, seed=seed) if directions is None
            else directions)
    info = {"directions": len(dirs), "direction_lines": [int(d[2].sum()) for d in dirs],
            "separation_deg": _separation_deg(dirs)}
    if not info["separation_deg"] >= VP_MIN_SEPARATION_DEG:  # NaN directions too
        return _failed(n, "vp", (time.perf_counter() - start) * 1e3, **info,
                       reason=_directions_text(len(dirs), info["separation_deg"])
                       + f": vp needs two at least {VP_MIN_SEPARATION_DEG:g} deg apart")
    rotations = _rotations(dirs, max_angle_error_deg)
    if not rotations:  # the lines fix no rotation: a start is not refined on them either
        return _failed(n, "vp", (time.perf_counter() - start) * 1e3, **info,
                       reason=_directions_text(len(dirs), None)
                       + ": vp needs two at an angle both images agree on")
    x0, x1, focal = normalised_matches(matches)
    h0, h1 = _homogeneous(x0.numpy()), _homogeneous(x1.numpy())
    thr = threshold_px / focal
    pairs = np.array(np.triu_indices(n, 1)).T
    if len(pairs) > max_pairs:
        rng = np.random.default_rng(seed)
        pairs = pairs[rng.choice(len(pairs), max_pairs, replace=False)]
    best = _best_translation(rotations, pairs, h0, h1, x0, x1, thr)
    found = best is not None and best[0] >= 2
    if not found and not (given and line_sigma_px is not None):
        return _failed(n, "vp", (time.perf_counter() - start) * 1e3, **info,
                       reason="no translation direction has two point matches in front of "
                              "both cameras")
    R, t, inl = best[2:] if found else (None, None, None)
    refined = False
    if line_sigma_px is not None:
        cands = ([("vp", R, t)] if found else []) + [(i, *rt) for i, rt in enumerate(given)]
        out = _refine_jointly(matches, cands, dirs, line_sigma_px)
        if not out:
            return _failed(n, "vp", (time.perf_counter() - start) * 1e3, **info,
                           reason="the joint refinement gave no finite pose")
        _, info["start"], R, t = min(out, key=lambda o: o[0])
        close = _sampson(R, t[None], x0, x1)[0] < thr
        if (_in_front(R, -t, h0, h1) & close).sum() > (_in_front(R, t, h0, h1) & close).sum():
            t = -t
        refined = True
    elif inl.sum() >= 5:  # the points alone (the solver before the joint refinement)
        from strl_pyg.geometry.essential import refine_pose
        from strl_pyg.geometry.pose import rotation_angle_deg

        Rr, tr = refine_pose(torch.from_numpy(R)[None], torch.from_numpy(t)[None],
                             x0[None], x1[None], torch.from_numpy(inl.astype(float))[None])
        Rr, tr = Rr[0].numpy(), tr[0].numpy()
        if float(rotation_angle_deg(torch.from_numpy(Rr.T @ R))) <= max_refine_deg:
            R, t, refined = Rr, tr, True
    r = _sampson(R, t[None], x0, x1)[0]
    inl = (r < thr) & _in_front(R, t, h0, h1)
    info["refined"] = refined
    if inl.sum() < 2:
        return _failed(n, "vp", (time.perf_counter() - start) * 1e3, **info,
                       reason="the refined pose has fewer than two point matches in front of "
                              "both cameras")
    return BaselineResult(Pose(R, t / np.linalg.norm(t)), inl,
                          (time.perf_counter() - start) * 1e3, "vp", True, info)
