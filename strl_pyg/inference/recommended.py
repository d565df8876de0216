"""The recommended pose without the work it does not need (``strl-pose predict``'s default).

:class:`~strl_pyg.inference.PoseEstimator` with its default runs every installed method and
then picks the recommended pose: the first ``"ok"`` method of the checkpoint's recommended
order (:func:`~strl_pyg.inference.policy.recommended_order`). With ``methods="recommended"``
(:data:`~strl_pyg.inference.registry.RECOMMENDED`; :func:`estimate_recommended` here) it gives
the same recommended pose in one pass over the pair: the images matched once (the points
first, the line segments added to them only once a method that reads them, the network's or
``vp``, is about to run: the classical solvers use points only), the matches checked and
normalised once, and the methods of that order run one at a time, stopping at the first
``"ok"`` one (with the methods it needs: ``fused`` reads ``regression`` and a classical
estimate, ``guided`` reuses the classical one; or at the first ``"unreliable"`` one when the
intrinsics fail the input checks: every later pose would be too). With few point matches the
order starts with :data:`~strl_pyg.inference.policy.POINT_POOR_ORDER`.

Same pose: every method is deterministic in the matches and the seed, the point matches do not
depend on whether lines are matched (``filter_points`` off), and a method's result depends only
on the methods before it. The estimate's ``methods`` holds only the methods that ran.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["estimate_recommended", "estimate_methods"]


def estimate_recommended(model: Any, image0: np.ndarray, image1: np.ndarray, K0: Any = None,
                         K1: Any = None, frontend_config: Any = None, **estimator_kw: Any):
    """The recommended :class:`~strl_pyg.inference.estimator.PoseEstimate` of two images (module
    docstring), running only the methods it needs:
    ``PoseEstimator(model, **estimator_kw).estimate_images(..., methods="recommended")``.

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
    from strl_pyg.inference import RECOMMENDED
    from strl_pyg.inference.estimator import PoseEstimator

    if "methods" in estimator_kw:
        raise ValueError("Expected no methods for estimate_recommended (got methods="
                         f"{estimator_kw['methods']!r}): it runs the recommended ones; "
                         "PoseEstimator(...).estimate_images(..., methods=...) runs others")
    return PoseEstimator(model, **estimator_kw).estimate_images(
        image0, image1, K0, K1, frontend_config, methods=RECOMMENDED)


def estimate_methods(model: Any, image0: np.ndarray, image1: np.ndarray, K0: Any, K1: Any,
                     frontend_config: Any, methods: str = "recommended", **estimator_kw: Any):
    """``strl-pose predict --methods``: ``"recommended"`` (:func:`estimate_recommended`),
    ``"all"`` (every installed method) or comma-separated names of
    :data:`~strl_pyg.inference.registry.METHODS` (``ValueError`` for others); these override
    the methods of a ``config=``."""
    from strl_pyg.inference.estimator import PoseEstimator
    from strl_pyg.inference.registry import RECOMMENDED, checked_method_names

    names = checked_method_names(methods)  # the registry's one parser (any case, "all")
    if names == RECOMMENDED:
        return estimate_recommended(model, image0, image1, K0, K1, frontend_config,
                                    **estimator_kw)
    return PoseEstimator(model, methods=names, **estimator_kw).estimate_images(
        image0, image1, K0, K1, frontend_config=frontend_config)
