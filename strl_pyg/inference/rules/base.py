"""What a rule is: :class:`PoseRule`, one decision about the recommended pose of a pair.

A rule reads the pair's run (:class:`~strl_pyg.inference.pair.PairRun`: the checked matches
with their two :class:`~strl_pyg.data.Camera`-like intrinsics, the pair's two-view
configuration, every method's result, the estimator's configuration) and the estimate so far,
and returns a :class:`~strl_pyg.inference.status.Verdict` (``None``: nothing to say). Where it
refuses, widens or replaces the pose it also puts the new pose in the estimate; the estimator's
loop (:func:`apply_rules`) records the verdict on the pose, so every non-``ok`` pose and every
widened sigma names its rule. Each evidence pass a rule needs runs once per pair
(:meth:`PairRun.once <strl_pyg.inference.pair.PairRun.once>`), however many steps the
recommended walk takes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from strl_pyg.inference.status import Verdict

if TYPE_CHECKING:  # pragma: no cover
    from strl_pyg.inference.pair import PairRun
    from strl_pyg.inference.record import PoseEstimate

__all__ = ["PoseRule", "apply_rules"]


class PoseRule:
    """One rule on the recommended pose (subclass it; the instance is its own record).

    Class attributes:
        name: the rule's name, as records and benchmarks read it.
        summary: one line for the rules table (``strl-pose rules``).
        order: rules run by increasing order (built-ins 10, 20, ...; a plugin picks its
            place between them).
        decides: what it may do: ``"refuse"``, ``"widen"``, ``"report"`` (documentation, and
            the rules table).
        warns: whether its verdicts' reasons go to the pose's warnings too (they are always
            in :attr:`MethodResult.verdicts <strl_pyg.inference.record.MethodResult.verdicts>`).
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    order: ClassVar[float] = 100.0
    decides: ClassVar[str] = "report"
    #: whether a verdict's reason also goes to the pose's warnings
    warns: ClassVar[bool] = True

    def enabled(self, config: Any) -> bool:
        """Whether the estimator's configuration runs this rule (default: always)."""
        return True

    def __call__(self, estimate: PoseEstimate, run: PairRun) -> Verdict | None:
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


def apply_rules(estimate: PoseEstimate, run: PairRun, rules: Any) -> PoseEstimate:
    """Each enabled rule of ``rules`` (in order) on ``estimate``; every verdict a rule
    returns is recorded on the pose it leaves (:attr:`MethodResult.verdicts
    <strl_pyg.inference.record.MethodResult.verdicts>`) unless that pose already holds it."""
    for rule in rules:
        if not rule.enabled(run.ctx.config):
            continue
        verdict = rule(estimate, run)
        if verdict is None:
            continue
        pose = estimate.pose
        if not pose.verdicts or pose.verdicts[-1] is not verdict:
            estimate.pose = pose.with_verdict(verdict, warn=rule.warns)
    return estimate
