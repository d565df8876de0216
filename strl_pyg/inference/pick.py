"""Which method's record fills the recommended pose of a pair (:func:`pick_recommended`): the
first ``"ok"`` one of the recommended order (:mod:`strl_pyg.inference.policy`), a learned pose
only with the matches' support (the ``learned_support`` rule); without one, the first
``"unreliable"`` one (no pose to use either, but the reason and the computed pose); else
``"degenerate"`` or ``"failed"``, naming the rule that refused the first method of the order."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from strl_pyg.data.matches import PairMatches
from strl_pyg.inference.checks import BAD_INTRINSICS
from strl_pyg.inference.evidence import learned_pose_evidence
from strl_pyg.inference.methods.regression import Regression
from strl_pyg.inference.pair import unique_in_order
from strl_pyg.inference.policy import (
    POSELIB_MISSING,
    measured_with_missing_poselib,
    recommended_order,
)
from strl_pyg.inference.record import MethodResult, PoseEstimate
from strl_pyg.inference.registry import METHODS
from strl_pyg.inference.status import Action, Status, Verdict

__all__ = ["pick_recommended"]


def pick_recommended(results: dict[str, MethodResult], warnings: list[str],
                     matches: PairMatches, settings: Any, config: Any,
                     geometry: Any = None) -> PoseEstimate:
    """The estimate whose pose is the recommended record of ``results`` (module docstring).
    Its warnings say why the earlier methods were passed over and which methods could not run
    at all (an exception: e.g. the network on a device it cannot use)."""
    chosen = recommended_order(settings, matches.num_distinct_points)
    order = [m for m in chosen if m in results]
    notes = [POSELIB_MISSING] if measured_with_missing_poselib(settings) else []
    raised = [m for m, r in results.items() if r.raised]
    notes += [f"{m} could not run: {'; '.join(results[m].warnings)}" for m in raised]
    # the regression stands in only while some solver's pose is supported or none was
    # refused for lack of support
    unsupported = any(r.unsupported for r in results.values()) and not any(
        r.status is Status.OK for m, r in results.items()
        if m in METHODS and METHODS[m].support_checked)

    def estimate(pose: MethodResult) -> PoseEstimate:
        return PoseEstimate(pose, results, matches.num_points, matches.num_lines, matches)

    fallback = None  # (record, notes so far) of the first "unreliable" pose
    for m in order:
        r = results[m]
        if r.status in (Status.OK, Status.UNRELIABLE) and m == Regression.name and unsupported:
            notes.append("regression not used: the matches support no solver's pose")
            continue
        if r.status is Status.OK and not METHODS[m].support_checked:
            # a learned pose is recommended only with the matches' support
            r = learned_pose_evidence(r, matches, config.threshold_px, config.support,
                                      geometry)
        if r.status is Status.OK:
            return estimate(replace(r, warnings=unique_in_order(warnings + notes + r.warnings)))
        if r.status is Status.UNRELIABLE and fallback is None:
            fallback = (r, list(notes))
        reasons = [w for w in r.warnings if w not in warnings]
        if reasons and m not in raised:
            notes.append(f"{m} {r.status}: {'; '.join(reasons)}")
    if fallback is not None:
        r, before = fallback
        # the intrinsics' problems are the pair's warnings already: named once
        said = {v.reason for v in r.verdicts if v.rule == "intrinsics"}
        own = [f"{BAD_INTRINSICS} (the warnings on K above)" if w in said else w
               for w in r.warnings]
        return estimate(replace(r, warnings=unique_in_order(warnings + before + own)))
    if not order:
        notes.append(f"none of the recommended methods {chosen} was run")
    status = Status.DEGENERATE if any(results[m].status is Status.DEGENERATE
                                      for m in order) else Status.FAILED
    # the rule that refused the first method of the order (a solver that found nothing
    # names none: "solver")
    rule = next((results[m].rule for m in order if results[m].rule), None) or "solver"
    return estimate(MethodResult(None, status, warnings=unique_in_order(warnings + notes),
                                 verdicts=[Verdict(rule, Action.REFUSED, status,
                                                   "no method of the recommended order gave "
                                                   "a pose", {"methods": {
                                                       m: results[m].status.value
                                                       for m in order}})]))
