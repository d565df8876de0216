"""The pose methods that read the matched line segments' vanishing directions:

* ``vp`` (:class:`VanishingPoint`): the vanishing-point rotation of the matched lines and a 2-point
  translation (:func:`~strl_pyg.estimation.vanishing.vanishing_point_pose`), first in the
  recommended order where a pair has at most
  :data:`~strl_pyg.inference.methods.POINT_POOR_MAX_POINTS` point matches.
* ``vp_checked`` (:class:`VanishingPointChecked`): the classical pose, replaced by ``vp``'s where
  the points are few and the lines' strongest vanishing direction contradicts its rotation.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from strl_pyg.data.matches import PairMatches
from strl_pyg.inference.methods.base import CLASSICAL, PoseMethod
from strl_pyg.inference.methods.classical import Classical
from strl_pyg.inference.methods.context import (
    POINT_POOR_MAX_POINTS,
    MethodContext,
    classical_base,
    with_covariance,
)
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.status import Status

__all__ = ["VanishingPoint", "VanishingPointChecked", "VP_CHECK_ANGLE_DEG",
           "VP_CHECK_SUPPORT_SLACK"]


class VanishingPoint(PoseMethod):
    """The lines' vanishing-point rotation and a 2-point translation."""

    name = "vp"
    needs_lines = True
    label = "vanishing-point rotation + 2-point translation"
    summary = ("the matched lines' vanishing-point rotation, a 2-point translation RANSAC over "
               "the points, refined on points and lines; first in the recommended order where "
               "a pair has at most 30 point matches")
    reads_lines = True
    depends_on = (CLASSICAL,)

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        """The vanishing-point rotation and 2-point translation
        (:func:`~strl_pyg.estimation.vanishing.vanishing_point_pose`), with the classical pose
        (PoseLib's, else OpenCV's) as a second start of its joint refinement on the points and
        the lines (``info["start"]``: ``"vp"`` or ``0``, the classical pose): needs line matches,
        and answers where the points are too few for the 5-point solvers; its covariance is the
        first-order one of its inlier points (no bootstrap, not calibrated)."""
        from strl_pyg.estimation import line_refine
        from strl_pyg.estimation.vanishing import vanishing_point_pose

        if matches.num_lines == 0:
            # the input lacks what vp reads: "skipped", as for a model without its pixels
            return MethodResult(self.name, Status.SKIPPED, warnings=[
                "vp needs line matches (got none: FrontendConfig(lines=True), or lines0/lines1)"])
        # the 5-point solver's supported pose is a second start of the joint refinement with the
        # lines: its record of this run when it ran before, else solved and support-checked here
        # (once per pair), so that vp's answer does not depend on the order of the methods
        sigma = line_refine.VP_LINE_SIGMA_PX
        starts = None
        if sigma is not None:
            from strl_pyg.inference.support import check_support

            base = classical_base(ctx)
            cls = ctx.results.get(base) or ctx.vp_start
            if cls is None:
                cls = ctx.vp_start = check_support(
                    Classical.of(base)(matches, ctx), matches, ctx.config.threshold_px,
                    *ctx.config.support)
            starts = [cls.T_0to1] if cls.status == Status.OK else []
        res = vanishing_point_pose(matches, ctx.config.threshold_px, seed=ctx.config.seed,
                                   directions=_vanishing_directions(matches, ctx), starts=starts,
                                   line_sigma_px=sigma)
        if not res.success:
            return MethodResult(self.name, Status.FAILED, time_ms=res.time_ms, num_inliers=0,
                                raw=res,
                                info=dict(res.info), warnings=[f"vp: {res.info['reason']}"])
        rec = with_covariance(self.name, res.pose, matches, ctx.config.threshold_px,
                               time_ms=res.time_ms, info=dict(res.info), raw=res)
        if rec.covariance is not None:  # the documented key (the CLI prints it)
            rec.info["covariance"] = "first-order"
        return rec


def _vanishing_directions(matches: PairMatches, ctx: MethodContext) -> list:
    """The matched lines' vanishing directions (default thresholds, ``ctx.config.seed``), found once
    per pair and shared by ``vp`` and ``vp_checked``."""
    from strl_pyg.estimation.vanishing import vanishing_directions

    if ctx.vanishing_directions is None:
        ctx.vanishing_directions = vanishing_directions(matches, seed=ctx.config.seed)
    return ctx.vanishing_directions


#: How far (deg) the classical rotation may carry the strongest vanishing direction shared by
#: both images' lines (``d1 = +-R d0``) from where the second image sees it before
#: ``vp_checked`` turns to ``vp``'s pose; fitted with :data:`VP_CHECK_SUPPORT_SLACK` on a
#: calibration split (``benchmarks/studies/bench_vanishing.py --fit``).
VP_CHECK_ANGLE_DEG = 2.0


#: ``vp``'s pose replaces the classical one only while it is supported by at least this many
#: fewer point matches than the classical pose (fitted with :data:`VP_CHECK_ANGLE_DEG`).
VP_CHECK_SUPPORT_SLACK = 3


def _result_of(name: str, matches: PairMatches, ctx: MethodContext) -> MethodResult:
    """The record of ``name`` (``"poselib"``, ``"opencv"`` or ``"vp"``) from the methods run
    before, else run here; ``info["support_inliers"]`` counted as the support check counts."""
    from strl_pyg.inference.support import check_support

    res = ctx.results.get(name)
    if res is None:
        solver = VanishingPoint() if name == VanishingPoint.name else Classical.of(name)
        res = solver(matches, ctx)
    if res.status == Status.OK and "support_inliers" not in res.info:
        res = check_support(res, matches, ctx.config.threshold_px, min_inlier_ratio=0.0,
                            min_inliers=0, min_in_front=0.0)
    return res


class VanishingPointChecked(PoseMethod):
    """The classical pose, replaced by ``vp``'s where the points are few and the lines' strongest
    vanishing direction contradicts its rotation (opt-in)."""

    name = "vp_checked"
    label = "PoseLib checked by the lines' vanishing direction"
    summary = ("the classical pose, replaced by `vp`'s where the points are few and the lines' "
               "strongest vanishing direction contradicts its rotation (opt-in)")
    reads_lines = True
    depends_on = (CLASSICAL,)  # and vp's result where it ran (else it runs vp itself)
    angle_deg = VP_CHECK_ANGLE_DEG
    support_slack = VP_CHECK_SUPPORT_SLACK

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        """The classical pose, checked against the lines where the points are few: with at most
        :data:`POINT_POOR_MAX_POINTS` point matches, when the classical rotation contradicts the
        strongest vanishing direction of the matched lines by more than :attr:`angle_deg`
        and ``vp``'s pose (whose rotation comes from those directions) is supported by about as
        many point matches (:attr:`support_slack`), ``vp``'s pose; ``vp``'s also where the
        classical solver gives none. ``info["source"]`` names the pose taken, ``info["reason"]``
        why; the covariance is that pose's own record's (calibrated when that record was:
        ``info["calibration_scale"]``)."""
        start = time.perf_counter()
        base = classical_base(ctx)
        cls = _result_of(base, matches, ctx)
        info: dict[str, Any] = {"classical": base}

        def take(rec: MethodResult, reason: str) -> MethodResult:
            ms = (time.perf_counter() - start) * 1e3
            if rec.status != Status.OK:
                return MethodResult(self.name, rec.status, time_ms=ms, info={**info,
                                    "reason": reason}, warnings=[f"vp_checked: {reason}"]
                                    + [w for w in rec.warnings if w not in reason],
                                    bad_intrinsics=rec.bad_intrinsics)
            return MethodResult(self.name, Status.OK, rec.as_pose(), rec.covariance,
                                list(rec.warnings), ms, rec.num_inliers,
                                info={**info, "source": rec.method, "reason": reason,
                                      "covariance": rec.info.get("covariance"),
                                      "calibration_scale": rec.info.get("calibration_scale")},
                                raw=rec.raw, calibrated=rec.calibrated,
                                bad_intrinsics=rec.bad_intrinsics)

        if matches.num_distinct_points > POINT_POOR_MAX_POINTS:
            return take(cls, f"{matches.num_distinct_points} distinct point matches (> "
                        f"{POINT_POOR_MAX_POINTS}): the {base} pose as it is")
        if matches.num_lines == 0:
            return take(cls, "no line matches to check the pose against")
        vp = _result_of(VanishingPoint.name, matches, ctx)
        if cls.status != Status.OK:
            return take(vp, f"{base} gave no supported pose" + (
                "; vp's pose" if vp.status == Status.OK else "; nor did vp"))
        dirs = _vanishing_directions(matches, ctx)
        if not dirs:
            return take(cls, "no vanishing direction shared by both images' lines")
        d0, d1, lines = dirs[0]
        R = np.asarray(cls.T_0to1, dtype=np.float64)[:3, :3]
        angle = float(np.degrees(np.arccos(np.clip(abs(float(d1 @ (R @ d0))), 0.0, 1.0))))
        info.update(line_angle_deg=angle, direction_lines=int(lines.sum()))
        if angle <= self.angle_deg:
            return take(cls, f"the {base} rotation agrees with the lines' strongest vanishing "
                             f"direction ({angle:.1f} deg)")
        if vp.status != Status.OK:
            return take(cls, f"the {base} rotation is {angle:.1f} deg off the lines' vanishing "
                             f"direction, but vp has no supported pose")
        s_cls, s_vp = cls.info["support_inliers"], vp.info["support_inliers"]
        info.update(support_classical=s_cls, support_vp=s_vp)
        if s_vp < s_cls - self.support_slack:
            return take(cls, f"the {base} rotation is {angle:.1f} deg off the lines' vanishing "
                             f"direction, but vp's pose fits fewer point matches ({s_vp} against "
                             f"{s_cls})")
        return take(vp, f"the {base} rotation is {angle:.1f} deg off the lines' strongest "
                        f"vanishing direction ({int(lines.sum())} lines); vp's pose fits {s_vp} "
                        f"point matches against {s_cls}")
