"""Bootstrap covariance of a classical robust pose: the part of the uncertainty that the
first-order (Jacobian) covariance cannot see.

The first-order covariance of :func:`strl_pyg.estimation.pose_fusion.classical_covariance`
describes the noise of a *correct* solution around it. A robust solver also fails in ways that
have nothing to do with that noise: a wrong RANSAC solution, a near-degenerate configuration (an
object filling little of the image, low texture) where several poses explain the inliers about
as well. Then the estimate moves far when the matches change a little. The bootstrap measures
exactly that: the solver is re-run on ``n`` resamples (with replacement) of the point matches
and the covariance of the resampled poses, in the tangent chart of the estimate, is returned.
The estimators' ``poselib`` / ``opencv`` / ``guided`` records carry first-order + bootstrap
covariances, the ``fused`` one information form + the classical bootstrap
(:class:`strl_pyg.inference.PoseEstimator`, ``bootstrap=8``, ``PoseMethod.bootstrapped``),
calibrated with one scale per method (``benchmarks/bench_pose.py --calibrate``). """

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import POSELIB, estimate_relative_pose
from strl_pyg.geometry import Pose
from strl_pyg.utils.threads import available_cores, shared_pool

__all__ = ["bootstrap_covariance", "bootstrap_resamples", "Bootstrap", "cap_covariance",
           "MIN_BOOTSTRAP", "FAR_ROTATION_DEG", "FAR_TRANSLATION_DEG",
           "MAX_SIGMA_DEG", "data_covariance", "swap_covariance"]

# Which methods' records carry first-order + bootstrap covariances is their registry entry's
# (PoseMethod.bootstrapped; strl_pyg.inference.BOOTSTRAPPED lists them): ``guided`` carries
# the bootstrap of its chosen classical solve, ``fused`` that of the classical estimate it
# starts from.

#: Fewest resamples that give a covariance (a 5x5 covariance from fewer is mostly noise).
MIN_BOOTSTRAP = 3

#: A resample whose pose is this far from the estimate (rotation, or translation direction)
#: found another solution, not the same one with other noise: far beyond the first-order
#: spread of any pair the solvers call supported (tenths of a degree to a few degrees).
FAR_ROTATION_DEG = 10.0
FAR_TRANSLATION_DEG = 30.0

#: The largest RMS angle a sigma can state: no rotation or direction is further than 180 deg
#: from another, so a larger sigma says nothing more (:func:`cap_covariance`).
MAX_SIGMA_DEG = 180.0


@dataclass
class Bootstrap:
    """:func:`bootstrap_resamples`: the second moment ``covariance`` ``[5, 5]`` of the
    resampled poses about the estimate, how many ``resamples`` gave a pose, and how many of
    them are ``far`` (:data:`FAR_ROTATION_DEG` / :data:`FAR_TRANSLATION_DEG`): resamples that
    disagree with the estimate about the solution itself."""

    covariance: np.ndarray
    resamples: int
    far: int


def cap_covariance(cov: np.ndarray) -> tuple[np.ndarray, bool]:
    """``cov`` ``[5, 5]`` (tangent parameters, rad) with its rotation and translation blocks
    each scaled down so that the RMS angle ``sqrt(trace)`` is at most :data:`MAX_SIGMA_DEG`;
    and whether it was capped. A first-order Gaussian in a chart of the sphere or of SO(3)
    means nothing beyond that (the calibrated bootstrap of an ambiguous pair reached 203 deg)."""
    cov = np.array(cov, dtype=np.float64, copy=True)
    limit = np.radians(MAX_SIGMA_DEG) ** 2
    capped = False
    for sl in (slice(0, 3), slice(3, 5)):
        tr = float(np.trace(cov[sl, sl]))
        if tr > limit:
            cov[sl, :] *= np.sqrt(limit / tr)
            cov[:, sl] *= np.sqrt(limit / tr)
            capped = True
    return cov, capped


def bootstrap_covariance(matches: PairMatches, pose: Pose, method: str = POSELIB,
                         n: int = 8, threshold_px: float = 1.0, seed: int = 0,
                         workers: int | None = None) -> np.ndarray | None:
    """The covariance of :func:`bootstrap_resamples` (``None`` with fewer than
    :data:`MIN_BOOTSTRAP` poses); arguments as there."""
    boot = bootstrap_resamples(matches, pose, method, n, threshold_px, seed, workers)
    return None if boot is None else boot.covariance


def _solve_resamples(matches: PairMatches, draws: list, method: str, threshold_px: float,
                     seed: int, workers: int) -> list:
    """The solver's result on each resample (``draws``: row indices), in ``workers``
    threads; resample ``b`` is solved with seed ``seed + b + 1``."""
    n = len(draws)
    fast = template = None
    if method == POSELIB and matches.has_intrinsics:
        # the pair normalised once, the resamples' rows taken from it (normalising is per
        # point, so this is the same input as normalising each resample)
        import poselib

        from strl_pyg.estimation.classical import _normalised, poselib_normalised

        fast = _normalised(matches, threshold_px)
    else:
        # points only: the solver reads neither lines nor images. The first resample is
        # built (and checked) as a PairMatches; the others are copies of it with their points
        # swapped in: rows of points already checked need no second check (which held the
        # GIL for ~0.5 ms per resample, the threads' solves waiting on it)
        template = replace(matches, points0=matches.points0[draws[0]],
                           points1=matches.points1[draws[0]],
                           point_scores=None if matches.point_scores is None
                           else matches.point_scores[draws[0]], lines0=None, lines1=None,
                           line_scores=None, image0=None, image1=None)

    def solve(b: int):
        if fast is not None:
            idx = draws[b]
            return poselib_normalised(np.ascontiguousarray(fast[0][idx]),
                                      np.ascontiguousarray(fast[1][idx]), fast[2], poselib,
                                      seed=seed + b + 1)
        sample = template
        if b:
            idx = draws[b]
            sample = copy.copy(template)
            sample.points0, sample.points1 = matches.points0[idx], matches.points1[idx]
            if matches.point_scores is not None:
                sample.point_scores = matches.point_scores[idx]
        return estimate_relative_pose(sample, method, threshold_px, seed=seed + b + 1)

    workers = min(workers, n)
    if workers == 1:
        results = [solve(b) for b in range(n)]
    else:  # one task per worker (resamples w, w + workers, ...); the last chunk runs here
        chunks = [range(w, n, workers) for w in range(workers)]
        futures = [shared_pool("bootstrap", workers - 1).submit(lambda c=c: [solve(b) for b in c])
                   for c in chunks[1:]]
        by_index = dict(zip(chunks[0], [solve(b) for b in chunks[0]], strict=True))
        for c, f in zip(chunks[1:], futures, strict=True):
            by_index.update(zip(c, f.result(), strict=True))
        results = [by_index[b] for b in range(n)]
    return results


def bootstrap_resamples(matches: PairMatches, pose: Pose, method: str = POSELIB,
                        n: int = 8, threshold_px: float = 1.0, seed: int = 0,
                        workers: int | None = None) -> Bootstrap | None:
    """Covariance ``[5, 5]`` (float64) of the robust estimate ``pose`` of ``matches``, from
    ``n`` bootstrap resamples of its point matches, in the tangent parameters of
    :func:`strl_pyg.estimation.pose_fusion.pose_to_tangent` (rotation increment ``w``, rad;
    translation direction on the sphere, rad) around ``pose``.

    Each resample draws ``num_points`` point matches with replacement (seeded: the same inputs
    give the same covariance) and runs :func:`~strl_pyg.estimation.estimate_relative_pose` with
    ``method``; line segments are not used. The covariance is the second moment of the
    resampled poses' tangent coordinates about ``pose`` (so a consistent offset counts, not
    only the spread). Returns ``None`` when fewer than
    :data:`MIN_BOOTSTRAP` resamples gave a pose.

    The resamples are solved in ``workers`` threads (default: one per available core, at most
    ``n``; PoseLib and OpenCV release the GIL): every resample's draw and solver seed are fixed
    before any is solved, so the covariance is the same for any ``workers`` (tested).
    """
    from strl_pyg.estimation.pose_fusion import pose_to_tangent
    from strl_pyg.geometry import tangent_basis

    if not isinstance(matches, PairMatches):
        raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
    if not isinstance(pose, Pose) or pose.R.dim() != 2:
        raise TypeError(f"Expected an unbatched Pose (got {type(pose).__name__})")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < MIN_BOOTSTRAP:
        raise ValueError(f"Expected n as an integer >= {MIN_BOOTSTRAP} (got {n!r})")
    if not threshold_px > 0:
        raise ValueError(f"Expected threshold_px > 0 (got {threshold_px!r})")
    n = int(n)
    R0 = pose.R.double()
    t0 = pose.t.double()
    norm = float(t0.norm())
    if not norm > 0:
        raise ValueError("Expected a pose with a non-zero translation (got t = 0)")
    t0 = t0 / norm
    basis = tangent_basis(t0)
    if workers is None:
        workers = available_cores()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ValueError(f"Expected workers as an integer >= 1 or None (got {workers!r})")
    rng = np.random.default_rng(seed)
    draws = [rng.integers(0, matches.num_points, matches.num_points) for _ in range(n)]

    results = _solve_resamples(matches, draws, method, threshold_px, seed, int(workers))
    ok = [r.pose for r in results if r.success]
    if len(ok) < MIN_BOOTSTRAP:
        return None
    X = pose_to_tangent(Pose(torch.stack([p.R for p in ok]), torch.stack([p.t for p in ok])),
                        R0, t0, basis).numpy().astype(np.float64)
    # second moment about the estimate (the chart origin), not about the resamples' mean: when
    # the resamples agree on another solution, that offset is part of the uncertainty
    rot = np.degrees(np.linalg.norm(X[:, :3], axis=1))
    trans = np.degrees(np.linalg.norm(X[:, 3:], axis=1))
    far = int(((rot > FAR_ROTATION_DEG) | (trans > FAR_TRANSLATION_DEG)).sum())
    return Bootstrap(X.T @ X / len(X), len(X), far)


def data_covariance(rotation_rad: float, translation_rad: float) -> np.ndarray:
    """The ``[5, 5]`` tangent covariance that the regression's data check adds
    (:attr:`strl_pyg.inference.methods.MethodContext.data_check`), before its calibration scale as
    the swap check's term:
    the classical pose is far more precise than the network's where it is right, so the
    distance to it stands for the network's own error, its square spread over the 3 rotation
    and the 2 direction axes (``d_R^2 / 3``, ``d_t^2 / 2``). Where the classical pose is wrong
    the term is wide whatever the network's error (conservative). The regression's record
    carries it; the fusion does not (its consistency gate compares the network with the same
    classical pose: the term would let every network pose pass it)."""
    return np.diag([rotation_rad ** 2 / 3] * 3 + [translation_rad ** 2 / 2] * 2)


def swap_covariance(rotation_rad: float, translation_rad: float) -> np.ndarray:
    """The ``[5, 5]`` tangent covariance that a disagreement between the network's pose and
    the inverse of its pose of the swapped pair adds
    (:attr:`strl_pyg.inference.methods.MethodContext.swap_check`): were
    the two errors independent and alike, their difference would hold twice the variance of
    each, spread over the 3 rotation and the 2 direction axes, so ``d_R^2 / 6`` and
    ``d_t^2 / 4`` per axis. The network's own log-variances are fitted on the training
    distribution and stay small away from it; the two passes disagree there."""
    return np.diag([rotation_rad ** 2 / 6] * 3 + [translation_rad ** 2 / 4] * 2)
