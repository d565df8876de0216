"""Relative-pose and trajectory metrics.

* Two-view errors as in DeMoN: the rotation error is the angle of ``R_est^T R_gt`` and the
  translation error the angle between the translation directions, both in degrees. DeMoN does
  **not** fold the sign of ``t``; essential-matrix benchmarks (SuperGlue, LightGlue,
  glue-factory) fold it to ``min(e, 180 - e)`` because ``E`` fixes ``t`` only up to sign.
  :func:`translation_angle_error_deg` takes ``fold_sign`` (default ``False``, DeMoN).
* :func:`pose_auc`: area under the recall curve of ``max(rotation, translation)`` errors up to
  5, 10 and 20 degrees, normalised by the threshold (SuperGlue's definition).
* Trajectory metrics, defined in :mod:`strl_pyg.metrics.odometry` and importable from here:
  :func:`kitti_odometry_errors` (the KITTI odometry benchmark's drift measure, written after
  the official devkit's definition, ``evaluate_odometry.cpp``) and
  :func:`kitti_odometry_summary`; :func:`absolute_trajectory_error` with Umeyama alignment;
  :func:`integrate_relative_poses` to chain ``T_0to1`` predictions into camera-to-world poses.
  The trajectory writers of :mod:`strl_pyg.metrics.trajectory` are re-exported too.

Trajectories are **camera-to-world** poses ``T_w_c`` (as KITTI's ``poses/NN.txt``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from strl_pyg.geometry import Pose, as_pose, as_tensor, check_tail, rotation_angle_deg

__all__ = ["rotation_error_deg", "translation_angle_error_deg", "relative_pose_error", "pose_auc"]


# ----------------------------------------------------------------------------- two-view errors
def rotation_error_deg(R_est: Any, R_gt: Any) -> torch.Tensor:
    """Angle of ``R_est^T R_gt`` in degrees, in ``[0, 180]``.

    Args:
        R_est, R_gt: rotations ``(*, 3, 3)`` (batch shapes broadcast), or :class:`Pose`.

    Returns:
        errors, shape ``(*)``. Differentiable except at exactly 0 degrees.
    """
    R_est = R_est.R if isinstance(R_est, Pose) else as_tensor(R_est, "R_est")
    R_gt = R_gt.R if isinstance(R_gt, Pose) else as_tensor(R_gt, "R_gt")
    check_tail(R_est, (3, 3), "R_est")
    check_tail(R_gt, (3, 3), "R_gt")
    dtype = torch.promote_types(R_est.dtype, R_gt.dtype)
    return rotation_angle_deg(R_est.to(dtype).transpose(-1, -2) @ R_gt.to(dtype))


def translation_angle_error_deg(
    t_est: Any, t_gt: Any, fold_sign: bool = False, eps: float = 1e-12
) -> torch.Tensor:
    """Angle between translation directions in degrees.

    Args:
        t_est, t_gt: translations ``(*, 3)`` (any scale; batch shapes broadcast).
        fold_sign: ``False`` (default, DeMoN): error in ``[0, 180]``. ``True`` (essential-matrix
            benchmarks): ``min(e, 180 - e)`` in ``[0, 90]``.
        eps: a translation shorter than this has no direction and gives ``NaN`` (count it as a
            failure; :func:`pose_auc` does).

    Returns:
        errors, shape ``(*)``.
    """
    a, b = as_tensor(t_est, "t_est"), as_tensor(t_gt, "t_gt")
    check_tail(a, (3,), "t_est")
    check_tail(b, (3,), "t_gt")
    dtype = torch.promote_types(a.dtype, b.dtype)
    a, b = a.to(dtype), b.to(dtype)
    # atan2 of |a x b| and a.b is accurate at 0 and 180 degrees, unlike acos.
    e = torch.rad2deg(torch.atan2(torch.linalg.cross(a, b).norm(dim=-1), (a * b).sum(-1)))
    if fold_sign:
        e = torch.minimum(e, 180.0 - e)
    degenerate = (a.norm(dim=-1) < eps) | (b.norm(dim=-1) < eps)
    return torch.where(degenerate, torch.full_like(e, float("nan")), e)


def relative_pose_error(
    T_est: Any, T_gt: Any, fold_sign: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(rotation error, translation-direction error)`` in degrees of ``T_0to1`` estimates.

    Args:
        T_est, T_gt: :class:`Pose` or matrices ``(*, 4, 4)`` / ``(*, 3, 4)``.
        fold_sign: see :func:`translation_angle_error_deg` (default ``False``).

    Returns:
        two tensors of shape ``(*)``.
    """
    T_est, T_gt = as_pose(T_est, "T_est"), as_pose(T_gt, "T_gt")
    return (
        rotation_error_deg(T_est.R, T_gt.R),
        translation_angle_error_deg(T_est.t, T_gt.t, fold_sign=fold_sign),
    )


def pose_auc(errors_deg: Any, thresholds: Sequence[float] = (5.0, 10.0, 20.0)) -> list[float]:
    """Area under the cumulative error curve up to each threshold, divided by the threshold.

    The recall curve is the polyline through ``(0, 0)`` and ``(e_(i), i / n)`` for the sorted
    errors, held flat to the threshold (as SuperGlue and LightGlue compute it). Non-finite
    errors (failures, ``NaN``) count as errors beyond every threshold.

    Args:
        errors_deg: per-pair errors, usually ``max(rotation, translation)``, shape ``(n,)``.
        thresholds: in degrees (default 5, 10, 20).

    Returns:
        one AUC in ``[0, 1]`` per threshold, in the order given.
    """
    e = as_tensor(errors_deg, "errors_deg").detach().cpu().double().numpy().reshape(-1)
    if e.size == 0:
        raise ValueError("Expected at least one error to compute an AUC (got none)")
    if np.any(e[np.isfinite(e)] < 0):
        raise ValueError(f"Expected non-negative errors (got min {np.nanmin(e)})")
    if len(thresholds) == 0 or any(not (t > 0) for t in thresholds):
        raise ValueError(f"Expected positive thresholds (got {tuple(thresholds)})")
    e = np.sort(np.where(np.isfinite(e), e, np.inf))
    n = e.size
    x_all = np.concatenate([[0.0], e])
    y_all = np.arange(n + 1, dtype=np.float64) / n
    out = []
    for thr in thresholds:
        k = int(np.searchsorted(x_all, thr, side="left"))  # points with error < thr (and 0)
        x = np.concatenate([x_all[:k], [thr]])
        y = np.concatenate([y_all[:k], [y_all[k - 1]]])
        area = float(np.sum((x[1:] - x[:-1]) * (y[1:] + y[:-1]) / 2.0))
        out.append(area / thr)
    return out
