"""Pose estimation from matches without a network of its own: the classical solvers
(:mod:`.classical`: OpenCV, PoseLib), network-guided robust estimation (:mod:`.guided`),
bootstrap covariances (:mod:`.uncertainty`) and the fusion of a network pose with a classical
one (:mod:`.fusion`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "BaselineResult": "strl_pyg.estimation.classical",
    "BASELINE_METHODS": "strl_pyg.estimation.classical",
    "MIN_POINTS": "strl_pyg.estimation.classical",
    "estimate_relative_pose": "strl_pyg.estimation.classical",
    "mean_focal": "strl_pyg.estimation.classical",
    "normalised_matches": "strl_pyg.estimation.classical",
    "have_poselib": "strl_pyg.estimation.classical",
    "msac_cost": "strl_pyg.estimation.guided",
    "guided_estimate": "strl_pyg.estimation.guided",
    "REFINE_WEIGHTINGS": "strl_pyg.estimation.guided",
    "bootstrap_covariance": "strl_pyg.estimation.uncertainty",
    "MIN_BOOTSTRAP": "strl_pyg.estimation.uncertainty",
    "FusedPose": "strl_pyg.estimation.pose_fusion",
    "FUSION_MODES": "strl_pyg.estimation.pose_fusion",
    "MIN_INLIERS": "strl_pyg.estimation.pose_fusion",
    "GATE_CHI2": "strl_pyg.estimation.pose_fusion",
    "PARAMETER_NAMES": "strl_pyg.estimation.pose_fusion",
    "pose_to_tangent": "strl_pyg.estimation.pose_fusion",
    "tangent_to_pose": "strl_pyg.estimation.pose_fusion",
    "sampson_residuals": "strl_pyg.estimation.pose_fusion",
    "sampson_jacobian": "strl_pyg.estimation.pose_fusion",
    "truncated_sigma": "strl_pyg.estimation.pose_fusion",
    "classical_covariance": "strl_pyg.estimation.pose_fusion",
    "network_covariance": "strl_pyg.estimation.pose_fusion",
    "fuse_poses": "strl_pyg.estimation.pose_fusion",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
