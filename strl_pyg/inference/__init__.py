"""Pose of one image pair by every method: :class:`PoseEstimator` (:mod:`.estimator`), the
method registry (:mod:`.registry`), the method classes (:mod:`.methods`, a module per concept),
the support check (:mod:`.support`), the input checks (:mod:`.checks`), the network's input
graph (:mod:`.network`), the records (:mod:`.record`), the statuses and verdicts
(:mod:`.status`), the rules on a pose (:mod:`.rules`, a module per rule), one pair's run
(:mod:`.pair`, :mod:`.running`), the pick of the recommended record (:mod:`.pick`,
:mod:`.policy`), the calibration (:mod:`.calibration`), the evidence the rules read
(:mod:`.evidence`), two images to a pose (:mod:`.images`) and the lazy recommended path
(:mod:`.recommended`).

The registry (:data:`METHODS`) holds the built-in methods from its first read, whichever module
reads it; methods registered later follow them.
"""

from __future__ import annotations

import sys

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "STATUSES": "strl_pyg.inference.status",
    "Status": "strl_pyg.inference.status",
    "network_poses": "strl_pyg.inference.network",
    "NetworkPoses": "strl_pyg.inference.network",
    "Verdict": "strl_pyg.inference.status",
    "ZERO_PARALLAX_PX": "strl_pyg.inference.checks",
    "ZERO_PARALLAX_FRACTION": "strl_pyg.inference.checks",
    "FOCAL_RANGE": "strl_pyg.inference.checks",
    "MethodResult": "strl_pyg.inference.record",
    "MethodContext": "strl_pyg.inference.methods.context",
    "PoseEstimate": "strl_pyg.inference.record",
    "prepare_matches": "strl_pyg.inference.network",
    "prepare_graph": "strl_pyg.inference.network",
    "forward_pose": "strl_pyg.inference.network",
    "input_warnings": "strl_pyg.inference.checks",
    "zero_parallax": "strl_pyg.inference.checks",
    "flipped_lines": "strl_pyg.inference.checks",
    "RECOMMENDED_ORDER": "strl_pyg.inference.policy",
    "RECOMMENDED": "strl_pyg.inference.registry",
    "POINT_POOR_ORDER": "strl_pyg.inference.policy",
    "POINT_POOR_MAX_POINTS": "strl_pyg.inference.methods.context",
    "recommended_order": "strl_pyg.inference.policy",
    "METHODS": "strl_pyg.inference.registry",
    "PoseEstimator": "strl_pyg.inference.estimator",
    "register_method": "strl_pyg.inference.registry",
    "MethodFn": "strl_pyg.inference.methods.context",
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
    "methods_needed": "strl_pyg.inference.registry",
    "methods_where": "strl_pyg.inference.registry",
    "checked_method_names": "strl_pyg.inference.registry",
    "POSELIB_MISSING": "strl_pyg.inference.policy",
    "BAD_INTRINSICS": "strl_pyg.inference.checks",
    "NO_INTRINSICS": "strl_pyg.inference.pair",
    "EstimatorConfig": "strl_pyg.inference.config",
    "CheckpointSettings": "strl_pyg.inference.settings",
    "check_device": "strl_pyg.inference.checks",
}

__all__ = [*_EXPORTS, "SUPPORT_CHECKED", "NETWORK_METHODS", "DEPENDENCIES", "BOOTSTRAPPED"]

_lazy_getattr, _lazy_dir = lazy_exports(__name__, _EXPORTS, globals())

#: Tables derived from the method registry on every access (never cached on the face): a
#: method registered later is in them.
_DERIVED = ("SUPPORT_CHECKED", "BOOTSTRAPPED", "NETWORK_METHODS", "DEPENDENCIES")


def __getattr__(name: str):
    if name.startswith("_"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import strl_pyg.inference.registry

    if name in _DERIVED:
        return strl_pyg.inference.registry.DERIVED[name]()
    module = sys.modules.get(f"{__name__}.{name}")  # a submodule the import above loaded
    if module is not None and name not in _EXPORTS:
        return module
    return _lazy_getattr(name)


def __dir__() -> list[str]:
    return sorted(set(_lazy_dir()) | set(_DERIVED))
