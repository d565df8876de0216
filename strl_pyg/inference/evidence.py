"""What the matches say about a pair before any pose is believed: its two-view configuration,
whether its focal lengths fit, and whether a learned pose has the matches' support.

One step of the estimator's pass over a pair (:func:`pair_geometry`, run once on the checked
matches) and two rules on the recommended pose:

* :func:`apply_configuration`: a pure rotation is answered as a rotation
  (``"rotation_only"``: the rotation, its sigma, no translation direction); a planar pair keeps
  its pose only where it is one of the plane's homography decompositions, and says which other
  decomposition the matches cannot rule out.
* :func:`learned_pose_evidence`: the network's pose (``regression``, the only learned method
  of the recommended order) stands in for the classical solvers only when the point matches
  support it as they would a solver's pose: enough of them within the support band of its
  epipolar geometry and in front of both cameras (:func:`~strl_pyg.inference.support.check_support`
  with ``checked=True``). Otherwise it is ``"unreliable"``, with the reason: its sigma was
  calibrated on generated scenes and is far too small where the solvers fail.

The focal length (:func:`focal_sensitivity`): two views rarely verify it. On the real_scenes
validation pairs an essential matrix with both focal lengths x2 or x0.5 explains at least 95 %
as many matches as the true one on 81 % of the pairs (``benchmarks/results_real_scenes/
status``), and the
singular-value ratio of the implied essential matrix ``K1^T F K0`` (:func:`focal_consistency`,
1 for a perfect fit; in ``est.geometry.focal_sv_ratio``) was as close to 1 with x0.5 / x2 / x10
as with the true K, while refusing right poses at 0.5-0.6 on real pairs kept apart from this
project: it no longer decides anything. Instead the recommended pose is solved again with both
focal lengths scaled by :data:`FOCAL_RANGE_FACTOR` each way; unless both of those explain
clearly fewer matches (at most :data:`FOCAL_VERIFIED_SHARE` of the given K's inliers), their
spread around the pose is added to its covariance, so that a wrong K gives a wide sigma rather
than a tight wrong pose.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import (
    OPENCV,
    fundamental_matrix,
    normalised_matches,
    preferred_solver,
)
from strl_pyg.estimation.two_view import (
    TwoViewGeometry,
    bearings,
    classify_two_view,
)
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.status import Status
from strl_pyg.inference.support import check_support
from strl_pyg.utils.threads import available_cores, shared_pool

__all__ = ["LEARNED_SUPPORT_SHARE", "FOCAL_MIN_INLIERS", "PLANAR_AGREE_DEG",
           "FOCAL_RANGE_FACTOR", "FOCAL_VERIFIED_SHARE", "pair_geometry", "focal_consistency",
           "focal_sensitivity", "learned_pose_evidence", "MULTIPLE_MIN_INLIERS", "MULTIPLE_SHARE",
           "MULTIPLE_APART_DEG", "MULTIPLE_MOVING_RATIO", "MULTIPLE_MOVING_MIN_INLIERS",
           "MULTIPLE_MOVING_SHARE",
           "ray_turn_deg", "WATERMARK_MIN_MATCHES",
           "WATERMARK_STILL_PX", "WATERMARK_BORDER", "WATERMARK_MOVING_PX", "WATERMARK_SHARE"]

#: The singular-value ratio (information only) is read from a fundamental matrix with at
#: least this many inliers, on a pair whose configuration is ``"general"``.
FOCAL_MIN_INLIERS = 30
#: How far a user's focal lengths may be off where the matches cannot tell (a factor each way;
#: an EXIF guess or a wrong sensor width is off by 2; at sqrt(2) a focal length x0.5 left 36
#: confident wrong poses of 211 real_scenes validation pairs, at 2 none outside the turntable
#: capture: benchmarks/results_real_scenes/status)
FOCAL_RANGE_FACTOR = 2.0
#: The matches verify the focal length where each solve with it scaled by
#: :data:`FOCAL_RANGE_FACTOR` explains at most this share of the given K's inliers.
FOCAL_VERIFIED_SHARE = 0.9
#: A second rigid motion among the pose's outliers with at least this many inliers ...
MULTIPLE_MIN_INLIERS = 15
#: ... and this share of the pose's own makes the pair "multiple" (measured on the real_scenes
#: training scenes: 0 right and 3 wrong poses refused of 236 pairs,
#: benchmarks/studies/results_multiple_motions.md)
MULTIPLE_SHARE = 0.4
#: ... when it is this far (deg) from the pose in rotation, or 3x this in translation direction
MULTIPLE_APART_DEG = 5.0
#: A second motion whose matches move this many times as far as the pose's (the median angle
#: between a match's two viewing rays) needs only :data:`MULTIPLE_MOVING_MIN_INLIERS` and
#: :data:`MULTIPLE_MOVING_SHARE` of the pose's inliers: a pose carried by matches that barely
#: move beside a group that does is a still background beside a moving object (a turntable's
#: room, a parked camera and a passing car; on the real_scenes training scenes it refuses
#: nothing: benchmarks/studies/results_multiple_motions.md). The share keeps a driving car's
#: few left-out matches (KITTI: 5-8 % of the pose's) from costing a second solve.
MULTIPLE_MOVING_RATIO = 3.0
MULTIPLE_MOVING_MIN_INLIERS = 25
MULTIPLE_MOVING_SHARE = 0.1
#: WATERMARK: this many of the pose's inliers ...
WATERMARK_MIN_MATCHES = 15
#: ... moving less than this (px) ...
WATERMARK_STILL_PX = 1.0
#: ... within this share of the image size from a border, while the others move this much (px)
WATERMARK_BORDER = 0.15
WATERMARK_MOVING_PX = 3.0
#: ... and they are at least this share of the pose's inliers: they carry it (a static
#: background of a turntable capture also stays put near the borders, beside a pose the
#: object's matches carry: measured on ethiopian_head, 3 right poses refused without it)
WATERMARK_SHARE = 0.5
#: The network's pose stands in for the solvers only where it explains at least this share of
#: the matches that the pair's best essential matrix explains (its inliers within the support
#: band, against the essential matrix's within the inlier threshold).
LEARNED_SUPPORT_SHARE = 0.8
#: A planar pair's pose agrees with a decomposition of its homography when their rotations
#: are within this angle.
PLANAR_AGREE_DEG = 5.0


def focal_consistency(matches: PairMatches, threshold_px: float = 1.0,
                      seed: int = 0) -> tuple[float | None, int]:
    """``(s2 / s1, inliers)`` of the essential matrix ``K1^T F K0`` implied by the
    fundamental matrix of the point matches (:func:`~strl_pyg.estimation.classical.
    fundamental_matrix`); ``(None, 0)`` where no F is found."""
    found = fundamental_matrix(matches, threshold_px, seed)
    if found is None:
        return None, 0
    F, mask = found
    E = np.asarray(matches.K1, dtype=np.float64).T @ F @ np.asarray(matches.K0, np.float64)
    s = np.linalg.svd(E, compute_uv=False)
    return (float(s[1] / s[0]) if s[0] > 0 else None), int(mask.sum())


def pair_geometry(matches: PairMatches, threshold_px: float = 1.0,
                  seed: int = 0) -> TwoViewGeometry | None:
    """The pair's two-view configuration (:func:`~strl_pyg.estimation.two_view.
    classify_two_view`) with the focal check of a general one (``focal_sv_ratio``,
    ``focal_inliers``); ``None`` without intrinsics."""
    if not matches.has_intrinsics or matches.num_points == 0:
        return None
    x0, x1, focal = normalised_matches(matches)
    geo = classify_two_view(x0.numpy(), x1.numpy(), focal, threshold_px, seed,
                            np.asarray(matches.points0), np.asarray(matches.points1))
    if geo.configuration == "general":
        geo.focal_sv_ratio, geo.focal_inliers = focal_consistency(matches, threshold_px, seed)
    return geo


def focal_sensitivity(pose: MethodResult, matches: PairMatches, threshold_px: float,
                      seed: int = 0, factor: float = FOCAL_RANGE_FACTOR) -> MethodResult:
    """``pose`` (an ``"ok"`` pose with a covariance) with its sensitivity to the focal length:
    ``covariance_with_focal`` is its covariance plus, where the matches do not verify the
    focal length, the spread of the solves with both focal lengths scaled by ``factor`` each
    way (module docstring); its own ``covariance`` (the uncertainty for the K given) is
    unchanged. ``info["focal"]`` says which (``"verified"`` or ``"not verified"``), with the
    inlier counts and the added RMS angles."""
    from strl_pyg.estimation.classical import estimate_relative_pose

    if pose.status != Status.OK or pose.covariance is None or not matches.has_intrinsics \
            or pose.T_0to1 is None or len(np.asarray(pose.covariance)) != 5:
        return pose
    solver = OPENCV if pose.method == OPENCV else preferred_solver()
    T = np.asarray(pose.T_0to1, dtype=np.float64)
    n_given = int(_pose_inliers(T, matches, threshold_px).sum())  # the pose's own support

    def solve(s: float):
        K0, K1 = (np.asarray(K, dtype=np.float64).copy() for K in (matches.K0, matches.K1))
        K0[:2, :2] *= s
        K1[:2, :2] *= s
        return estimate_relative_pose(matches._derived(K0=K0, K1=K1), solver, threshold_px,
                                      seed=seed)

    if available_cores() > 1:  # the solver releases the GIL: the two solves side by side
        wide = shared_pool("focal", 1).submit(solve, factor)
        solved = [solve(1.0 / factor), wide.result()]
    else:
        solved = [solve(1.0 / factor), solve(factor)]
    counts = [int(alt.inliers.sum()) if alt.success else 0 for alt in solved]
    verified = n_given > 0 and all(c <= FOCAL_VERIFIED_SHARE * n_given for c in counts)
    focal = {"verdict": "verified" if verified else "not verified", "inliers_given": n_given,
             "inliers_scaled": counts, "factor": factor}
    poses = [alt.T_0to1.matrix().numpy() for alt in solved if alt.success]
    if verified or not poses:
        return replace(pose, info={**pose.info, "focal": focal},
                       covariance_with_focal=np.asarray(pose.covariance, np.float64).copy())
    # the scaled solves as a two-point spread about the pose: their mean second moment
    wider, added = _with_spread(pose, poses, len(poses))
    return replace(pose, info={**pose.info, "focal": {**focal, "added_sigma_deg": added}},
                   covariance_with_focal=wider.covariance)


def _pose_inliers(T: np.ndarray, matches: PairMatches, threshold_px: float) -> np.ndarray:
    """Point matches within ``threshold_px`` (Sampson, pixels) of the pose ``T``."""
    from strl_pyg.geometry.epipolar import epipolar_residuals

    return epipolar_residuals(matches, T)[0] < threshold_px


def ray_turn_deg(matches: PairMatches) -> np.ndarray:
    """Per point match, the angle (deg) between its two viewing rays, each in its own camera
    (``K0^-1 x0`` and ``K1^-1 x1``, :func:`~strl_pyg.estimation.classical.normalised_matches`):
    how far the match moves, independent of the lens."""
    x0, x1, _ = normalised_matches(matches)
    cos = (bearings(x0.numpy()) * bearings(x1.numpy())).sum(1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = float(np.dot(a, b) / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def learned_pose_evidence(res: MethodResult, matches: PairMatches, threshold_px: float,
                          support: tuple[float, int, float],
                          geo: TwoViewGeometry | None = None) -> MethodResult:
    """The network's pose as the recommended one: unchanged where the point matches support
    it (module docstring; with the pair's configuration ``geo``, at least
    :data:`LEARNED_SUPPORT_SHARE` of its essential matrix's inliers), else ``"unreliable"``
    with the reason (the pose kept in ``info`` for inspection)."""
    if res.status != Status.OK or not matches.has_intrinsics:
        return res
    ratio, floor, in_front = support
    checked = check_support(replace(res, info=dict(res.info)), matches, threshold_px, ratio,
                            floor, in_front, checked=True)
    k = checked.info.get("support_inliers", 0)
    best = 0 if geo is None else geo.inliers_E
    if checked.status == Status.OK and k >= LEARNED_SUPPORT_SHARE * best:
        return res
    if checked.status == Status.OK:
        why = (f"it explains {k} point matches within the support band, the pair's essential "
               f"matrix {best} (below {100 * LEARNED_SUPPORT_SHARE:.0f} %)")
    else:
        why = checked.warnings[-1] if checked.warnings else "the matches do not support it"
    return res.unreliable([
        f"the network's pose stands in for no solver here: {why} (its sigma is calibrated on "
        "generated scenes; where the classical solvers fail it is not evidence)"],
        rule="learned_support", evidence={"support_inliers": k, "essential_inliers": best})


def _with_planar_spread(pose: MethodResult, cands: list) -> MethodResult:
    """``pose`` with the plane's ambiguity in its covariance: the decompositions of the
    plane's homography that the matches cannot tell apart (``cands``, all in front of both
    cameras) are as likely as the pose (an essential matrix of a plane is poorly determined),
    so the second moment of the pose and them about the pose (in the pose's tangent space) is
    added; the added RMS angles in ``info["planar_added_sigma_deg"]``. A plane fixes its
    rotation better than its translation, so mostly the translation's sigma widens."""
    if pose.covariance is None or len(np.asarray(pose.covariance)) != 5 or not cands:
        return pose
    poses = []
    for Rc, tc in cands:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Rc, np.asarray(tc, dtype=np.float64).reshape(3)
        poses.append(T)
    pose, added = _with_spread(pose, poses, len(poses) + 1)
    return replace(pose, info={**pose.info, "planar_added_sigma_deg": added})


def _with_spread(pose: MethodResult, others: list, n: int) -> tuple[MethodResult, list]:
    """``pose`` with ``sum(d d^T) / n`` added to its covariance (capped), ``d`` each pose of
    ``others`` (``[4, 4]``) in the pose's tangent space; and the added RMS rotation and
    translation angles (deg)."""
    from strl_pyg.estimation.pose_fusion import pose_to_tangent
    from strl_pyg.estimation.uncertainty import cap_covariance
    from strl_pyg.geometry import Pose, tangent_basis

    T = np.asarray(pose.T_0to1, dtype=np.float64)
    R_ref = torch.as_tensor(T[:3, :3])
    t_ref = torch.as_tensor(T[:3, 3] / max(np.linalg.norm(T[:3, 3]), 1e-300))
    basis = tangent_basis(t_ref)
    D = np.stack([pose_to_tangent(Pose.from_matrix(torch.as_tensor(np.asarray(o, np.float64))),
                                  R_ref, t_ref, basis).numpy() for o in others])
    term = D.T @ D / n
    cov, capped = cap_covariance(np.asarray(pose.covariance, dtype=np.float64) + term)
    added = [float(np.degrees(np.sqrt(np.trace(term[:3, :3])))),
             float(np.degrees(np.sqrt(np.trace(term[3:, 3:]))))]
    info = {**pose.info, "sigma_capped": True} if capped else pose.info
    return replace(pose, covariance=cov, info=info), added


def _rot_deg(A: np.ndarray, B: np.ndarray) -> float:
    from strl_pyg.geometry.pose import rotation_angle_deg

    return float(rotation_angle_deg(np.asarray(A, dtype=np.float64) @ np.asarray(B).T))

