"""What every pose method shares: the pair's :class:`MethodContext` (configuration, model,
the results of the methods run before, shared work), the one classical solve a pair gets
(:func:`_solve`), the classical base other methods start from, the network's full forward
pass, and the covariance and bootstrap helpers."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import (
    OPENCV,
    POSELIB,
    estimate_relative_pose,
    have_poselib,
)
from strl_pyg.estimation.uncertainty import FAR_ROTATION_DEG, FAR_TRANSLATION_DEG, MIN_BOOTSTRAP
from strl_pyg.inference.network import network_pose
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.settings import CheckpointSettings
from strl_pyg.inference.status import Status

if TYPE_CHECKING:
    from strl_pyg.inference.config import EstimatorConfig

__all__ = ["MethodContext", "MethodFn", "DATA_CHECK_MIN_POINTS", "POINT_POOR_MAX_POINTS",
           "classical_base", "with_covariance"]


@dataclass
class MethodContext:
    """What a method sees besides the matches: the estimator's one read-only configuration
    (:class:`~strl_pyg.inference.config.EstimatorConfig`: seed, classical inlier threshold,
    bootstrap count, device, resampling, the swap and data checks, the support thresholds),
    the model (loaded on first use by ``load_model``), what the checkpoint says, the results
    of the methods run before it, and the work they share, each in its own field (one solve
    per solver, its bootstrap, the network's full forward pass, the lines' vanishing
    directions)."""

    config: EstimatorConfig
    load_model: Callable[[], torch.nn.Module] | None = field(default=None, repr=False)
    results: dict[str, MethodResult] = field(default_factory=dict)
    #: what the checkpoint says (calibration, fusion inflation); None: read from ``model``
    settings: CheckpointSettings | None = None
    #: the network, once loaded (:attr:`model`)
    loaded_model: torch.nn.Module | None = field(default=None, repr=False)
    #: each classical solver's one solve of the pair (:func:`_solve`), by solver name
    solves: dict[str, Any] = field(default_factory=dict, repr=False)
    #: each classical solver's bootstrap resamples, by solver name: a ``LazyBootstrap``
    #: (``strl_pyg.inference.methods.classical``), computed when first called (guided and
    #: fused reuse them)
    bootstraps: dict[str, Any] = field(default_factory=dict, repr=False)
    #: the network on every match and its time in ms (:func:`_full_forward`)
    full_forward: tuple[Any, float] | None = field(default=None, repr=False)
    #: the lines' vanishing directions (``vp``, ``vp_checked``)
    vanishing_directions: list | None = field(default=None, repr=False)
    #: the classical start of ``vp``'s joint refinement, where no classical method ran
    vp_start: MethodResult | None = field(default=None, repr=False)

    @property
    def model(self) -> torch.nn.Module:
        if self.loaded_model is None:
            if self.load_model is None:
                raise ValueError("Expected a model for a network method (got none)")
            self.loaded_model = self.load_model()
        return self.loaded_model

    def forget_lines(self) -> None:
        """Drops the shared work that read the lines (the pair's lines were replaced)."""
        self.vanishing_directions = None
        self.full_forward = None


MethodFn = Callable[[PairMatches, MethodContext], MethodResult]


# ----------------------------------------------------------------------------- methods


DATA_CHECK_MIN_POINTS = 8


def _solve(name: str, matches: PairMatches, ctx: MethodContext) -> Any:
    """The classical solver ``name`` on the pair, run once per pair (the data check and the
    classical method share it)."""
    if name not in ctx.solves:
        ctx.solves[name] = estimate_relative_pose(matches, name, ctx.config.threshold_px,
                                                  seed=ctx.config.seed)
    return ctx.solves[name]


def classical_base(ctx: MethodContext) -> str:
    """The classical solver a method reads: the one the run holds a result of (PoseLib first),
    else PoseLib where installed, else OpenCV; a method's
    :data:`~strl_pyg.inference.methods.base.CLASSICAL` dependency is that
    solver (:func:`~strl_pyg.inference.registry.methods_needed`): :func:`classical_solver` of
    the run's results."""
    return classical_solver(ctx.results, have_poselib())


def classical_solver(results: Any, poselib_available: bool) -> str:
    """Which classical solver the inference layer starts from, decided here only (the
    methods' base, the registry's :func:`~strl_pyg.inference.registry.classical_method`, the
    data check, MULTIPLE's second solve): the one ``results`` (a pair's method results) hold
    a result of, PoseLib first; else PoseLib where available, else OpenCV."""
    found = next((c for c in (POSELIB, OPENCV) if results and c in results), None)
    return found or (POSELIB if poselib_available else OPENCV)


#: The point-poor regime, one bound for everything that depends on it: at or below this many
#: point matches the recommended order puts the line solver first (``POINT_POOR_ORDER``) and
#: ``vp_checked`` consults the lines (above it, it is the classical pose). It is the definition
#: of the evaluation set ``point_poor`` and its calibration split, not a fit.
POINT_POOR_MAX_POINTS = 30


def _full_forward(matches: PairMatches, ctx: MethodContext):
    """The network on every match (no resampling: the geometric head weighs each match),
    computed once per pair and shared by ``geometric`` and ``guided``."""
    if ctx.full_forward is None:
        model = ctx.model
        start = time.perf_counter()
        out = network_pose(model, matches, ctx.config.seed, None, ctx.config.device)
        ctx.full_forward = (out, (time.perf_counter() - start) * 1e3)
    return ctx.full_forward


def _no_head(name: str, ctx: MethodContext) -> MethodResult | None:
    if not getattr(ctx.model.config, "geometric", False):
        return MethodResult(name, Status.FAILED, warnings=[
            f"{name} needs a model with the geometric head (config.geometric=True); this "
            "checkpoint has only the regression head"])
    return None


def with_covariance(name: str, pose: Any, matches: PairMatches, thr: float,
                     **kw: Any) -> MethodResult:
    """An ``"ok"`` record of ``pose`` (a float64 :class:`~strl_pyg.geometry.Pose`) with the
    first-order covariance of the point matches within ``thr`` px of it."""
    from strl_pyg.estimation.classical import normalised_matches
    from strl_pyg.estimation.pose_fusion import classical_covariance
    from strl_pyg.geometry import pose_sampson

    x0, x1, focal = normalised_matches(matches)
    inl = (pose_sampson(pose.R, pose.t, x0, x1).abs() < thr / focal).numpy()
    warnings = list(kw.pop("warnings", []))
    cov = None
    try:
        cov = classical_covariance(pose, matches, inl, threshold_px=thr)[1].numpy()
    except ValueError as err:
        warnings.append(f"{name}: no covariance ({err})")
    return MethodResult(name, Status.OK, pose, cov, warnings, num_inliers=int(inl.sum()), **kw)


def _add_bootstrap(rec: MethodResult, boot: np.ndarray | None, n_boot: int, kind: str,
                   source: str = "", resampled: str | None = None) -> MethodResult:
    """``rec`` with the bootstrap term ``boot`` added to its covariance (if both exist) and
    ``info["covariance"]`` saying which covariance it carries (``kind``, ``+ <source>bootstrap
    (n)``); a warning when the bootstrap was asked for but gave too few poses."""
    if rec.covariance is None:
        return rec
    if boot is not None:
        rec.covariance = rec.covariance + boot.covariance
        rec.info["covariance"] = f"{kind} + {source}bootstrap ({n_boot})"
        rec.info["bootstrap_far"] = boot.far
        if boot.far:  # named by the solve it resampled: said once per pose, however many
            who = resampled or source.strip() or rec.method  # methods reuse it
            rec.warnings.append(
                f"{who} bootstrap: {boot.far} of {boot.resamples} resamples found "
                f"another pose (over {FAR_ROTATION_DEG:g} deg in rotation or "
                f"{FAR_TRANSLATION_DEG:g} deg in translation away): the matches do not "
                "single out this solution; its sigma includes the others")
    else:
        rec.info["covariance"] = kind
        if n_boot:
            rec.warnings.append(f"{rec.method}: fewer than {MIN_BOOTSTRAP} of {n_boot} "
                                f"bootstrap resamples gave a pose; {kind} covariance only")
    return rec
