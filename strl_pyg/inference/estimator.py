"""Inference: one call from a pair's matches (or two images and K) to a pose with a status.

:class:`PoseEstimator` runs every registered method (:data:`METHODS`, in registration order)
on the same :class:`~strl_pyg.data.PairMatches` and picks the recommended pose: the first
method of the checkpoint's order (:func:`recommended_order`; without one
:data:`RECOMMENDED_ORDER`: PoseLib when installed, else OpenCV, else the network's regression)
whose status is ``"ok"``, after :data:`POINT_POOR_ORDER` (the vanishing-point solver) where the
pair has at most :data:`POINT_POOR_MAX_POINTS` point matches. All poses are ``T_0to1``
(``X1 = R X0 + t``).

Statuses (:data:`STATUSES`, :mod:`strl_pyg.inference.record`): ``"ok"`` (a pose),
``"unreliable"`` (a pose was computed but must not be used, so none is given: the intrinsics
fail the input checks (:func:`intrinsics_problems`: principal point outside the image, focal
length out of range, a normalised K with pixel points, one K for two image sizes), or more
than 10 % of the matches that fit its epipolar geometry lie behind a camera
(:data:`CHEIRALITY_MIN`); the reasons are in its warnings, the computed pose in
``info["unreliable_T_0to1"]``), ``"degenerate"`` (the input does not determine the pose: fewer
point matches than the solvers need (:data:`MIN_POINTS`), or zero parallax (identical
images): no pose is given), ``"failed"`` (the method found no pose, e.g. RANSAC returned no
model, or the matches do not support it; never replaced by an identity pose). A pose exists
only with ``"ok"``.

The folder's modules: the records (:mod:`~strl_pyg.inference.record`), the input checks
(:mod:`~strl_pyg.inference.checks`), the network's graph and forward
(:mod:`~strl_pyg.inference.network`), the method classes (:mod:`~strl_pyg.inference.methods`,
:mod:`~strl_pyg.inference.methods.vanishing_point`) and their registry
(:mod:`~strl_pyg.inference.registry`: ``register_method(MyMethod())``, a
:class:`~strl_pyg.inference.methods.base.PoseMethod`), one pair's run
(:mod:`~strl_pyg.inference.pair`), the calibration (:mod:`~strl_pyg.inference.calibration`),
the recommended order (:mod:`~strl_pyg.inference.policy`), the evidence for a pose
(:mod:`~strl_pyg.inference.evidence`) and this module, :class:`PoseEstimator`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import normalisation_scope
from strl_pyg.inference.calibration import calibrate, shipped_header
from strl_pyg.inference.checks import BAD_INTRINSICS, input_warnings
from strl_pyg.inference.config import EstimatorConfig
from strl_pyg.inference.evidence import (
    apply_configuration,
    apply_multiple_motions,
    apply_watermark,
    focal_sensitivity,
    learned_pose_evidence,
)
from strl_pyg.inference.methods.context import MethodContext
from strl_pyg.inference.methods.regression import Regression
from strl_pyg.inference.pair import (
    PairRun,
    attach_fundamental,
    checked_pair,
    pair_rules,
    start_geometry,
    unique_in_order,
)
from strl_pyg.inference.policy import (
    POSELIB_MISSING,
    measured_with_missing_poselib,
    recommended_order,
)
from strl_pyg.inference.record import MethodResult, PoseEstimate
from strl_pyg.inference.registry import (
    CLASSICAL,
    METHODS,
    RECOMMENDED,
    PoseMethod,
    checked_method_names,
    classical_method,
    methods_needed,
    network_free_methods,
)
from strl_pyg.inference.settings import CheckpointSettings
from strl_pyg.inference.support import (
    check_support,
)

__all__ = ["PoseEstimator"]


# ----------------------------------------------------------------------------- estimator


class PoseEstimator:
    """Pose of one image pair by every registered method, with a recommended one.

    Args:
        model: a :class:`~strl_pyg.model.strl_pose.StrLPose` (any dtype or device), or a checkpoint
            path; ``None``: the shipped model,
            :meth:`StrLPose.from_pretrained() <strl_pyg.model.strl_pose.StrLPose.from_pretrained>`,
            loaded on the first estimate (its metadata calibrates every method and gives the
            recommended order, also when only classical methods run). A checkpoint whose
            metadata has no ``calibration`` entry keeps the shipped scales for the methods
            that do not read the network (PoseLib, OpenCV).
        methods: names from :data:`METHODS` to run (default: all installed ones); one name
            as a ``str`` is one method.
        seed: resampling and RANSAC seed (same input, same result).
        threshold_px: inlier threshold of the classical solvers, pixels.
        device: where the network runs: the model is moved there (``model.to(device)``,
            in place); default: the model's device. A device this machine does not have
            (``"cuda"`` without CUDA) is a ``ValueError`` here, not a failure of every network
            method later.
        raise_errors: re-raise a method's exception instead of recording ``"failed"``.
        bootstrap: resamples of the point matches behind the ``poselib`` / ``opencv``
            covariances (first order + bootstrap, :mod:`strl_pyg.estimation.uncertainty`); ``0``:
            first order only. Their calibration scales apply only when the checkpoint's
            ``metadata["calibration_bootstrap"]`` (0 when absent) equals it; otherwise the
            record keeps the uncalibrated covariance and says so in ``warnings``.
        min_inlier_ratio, min_inliers: a solver's pose (``PoseMethod.support_checked``) is
            ``"failed"`` when the matches do not support it: fewer of the point matches lie
            within :data:`SUPPORT_BAND` x ``threshold_px`` of it (Sampson distance; the band
            keeps correct poses of 2 px matches) than this fraction of them, or than
            ``min(min_inliers, number of matches)`` (with fewer matches than that, every match
            must agree). Random matches give RANSAC a few percent (11 of 300), and on a few
            dozen its 5-point sample plus a handful (9 of 32 on two unrelated images). When no
            checked solver is left ``"ok"`` for that reason, the regression is not used as the
            recommended pose either. Defaults 0.1 and 12; ``0`` switches either off. Only
            matches in front of both cameras count (as in the solvers' own counts).
        min_in_front: a checked pose is ``"unreliable"`` when fewer than this fraction of the
            point matches within the support band lie in front of both cameras (its sign or
            decomposition is wrong; default :data:`CHEIRALITY_MIN`, ``0`` = off). Every pose
            is ``"unreliable"`` when the intrinsics fail :func:`intrinsics_problems`.
        resample: the regression's input graph: ``"model"`` (default: the point / line counts
            the checkpoint was trained with, seeded by ``seed``), ``(points, lines)`` or
            ``None`` (every match).
        swap_check: the regression also runs on the swapped pair (image 1 first) and its
            covariance grows by the disagreement of the two passes
            (:func:`~strl_pyg.estimation.uncertainty.swap_covariance`; default ``True``): the
            network's own variances are fitted on its training distribution and stay small
            away from it.
        data_check: the regression's covariance also grows by its distance to the classical
            pose of the same matches (PoseLib's, else OpenCV's; one solve per pair, shared
            with that method) (:func:`~strl_pyg.estimation.uncertainty.data_covariance`; default
            ``True``; needs intrinsics and 8 distinct point matches).
        focal_sensitivity: the recommended pose is solved again with both focal lengths
            scaled by ``focal_range`` (default 2) each way; where the matches do not verify
            the focal length, the spread is added to its covariance
            (:func:`~strl_pyg.inference.evidence.focal_sensitivity`; default ``True``; two
            more solves per pair).
    """

    def __init__(self, model: Any = None, methods: Any = None, *,
                 config: EstimatorConfig | None = None, **options: Any) -> None:
        if isinstance(model, (str, os.PathLike)):  # a checkpoint path, as --checkpoint takes
            from strl_pyg.model.strl_pose import StrLPose

            model = StrLPose.load(model)
        elif model is not None and not isinstance(model, torch.nn.Module):
            raise TypeError(f"Expected a StrLPose, a checkpoint path or None (got "
                            f"{type(model).__name__})")
        if config is not None and not isinstance(config, EstimatorConfig):
            raise TypeError(f"Expected config as an EstimatorConfig (got "
                            f"{type(config).__name__})")
        if methods is not None:
            options["methods"] = methods
        cfg = (config or EstimatorConfig()).replace(**options) if options else (
            config or EstimatorConfig())
        self.config = cfg
        names = checked_method_names(cfg.methods)
        #: whether estimate() walks the recommended order by default (methods="recommended")
        self.recommended_only = names == RECOMMENDED
        #: the methods this estimator may run (all installed ones for "recommended")
        self.method_names = checked_method_names(None) if self.recommended_only else names
        self._model = model
        self._settings: CheckpointSettings | None = None
        if cfg.device is not None and self._model is not None:
            self._model = self._model.to(cfg.device)

    @property
    def model_config(self) -> Any:
        """The model's :class:`~strl_pyg.model.StrLPoseConfig`, without building the shipped
        network when none was given."""
        return self._metadata_source().config

    @property
    def settings(self) -> CheckpointSettings:
        """What the checkpoint's metadata says about estimation (calibration, recommended
        order, ...), read once: from the model when one was given or built, else from the
        shipped checkpoint's metadata alone (without building the network) when no method
        needs it."""
        if self._settings is None:
            own = CheckpointSettings.of(self._metadata_source())
            free = network_free_methods()
            # without a model the source is the shipped header itself
            if self._model is not None and any(m not in own.calibration for m in free):
                try:  # the shipped scales of PoseLib's and OpenCV's covariances
                    own = own.with_fallback(CheckpointSettings.of(shipped_header()), free)
                except (OSError, ValueError, RuntimeError):
                    pass  # no shipped weights readable: those methods say "not calibrated"
            self._settings = own
        return self._settings

    @property
    def model(self) -> torch.nn.Module:
        if self._model is None:
            from strl_pyg.model.strl_pose import StrLPose

            self._model = StrLPose.from_pretrained()
            if self.config.device is not None:
                self._model = self._model.to(self.config.device)
            self._settings = None  # now read from the model itself
        return self._model

    def _metadata_source(self) -> Any:
        """What the calibration and the recommended order are read from: the model when one
        was given or built, else the shipped checkpoint's metadata alone (read once, without
        building the network)."""
        # without a model the one built later is the shipped one: its metadata is the same
        return self._model if self._model is not None else shipped_header()

    def estimate(self, matches: PairMatches, known: dict[str, MethodResult] | None = None,
                 methods: Any = None) -> PoseEstimate:
        """Runs the methods on ``matches`` (pixels; ``K0``/``K1`` for the classical ones).

        ``known``: results of methods already run on these same matches (e.g. by an earlier
        call, :attr:`PoseEstimate.methods`); they are taken as they are, not run again.
        ``methods``: the names to run this time (default: the estimator's own), with the
        same configuration and checkpoint settings; :data:`RECOMMENDED`: the methods of the
        recommended order one at a time (with the methods each reads) until the first
        ``"ok"`` one, the same recommended pose as running every method."""
        if not isinstance(matches, PairMatches):
            raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
        names = self._names(methods)
        pair = self._pair(matches)
        if names == RECOMMENDED:
            return self._recommended(pair, known=known)
        self._run_methods(pair, methods_needed(names), known)  # with what they read
        return self._finish(pair, names)

    def _names(self, methods: Any) -> tuple[str, ...] | str:
        """The names to run: ``methods`` checked, or the estimator's own (:data:`RECOMMENDED`
        for an estimator made with it)."""
        if methods is not None:
            return checked_method_names(methods)
        return RECOMMENDED if self.recommended_only else self.method_names

    def _pair(self, matches: PairMatches) -> PairRun:
        """The pair's one context: its input check, and the context its methods share. The
        model's metadata (the shipped one's when None was given) calibrates the classical
        methods too, also when no network method runs; the network itself is built only
        when a method needs it."""
        checked, warnings, rows, degenerate, problems = checked_pair(matches)
        memo: dict = {}
        geometry = None if degenerate is not None or problems or not checked.has_intrinsics \
            else start_geometry(checked, memo, self.config.threshold_px, self.config.seed)
        ctx = MethodContext(self.config, load_model=lambda: self.model, settings=self.settings)
        return PairRun(checked, warnings, rows, degenerate, problems, ctx, memo, geometry)

    def _run_methods(self, pair: PairRun, names: Any,
                     known: dict[str, MethodResult] | None = None) -> None:
        """Runs the methods of ``names`` the pair has no result of yet, in the registry's
        order (a method that reads another's result runs after it, whatever order the caller
        named them in), inside the pair's normalisation scope."""
        registry = list(METHODS)
        results = pair.ctx.results
        with normalisation_scope(pair.memo):
            for name in sorted(names, key=registry.index):
                if name in results:
                    continue
                if known and name in known:
                    results[name] = known[name]
                    continue
                res = self._support(self._run(name, pair.matches, pair.ctx, pair.degenerate),
                                    pair.matches)
                results[name] = calibrate(name, res, pair.ctx.settings, self.config.bootstrap)

    def _finish(self, pair: PairRun, names: Any, fundamental: bool = True) -> PoseEstimate:
        """The estimate of the methods ``names`` of the pair (in that order): the rules that
        hold for every method of a pair, then the recommended pose; without intrinsics, the
        pair's fundamental matrix (``fundamental``)."""
        results = {name: pair.ctx.results[name] for name in names}  # the caller's order
        pair_rules(results, pair.matches, pair.rows, pair.problems)
        estimate = self._recommend(results, list(pair.warnings), pair.matches, pair.geometry)
        with normalisation_scope(pair.memo):
            estimate = apply_watermark(estimate, pair.geometry, pair.matches,
                                       self.config.threshold_px)
            estimate = apply_multiple_motions(estimate, estimate.geometry or pair.geometry,
                                              pair.matches, self.config.threshold_px,
                                              self.config.seed)
            if self.config.focal_sensitivity:
                estimate.pose = focal_sensitivity(estimate.pose, pair.matches,
                                                  self.config.threshold_px, self.config.seed,
                                                  self.config.focal_range)
            estimate = apply_configuration(estimate, estimate.geometry or pair.geometry,
                                           pair.matches)
        estimate.point_rows = pair.rows
        if fundamental and not pair.matches.has_intrinsics:
            with normalisation_scope(pair.memo):
                cfg = self.config
                attach_fundamental(estimate, pair.matches, cfg.threshold_px, cfg.seed,
                                    pair.rows)
        return estimate

    def _installed_order(self, num_points: int | None = None) -> list[str]:
        return [m for m in recommended_order(self.settings, num_points)
                if m in METHODS and METHODS[m].available()]

    def _recommended(self, pair: PairRun, more_lines: Callable[[], PairMatches] | None = None,
                     known: dict[str, MethodResult] | None = None) -> PoseEstimate:
        """The recommended order walked one method at a time (with the methods it reads),
        stopping once the recommended pose is ``"ok"``, or at the first ``"unreliable"`` one
        when the intrinsics fail the input checks (every later pose would be too).
        ``more_lines``: the pair's matches with lines added, called once before the first
        method that reads lines runs (the front end's second half). ``known``: as in
        :meth:`estimate`.

        The same pose as running every method: when the walk ends without an ``"ok"`` pose
        and a solver's pose was refused for lack of support, the remaining installed methods
        run too (the regression stands in only while some solver's pose is supported, and
        a solver outside the order, e.g. ``vp``, may be)."""
        order = self._installed_order(pair.matches.num_distinct_points)
        if not order:  # nothing recommended is installed: the estimator's methods run
            return self._run_all(pair, more_lines, known)
        bad_K = not pair.matches.has_intrinsics or bool(pair.problems)
        run: tuple[str, ...] = ()
        est = None
        for name in order:
            run = methods_needed((*run, name))
            if more_lines is not None and any(METHODS[r].reads_lines for r in run):
                pair.add_lines(more_lines())
                more_lines = None
            self._run_methods(pair, run, known)
            est = self._finish(pair, run, fundamental=False)
            if est.pose.status == "ok":
                break
            if bad_K and est.pose.status == "unreliable" and est.pose.method == name:
                break  # every method reads the same K (or none): the later ones are too
        else:
            if any(r.unsupported for r in pair.ctx.results.values()):
                return self._run_all(pair, more_lines, known)
        # the last step's estimate is the answer; without intrinsics it gets the pair's
        # fundamental matrix (fitted once, at the end)
        return est if pair.matches.has_intrinsics else self._finish(pair, run)

    def _run_all(self, pair: PairRun, more_lines: Callable[[], PairMatches] | None,
                 known: dict[str, MethodResult] | None) -> PoseEstimate:
        """Every method of the estimator on the pair (the results it has are kept)."""
        if more_lines is not None and any(METHODS[m].reads_lines for m in self.method_names):
            pair.add_lines(more_lines())
        self._run_methods(pair, self.method_names, known)
        return self._finish(pair, self.method_names)

    def _run(self, name: str, matches: PairMatches, ctx: MethodContext,
             degenerate: str | None) -> MethodResult:
        """One method's own result on the checked matches (before the support check)."""
        spec, n = METHODS[name], matches.num_distinct_points
        if degenerate is not None:
            return MethodResult(name, "degenerate", warnings=[degenerate])
        if n < spec.min_points:
            return MethodResult(name, "degenerate", warnings=[
                f"too few point matches for {name}: {n} distinct (needs {spec.min_points})"])
        if spec.needs_intrinsics and not matches.has_intrinsics:
            return MethodResult(name, "failed",
                                warnings=[f"{name} needs intrinsics K0, K1 (got none)"])
        skip = self._missing_input(name, spec, matches, ctx)
        if skip is not None:
            return MethodResult(name, "skipped", warnings=[skip])
        try:
            return spec(matches, ctx)
        except Exception as err:
            if self.config.raise_errors:
                raise
            first = str(err).splitlines()[0] if str(err) else ""
            return MethodResult(name, "failed", raised=type(err).__name__,
                                warnings=[f"{name} raised {type(err).__name__}: {first}"])

    def _missing_input(self, name: str, spec: PoseMethod, matches: PairMatches,
                       ctx: MethodContext) -> str | None:
        """Why ``name`` cannot run on this input (``None`` when it can): the network reads
        pixels and the matches carry no images, or a method it reads was skipped."""
        if spec.uses_network and not matches.has_images:
            visual = getattr(getattr(self.model, "config", None), "visual", None)
            if visual is not None:
                return (f"the model reads the images (visual={visual!r}) and "
                        "the matches carry none: attach them (PairMatches(..., image0=, "
                        "image1=) or load_external_matches(..., image0=, image1=))")
        for dep in spec.depends_on:
            dep = classical_method() if dep == CLASSICAL else dep
            if dep in ctx.results and ctx.results[dep].status == "skipped":
                return f"it reads {dep}, which was skipped"
        return None

    def estimate_images(self, image0: np.ndarray, image1: np.ndarray, K0: Any = None,
                        K1: Any = None, frontend_config: Any = None,
                        methods: Any = None, original: Any = None) -> PoseEstimate:
        """Matches two images with :func:`~strl_pyg.frontend.match_images`, then
        :meth:`estimate` (``methods`` as there). ``K1`` defaults to ``K0`` (one camera). No
        matches at all gives status ``"degenerate"``. ``original``: where the images are a
        resized copy, the sizes and intrinsics the user gave (``{"size0", "size1", "K0",
        "K1"}``, ``matches.info["original_frame"]``): the intrinsics warnings quote them. With
        :data:`RECOMMENDED`, the images
        are matched once: the points first, the line segments added to them (without
        detecting the points again) only when a method that reads lines is about to run and
        ``frontend_config.lines`` is on."""
        from strl_pyg.data.checks import check_K
        from strl_pyg.frontend import FrontendConfig, NoMatchesError, match_images
        from strl_pyg.frontend.pipeline import add_lines

        names = self._names(methods)
        cfg = frontend_config if frontend_config is not None else FrontendConfig()
        if not isinstance(cfg, FrontendConfig):
            raise TypeError(f"Expected a FrontendConfig (got {type(cfg).__name__})")
        if K0 is None and K1 is not None:
            raise ValueError("Expected K0 with K1 (got K1 only)")
        K0 = check_K(K0, "K0")  # before any use: the no-match path reads them too
        K1 = K0 if K1 is None else check_K(K1, "K1")
        recommended = names == RECOMMENDED
        if recommended:  # the first method's matches first (points only unless it reads lines)
            order = self._installed_order()
            names = methods_needed(order[:1]) if order else self.method_names
            first = replace(cfg, lines=cfg.lines and any(METHODS[m].reads_lines
                                                         for m in names))
        else:
            first = cfg
        try:
            matches = match_images(image0, image1, K0=K0, K1=K1, config=first)
            if original is not None:
                matches.info["original_frame"] = dict(original)
        except NoMatchesError as err:
            o = original or {"size0": np.shape(image0)[:2], "size1": np.shape(image1)[:2],
                             "K0": K0, "K1": K1}
            warnings = input_warnings(o["size0"], o["size1"], o["K0"], o["K1"])
            why = f"no matches: {str(err).splitlines()[0]}"
            records = {m: MethodResult(m, "degenerate", warnings=[why]) for m in names}
            return PoseEstimate(MethodResult(None, "degenerate", warnings=warnings + [why]),
                                records, 0, 0, None)
        if not recommended:
            return self.estimate(matches, methods=names)
        more = (lambda: add_lines(matches, cfg)) if cfg.lines and not first.lines else None
        return self._recommended(self._pair(matches), more)

    def _support(self, res: MethodResult, matches: PairMatches) -> MethodResult:
        method = METHODS.get(res.method)
        return check_support(res, matches, self.config.threshold_px, *self.config.support,
                             checked=method is None or method.support_checked)

    def _recommend(self, results: dict[str, MethodResult], warnings: list[str],
                   matches: PairMatches, geometry: Any = None) -> PoseEstimate:
        """The first ``"ok"`` method of the recommended order; without one, the first
        ``"unreliable"`` one (no pose to use either, but the reason and the computed pose);
        else ``"degenerate"`` or ``"failed"``.
        The pose's warnings say why the earlier methods were passed over and which methods
        could not run at all (an exception: e.g. the network on a device it cannot use)."""
        chosen = recommended_order(self.settings, matches.num_distinct_points)
        order = [m for m in chosen if m in results]
        notes = [POSELIB_MISSING] if measured_with_missing_poselib(self.settings) else []
        raised = [m for m, r in results.items() if r.raised]
        notes += [f"{m} could not run: {'; '.join(results[m].warnings)}" for m in raised]
        # the regression stands in only while some solver's pose is supported or none was
        # refused for lack of support
        unsupported = any(r.unsupported for r in results.values()) and not any(
            r.status == "ok" for m, r in results.items()
            if m in METHODS and METHODS[m].support_checked)
        fallback = None  # (record, notes so far) of the first "unreliable" pose
        for m in order:
            r = results[m]
            if r.status in ("ok", "unreliable") and m == Regression.name and unsupported:
                notes.append("regression not used: the matches support no solver's pose")
                continue
            if r.status == "ok" and not METHODS[m].support_checked:
                # a learned pose is recommended only with the matches' support
                r = learned_pose_evidence(r, matches, self.config.threshold_px,
                                          self.config.support, geometry)
            if r.status == "ok":
                pose = replace(r, warnings=unique_in_order(warnings + notes + r.warnings))
                return PoseEstimate(pose, results, matches.num_points, matches.num_lines,
                                    matches)
            if r.status == "unreliable" and fallback is None:
                fallback = (r, list(notes))
            reasons = [w for w in r.warnings if w not in warnings]
            if reasons and m not in raised:
                notes.append(f"{m} {r.status}: {'; '.join(reasons)}")
        if fallback is not None:
            r, before = fallback
            own = [f"{BAD_INTRINSICS} (the warnings on K above)"
                   if w.startswith(f"{BAD_INTRINSICS}: ") else w for w in r.warnings]
            pose = replace(r, warnings=unique_in_order(warnings + before + own))
            return PoseEstimate(pose, results, matches.num_points, matches.num_lines, matches)
        if not order:
            notes.append(f"none of the recommended methods {chosen} was run")
        status = "degenerate" if any(results[m].status == "degenerate" for m in order) \
            else "failed"
        pose = MethodResult(None, status, warnings=unique_in_order(warnings + notes))
        return PoseEstimate(pose, results, matches.num_points, matches.num_lines, matches)
