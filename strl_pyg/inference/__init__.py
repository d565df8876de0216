"""Pose of one image pair by every method: :class:`PoseEstimator` and the method registry
(:mod:`.estimator`), the methods (:mod:`.methods`), the support check (:mod:`.support`),
input checks and the network's input graph (:mod:`.inputs`), the records (:mod:`.record`)
and the lazy recommended path (:mod:`.recommended`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

__all__ = [
    "STATUSES",
    "MIN_POINTS",
    "ZERO_PARALLAX_PX",
    "ZERO_PARALLAX_FRACTION",
    "FOCAL_RANGE",
    "MethodResult",
    "MethodContext",
    "PoseEstimate",
    "prepare_matches",
    "prepare_graph",
    "forward_pose",
    "input_warnings",
    "zero_parallax",
    "flipped_lines",
    "RECOMMENDED_ORDER",
    "RECOMMENDED",
    "POINT_POOR_ORDER",
    "POINT_POOR_MAX_POINTS",
    "recommended_order",
    "METHODS",
    "MethodSpec",
    "PoseEstimator",
    "register_method",
    "MethodFn",
    "MIN_INLIER_RATIO",
    "MIN_SUPPORT_INLIERS",
    "SUPPORT_BAND",
    "SUPPORT_CHECKED",
    "CHEIRALITY_MIN",
    "check_support",
    "NORMALISED_K_MAX",
    "intrinsics_problems",
    "network_pose",
    "estimate_recommended",
    "estimate_methods",
    "methods_needed",
    "NETWORK_METHODS",
    "DEPENDENCIES",
    "BOOTSTRAPPED",
    "methods_where",
    "POSELIB_MISSING",
    "BAD_INTRINSICS",
    "NO_INTRINSICS",
    "EstimatorConfig",
    "CheckpointSettings",
    "check_device",
]

# 0.2 code read other names of the module this folder was: they resolve too
_lazy_getattr, __dir__ = lazy_exports(__name__, {
    "STATUSES": "strl_pyg.inference.record",
    "MIN_POINTS": "strl_pyg.inference.estimator",
    "ZERO_PARALLAX_PX": "strl_pyg.inference.checks",
    "ZERO_PARALLAX_FRACTION": "strl_pyg.inference.checks",
    "FOCAL_RANGE": "strl_pyg.inference.checks",
    "MethodResult": "strl_pyg.inference.record",
    "MethodContext": "strl_pyg.inference.methods",
    "PoseEstimate": "strl_pyg.inference.record",
    "prepare_matches": "strl_pyg.inference.network",
    "prepare_graph": "strl_pyg.inference.network",
    "forward_pose": "strl_pyg.inference.network",
    "input_warnings": "strl_pyg.inference.checks",
    "zero_parallax": "strl_pyg.inference.checks",
    "flipped_lines": "strl_pyg.inference.checks",
    "RECOMMENDED_ORDER": "strl_pyg.inference.policy",
    "RECOMMENDED": "strl_pyg.inference.estimator",
    "POINT_POOR_ORDER": "strl_pyg.inference.policy",
    "POINT_POOR_MAX_POINTS": "strl_pyg.inference.estimator",
    "recommended_order": "strl_pyg.inference.policy",
    "METHODS": "strl_pyg.inference.estimator",
    "MethodSpec": "strl_pyg.inference.estimator",
    "PoseEstimator": "strl_pyg.inference.estimator",
    "register_method": "strl_pyg.inference.estimator",
    "MethodFn": "strl_pyg.inference.methods",
    "MIN_INLIER_RATIO": "strl_pyg.inference.support",
    "MIN_SUPPORT_INLIERS": "strl_pyg.inference.support",
    "SUPPORT_BAND": "strl_pyg.inference.support",
    "CHEIRALITY_MIN": "strl_pyg.inference.support",
    "check_support": "strl_pyg.inference.support",
    "NORMALISED_K_MAX": "strl_pyg.inference.checks",
    "intrinsics_problems": "strl_pyg.inference.checks",
    "network_pose": "strl_pyg.inference.network",
    "estimate_recommended": "strl_pyg.inference.recommended",
    "estimate_methods": "strl_pyg.inference.recommended",
    "methods_needed": "strl_pyg.inference.estimator",
    "methods_where": "strl_pyg.inference.estimator",
    "POSELIB_MISSING": "strl_pyg.inference.policy",
    "BAD_INTRINSICS": "strl_pyg.inference.estimator",
    "NO_INTRINSICS": "strl_pyg.inference.estimator",
    "EstimatorConfig": "strl_pyg.inference.config",
    "CheckpointSettings": "strl_pyg.inference.config",
    "check_device": "strl_pyg.inference.checks",
}, globals())

#: Tables derived from the method registry on every access (never cached on the face): a
#: method registered later is in them.
_DERIVED = ("SUPPORT_CHECKED", "BOOTSTRAPPED", "NETWORK_METHODS", "DEPENDENCIES")


def __getattr__(name: str):
    if name in _DERIVED:
        from strl_pyg.inference import estimator

        return getattr(estimator, name)
    return _lazy_getattr(name)
