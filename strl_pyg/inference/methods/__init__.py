"""The pose methods :class:`~strl_pyg.inference.PoseEstimator` runs, one module per concept,
one small class each (:class:`~strl_pyg.inference.methods.base.PoseMethod`: its class attributes
are its description), and the context they share (:mod:`.context`);
they are the first entries of :data:`METHODS <strl_pyg.inference.registry.METHODS>`
(:func:`builtin_methods`, read by the registry itself), in this order:

* ``regression`` (:mod:`.regression`): the network's pose head (resampled graph, as in
  training).
* ``opencv``, ``poselib`` (:mod:`.classical`: :class:`OpenCV`, :class:`PoseLib`): the classical
  essential-matrix solvers
  (:mod:`strl_pyg.estimation.classical`).
* ``fused`` (:mod:`.fused`): the network and the first ``"ok"`` classical pose combined in
  information form (:func:`~strl_pyg.estimation.pose_fusion.fuse_poses`).
* ``geometric``, ``guided`` (:mod:`.geometric`): the weighted eight-point solve of the
  geometric head, refined; the classical solver guided by its inlier weights
  (:func:`~strl_pyg.estimation.guided.guided_estimate`).
* ``vp``, ``vp_checked`` (:mod:`.vanishing_point`): the methods of the lines' vanishing
  directions.

A method is ``fn(matches, context) -> MethodResult``; ``context.results`` holds the methods
run before it. Covariances (:mod:`strl_pyg.inference.record`): the network's from its predicted
log-variances, the classical ones from the Sampson residuals of their inliers (first order:
optimistic for RANSAC estimates), the fused one from the information-form fusion.
"""

from __future__ import annotations

from strl_pyg.inference.methods.base import CLASSICAL, DESCRIPTION, FunctionMethod, PoseMethod
from strl_pyg.inference.methods.builtin import builtin_methods
from strl_pyg.inference.methods.classical import Classical, OpenCV, PoseLib
from strl_pyg.inference.methods.fused import Fused
from strl_pyg.inference.methods.geometric import Geometric, Guided
from strl_pyg.inference.methods.regression import Regression, swap_term
from strl_pyg.inference.methods.vanishing_point import (
    VP_CHECK_ANGLE_DEG,
    VP_CHECK_SUPPORT_SLACK,
    VanishingPoint,
    VanishingPointChecked,
)

__all__ = ["Regression", "Classical", "OpenCV", "PoseLib", "Geometric", "Guided", "Fused",
           "VanishingPoint",
           "VanishingPointChecked", "VP_CHECK_ANGLE_DEG", "VP_CHECK_SUPPORT_SLACK", "swap_term",
           "builtin_methods", "PoseMethod", "FunctionMethod", "DESCRIPTION", "CLASSICAL"]

