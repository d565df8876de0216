"""The pose methods :class:`~strl_pyg.inference.PoseEstimator` runs, one small class each
(:class:`~strl_pyg.inference.registry.PoseMethod`), and the context they share;
:mod:`strl_pyg.inference.estimator` registers them in :data:`METHODS
<strl_pyg.inference.registry.METHODS>`, in this order:

* ``regression``: the network's pose head (resampled graph, as in training).
* ``opencv``, ``poselib``: the classical essential-matrix solvers
  (:mod:`strl_pyg.estimation.classical`).
* ``fused`` (:class:`Fused`): the network and the first ``"ok"`` classical pose combined in
  information form (:func:`~strl_pyg.estimation.pose_fusion.fuse_poses`).
* ``geometric``: the weighted eight-point solve of the geometric head, refined.
* ``guided``: the classical solver guided by the geometric head's inlier weights
  (:func:`~strl_pyg.estimation.guided.guided_estimate`).
* ``vp``, ``vp_checked``: the methods of the lines' vanishing directions
  (:mod:`strl_pyg.inference.line_methods`).

A method is ``fn(matches, context) -> MethodResult``; ``context.results`` holds the methods
run before it. Covariances (:mod:`strl_pyg.inference.record`): the network's from its predicted
log-variances, the classical ones from the Sampson residuals of their inliers (first order:
optimistic for RANSAC estimates), the fused one from the information-form fusion.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import estimate_relative_pose, have_poselib
from strl_pyg.estimation.uncertainty import (
    FAR_ROTATION_DEG,
    FAR_TRANSLATION_DEG,
    MIN_BOOTSTRAP,
    bootstrap_resamples,
    data_covariance,
    swap_covariance,
)
from strl_pyg.inference.config import CheckpointSettings, EstimatorConfig
from strl_pyg.inference.network import network_pose
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.registry import PoseMethod

__all__ = ["MethodContext", "MethodFn", "POINT_POOR_MAX_POINTS", "Regression", "Classical",
           "Geometric", "Guided", "Fused", "with_covariance", "classical_base"]


# ----------------------------------------------------------------------------- context
@dataclass
class MethodContext:
    """What a method sees besides the matches: the estimator's one read-only configuration
    (:class:`~strl_pyg.inference.config.EstimatorConfig`: seed, classical inlier threshold,
    bootstrap count, device, resampling, the swap and data checks, the support thresholds),
    the model (loaded on first use by ``load_model``), what the checkpoint says, the results
    of the methods run before it, and shared work (e.g. a forward pass)."""

    config: EstimatorConfig = field(default_factory=EstimatorConfig)
    load_model: Callable[[], torch.nn.Module] | None = field(default=None, repr=False)
    results: dict[str, MethodResult] = field(default_factory=dict)
    cache: dict[str, Any] = field(default_factory=dict)
    #: what the checkpoint says (calibration, fusion inflation); None: read from ``model``
    settings: CheckpointSettings | None = None

    @property
    def model(self) -> torch.nn.Module:
        if "model" not in self.cache:
            if self.load_model is None:
                raise ValueError("Expected a model for a network method (got none)")
            self.cache["model"] = self.load_model()
        return self.cache["model"]


MethodFn = Callable[[PairMatches, MethodContext], MethodResult]


# ----------------------------------------------------------------------------- methods
class Regression(PoseMethod):
    """The network's pose head on the pair's resampled graph (as in training), with its covariance
    from the predicted log-variances, the swap check and the data check."""

    name = "regression"
    label = "the network's pose head"
    needs_intrinsics = False
    uses_network = True
    reads_lines = True
    support_checked = False

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.pose_fusion import network_covariance
        from strl_pyg.geometry import tangent_basis
        from strl_pyg.geometry import Pose

        model = ctx.model
        start = time.perf_counter()
        # the swap check runs its own forward pass: one batch of both pairs measured 2x slower on
        # a CPU (330 ms against 81 + 80 ms on KITTI: the batched graph loses the one-pair path)
        out = network_pose(model, matches, ctx.config.seed, ctx.config.resample, ctx.config.device)
        ms = (time.perf_counter() - start) * 1e3
        q, t, lv = (x[0].detach().cpu().double() for x in (out.quaternion, out.translation,
                                                           out.log_var))
        if not all(bool(torch.isfinite(x).all()) for x in (q, t, lv)) or float(t.norm()) < 1e-12:
            return MethodResult("regression", "failed", time_ms=ms, raw=out,
                                warnings=["the network returned a non-finite or zero pose"])
        cov = network_covariance(q, t, lv, tangent_basis(t)).numpy()
        info = {"quaternion": q, "translation": t, "log_var": lv,
                "sigma_components": torch.exp(0.5 * lv),
                "translation_kind": model.config.translation}
        pose = Pose.from_quaternion(q, t)
        warnings = []
        if ctx.config.swap_check:
            start = time.perf_counter()
            try:
                found = _swap_disagreement(model, matches, ctx, pose)
            except Exception as err:  # the forward pose stands; only its check is missing
                found = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            # its own time: time_ms stays the forward pass's, comparable with runs without it
            info["swap_check_ms"] = (time.perf_counter() - start) * 1e3
            if found is None or isinstance(found, str):
                why = ("the swapped pair's forward pass gave a non-finite or zero pose"
                       if found is None else f"the swapped pair's forward pass raised {found}")
                warnings.append(f"regression: no swap check ({why}); its covariance is the "
                                "network's own")
            else:
                rot, trans = found
                cov = cov + swap_covariance(rot, trans)
                info["swap_disagreement_deg"] = {"rotation": math.degrees(rot),
                                                 "translation": math.degrees(trans)}
        if ctx.config.data_check:
            start = time.perf_counter()
            try:
                found = _data_disagreement(matches, pose, ctx)
            except Exception as err:  # the forward pose stands; only its check is missing
                found = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            info["data_check_ms"] = (time.perf_counter() - start) * 1e3
            if isinstance(found, str):
                info["data_check"] = f"not run: {found}"
                if matches.has_intrinsics:  # without K the pose is "unreliable" anyway
                    warnings.append(f"regression: no data check ({found}); its covariance does "
                                    "not hold the distance to the classical pose")
            else:
                cov = cov + data_covariance(*found)
                info["data_disagreement_deg"] = {"rotation": math.degrees(found[0]),
                                                 "translation": math.degrees(found[1])}
        return MethodResult("regression", "ok", pose, cov, warnings, time_ms=ms,
                            info=info, raw=out)


#: Fewest distinct point matches for the regression's data check (a 5-dof pose needs 5; the
#: classical solvers need more to be worth comparing with).
DATA_CHECK_MIN_POINTS = 8


def _solve(name: str, matches: PairMatches, ctx: MethodContext) -> Any:
    """The classical solver ``name`` on the pair, run once per pair (the data check and the
    classical method share it)."""
    key = f"solve_{name}"
    if key not in ctx.cache:
        ctx.cache[key] = estimate_relative_pose(matches, name, ctx.config.threshold_px,
                                                seed=ctx.config.seed)
    return ctx.cache[key]


def _data_disagreement(matches: PairMatches, pose: Any,
                       ctx: MethodContext) -> tuple[float, float] | str:
    """Angles (rad) between ``pose`` and the pose the point matches support: the classical
    solver's (PoseLib's where installed, else OpenCV's; robust, so a global answer, with its
    sign of ``t`` from cheirality), rotation and translation direction. A string says why it
    did not run."""

    if not matches.has_intrinsics:
        return "no intrinsics"
    n = matches.num_distinct_points
    if n < DATA_CHECK_MIN_POINTS:
        return f"{n} distinct point matches (fewer than {DATA_CHECK_MIN_POINTS})"
    name = "poselib" if have_poselib() else "opencv"
    res = _solve(name, matches, ctx)
    if not res.success:
        return f"{name} found no pose"
    R0, t0 = pose.R.double(), pose.t.double() / pose.t.double().norm()
    R, t = res.pose.R.double(), res.pose.t.double() / res.pose.t.double().norm()
    cos_r = ((torch.trace(R0.T @ R) - 1) / 2).clamp(-1, 1)
    cos_t = (t0 @ t).clamp(-1, 1)
    return float(torch.arccos(cos_r)), float(torch.arccos(cos_t))


def swap_term(regression: MethodResult) -> np.ndarray | None:
    """The swap check's :func:`swap_covariance` of a regression record (``None`` when it ran
    without one): what the fusion adds to the network's variance, as the record did."""
    swap = regression.info.get("swap_disagreement_deg")
    return None if swap is None else swap_covariance(math.radians(swap["rotation"]),
                                                     math.radians(swap["translation"]))


def _swap_disagreement(model: torch.nn.Module, matches: PairMatches, ctx: MethodContext,
                       pose: Any, back: Any = None) -> tuple[float, float] | None:
    """Angles (rad) between ``pose`` and the inverse of the network's pose of the swapped
    pair (``back``, its ``PoseOutput``, or computed here): rotation, translation direction;
    ``None`` when that pose is not finite."""
    from strl_pyg.geometry import Pose

    if back is None:
        cfg = ctx.config
        back = network_pose(model, matches.swapped(), cfg.seed, cfg.resample, cfg.device)
    qb, tb = (x[0].detach().cpu().double() for x in (back.quaternion, back.translation))
    if not (bool(torch.isfinite(qb).all()) and bool(torch.isfinite(tb).all())
            and float(tb.norm()) > 1e-12):
        return None
    inv = Pose.from_quaternion(qb, tb).inv()
    R_inv, t_inv = inv.R, inv.t
    cos_r = ((torch.trace(pose.R.T @ R_inv) - 1) / 2).clamp(-1, 1)
    cos_t = (pose.t @ t_inv / (pose.t.norm() * t_inv.norm())).clamp(-1, 1)
    return float(torch.arccos(cos_r)), float(torch.arccos(cos_t))


class Classical(PoseMethod):
    """A classical essential-matrix solver (:mod:`strl_pyg.estimation.classical`):
    ``Classical("opencv")`` (OpenCV MAGSAC) or ``Classical("poselib")`` (PoseLib LO-RANSAC,
    where installed), with the first-order covariance of its inliers and the bootstrap."""

    bootstrapped = True
    LABELS = {"opencv": "OpenCV MAGSAC", "poselib": "PoseLib"}

    def __init__(self, solver: str) -> None:
        if solver not in self.LABELS:
            raise ValueError(f"Expected a classical solver in {sorted(self.LABELS)} "
                             f"(got {solver!r})")
        self.name, self.label = solver, self.LABELS[solver]

    def available(self) -> bool:
        return self.name != "poselib" or have_poselib()

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        name = self.name
        from strl_pyg.estimation.pose_fusion import classical_covariance

        thr = ctx.config.threshold_px
        res = _solve(name, matches, ctx)
        if not res.success:
            return MethodResult(name, "failed", time_ms=res.time_ms, num_inliers=0, raw=res,
                                warnings=[f"{name} found no pose (no essential matrix with "
                                          "points in front of both cameras)"])
        warnings, cov, info = [], None, dict(res.info)
        try:
            cov = classical_covariance(res.pose, matches, res.inliers, threshold_px=thr)[1]
            cov = cov.numpy()
        except ValueError as err:
            warnings.append(f"{name}: no covariance ({err})")
        rec = MethodResult(name, "ok", res.pose, cov, warnings, res.time_ms,
                           res.num_inliers, info=info, raw=res)
        if cov is not None and ctx.config.bootstrap:
            # first order (noise around a right solution) + bootstrap (instability of the
            # solution itself), see strl_pyg.estimation.uncertainty
            start = time.perf_counter()
            boot = bootstrap_resamples(matches, res.pose, name, ctx.config.bootstrap, thr,
                                       ctx.config.seed)
            rec.time_ms += (time.perf_counter() - start) * 1e3
            ctx.cache[f"bootstrap_{name}"] = boot  # guided and fused reuse it
        else:
            boot = None
        return _add_bootstrap(rec, boot, ctx.config.bootstrap, "first-order")


def classical_base(ctx: MethodContext) -> str:
    """The classical solver a method reads: the one the run holds a result of (PoseLib first),
    else PoseLib where installed, else OpenCV; a method's ``"classical"`` dependency is that
    solver (:func:`~strl_pyg.inference.registry.methods_needed`)."""
    return next((c for c in ("poselib", "opencv") if c in ctx.results),
                "poselib" if have_poselib() else "opencv")


#: The point-poor regime, one bound for everything that depends on it: at or below this many
#: point matches the recommended order puts the line solver first (``POINT_POOR_ORDER``) and
#: ``vp_checked`` consults the lines (above it, it is the classical pose). It is the definition
#: of the evaluation set ``point_poor`` and its calibration split, not a fit.
POINT_POOR_MAX_POINTS = 30


def _full_forward(matches: PairMatches, ctx: MethodContext):
    """The network on every match (no resampling: the geometric head weighs each match),
    computed once per pair and shared by ``geometric`` and ``guided``."""
    if "full_forward" not in ctx.cache:
        model = ctx.model
        start = time.perf_counter()
        out = network_pose(model, matches, ctx.config.seed, None, ctx.config.device)
        ctx.cache["full_forward"] = (out, (time.perf_counter() - start) * 1e3)
    return ctx.cache["full_forward"]


def _no_head(name: str, ctx: MethodContext) -> MethodResult | None:
    if not getattr(ctx.model.config, "geometric", False):
        return MethodResult(name, "failed", warnings=[
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
    return MethodResult(name, "ok", pose, cov, warnings, num_inliers=int(inl.sum()), **kw)


class Geometric(PoseMethod):
    """The geometric head's weighted eight-point solve, refined, with a first-order covariance."""

    name = "geometric"
    label = "the network's weighted eight-point"
    uses_network = True
    reads_lines = True
    needs_geometric_head = True

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.classical import normalised_matches
        from strl_pyg.geometry import Pose
        from strl_pyg.geometry.essential import DEGENERATE, refine_pose

        bad = _no_head("geometric", ctx)
        if bad is not None:
            return bad
        out, ms = _full_forward(matches, ctx)
        geo = out.geometric
        status = int(geo.status[0])
        if status != 0:
            why = "degenerate weighted solve (too few effective matches or rank-deficient)" \
                if status == DEGENERATE else "no intrinsics: the weighted solve needs K0, K1"
            return MethodResult("geometric", "degenerate" if status == DEGENERATE else "failed",
                                time_ms=ms, warnings=[f"geometric: {why}"], raw=out)
        start = time.perf_counter()
        w = torch.sigmoid(geo.point_logits.double().cpu())
        x0, x1, focal = normalised_matches(matches)
        R, t = refine_pose(geo.R[:1].cpu(), geo.t[:1].cpu(), x0[None], x1[None], w[None],
                           iterations=10, tau=ctx.config.threshold_px / focal)
        T = Pose(R[0], t[0])
        ms += (time.perf_counter() - start) * 1e3
        return with_covariance("geometric", T, matches, ctx.config.threshold_px, time_ms=ms,
                                info={"mean_weight": float(w.mean())}, raw=out)


class Guided(PoseMethod):
    """The classical solver guided by the geometric head's inlier weights
    (:func:`~strl_pyg.estimation.guided.guided_estimate`)."""

    name = "guided"
    label = "network-guided classical solve"
    uses_network = True
    reads_lines = True
    bootstrapped = True
    classical_base = True
    depends_on = ("classical",)
    needs_geometric_head = True

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.guided import guided_estimate

        bad = _no_head("guided", ctx)
        if bad is not None:
            return bad
        base = classical_base(ctx)
        out, ms = _full_forward(matches, ctx)
        w = torch.sigmoid(out.geometric.point_logits.double().cpu()).numpy()
        prior = ctx.results.get(base)
        classical = prior.raw if prior is not None and prior.status == "ok" else None
        res = guided_estimate(matches, w, base, ctx.config.threshold_px, seed=ctx.config.seed,
                              classical=classical)
        ms += res.time_ms
        if not res.success:
            return MethodResult("guided", "failed", time_ms=ms, raw=res,
                                warnings=[f"guided {base}: no hypothesis found"])
        info = {"base": base, "candidate": res.info["candidate"], "refined": res.info["refined"]}
        rec = with_covariance("guided", res.pose, matches,
                               ctx.config.threshold_px, time_ms=ms, info=info, raw=res)
        boot, n_boot, resampled = None, ctx.config.bootstrap, None
        if rec.covariance is not None and n_boot:
            # the same bootstrap as the classical records, of the solve guided kept: on all the
            # matches (then it is the base method's own, computed once) or on the network's top
            # matches; the refinement, when kept, is not re-run per resample
            start = time.perf_counter()
            subset = res.info.get("point_index")
            key = f"bootstrap_{base}"
            if (subset is None and res.info["candidate"] == "all" and not res.info["refined"]
                    and key in ctx.cache):
                boot, resampled = ctx.cache[key], base
            else:
                sub = matches if subset is None else matches.select(point_index=subset)
                boot = bootstrap_resamples(sub, res.pose, base, n_boot,
                                           ctx.config.threshold_px, ctx.config.seed)
            rec.time_ms += (time.perf_counter() - start) * 1e3
        return _add_bootstrap(rec, boot, n_boot, "first-order", resampled=resampled)


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


class Fused(PoseMethod):
    """The network's pose and the first ``"ok"`` classical pose combined in information form
    (:func:`~strl_pyg.estimation.pose_fusion.fuse_poses`)."""

    name = "fused"
    label = "network + classical, information form"
    uses_network = True
    reads_lines = True
    bootstrapped = True
    classical_base = True
    depends_on = ("regression", "classical")

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.pose_fusion import fuse_poses

        net = ctx.results.get("regression")
        cls = next((ctx.results[c] for c in ("poselib", "opencv")
                    if c in ctx.results and ctx.results[c].status == "ok"), None)
        if net is None or net.status != "ok" or cls is None:
            return MethodResult("fused", "failed", warnings=[
                "fused needs an 'ok' regression and an 'ok' classical estimate (poselib or "
                "opencv)"])
        start = time.perf_counter()
        # the regression's calibrated variance, times the fusion's own inflation (fitted on the
        # held-out calibration pairs by benchmarks/bench_pose.py --calibrate: the smallest that
        # keeps the 95 % upper bound of the median change against the classical pose <= +5 %)
        settings = ctx.settings if ctx.settings is not None else CheckpointSettings.of(ctx.model)
        scale = settings.calibration.get("regression", 1.0) * settings.fusion_inflation
        f = fuse_poses(net.raw, None, cls.raw, matches, threshold_px=ctx.config.threshold_px,
                       network_scale=scale, network_extra=swap_term(net))
        ms = (time.perf_counter() - start) * 1e3 + net.time_ms + cls.time_ms
        if f.source == "network":
            return MethodResult("fused", "failed", time_ms=ms, raw=f, warnings=[
                f"fused: too few {cls.method} inliers for a covariance ({f.info['num_inliers']})"])
        gate = f.info.get("gate", {})
        info = {"classical": cls.method, "network_weight": f.weights,
                "sign_disagreement": f.info["sign_disagreement"], "used": f.source,
                "gate_d2": gate.get("d2"), "network_variance_scale": scale}
        warnings = [] if f.source == "fused" else [f"fused: {gate.get('reason')}"]
        rec = MethodResult("fused", "ok", f.pose, f.covariance.numpy(),
                           warnings, time_ms=ms, num_inliers=f.info["num_inliers"], info=info,
                           raw=f)
        # the fused pose stays near the classical one and moves with it when the matches change:
        # the classical bootstrap term (instability of the solve, which the information form
        # cannot see) is added, as for the classical record itself (its warning, if any, is there)
        boot = ctx.cache.get(f"bootstrap_{cls.method}")
        rec = _add_bootstrap(rec, boot, 0 if boot is None else ctx.config.bootstrap,
                             "information form", f"{cls.method} ")
        return rec
