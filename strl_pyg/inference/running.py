"""The methods' run on one pair: each method's own result (:func:`run_method`), its support
check and calibration (:func:`run_methods`), and the record of a method that gave no pose
(:func:`refused_record`), each naming its rule."""

from __future__ import annotations

from typing import Any

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import normalisation_scope
from strl_pyg.inference.calibration import calibrate
from strl_pyg.inference.methods.base import PoseMethod
from strl_pyg.inference.methods.context import MethodContext
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.registry import CLASSICAL, METHODS, classical_method
from strl_pyg.inference.status import Action, Status, Verdict
from strl_pyg.inference.support import check_support

__all__ = ["refused_record", "run_method", "run_methods", "missing_input"]


def refused_record(method: str | None, status: Status, rule: str, why: str,
                   evidence: dict | None = None, warnings: list[str] | None = None
                   ) -> MethodResult:
    """A record without a pose (``status``), refused by ``rule`` for the reason ``why`` (also
    its last warning, after ``warnings``)."""
    return MethodResult(method, status, warnings=[*(warnings or []), why], verdicts=[
        Verdict(rule, Action.REFUSED, status, why, dict(evidence or {}))])


def run_methods(pair: Any, names: Any, known: dict[str, MethodResult] | None = None) -> None:
    """Runs the methods of ``names`` the pair (:class:`~strl_pyg.inference.pair.PairRun`) has no
    result of yet, in the registry's order (a method that reads another's result runs after
    it, whatever order the caller named them in), inside the pair's normalisation scope: each
    one's own result (:func:`run_method`), its support check and its calibration. ``known``:
    results of these same matches, taken as they are."""
    registry = list(METHODS)
    results, cfg = pair.ctx.results, pair.ctx.config
    with normalisation_scope(pair.memo):
        for name in sorted(names, key=registry.index):
            if name in results:
                continue
            if known and name in known:
                results[name] = known[name]
                continue
            res = run_method(name, pair.matches, pair.ctx, pair.degenerate)
            method = METHODS.get(res.method)
            res = check_support(res, pair.matches, cfg.threshold_px, *cfg.support,
                                checked=method is None or method.support_checked)
            results[name] = calibrate(name, res, pair.ctx.settings, cfg.bootstrap)


def run_method(name: str, matches: PairMatches, ctx: MethodContext,
               degenerate: str | None) -> MethodResult:
    """One method's own result on the checked matches (before the support check)."""
    spec, n = METHODS[name], matches.num_distinct_points
    if degenerate is not None:
        return refused_record(name, Status.DEGENERATE, "degenerate_input", degenerate)
    if n < spec.min_points:
        return refused_record(name, Status.DEGENERATE, "too_few_matches",
                              f"too few point matches for {name}: {n} distinct (needs "
                              f"{spec.min_points})", {"points": n})
    if spec.needs_intrinsics and not matches.has_intrinsics:
        return refused_record(name, Status.FAILED, "no_intrinsics",
                              f"{name} needs intrinsics K0, K1 (got none)")
    skip = missing_input(name, spec, matches, ctx)
    if skip is not None:
        return refused_record(name, Status.SKIPPED, "missing_input", skip)
    try:
        return spec(matches, ctx)
    except Exception as err:
        if ctx.config.raise_errors:
            raise
        first = str(err).splitlines()[0] if str(err) else ""
        rec = refused_record(name, Status.FAILED, "raised",
                             f"{name} raised {type(err).__name__}: {first}")
        rec.raised = type(err).__name__
        return rec


def missing_input(name: str, spec: PoseMethod, matches: PairMatches,
                  ctx: MethodContext) -> str | None:
    """Why ``name`` cannot run on this input (``None`` when it can): the network reads
    pixels and the matches carry no images, or a method it reads was skipped."""
    if spec.uses_network and not matches.has_images:
        visual = getattr(getattr(ctx.model, "config", None), "visual", None)
        if visual is not None:
            return (f"the model reads the images (visual={visual!r}) and "
                    "the matches carry none: attach them (PairMatches(..., image0=, "
                    "image1=) or load_external_matches(..., image0=, image1=))")
    for dep in spec.depends_on:
        dep = classical_method() if dep == CLASSICAL else dep
        if dep in ctx.results and ctx.results[dep].status is Status.SKIPPED:
            return f"it reads {dep}, which was skipped"
    return None
