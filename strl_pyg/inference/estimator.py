"""Inference: one call from a pair's matches (or two images and K) to a pose with a status.

:class:`PoseEstimator` runs every registered method (:data:`METHODS`, in registration order)
on the same :class:`~strl_pyg.data.PairMatches` and picks the recommended pose: the first
method of the checkpoint's order (:func:`recommended_order`; without one
:data:`RECOMMENDED_ORDER`: PoseLib when installed, else OpenCV, else the network's regression)
whose status is ``"ok"``, after :data:`POINT_POOR_ORDER` (the vanishing-point solver) where the
pair has at most :data:`POINT_POOR_MAX_POINTS` point matches. All poses are ``T_0to1``
(``X1 = R X0 + t``).

Statuses: :mod:`strl_pyg.inference.status`; what a record holds: :mod:`~strl_pyg.inference.
record`; the rules that decide: :mod:`strl_pyg.inference.rules`; the other modules of the
folder: :mod:`strl_pyg.inference`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import normalisation_scope
from strl_pyg.inference.calibration import shipped_header
from strl_pyg.inference.config import EstimatorConfig
from strl_pyg.inference.methods.context import MethodContext
from strl_pyg.inference.pair import PairRun, attach_fundamental, pair_rules
from strl_pyg.inference.pick import pick_recommended
from strl_pyg.inference.policy import recommended_order
from strl_pyg.inference.record import MethodResult, PoseEstimate
from strl_pyg.inference.registry import (
    METHODS,
    RECOMMENDED,
    checked_method_names,
    methods_needed,
    network_free_methods,
)
from strl_pyg.inference.rules import apply_rules, ordered_rules
from strl_pyg.inference.running import run_methods
from strl_pyg.inference.settings import CheckpointSettings
from strl_pyg.inference.status import Status

__all__ = ["PoseEstimator"]


class PoseEstimator:
    """Pose of one image pair by every registered method, with a recommended one.

    Args:
        model: a :class:`~strl_pyg.model.strl_pose.StrLPose` (any dtype or device), or a
            checkpoint path; ``None``: the shipped model,
            :meth:`StrLPose.from_pretrained() <strl_pyg.model.strl_pose.StrLPose.from_pretrained>`,
            loaded on the first estimate (its metadata calibrates every method and gives the
            recommended order, also when only classical methods run). A checkpoint whose
            metadata has no ``calibration`` entry keeps the shipped scales for the methods
            that do not read the network (PoseLib, OpenCV).
        methods, seed, threshold_px, device, raise_errors, bootstrap, min_inlier_ratio,
            min_inliers, min_in_front, resample, swap_check, data_check, focal_sensitivity,
            focal_range: the options, :class:`~strl_pyg.inference.config.EstimatorConfig`'s
            fields (documented there); or ``config=`` an ``EstimatorConfig``.

    The recommended pose is judged by the rules of :data:`~strl_pyg.inference.rules.RULES`
    (one module each, :mod:`strl_pyg.inference.rules`): every non-``ok`` pose and every widened
    sigma names its rule (``pose.rule``, ``pose.verdicts``).
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
        run_methods(pair, methods_needed(names), known)  # with what they read
        return self._finish(pair, names)

    def _names(self, methods: Any) -> tuple[str, ...] | str:
        """The names to run: ``methods`` checked, or the estimator's own (:data:`RECOMMENDED`
        for an estimator made with it)."""
        if methods is not None:
            return checked_method_names(methods)
        return RECOMMENDED if self.recommended_only else self.method_names

    def _pair(self, matches: PairMatches) -> PairRun:
        """The pair's one context (:meth:`PairRun.start`); the network is built only when a
        method needs it."""
        ctx = MethodContext(self.config, load_model=lambda: self.model, settings=self.settings)
        return PairRun.start(matches, ctx)

    def _finish(self, pair: PairRun, names: Any, fundamental: bool = True) -> PoseEstimate:
        """The estimate of the methods ``names`` of the pair (in that order): the rules that
        hold for every method of a pair, then the recommended pose; without intrinsics, the
        pair's fundamental matrix (``fundamental``)."""
        results = {name: pair.ctx.results[name] for name in names}  # the caller's order
        pair_rules(results, pair.matches, pair.rows, pair.problems)
        estimate = pick_recommended(results, list(pair.warnings), pair.matches, self.settings,
                                    self.config, pair.geometry)
        estimate.geometry = pair.geometry
        with normalisation_scope(pair.memo):
            estimate = apply_rules(estimate, pair, ordered_rules())
        estimate.point_rows = pair.rows
        if fundamental and not pair.matches.has_intrinsics:
            with normalisation_scope(pair.memo):
                attach_fundamental(estimate, pair.matches, self.config.threshold_px,
                                   self.config.seed, pair.rows)
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
            run_methods(pair, run, known)
            est = self._finish(pair, run, fundamental=False)
            if est.pose.status == Status.OK:
                break
            if bad_K and est.pose.status == Status.UNRELIABLE and est.pose.method == name:
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
        run_methods(pair, self.method_names, known)
        return self._finish(pair, self.method_names)

    def estimate_images(self, image0: np.ndarray, image1: np.ndarray, K0: Any = None,
                        K1: Any = None, frontend_config: Any = None,
                        methods: Any = None, original: Any = None,
                        features: Any = None) -> PoseEstimate:
        """Matches two images with :func:`~strl_pyg.frontend.match_images`, then
        :meth:`estimate` (``methods`` as there): :func:`strl_pyg.inference.images.
        estimate_images` (``K1`` defaults to ``K0``; no matches at all: ``"degenerate"``;
        ``original``: the sizes and K of images matched resized; ``features``: the images'
        feature sources, :mod:`strl_pyg.frontend.features`)."""
        from strl_pyg.inference.images import estimate_images

        return estimate_images(self, image0, image1, K0, K1, frontend_config, methods,
                               original, features)
