"""Trajectory files in the two formats of the field, and the projection onto SO(3) that keeps
chained rotations valid for the tools that read them.

* KITTI odometry (``poses/NN.txt``, the devkit's ``loadPoses``, evo's
  ``read_kitti_poses_file``): one line per frame, 12 numbers separated by single spaces, the
  row-major 3x4 ``[R | t]`` of the **camera-to-world** pose ``T_w_c``. No header, no
  timestamps, no trailing delimiter (evo splits on single spaces and counts the fields).
* TUM RGB-D (evo's ``read_tum_trajectory_file``): one line per frame,
  ``timestamp tx ty tz qx qy qz qw`` (Hamilton quaternion, scalar **last**), the pose of the
  camera in the world frame (camera-to-world); lines starting with ``#`` are comments.

evo rejects rotations that are not orthonormal to 1e-6 (``lie_algebra.is_so3``): a
chain of float32 rotations drifts past that after about a thousand steps, hence
:func:`project_to_so3`. Numbers are written with 17 significant digits, so that a float64
pose reads back exactly.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from strl_pyg.geometry import Pose, as_tensor, rotation_to_quaternion
from strl_pyg.utils.io import atomic_open

__all__ = ["project_to_so3", "write_kitti_trajectory", "write_tum_trajectory"]


def project_to_so3(R: Any, name: str = "R", tol: float | None = 1e-4) -> torch.Tensor:
    """The nearest rotation (Frobenius norm, polar decomposition by SVD) of each matrix, in
    float64: ``U diag(1, 1, det(U V^T)) V^T``.

    Args:
        R: matrices ``(*, 3, 3)``.
        name: name for error messages.
        tol: largest accepted ``max |R R^T - I|`` of the input, so that only rounding errors
            are corrected and a matrix that is no rotation (a reflection, a scaled or
            garbage matrix) is an error, never a confident rotation. ``None``: no check.

    Returns:
        float64 rotations ``(*, 3, 3)``, orthonormal to ~1e-15.
    """
    R = as_tensor(R, name).double()
    if R.dim() < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"Expected '{name}' of shape (*, 3, 3) (got {tuple(R.shape)})")
    if not bool(torch.isfinite(R).all()):
        raise ValueError(f"Expected finite rotations in '{name}' (got NaN or inf)")
    if tol is not None and R.numel():
        eye = torch.eye(3, dtype=R.dtype, device=R.device)
        err = float((R @ R.transpose(-1, -2) - eye).abs().max())
        det = float(torch.linalg.det(R).min())
        if err > tol or det <= 0:
            raise ValueError(f"Expected rotations in '{name}' (orthonormal to {tol:g}, det +1) "
                             f"(got |RR^T - I| = {err:.2e}, det = {det:.3f})")
    U, _, Vh = torch.linalg.svd(R)
    d = torch.linalg.det(U @ Vh)
    ones = torch.ones_like(d)
    return U @ torch.diag_embed(torch.stack([ones, ones, d], dim=-1)) @ Vh


def _poses(T_w_c: Any) -> Pose:
    if isinstance(T_w_c, Pose):
        pose = T_w_c
    else:
        T = as_tensor(T_w_c, "T_w_c")
        if T.dim() == 2 and T.shape[1] == 12:
            T = T.reshape(-1, 3, 4)
        if T.dim() != 3 or T.shape[1:] not in ((3, 4), (4, 4)):
            raise ValueError("Expected 'T_w_c' as a Pose [N] or of shape [N, 4, 4], [N, 3, 4] "
                             f"or [N, 12] (got {tuple(T.shape)})")
        pose = Pose.from_matrix(T)
    if len(pose.shape) != 1:
        raise ValueError(f"Expected one batch dimension [N] in 'T_w_c' (got {tuple(pose.shape)})")
    if len(pose) == 0:
        raise ValueError("Expected at least one pose in 'T_w_c' (got none)")
    R = project_to_so3(pose.R.detach().cpu(), "T_w_c")
    t = pose.t.detach().cpu().double()
    if not bool(torch.isfinite(t).all()):
        raise ValueError("Expected finite translations in 'T_w_c' (got NaN or inf)")
    return Pose(R, t)


def _line(values) -> str:
    return " ".join(format(float(v), ".17g") for v in values) + "\n"


def write_kitti_trajectory(path: str | os.PathLike, T_w_c: Any) -> Path:
    """Writes camera-to-world poses as a KITTI odometry pose file, atomically.

    Args:
        path: output file (parent folders are created).
        T_w_c: :class:`~strl_pyg.geometry.Pose` ``[N]`` or matrices ``[N, 4, 4]`` /
            ``[N, 3, 4]`` / ``[N, 12]``; rotations are projected onto SO(3) (rounding only:
            a matrix off by more than 1e-4 is an error).

    Returns:
        ``path``.
    """
    pose = _poses(T_w_c)
    rows = pose.to_kitti_row().numpy()
    path = Path(path)
    with atomic_open(path, "w") as f:
        f.writelines(_line(r) for r in rows)
    return path


def write_tum_trajectory(
    path: str | os.PathLike, T_w_c: Any, timestamps: Any = None
) -> Path:
    """Writes camera-to-world poses as a TUM trajectory file
    (``timestamp tx ty tz qx qy qz qw``), atomically, after a ``#`` header line.

    Args:
        path: output file (parent folders are created).
        T_w_c: as for :func:`write_kitti_trajectory`.
        timestamps: ``[N]`` strictly increasing finite times in seconds (KITTI's
            ``times.txt``); default: the frame index ``0, 1, ...``.

    Returns:
        ``path``.
    """
    pose = _poses(T_w_c)
    n = len(pose)
    if timestamps is None:
        stamps = np.arange(n, dtype=np.float64)
    else:
        stamps = as_tensor(timestamps, "timestamps").detach().cpu().double().numpy()
        if stamps.shape != (n,):
            raise ValueError(f"Expected 'timestamps' of shape ({n},) (got {stamps.shape})")
        if not np.isfinite(stamps).all() or (np.diff(stamps) <= 0).any():
            raise ValueError("Expected finite, strictly increasing 'timestamps' (got "
                             f"{'non-finite' if not np.isfinite(stamps).all() else 'unsorted'}"
                             " values)")
    q = rotation_to_quaternion(pose.R)  # (w, x, y, z), w >= 0
    q = (q / q.norm(dim=-1, keepdim=True)).numpy()
    xyzw = np.concatenate([q[:, 1:], q[:, :1]], axis=1)
    table = np.concatenate([stamps[:, None], pose.t.numpy(), xyzw], axis=1)
    path = Path(path)
    with atomic_open(path, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        f.writelines(_line(r) for r in table)
    return path
