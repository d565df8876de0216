"""Errors and statistics of poses: two-view rotation / translation errors and AUC
(:mod:`.two_view`), KITTI drift and ATE (:mod:`.odometry`), trajectory files
(:mod:`.trajectory`), intervals and summaries over pairs (:mod:`.stats`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "KITTI_SEGMENT_LENGTHS": "strl_pyg.metrics.odometry",
    "KittiSegmentErrors": "strl_pyg.metrics.odometry",
    "kitti_odometry_errors": "strl_pyg.metrics.odometry",
    "kitti_odometry_summary": "strl_pyg.metrics.odometry",
    "umeyama_alignment": "strl_pyg.metrics.odometry",
    "ATEResult": "strl_pyg.metrics.odometry",
    "absolute_trajectory_error": "strl_pyg.metrics.odometry",
    "relative_translation_norms": "strl_pyg.metrics.odometry",
    "integrate_relative_poses": "strl_pyg.metrics.odometry",
    "project_to_so3": "strl_pyg.metrics.trajectory",
    "write_kitti_trajectory": "strl_pyg.metrics.trajectory",
    "write_tum_trajectory": "strl_pyg.metrics.trajectory",
    "rotation_error_deg": "strl_pyg.metrics.two_view",
    "translation_angle_error_deg": "strl_pyg.metrics.two_view",
    "relative_pose_error": "strl_pyg.metrics.two_view",
    "pose_auc": "strl_pyg.metrics.two_view",
    "AUC_THRESHOLDS": "strl_pyg.metrics.stats",
    "pose_error_stats": "strl_pyg.metrics.stats",
    "coverage_interval": "strl_pyg.metrics.stats",
    "median_ratio_interval": "strl_pyg.metrics.stats",
    "seeded_median_ratio_interval": "strl_pyg.metrics.stats",
    "auc_difference_interval": "strl_pyg.metrics.stats",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
