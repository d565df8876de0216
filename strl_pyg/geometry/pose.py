"""Tensor boundary, rotations and :class:`Pose` (conventions: :mod:`strl_pyg.geometry`).

kornia (quaternion conversions) is imported on first use, so importing this module needs only
numpy and torch.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

__all__ = [
    "as_tensor",
    "check_rotation",
    "ROTATION_TOLERANCE",
    "rotation_to_quaternion",
    "quaternion_to_rotation",
    "rotation_angle_deg",
    "Pose",
    "as_pose",
    "check_tail",
    "relative_pose_from_c2w",
    "relative_pose_from_w2c",
]


#: How far ``R R^T`` may be from the identity (max abs entry) for :func:`check_rotation` by
#: default (float32 rotations converted to float64 reach ~1e-7).
ROTATION_TOLERANCE = 1e-5


def check_rotation(R: Any, what: str = "R", tol: float = ROTATION_TOLERANCE) -> None:
    """Raises a one-line ``ValueError`` unless ``R`` is a finite ``(3, 3)`` rotation:
    ``max |R R^T - I| <= tol`` and ``det R > 0`` (a scaled matrix or a reflection is an error,
    never a rotation). ``what`` names ``R`` in the message."""
    R = np.asarray(R.detach().cpu() if isinstance(R, torch.Tensor) else R, dtype=np.float64)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise ValueError(f"Expected {what} as a finite (3, 3) rotation (got shape {R.shape}"
                         + ("" if R.shape != (3, 3) else ", non-finite entries") + ")")
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if err > tol or det <= 0:
        raise ValueError(f"Expected {what} to be a rotation (orthonormal within {tol:g}, det +1) "
                         f"(got |RR^T - I| = {err:.2e}, det = {det:.3f})")


def _kornia_conversions():
    """kornia's quaternion conversions, imported on first use (kornia loads slowly and is
    not needed to import the geometry, the data containers or the layers)."""
    from kornia.geometry import conversions

    return conversions.rotation_matrix_to_quaternion, conversions.quaternion_to_rotation_matrix


# ----------------------------------------------------------------------------- boundary helpers
def as_tensor(x: Any, name: str = "input") -> torch.Tensor:
    """Converts ``x`` (torch tensor, numpy array or nested list) to a floating torch tensor.

    Float tensors and float numpy arrays keep their dtype; integers, booleans and lists become
    float64. Raises ``TypeError`` for anything non-numeric.
    """
    if isinstance(x, torch.Tensor):
        return x if x.is_floating_point() else x.to(torch.float64)
    try:
        arr = np.asarray(x)
    except Exception as err:  # pragma: no cover - numpy accepts nearly everything
        raise TypeError(
            f"Expected a tensor or array for '{name}' (got {type(x).__name__})"
        ) from err
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise TypeError(f"Expected a numeric array for '{name}' (got dtype {arr.dtype})")
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    return torch.from_numpy(np.ascontiguousarray(arr))


def check_tail(x: torch.Tensor, tail: tuple[int, ...], name: str) -> None:
    """Raises a one-line ``ValueError`` unless the trailing dimensions of ``x`` are ``tail``."""
    if x.dim() < len(tail) or tuple(x.shape[x.dim() - len(tail):]) != tail:
        want = "(*, " + ", ".join(map(str, tail)) + ")"
        raise ValueError(f"Expected '{name}' of shape {want} (got {tuple(x.shape)})")


def _common(*xs: torch.Tensor) -> list[torch.Tensor]:
    dtype = xs[0].dtype
    for x in xs[1:]:
        dtype = torch.promote_types(dtype, x.dtype)
    return [x.to(dtype) for x in xs]


# ----------------------------------------------------------------------------- rotations
def rotation_to_quaternion(R: Any) -> torch.Tensor:
    """Rotation matrices to unit quaternions ``(w, x, y, z)`` with canonical sign ``w >= 0``.

    Args:
        R: rotation matrices, shape ``(*, 3, 3)``.

    Returns:
        quaternions, shape ``(*, 4)``. Differentiable (via kornia) away from the branch
        switches of the conversion.
    """
    R = as_tensor(R, "R")
    check_tail(R, (3, 3), "R")
    r2q, _ = _kornia_conversions()
    q = r2q(R.contiguous(), eps=torch.finfo(R.dtype).eps)
    return torch.where(q[..., :1] < 0, -q, q)


def quaternion_to_rotation(q: Any) -> torch.Tensor:
    """Quaternions ``(w, x, y, z)`` to rotation matrices; ``q`` is normalised first.

    Args:
        q: quaternions (any non-zero norm), shape ``(*, 4)``.

    Returns:
        rotation matrices, shape ``(*, 3, 3)``.
    """
    q = as_tensor(q, "q")
    check_tail(q, (4,), "q")
    norm = q.norm(dim=-1, keepdim=True)
    if q.numel() and bool((norm < 1e-12).any()):
        raise ValueError("Expected quaternions of non-zero norm (got a zero quaternion)")
    _, q2r = _kornia_conversions()
    return q2r(q / norm)


def rotation_angle_deg(R: Any) -> torch.Tensor:
    """Rotation angle of ``R`` in degrees, in ``[0, 180]``.

    Uses ``atan2(|vee(R - R^T)| / 2, (trace(R) - 1) / 2)``, accurate near 0 and near 180
    degrees (unlike ``acos`` of the trace). The gradient is undefined at exactly 0 degrees.

    Args:
        R: rotation matrices, shape ``(*, 3, 3)``.

    Returns:
        angles, shape ``(*)``.
    """
    R = as_tensor(R, "R")
    check_tail(R, (3, 3), "R")
    cos = (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0) / 2.0
    w = torch.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        dim=-1,
    )
    sin = w.norm(dim=-1) / 2.0
    return torch.rad2deg(torch.atan2(sin, cos))


# ----------------------------------------------------------------------------- Pose
class Pose:
    """A rigid transform ``X -> R X + t`` (batched over leading dimensions ``*``).

    Used for ``T_0to1`` (camera 0 to camera 1), camera-to-world ``T_w_c`` and world-to-camera
    ``T_c_w`` alike; the variable name carries the meaning.

    Args:
        R: rotations, shape ``(*, 3, 3)``.
        t: translations, shape ``(*, 3)``; batch shapes of ``R`` and ``t`` broadcast.

    Composition: ``(a @ b)`` (= ``a.compose(b)``) applies ``b`` first, then ``a``, like the
    product of 4x4 matrices: ``(a @ b).matrix() == a.matrix() @ b.matrix()``.
    """

    def __init__(self, R: Any, t: Any) -> None:
        R, t = as_tensor(R, "R"), as_tensor(t, "t")
        check_tail(R, (3, 3), "R")
        check_tail(t, (3,), "t")
        try:
            shape = torch.broadcast_shapes(R.shape[:-2], t.shape[:-1])
        except RuntimeError as err:
            raise ValueError(
                "Expected batch shapes of 'R' and 't' that broadcast "
                f"(got {tuple(R.shape[:-2])} and {tuple(t.shape[:-1])})"
            ) from err
        R, t = _common(R, t)
        if R.device != t.device:
            raise ValueError(f"Expected R and t on one device (got {R.device} and {t.device})")
        self.R = R.expand(*shape, 3, 3)
        self.t = t.expand(*shape, 3)

    # -- constructors
    @classmethod
    def from_Rt(cls, R: Any, t: Any) -> Pose:
        """Same as ``Pose(R, t)``: ``R`` ``(*, 3, 3)``, ``t`` ``(*, 3)``."""
        return cls(R, t)

    @classmethod
    def from_matrix(cls, T: Any) -> Pose:
        """From homogeneous ``(*, 4, 4)`` or ``(*, 3, 4)`` matrices ``[R | t]``."""
        T = as_tensor(T, "T")
        if T.dim() < 2 or T.shape[-1] != 4 or T.shape[-2] not in (3, 4):
            raise ValueError(f"Expected 'T' of shape (*, 4, 4) or (*, 3, 4) (got {tuple(T.shape)})")
        return cls(T[..., :3, :3], T[..., :3, 3])

    @classmethod
    def from_kitti_row(cls, row: Any) -> Pose:
        """From KITTI pose-file rows: 12 values, the row-major 3x4 ``[R | t]``; ``(*, 12)``.

        The values are whatever the file holds (camera-to-world for ``poses/NN.txt``).
        """
        row = as_tensor(row, "row")
        check_tail(row, (12,), "row")
        return cls.from_matrix(row.reshape(*row.shape[:-1], 3, 4))

    @classmethod
    def from_quaternion(cls, q: Any, t: Any) -> Pose:
        """From quaternions ``(w, x, y, z)`` ``(*, 4)`` (normalised here) and ``t`` ``(*, 3)``."""
        return cls(quaternion_to_rotation(q), t)

    @classmethod
    def identity(
        cls,
        batch_shape: Sequence[int] = (),
        dtype: torch.dtype = torch.float64,
        device: Any = None,
    ) -> Pose:
        """Identity poses of the given batch shape."""
        R = torch.eye(3, dtype=dtype, device=device).expand(*batch_shape, 3, 3).clone()
        return cls(R, torch.zeros(*batch_shape, 3, dtype=dtype, device=device))

    @classmethod
    def stack(cls, poses: Sequence[Pose], dim: int = 0) -> Pose:
        """Stacks poses of one batch shape along a new dimension ``dim``."""
        if len(poses) == 0:
            raise ValueError("Expected at least one pose to stack (got none)")
        return cls(
            torch.stack([p.R for p in poses], dim=dim if dim >= 0 else dim - 2),
            torch.stack([p.t for p in poses], dim=dim if dim >= 0 else dim - 1),
        )

    # -- properties
    @property
    def shape(self) -> torch.Size:
        """The batch shape ``*``."""
        return self.R.shape[:-2]

    @property
    def dtype(self) -> torch.dtype:
        return self.R.dtype

    @property
    def device(self) -> torch.device:
        return self.R.device

    def __len__(self) -> int:
        if len(self.shape) == 0:
            raise TypeError("len() of an unbatched Pose")
        return self.shape[0]

    def __getitem__(self, index: Any) -> Pose:
        if len(self.shape) == 0:
            raise TypeError("Expected a batched Pose to index (got an unbatched one)")
        return Pose(self.R[index], self.t[index])

    def __repr__(self) -> str:
        return f"Pose(shape={tuple(self.shape)}, dtype={self.dtype}, device={self.device})"

    # -- algebra
    def matrix(self) -> torch.Tensor:
        """Homogeneous matrices, shape ``(*, 4, 4)``."""
        top = torch.cat([self.R, self.t[..., None]], dim=-1)
        bottom = torch.zeros(*self.shape, 1, 4, dtype=self.dtype, device=self.device)
        bottom[..., 0, 3] = 1.0
        return torch.cat([top, bottom], dim=-2)

    def inv(self) -> Pose:
        """The inverse ``X -> R^T (X - t)``."""
        Rt = self.R.transpose(-1, -2)
        return Pose(Rt, -(Rt @ self.t[..., None])[..., 0])

    def compose(self, other: Pose) -> Pose:
        """``self @ other``: applies ``other`` first, then ``self``. Batch shapes broadcast."""
        if not isinstance(other, Pose):
            raise TypeError(f"Expected a Pose to compose with (got {type(other).__name__})")
        R1, t1, R2, t2 = _common(self.R, self.t, other.R, other.t)
        return Pose(R1 @ R2, (R1 @ t2[..., None])[..., 0] + t1)

    def __matmul__(self, other: Pose) -> Pose:
        return self.compose(other)

    def transform(self, points: Any) -> torch.Tensor:
        """Applies the pose to 3D points: ``(*, N, 3) -> (*, N, 3)``."""
        points = as_tensor(points, "points")
        check_tail(points, (3,), "points")
        if points.dim() < 2:
            raise ValueError(f"Expected 'points' of shape (*, N, 3) (got {tuple(points.shape)})")
        R, t, points = _common(self.R, self.t, points)
        return points @ R.transpose(-1, -2) + t[..., None, :]

    def angle_deg(self) -> torch.Tensor:
        """Rotation angle of ``R`` in degrees, shape ``(*)``; see :func:`rotation_angle_deg`."""
        return rotation_angle_deg(self.R)

    def quaternion(self) -> torch.Tensor:
        """Rotation as quaternions ``(w, x, y, z)`` with ``w >= 0``, shape ``(*, 4)``."""
        return rotation_to_quaternion(self.R)

    def to_kitti_row(self) -> torch.Tensor:
        """Row-major 3x4 ``[R | t]`` as 12 values, shape ``(*, 12)``."""
        return torch.cat([self.R, self.t[..., None]], dim=-1).reshape(*self.shape, 12)

    def to(self, *args: Any, **kwargs: Any) -> Pose:
        """Like ``torch.Tensor.to`` (dtype and/or device)."""
        return Pose(self.R.to(*args, **kwargs), self.t.to(*args, **kwargs))

    def detach(self) -> Pose:
        return Pose(self.R.detach(), self.t.detach())

    def numpy(self) -> np.ndarray:
        """Homogeneous matrices as a numpy array, shape ``(*, 4, 4)``."""
        return self.matrix().detach().cpu().numpy()


def as_pose(T: Any, name: str = "T") -> Pose:
    """``T`` as a :class:`Pose`: a Pose is returned as is, matrices ``(*, 4, 4)`` /
    ``(*, 3, 4)`` are converted; anything else raises ``ValueError`` naming ``name``."""
    return T if isinstance(T, Pose) else _named_from_matrix(T, name)




def _named_from_matrix(T: Any, name: str) -> Pose:
    T = as_tensor(T, name)
    if T.dim() < 2 or T.shape[-1] != 4 or T.shape[-2] not in (3, 4):
        raise ValueError(
            f"Expected '{name}' as a Pose or of shape (*, 4, 4) or (*, 3, 4) (got {tuple(T.shape)})"
        )
    return Pose.from_matrix(T)


def relative_pose_from_c2w(T_w_c0: Any, T_w_c1: Any) -> Pose:
    """``T_0to1`` from two **camera-to-world** poses: ``T_0to1 = inv(T_w_c1) @ T_w_c0``.

    Args:
        T_w_c0, T_w_c1: :class:`Pose` or matrices ``(*, 4, 4)`` / ``(*, 3, 4)`` (KITTI rows
            reshaped to 3x4 are camera-to-world).

    Returns:
        :class:`Pose` ``T_0to1`` of the broadcast batch shape.
    """
    return as_pose(T_w_c1, "T_w_c1").inv() @ as_pose(T_w_c0, "T_w_c0")


def relative_pose_from_w2c(T_c0_w: Any, T_c1_w: Any) -> Pose:
    """``T_0to1`` from two **world-to-camera** poses: ``T_0to1 = T_c1_w @ inv(T_c0_w)``.

    Args:
        T_c0_w, T_c1_w: :class:`Pose` or matrices ``(*, 4, 4)`` / ``(*, 3, 4)`` (DeMoN
            ``poses.txt`` rows are world-to-camera).

    Returns:
        :class:`Pose` ``T_0to1`` of the broadcast batch shape.
    """
    return as_pose(T_c1_w, "T_c1_w") @ as_pose(T_c0_w, "T_c0_w").inv()
