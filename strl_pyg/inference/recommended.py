"""The recommended pose without the work it does not need (``strl-pose predict``'s default).

:class:`~strl_pyg.inference.PoseEstimator` with its default runs every installed method and
then picks the recommended pose: the first ``"ok"`` method of the checkpoint's recommended
order (:func:`~strl_pyg.inference.recommended_order`). :func:`estimate_recommended` gives the
same recommended pose but runs the methods of that order one at a time, stopping at the first
``"ok"`` one (with the methods it needs: ``fused`` reads ``regression`` and a classical
estimate, ``guided`` reuses the classical one; or at the first ``"unreliable"`` one when the
intrinsics fail the input checks: every later pose would be too), and matches line segments
only once a method that reads them (the network's, ``vp``) is about to run: the classical
solvers use points only. The point matches come first: with few of them the order starts with
:data:`~strl_pyg.inference.estimator.POINT_POOR_ORDER`.

Same pose: every method is deterministic in the matches and the seed, the point matches do not
depend on whether lines are matched (``filter_points`` off), and a method's result depends only
on the methods before it. The estimate's ``methods`` holds only the methods that ran.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

__all__ = ["estimate_recommended", "estimate_methods", "methods_needed",
           "NETWORK_METHODS", "DEPENDENCIES"]  # noqa: F822  (module __getattr__: the registry's)

# NETWORK_METHODS, LINE_METHODS, DEPENDENCIES: derived from the registry (MethodSpec), read
# through the estimator's module __getattr__ so a method registered later is in them too


def __getattr__(name: str):
    if name in ("NETWORK_METHODS", "LINE_METHODS", "DEPENDENCIES"):
        from strl_pyg.inference import estimator

        return getattr(estimator, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def methods_needed(names: Any) -> tuple[str, ...]:
    """``names`` with the methods they depend on, in registration order (the order
    :class:`~strl_pyg.inference.estimator.PoseEstimator` runs them)."""
    from strl_pyg.inference.estimator import METHODS, classical_method

    want, todo = set(), list(names)
    while todo:  # dependencies of dependencies too
        name = todo.pop()
        if name in want:
            continue
        want.add(name)
        deps = METHODS[name].depends_on if name in METHODS else ()
        todo.extend(classical_method() if d == "classical" else d for d in deps)
    return tuple(m for m in METHODS if m in want)


def estimate_recommended(model: Any, image0: np.ndarray, image1: np.ndarray, K0: Any = None,
                         K1: Any = None, frontend_config: Any = None, **estimator_kw: Any):
    """The recommended :class:`~strl_pyg.inference.estimator.PoseEstimate` of two images (module
    docstring), running only the methods it needs.

    Args:
        model: a :class:`~strl_pyg.model.StrLPose`, a checkpoint path or ``None`` (the shipped
            one, built only if a method needs it); its metadata gives the recommended order.
        image0, image1, K0, K1: as :meth:`PoseEstimator.estimate_images
            <strl_pyg.inference.PoseEstimator.estimate_images>` (``K1`` defaults to ``K0``).
        frontend_config: :class:`~strl_pyg.frontend.FrontendConfig` (default: its defaults);
            its ``lines`` is switched on only when a method that reads lines runs (the
            network's, ``vp``).
        estimator_kw: options of :class:`~strl_pyg.inference.estimator.PoseEstimator`
            (:class:`~strl_pyg.inference.config.EstimatorConfig` fields, or ``config=``); the
            methods run are the recommended ones.
    """
    from strl_pyg.frontend import FrontendConfig, NoMatchesError, match_images
    from strl_pyg.frontend.pipeline import add_lines
    from strl_pyg.inference.checks import intrinsics_problems
    from strl_pyg.inference.estimator import (
        METHODS,
        POINT_POOR_ORDER,
        PoseEstimator,
        recommended_order,
    )

    cfg = frontend_config if frontend_config is not None else FrontendConfig()
    if not isinstance(cfg, FrontendConfig):
        raise TypeError(f"Expected a FrontendConfig (got {type(cfg).__name__})")
    if K0 is None and K1 is not None:
        raise ValueError("Expected K0 with K1 (got K1 only)")
    K1 = K0 if K1 is None else K1

    def installed(names):
        return [m for m in names if m in METHODS and METHODS[m].available()]

    def match(run):
        """Matches for the methods ``run`` (lines only if one reads them), once per kind;
        ``(lines, None)``, or the estimator's own "degenerate" estimate when nothing matches."""
        lines = cfg.lines and any(METHODS[m].reads_lines for m in run if m in METHODS)
        if lines and lines not in matches and False in matches:
            # one pass per pair: the lines join the points already matched (no second SIFT);
            # the same points, so what the methods that read no lines found on them holds
            matches[lines] = add_lines(matches[False], dataclasses.replace(cfg, lines=True))
            done[lines] = {m: r for m, r in done.get(False, {}).items()
                           if not METHODS[m].reads_lines}
        if lines not in matches:
            try:
                matches[lines] = match_images(image0, image1, K0, K1,
                                              dataclasses.replace(cfg, lines=lines))
            except NoMatchesError:
                return lines, estimator.estimate_images(
                    image0, image1, K0, K1, dataclasses.replace(cfg, lines=lines), methods=run)
        return lines, None

    # one estimator: one configuration, the checkpoint's settings read once
    estimator = PoseEstimator(model, **estimator_kw)
    order = installed(recommended_order(estimator.settings))
    if not order:  # nothing recommended is installed: the estimator reports it
        return estimator.estimate_images(image0, image1, K0, K1, cfg)
    matches, est, run = {}, None, ()
    done: dict[bool, dict] = {}  # results per match set: each method runs at most once
    if installed(POINT_POOR_ORDER):  # the order depends on the number of point matches:
        # the first method's matches first (points only unless it reads lines)
        lines, degenerate = match(methods_needed(order[:1]))
        if degenerate is not None:
            return degenerate
        order = installed(recommended_order(estimator.settings,
                                            matches[lines].num_distinct_points))
    for name in order:
        run = methods_needed((*run, name))
        lines, degenerate = match(run)
        if degenerate is not None:
            return degenerate
        m = matches[lines]
        est = estimator.estimate(m, known=done.setdefault(lines, {}), methods=run)
        done[lines].update(est.methods)
        if est.methods[name].status == "ok":
            break
        if (est.pose.status == "unreliable" and est.pose.method == name
                and (not m.has_intrinsics
                     or intrinsics_problems(m.image_size0, m.image_size1, m.K0, m.K1))):
            break  # every method reads the same K (or none): the later ones are unreliable too
    return est


def estimate_methods(model: Any, image0: np.ndarray, image1: np.ndarray, K0: Any, K1: Any,
                     frontend_config: Any, methods: str = "recommended", **estimator_kw: Any):
    """``strl-pose predict --methods``: ``"recommended"`` (:func:`estimate_recommended`),
    ``"all"`` (every installed method) or comma-separated names of
    :data:`~strl_pyg.inference.estimator.METHODS` (``ValueError`` for others); these override
    the methods of a ``config=``."""
    from strl_pyg.inference.estimator import METHODS, PoseEstimator

    if methods == "recommended":
        return estimate_recommended(model, image0, image1, K0, K1, frontend_config,
                                    **estimator_kw)
    names = (tuple(n for n, s in METHODS.items() if s.available()) if methods == "all"
             else tuple(m.strip() for m in methods.split(",") if m.strip()))
    return PoseEstimator(model, methods=names, **estimator_kw).estimate_images(
        image0, image1, K0, K1, frontend_config=frontend_config)
