"""``configuration``: the recommended pose under the pair's two-view configuration.

A pure rotation is answered as a rotation (``"rotation_only"``: the rotation, its sigma, no
translation direction); a planar pair keeps its pose only where it is one of the plane's
homography decompositions, with the other decompositions the matches cannot rule out added to
its covariance (the plane's ambiguity, mostly in the translation direction). The configuration
is recorded in ``estimate.geometry`` and the pose's ``info["configuration"]``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from strl_pyg.estimation.classical import normalised_matches
from strl_pyg.estimation.two_view import planar_candidates
from strl_pyg.inference.evidence import (
    PLANAR_AGREE_DEG,
    _angle_deg,
    _rot_deg,
    _with_planar_spread,
)
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.rules.base import PoseRule
from strl_pyg.inference.status import Action, Status, Verdict

__all__ = ["Configuration"]


class Configuration(PoseRule):
    """Module docstring."""

    name = "configuration"
    summary = ("pure rotation: the rotation alone (rotation_only); planar: a homography "
               "decomposition or refused, the others in the sigma")
    order = 30.0
    decides = "replace, refuse, widen"
    warns = False  # its own warnings are in the pose it leaves (the note, the other plane)

    def __call__(self, estimate, run):
        geo = estimate.geometry or run.geometry
        estimate.geometry = geo
        if geo is None:
            return None
        pose = estimate.pose
        info = {**pose.info, "configuration": geo.configuration}
        if geo.configuration == "rotation" and pose.status in (
                Status.OK, Status.FAILED, Status.UNRELIABLE) \
                and geo.rotation is not None and not pose.bad_intrinsics:
            return self._rotation(estimate, geo, info)
        if geo.configuration == "planar" and pose.status is Status.OK and geo.H is not None:
            return self._planar(estimate, geo, info, run.matches)
        estimate.pose = replace(pose, info=info)
        return None

    def _rotation(self, estimate, geo, info) -> Verdict:
        pose = estimate.pose
        sigma = geo.rotation_sigma_deg if geo.rotation_sigma_deg is not None else float("nan")
        s = math.radians(max(sigma, 1e-3)) if math.isfinite(sigma) else None
        cov = None if s is None else np.eye(3) * s * s / 3.0
        note = (f"pure rotation: a rotation alone explains {geo.inliers_R} of the "
                f"{geo.num_points} point matches (the essential matrix {geo.inliers_E}), so "
                "the translation direction is not determined: the rotation is given "
                "(rotation, sigma['rotation_deg']), T_0to1 is None")
        if pose.status is Status.OK:
            info["rotation_vs_method_deg"] = _rot_deg(pose.T_0to1[:3, :3], geo.rotation)
        verdict = Verdict(self.name, Action.REPLACED, Status.ROTATION_ONLY, note,
                          {"inliers_R": geo.inliers_R, "inliers_E": geo.inliers_E,
                           "replaced": pose.method, "replaced_status": pose.status.value})
        estimate.pose = MethodResult("rotation", Status.ROTATION_ONLY, None, cov,
                                     pose.warnings + [note], pose.time_ms, geo.inliers_R,
                                     info, None, None, rotation=geo.rotation,
                                     verdicts=[*pose.verdicts, verdict])
        return verdict

    def _planar(self, estimate, geo, info, matches) -> Verdict | None:
        pose = estimate.pose
        x0, x1, _ = normalised_matches(matches)
        cands = planar_candidates(geo.H, np.asarray(matches.K0), np.asarray(matches.K1),
                                  x0.numpy(), x1.numpy())
        R, t = pose.T_0to1[:3, :3], pose.T_0to1[:3, 3]
        # the rotation decides: a plane seen with little parallax fixes its rotation well and
        # its translation poorly (measured: a right pose of office_drink, 0.04 / 3.9 deg off,
        # was 30 deg from the decomposition's translation)
        agree = [i for i, (Rc, _) in enumerate(cands) if _rot_deg(R, Rc) < PLANAR_AGREE_DEG]
        info["planar_candidates"] = [{"R": Rc, "t": tc, "rotation_from_pose_deg":
                                      _rot_deg(R, Rc), "translation_from_pose_deg":
                                      _angle_deg(t, tc)} for Rc, tc in cands]
        others = [c for i, c in enumerate(cands) if i not in agree
                  and not any(_rot_deg(c[0], cands[j][0]) < PLANAR_AGREE_DEG for j in agree)]
        if cands and not agree:
            estimate.pose = replace(pose, info=info).unreliable([
                f"planar scene: the pose is none of the {len(cands)} decompositions of the "
                "plane's homography that put the matches in front of the cameras "
                "(info['planar_candidates'])"], rule=self.name,
                evidence={"candidates": len(cands)})
            return estimate.pose.verdicts[-1]
        warn = []
        if others:
            warn = [f"planar scene: {len(others)} other decomposition(s) of the plane's "
                    "homography also put the matches in front of both cameras and the matches "
                    "cannot rule them out (info['planar_candidates'])"]
        estimate.pose = _with_planar_spread(replace(pose, info=info,
                                                    warnings=pose.warnings + warn), cands)
        added = estimate.pose.info.get("planar_added_sigma_deg")
        if added is None:
            return None
        return Verdict(self.name, Action.WIDENED, Status.OK,
                       warn[0] if warn else "planar scene: the plane's homography "
                       "decompositions are in the sigma", {"candidates": len(cands),
                                                           "others": len(others),
                                                           "added_sigma_deg": added})
