"""Classical relative-pose baselines on the same match lists as the learned model.

* ``"opencv"``: ``cv2.findEssentialMat`` with ``USAC_MAGSAC`` on normalised coordinates, then
  ``cv2.recoverPose`` (cheirality check picks one of the four decompositions).
* ``"poselib"``: ``poselib.estimate_relative_pose`` (LO-RANSAC with non-linear refinement);
  PoseLib is an optional dependency (``pip install strl-pyg[poselib]``).

Both use only the point matches of a :class:`~strl_pyg.data.PairMatches` (line endpoints are
not point correspondences) and need its intrinsics. Both return the same
:class:`BaselineResult`: ``T_0to1`` (``X1 = R X0 + t``) with a **unit** translation, the
inlier mask and the wall time. The threshold is in pixels: OpenCV applies it in image 0's
pixels (image 1 is re-expressed with ``K0``), PoseLib in normalised units scaled by the mean
focal length of both cameras; the two agree when both cameras share a focal length.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.geometry import Pose, normalize_points

__all__ = ["BaselineResult", "BASELINE_METHODS", "OPENCV", "POSELIB", "preferred_solver",
           "MIN_POINTS", "estimate_relative_pose",
           "mean_focal", "normalised_matches", "normalisation_scope", "have_poselib",
           "fundamental_matrix", "MIN_POINTS_FUNDAMENTAL"]

#: Point matches of the seven/eight-point fundamental-matrix estimate (its minimal sample is
#: 7; MAGSAC's final fit uses 8).
MIN_POINTS_FUNDAMENTAL = 8

#: The two solvers' names (:func:`estimate_relative_pose`'s ``method``; the inference methods
#: of the same names).
OPENCV, POSELIB = "opencv", "poselib"

#: Methods accepted by :func:`estimate_relative_pose`.
BASELINE_METHODS = (OPENCV, POSELIB)

#: Five correspondences determine an essential matrix (up to a finite set).
MIN_POINTS = 5


@dataclass
class BaselineResult:
    """Output of :func:`estimate_relative_pose`.

    Attributes:
        pose: ``T_0to1`` as a float64 :class:`~strl_pyg.geometry.Pose` (unbatched) with
            ``|t| = 1``; the identity with ``t = 0`` when ``success`` is ``False`` (its
            translation error is then ``NaN``, which :func:`~strl_pyg.metrics.two_view.pose_auc`
            counts as a failure).
        inliers: boolean mask over the point matches, shape ``[Np]``.
        time_ms: wall time of the estimator call(s) in milliseconds (normalising the points
            included, building the ``PairMatches`` excluded).
        method: ``"opencv"`` or ``"poselib"``.
        success: whether a pose was found.
        info: the library's extra output (e.g. PoseLib's iteration count).
    """

    pose: Pose
    inliers: np.ndarray
    time_ms: float
    method: str
    success: bool = True
    info: dict = field(default_factory=dict)

    @property
    def num_inliers(self) -> int:
        return int(self.inliers.sum())

    @property
    def T_0to1(self) -> Pose:
        return self.pose


def _failed(n: int, method: str, time_ms: float, **info: Any) -> BaselineResult:
    return BaselineResult(Pose.identity(), np.zeros(n, dtype=bool), time_ms, method, False, info)


def estimate_relative_pose(
    matches: PairMatches,
    method: str = OPENCV,
    threshold_px: float = 1.0,
    confidence: float = 0.9999,
    max_iterations: int = 10000,
    seed: int = 0,
) -> BaselineResult:
    """Estimates ``T_0to1`` from the point matches of one image pair.

    Args:
        matches: a :class:`~strl_pyg.data.PairMatches` with ``K0``, ``K1`` and at least 5
            point matches (pixels, OpenCV convention).
        method: ``"opencv"`` (default) or ``"poselib"``.
        threshold_px: inlier threshold in pixels on the epipolar (Sampson) error; divided by
            the mean focal length to get normalised units (default 1.0).
        confidence: RANSAC success probability (default 0.9999).
        max_iterations: RANSAC iteration cap (default 10000).
        seed: seeds ``cv2.setRNGSeed`` and PoseLib's ``seed``, so results are reproducible.

    Returns:
        :class:`BaselineResult`.
    """
    if not isinstance(matches, PairMatches):
        raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
    if method not in BASELINE_METHODS:
        raise ValueError(f"Expected method in {BASELINE_METHODS} (got {method!r})")
    if not matches.has_intrinsics:
        raise ValueError("Expected intrinsics K0 and K1 in the PairMatches (got none)")
    if matches.num_points < MIN_POINTS:
        raise ValueError(
            f"Expected at least {MIN_POINTS} point matches (got {matches.num_points})"
        )
    if not (threshold_px > 0):
        raise ValueError(f"Expected threshold_px > 0 (got {threshold_px})")
    if not (0 < confidence < 1):
        raise ValueError(f"Expected 0 < confidence < 1 (got {confidence})")
    if method == POSELIB:
        try:
            import poselib
        except ImportError as err:
            raise ImportError(
                "method='poselib' needs the optional dependency PoseLib: "
                "pip install poselib (or pip install strl-pyg[poselib])"
            ) from err
        return _poselib(matches, poselib, threshold_px, confidence, max_iterations, seed)
    return _opencv(matches, threshold_px, confidence, max_iterations, seed)


def fundamental_matrix(matches: PairMatches, threshold_px: float = 1.0, seed: int = 0,
                       confidence: float = 0.9999, max_iterations: int = 10_000
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """The fundamental matrix ``F`` (``x1^T F x0 = 0``, pixels) of the point matches by
    OpenCV's ``USAC_MAGSAC``, for pairs without intrinsics: the epipolar geometry they
    determine when no metric pose can be had. Returns ``(F [3, 3], inlier mask [Np])`` or
    ``None`` (fewer than :data:`MIN_POINTS_FUNDAMENTAL` matches, or no model)."""
    if matches.num_points < MIN_POINTS_FUNDAMENTAL:
        return None
    cv2.setRNGSeed(int(seed))
    try:
        F, mask = cv2.findFundamentalMat(
            np.ascontiguousarray(matches.points0, dtype=np.float64),
            np.ascontiguousarray(matches.points1, dtype=np.float64),
            cv2.USAC_MAGSAC, float(threshold_px), confidence, max_iterations)
    except cv2.error:
        return None
    if F is None or F.shape != (3, 3) or mask is None or not np.isfinite(F).all():
        return None
    return F / np.linalg.norm(F), mask.reshape(-1).astype(bool)


def have_poselib() -> bool:
    """Whether the optional PoseLib is importable (the one check of the package)."""
    try:
        import poselib  # noqa: F401
    except ImportError:
        return False
    return True


def preferred_solver() -> str:
    """The classical solver the package starts from: PoseLib where installed, else OpenCV."""
    return POSELIB if have_poselib() else OPENCV


def mean_focal(matches: PairMatches) -> float:
    """Mean of ``fx``, ``fy`` of both cameras: pixels per normalised unit of the thresholds."""
    K0, K1 = matches.K0, matches.K1
    return float(np.mean([K0[0, 0], K0[1, 1], K1[0, 0], K1[1, 1]]))


#: The memo of :func:`normalisation_scope` (``None`` outside one).
_SCOPE: ContextVar[dict | None] = ContextVar("strl_pyg_normalisation_scope", default=None)


@contextmanager
def normalisation_scope(memo: dict | None = None) -> Iterator[dict]:
    """Within it, :func:`normalised_matches` normalises the points of one pair once: the
    result is kept per ``(points0, points1, K0, K1)`` array objects (held, so an id is never
    reused) and returned again for any :class:`~strl_pyg.data.PairMatches` made of the same
    arrays (e.g. the same matches with lines added). :class:`~strl_pyg.inference.PoseEstimator`
    opens one per pair (with the pair's own ``memo``), so its methods, the support check, the
    covariances and the bootstrap share one normalisation. ``memo``: a dict to keep across
    scopes; without one, a scope opened inside another one uses the outer memo. Yields the
    memo. Each call returns its own copy of the tensors (a caller may write into them); a
    caller that edits a pair's point arrays in place inside a scope gets the normalisation of
    the old values (the estimator's scopes end with its call)."""
    outer = _SCOPE.get()
    if outer is not None and memo is None:
        yield outer
        return
    memo = {} if memo is None else memo
    token = _SCOPE.set(memo)
    try:
        yield memo
    finally:
        _SCOPE.reset(token)


def normalised_matches(matches: PairMatches) -> tuple[torch.Tensor, torch.Tensor, float]:
    """The point matches in normalised camera coordinates, the package's one normalisation
    of matches by their intrinsics: ``x0``, ``x1`` float64 ``[N, 2]``
    (:func:`~strl_pyg.geometry.normalize_points` with ``K0``, ``K1``) and
    :func:`mean_focal` (divide a pixel threshold by it to get normalised units); computed once
    per pair inside a :func:`normalisation_scope`. Treat the tensors as read-only."""
    memo = _SCOPE.get()
    known = _memoised(matches)
    if known is not None:
        x0, x1, focal = known
        return x0.clone(), x1.clone(), focal
    x0 = normalize_points(matches.points0, matches.K0).double()
    x1 = normalize_points(matches.points1, matches.K1).double()
    focal = mean_focal(matches)
    if memo is None:
        return x0, x1, focal
    arrays = (matches.points0, matches.points1, matches.K0, matches.K1)
    memo[tuple(map(id, arrays))] = (arrays, (x0, x1, focal))  # arrays held: ids stay theirs
    return x0.clone(), x1.clone(), focal


def _memoised(matches: PairMatches) -> tuple[torch.Tensor, torch.Tensor, float] | None:
    """The scope's normalisation of these matches' arrays (``None`` outside a scope or when
    not computed yet); the memo's own tensors: do not write into them."""
    memo = _SCOPE.get()
    if memo is None:
        return None
    entry = memo.get(tuple(map(id, (matches.points0, matches.points1, matches.K0,
                                    matches.K1))))
    return None if entry is None else entry[1]


def _normalised(matches: PairMatches, threshold_px: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Contiguous read-only numpy views for the solvers (of the pair's one normalisation), and
    the threshold in normalised units."""
    x0, x1, focal = normalised_matches(matches)

    def frozen(x: torch.Tensor) -> np.ndarray:
        a = np.ascontiguousarray(x.numpy()).view()
        a.flags.writeable = False
        return a

    return frozen(x0), frozen(x1), threshold_px / focal


def _unit_pose(R: np.ndarray, t: np.ndarray) -> Pose:
    t = np.asarray(t, dtype=np.float64).reshape(3)
    return Pose(np.asarray(R, dtype=np.float64), t / np.linalg.norm(t))


def _opencv(matches, threshold_px, confidence, max_iterations, seed,
            usac: int | None = None) -> BaselineResult:
    """OpenCV's USAC essential matrix + ``recoverPose``; ``usac`` selects the sampler
    (default ``cv2.USAC_MAGSAC``; ``cv2.USAC_PROSAC`` expects the matches ordered best first,
    see :mod:`strl_pyg.estimation.guided`)."""
    usac = cv2.USAC_MAGSAC if usac is None else usac
    n = matches.num_points
    cv2.setRNGSeed(int(seed))
    start = time.perf_counter()
    # findEssentialMat takes one camera matrix: image 1's points are re-expressed exactly in a
    # virtual camera with K0 (p1' = K0 K1^-1 p1). Pixel-scale coordinates matter: with
    # normalised coordinates and a threshold of ~1e-3, MAGSAC was measurably less accurate
    # (about 2x the rotation error on generated pairs with 30% outliers).
    # USAC in OpenCV 5.0 silently returns no model for a non-contiguous camera matrix (e.g. a
    # slice of a 3x4 projection matrix), hence the copy.
    K0 = np.ascontiguousarray(matches.K0, dtype=np.float64)
    p0 = np.ascontiguousarray(matches.points0)
    # the pair's one normalisation where a scope holds it; else image 1's points only
    known = _memoised(matches)
    x1 = (known[1] if known is not None
          else normalize_points(matches.points1, matches.K1).double()).numpy()
    p1 = np.ascontiguousarray(x1 @ K0[:2, :2].T + K0[:2, 2])
    try:
        E, mask = cv2.findEssentialMat(
            p0, p1, K0, method=usac, prob=confidence, threshold=float(threshold_px),
            maxIters=int(max_iterations),
        )
    except cv2.error:  # OpenCV 5's USAC asserts on some degenerate samples: no model found
        E, mask = None, None
    if E is None or E.shape[0] < 3 or mask is None:
        return _failed(n, OPENCV, (time.perf_counter() - start) * 1e3)
    best = None
    # A minimal solver may return several stacked 3x3 solutions; keep the one whose
    # decomposition has the most points in front of both cameras.
    for i in range(E.shape[0] // 3):
        count, R, t, m = cv2.recoverPose(E[3 * i: 3 * i + 3], p0, p1, K0, mask=mask.copy())
        if best is None or count > best[0]:
            best = (count, R, t, m)
    elapsed = (time.perf_counter() - start) * 1e3
    count, R, t, m = best
    if count == 0:
        return _failed(n, OPENCV, elapsed)
    return BaselineResult(_unit_pose(R, t), m.reshape(-1) > 0, elapsed, OPENCV, True,
                          {"ransac_inliers": int(mask.sum())})


def _poselib(matches, poselib, threshold_px, confidence, max_iterations, seed) -> BaselineResult:
    start = time.perf_counter()
    x0, x1, thr = _normalised(matches, threshold_px)
    return poselib_normalised(x0, x1, thr, poselib, confidence, max_iterations, seed, start)


def poselib_normalised(x0: np.ndarray, x1: np.ndarray, threshold: float, poselib: Any,
                       confidence: float = 0.9999, max_iterations: int = 10000,
                       seed: int = 0, start: float | None = None) -> BaselineResult:
    """PoseLib's relative pose of matches already in normalised camera coordinates
    (``x0``, ``x1`` contiguous float64 ``[N, 2]``, ``threshold`` in normalised units): the
    solve of :func:`estimate_relative_pose` after its normalisation, for callers that solve
    many subsets of one pair (the bootstrap) and normalise it once."""
    n = len(x0)
    start = time.perf_counter() if start is None else start
    cam = {"model": "PINHOLE", "width": 2, "height": 2, "params": [1.0, 1.0, 0.0, 0.0]}
    ransac = {
        "max_epipolar_error": float(threshold),
        "success_prob": float(confidence),
        "max_iterations": int(max_iterations),
        "min_iterations": min(100, int(max_iterations)),
        "seed": int(seed),
    }
    pose, info = poselib.estimate_relative_pose(x0, x1, cam, cam, ransac, {})
    elapsed = (time.perf_counter() - start) * 1e3
    inliers = np.asarray(info.get("inliers", []), dtype=bool).reshape(-1)
    t = np.asarray(pose.t, dtype=np.float64)
    if inliers.size != n or inliers.sum() < MIN_POINTS or np.linalg.norm(t) < 1e-12:
        return _failed(n, POSELIB, elapsed)
    extra = {k: v for k, v in info.items() if k != "inliers" and np.isscalar(v)}
    return BaselineResult(_unit_pose(pose.R, t), inliers, elapsed, POSELIB, True, extra)
