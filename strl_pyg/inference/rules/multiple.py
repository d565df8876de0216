"""``multiple``: COLMAP's MULTIPLE, a second rigid motion among the matches the pose leaves out.

Reported as COLMAP reports it: the configuration is ``"multiple"`` and both motions (their
support, rotation and translation direction) are in the record
(``info["motions"]``, ``estimate.geometry.second_motion_inliers``). The pose is refused
(``"unreliable"``) only where the second motion has at least :data:`MULTIPLE_COMPARABLE` of
the pose's inliers (fitted leave-one-scene-out: there the pose was more often wrong than
right); below that the pose's motion dominates and it stays ``"ok"``. A second "motion" with
the pose's rotation whose matches are interleaved with the pose's own is repeated structure
(a facade's windows matched one period off), not a second motion: reported, never refused.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from strl_pyg.inference.evidence import (
    MULTIPLE_APART_DEG,
    MULTIPLE_MIN_INLIERS,
    MULTIPLE_MOVING_MIN_INLIERS,
    MULTIPLE_MOVING_RATIO,
    MULTIPLE_MOVING_SHARE,
    MULTIPLE_SHARE,
    _angle_deg,
    _rot_deg,
    ray_turn_deg,
)
from strl_pyg.inference.rules.base import PoseRule
from strl_pyg.inference.status import Action, Status, Verdict

__all__ = ["Multiple", "MULTIPLE_COMPARABLE", "MULTIPLE_SEGREGATION", "second_motion",
           "segregation"]


def segregation(points: np.ndarray, group: np.ndarray, k: int = 5) -> float:
    """How much the points of ``group`` (bool ``[N]``) keep to themselves: the share of their
    ``k`` nearest neighbours (among ``points`` ``[N, 2]``) that are in ``group`` too, over the
    share expected if the labels were shuffled (``(n_group - 1) / (N - 1)``). About 1 for
    matches interleaved with the others (repeated structure matched one period off), several
    for a compact region (a moving object). ``nan`` with fewer than 2 points in the group or
    outside it."""
    points = np.asarray(points, dtype=np.float64)
    group = np.asarray(group, dtype=bool)
    n, g = len(points), int(group.sum())
    if g < 2 or g >= n:
        return float("nan")
    k = min(k, n - 1)
    rows, same = np.flatnonzero(group), 0
    for start in range(0, g, 256):  # 256 rows of distances at a time: memory bounded in n
        idx = rows[start:start + 256]
        d = np.linalg.norm(points[idx][:, None, :] - points[None, :, :], axis=2)
        d[np.arange(len(idx)), idx] = np.inf  # not itself
        same += int(group[np.argpartition(d, k - 1, axis=1)[:, :k]].sum())
    return (same / (g * k)) / ((g - 1) / (n - 1))

#: The second motion refuses the pose where its inliers are at least this share of the pose's.
#: Chosen on the real_scenes training scenes, leave-one-scene-out
#: (``benchmarks/studies/fit_rules_loso.py``, ``results_rules_loso.md``): among the poses the
#: other rules leave ``ok``, a second motion with at least a fifth of the pose's support
#: refused 22 wrong poses and 1 right one (true K and perturbed copies); with the true K it
#: refused 1 right pose and no wrong one: what it catches is a wrong K, whose matches split
#: into two "motions".
MULTIPLE_COMPARABLE = 0.2
#: A second "motion" with the pose's rotation (within
#: :data:`~strl_pyg.inference.evidence.MULTIPLE_APART_DEG`) that differs only in translation is
#: what repeated structure gives (a facade's windows matched one period off: ``X -> R (X + p) +
#: t``); it counts as a second motion only where its matches form a region of their own in
#: image 0 (:func:`segregation` at least this), as a moving object's do, not interleaved with
#: the pose's own as mismatched repeats are.
MULTIPLE_SEGREGATION = 2.0


def second_motion(T: np.ndarray, run) -> dict | None:
    """The second rigid motion among the matches the pose ``T`` leaves out (PoseLib, else
    OpenCV, on them), or ``None`` where there is none that counts: at least
    :data:`~strl_pyg.inference.evidence.MULTIPLE_MIN_INLIERS` inliers and
    :data:`~strl_pyg.inference.evidence.MULTIPLE_SHARE` of the pose's, or (its matches moving
    :data:`~strl_pyg.inference.evidence.MULTIPLE_MOVING_RATIO` times as far as the pose's, a
    still background beside a moving object) :data:`MULTIPLE_MOVING_MIN_INLIERS` and
    :data:`MULTIPLE_MOVING_SHARE` of them; more than
    :data:`~strl_pyg.inference.evidence.MULTIPLE_APART_DEG` from the pose in rotation, or
    three times that in translation direction where the pair shows parallax. Solved once per
    pair and pose (:meth:`PairRun.once <strl_pyg.inference.pair.PairRun.once>`)."""
    return run.once(("multiple", np.asarray(T, np.float64).tobytes()),
                    lambda: _second_motion(np.asarray(T, np.float64), run))


def _second_motion(T: np.ndarray, run) -> dict | None:
    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.inference.registry import classical_method

    matches, geo, cfg = run.matches, run.geometry, run.ctx.config
    first = run.pose_inliers(T)
    rest = np.flatnonzero(~first)
    n1 = int(first.sum())
    need = max(MULTIPLE_MIN_INLIERS, MULTIPLE_SHARE * n1)
    need_moving = max(MULTIPLE_MOVING_MIN_INLIERS, MULTIPLE_MOVING_SHARE * n1)
    turn = ray_turn_deg(matches)
    moving_at = MULTIPLE_MOVING_RATIO * float(np.median(turn[first])) if n1 else math.inf
    # a moving second motion needs this many left-out matches that move that far
    moving_possible = int((turn[rest] >= moving_at).sum()) >= need_moving
    if len(rest) < max(need, 8) and not moving_possible:
        return None  # too few left out to hold a second motion that counts
    others = replace(matches, points0=matches.points0[rest], points1=matches.points1[rest],
                     point_scores=None, lines0=None, lines1=None, line_scores=None)
    solver = classical_method(run.ctx.results)
    solved = estimate_relative_pose(others, solver, cfg.threshold_px, seed=cfg.seed)
    inl2 = np.asarray(solved.inliers, bool) if solved.success else np.zeros(len(rest), bool)
    n2 = int(inl2.sum())
    moving = n2 >= need_moving and float(np.median(turn[rest][inl2])) >= moving_at
    if n2 < need and not moving:
        return None
    T2 = solved.T_0to1.matrix().numpy()
    rot, trans = _rot_deg(T[:3, :3], T2[:3, :3]), _angle_deg(T[:3, 3], T2[:3, 3])
    if rot <= MULTIPLE_APART_DEG and (trans <= 3 * MULTIPLE_APART_DEG
                                      or geo.configuration == "rotation"):
        # the same motion, its matches just outside the threshold; or a pure rotation, whose
        # translation direction the matches do not determine
        return None
    both = first.copy()
    both[rest[inl2]] = True
    second_mask = np.zeros(len(first), bool)
    second_mask[rest[inl2]] = True
    seg = segregation(np.asarray(matches.points0)[both], second_mask[both])
    repeated = rot <= MULTIPLE_APART_DEG and not seg >= MULTIPLE_SEGREGATION
    return {"repeated_structure": bool(repeated), "segregation": seg, "T_0to1": T2,
            "inliers": n2, "pose_inliers": n1, "left_out": int(len(rest)),
            "rotation_from_pose_deg": rot, "translation_from_pose_deg": trans,
            "turn_deg": float(np.median(turn[rest][inl2])),
            "pose_turn_deg": float(np.median(turn[first])) if n1 else None,
            "still_background": bool(n2 < need)}


class Multiple(PoseRule):
    """Module docstring: the configuration ``"multiple"`` with both motions; the pose refused
    only where the second motion's support is comparable to its own."""

    name = "multiple"
    summary = ("a second rigid motion among the left-out matches: reported with both motions; "
               "refused where their support is comparable")
    order = 20.0
    decides = "report, refuse"

    def __call__(self, estimate, run):
        pose, geo = estimate.pose, estimate.geometry or run.geometry
        if geo is None or pose.status is not Status.OK or not run.matches.has_intrinsics:
            return None
        found = second_motion(pose.T_0to1, run)
        if found is None:
            return None
        n1, n2 = found["pose_inliers"], found["inliers"]
        evidence = {k: v for k, v in found.items() if k != "T_0to1"} | {"share": n2 / max(n1, 1)}
        if found["repeated_structure"]:
            return Verdict(self.name, Action.REPORTED, Status.OK,
                           f"{n2} of the matches the pose leaves out fit its rotation with "
                           f"another translation ({found['translation_from_pose_deg']:.0f} deg "
                           "away), interleaved with the pose's own matches: repeated structure "
                           "matched one period off, not a second motion", evidence)
        estimate.geometry = replace(geo, configuration="multiple", second_motion_inliers=n2)
        T, T2 = np.asarray(pose.T_0to1), found["T_0to1"]
        motions = [{"inliers": n1, "R": T[:3, :3], "t": T[:3, 3]},
                   {"inliers": n2, "R": T2[:3, :3], "t": T2[:3, 3]}]
        info = {**pose.info, "second_motion_T_0to1": T2, "second_motion_inliers": n2,
                "motions": motions}
        share = evidence["share"]
        still = (f"; its matches move {found['turn_deg']:.2f} deg, the pose's "
                 f"{found['pose_turn_deg']:.2f} deg: a still background beside a moving "
                 "object" if found["still_background"] else "")
        what = (f"two motions (COLMAP's MULTIPLE): {n2} of the {found['left_out']} matches "
                f"the pose leaves out fit a second rigid motion "
                f"({found['rotation_from_pose_deg']:.1f} deg in rotation and "
                f"{found['translation_from_pose_deg']:.1f} deg in translation direction from "
                f"the pose, which {n1} matches fit{still})")
        if share >= MULTIPLE_COMPARABLE:
            estimate.pose = replace(pose, info=info).unreliable([
                f"{what}: comparable support (at least {100 * MULTIPLE_COMPARABLE:.0f} % of "
                "the pose's), e.g. a turntable's room and object; which is the relative pose "
                "is yours to say (info['motions'])"], rule=self.name, evidence=evidence)
            return estimate.pose.verdicts[-1]
        estimate.pose = replace(pose, info=info)
        return Verdict(self.name, Action.REPORTED, Status.OK,
                       f"{what}: the pose's motion has {1 / max(share, 1e-9):.1f}x its support "
                       "and is kept; the other is in info['motions']", evidence)
