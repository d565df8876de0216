"""Rigid two-view geometry as pure functions on batched torch tensors.

Conventions (fixed for the whole project):

* Image suffixes ``0`` (reference) and ``1`` (target). ``T_0to1`` is the 4x4 pose that maps a
  point of camera 0 into camera 1: ``X1 = R X0 + t``.
* ``T_w_c`` is **camera-to-world** (KITTI ``poses/NN.txt``); ``T_c_w`` is **world-to-camera**
  (DeMoN ``poses.txt``). Names say which one a function expects.
* Quaternions are ``(w, x, y, z)`` as kornia uses; :func:`rotation_to_quaternion` returns the
  canonical sign ``w >= 0``.
* Pixels follow OpenCV: the centre of the top-left pixel is ``(0, 0)``. Normalised camera
  coordinates are ``K^-1 [u, v, 1]^T`` without the trailing 1.
* The essential matrix is ``E = [t]_x R`` so that ``x1^T E x0 = 0`` for normalised
  homogeneous ``x0``, ``x1``; the fundamental matrix ``F = K1^-T E K0^-1`` satisfies the same
  relation in pixels.

Every public function accepts torch tensors with leading batch dimensions ``*`` and also numpy
arrays or nested lists (converted at the boundary: float numpy keeps its precision, anything
else becomes float64). Results are torch tensors unless documented otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from kornia.geometry.conversions import (
    quaternion_to_rotation_matrix as _kornia_q2r,
)
from kornia.geometry.conversions import (
    rotation_matrix_to_quaternion as _kornia_r2q,
)

__all__ = [
    "as_tensor",
    "rotation_to_quaternion",
    "quaternion_to_rotation",
    "rotation_angle_deg",
    "Pose",
    "relative_pose_from_c2w",
    "relative_pose_from_w2c",
    "skew",
    "essential_from_pose",
    "fundamental_from_essential",
    "normalize_points",
    "project_points",
    "sampson_error",
    "symmetric_epipolar_error",
]


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


def _check_tail(x: torch.Tensor, tail: tuple[int, ...], name: str) -> None:
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
    _check_tail(R, (3, 3), "R")
    q = _kornia_r2q(R.contiguous(), eps=torch.finfo(R.dtype).eps)
    return torch.where(q[..., :1] < 0, -q, q)


def quaternion_to_rotation(q: Any) -> torch.Tensor:
    """Quaternions ``(w, x, y, z)`` to rotation matrices; ``q`` is normalised first.

    Args:
        q: quaternions (any non-zero norm), shape ``(*, 4)``.

    Returns:
        rotation matrices, shape ``(*, 3, 3)``.
    """
    q = as_tensor(q, "q")
    _check_tail(q, (4,), "q")
    norm = q.norm(dim=-1, keepdim=True)
    if q.numel() and bool((norm < 1e-12).any()):
        raise ValueError("Expected quaternions of non-zero norm (got a zero quaternion)")
    return _kornia_q2r(q / norm)


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
    _check_tail(R, (3, 3), "R")
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
        _check_tail(R, (3, 3), "R")
        _check_tail(t, (3,), "t")
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
        _check_tail(row, (12,), "row")
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
        _check_tail(points, (3,), "points")
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


def _as_pose(T: Any, name: str) -> Pose:
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
    return _as_pose(T_w_c1, "T_w_c1").inv() @ _as_pose(T_w_c0, "T_w_c0")


def relative_pose_from_w2c(T_c0_w: Any, T_c1_w: Any) -> Pose:
    """``T_0to1`` from two **world-to-camera** poses: ``T_0to1 = T_c1_w @ inv(T_c0_w)``.

    Args:
        T_c0_w, T_c1_w: :class:`Pose` or matrices ``(*, 4, 4)`` / ``(*, 3, 4)`` (DeMoN
            ``poses.txt`` rows are world-to-camera).

    Returns:
        :class:`Pose` ``T_0to1`` of the broadcast batch shape.
    """
    return _as_pose(T_c1_w, "T_c1_w") @ _as_pose(T_c0_w, "T_c0_w").inv()


# ----------------------------------------------------------------------------- epipolar
def skew(v: Any) -> torch.Tensor:
    """Cross-product matrices ``[v]_x`` with ``[v]_x w = v x w``: ``(*, 3) -> (*, 3, 3)``."""
    v = as_tensor(v, "v")
    _check_tail(v, (3,), "v")
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], dim=-1).reshape(*v.shape[:-1], 3, 3)


def essential_from_pose(R: Any, t: Any = None) -> torch.Tensor:
    """Essential matrices ``E = [t]_x R`` of ``T_0to1``; ``x1^T E x0 = 0`` (normalised coords).

    Args:
        R: rotations ``(*, 3, 3)``, or a :class:`Pose` ``T_0to1`` (then ``t`` is omitted).
        t: translations ``(*, 3)`` (any scale; ``E`` scales with it).

    Returns:
        essential matrices, shape ``(*, 3, 3)``.
    """
    if isinstance(R, Pose):
        if t is not None:
            raise ValueError("Expected no 't' when a Pose is given (got both)")
        R, t = R.R, R.t
    elif t is None:
        raise ValueError("Expected 't' with a rotation matrix 'R' (got None)")
    pose = Pose(R, t)
    return skew(pose.t) @ pose.R


def _inv_K(K: torch.Tensor) -> torch.Tensor:
    return torch.linalg.inv(K)


def fundamental_from_essential(E: Any, K0: Any, K1: Any) -> torch.Tensor:
    """``F = K1^-T E K0^-1``, so that ``p1^T F p0 = 0`` for homogeneous pixels ``p0``, ``p1``.

    Args:
        E: essential matrices ``(*, 3, 3)``.
        K0, K1: intrinsics of image 0 and 1 ``(*, 3, 3)`` (pixels).

    Returns:
        fundamental matrices, shape ``(*, 3, 3)``.
    """
    E, K0, K1 = (as_tensor(a, n) for a, n in ((E, "E"), (K0, "K0"), (K1, "K1")))
    for a, n in ((E, "E"), (K0, "K0"), (K1, "K1")):
        _check_tail(a, (3, 3), n)
    E, K0, K1 = _common(E, K0, K1)
    return _inv_K(K1).transpose(-1, -2) @ E @ _inv_K(K0)


def normalize_points(x: Any, K: Any) -> torch.Tensor:
    """Pixels to normalised camera coordinates: the first two entries of ``K^-1 [u, v, 1]``.

    Args:
        x: pixel coordinates (OpenCV convention), shape ``(*, N, 2)``.
        K: intrinsics, shape ``(*, 3, 3)`` with last row ``[0, 0, 1]`` (skew allowed).

    Returns:
        normalised coordinates, shape ``(*, N, 2)``.
    """
    x, K = as_tensor(x, "x"), as_tensor(K, "K")
    _check_tail(x, (2,), "x")
    _check_tail(K, (3, 3), "K")
    if x.dim() < 2:
        raise ValueError(f"Expected 'x' of shape (*, N, 2) (got {tuple(x.shape)})")
    x, K = _common(x, K)
    fx, s, cx = K[..., 0, 0, None], K[..., 0, 1, None], K[..., 0, 2, None]
    fy, cy = K[..., 1, 1, None], K[..., 1, 2, None]
    y = (x[..., 1] - cy) / fy
    return torch.stack([(x[..., 0] - cx - s * y) / fx, y], dim=-1)


def project_points(X: Any, K: Any) -> torch.Tensor:
    """Pinhole projection of camera-frame points to pixels: ``(*, N, 3) -> (*, N, 2)``.

    Args:
        X: 3D points in the camera frame (``z > 0`` in front), shape ``(*, N, 3)``.
        K: intrinsics, shape ``(*, 3, 3)``.
    """
    X, K = as_tensor(X, "X"), as_tensor(K, "K")
    _check_tail(X, (3,), "X")
    _check_tail(K, (3, 3), "K")
    X, K = _common(X, K)
    p = X @ K.transpose(-1, -2)
    return p[..., :2] / p[..., 2:3]


def _epipolar_terms(M: Any, x0: Any, x1: Any):
    M, x0, x1 = as_tensor(M, "E_or_F"), as_tensor(x0, "x0"), as_tensor(x1, "x1")
    _check_tail(M, (3, 3), "E_or_F")
    _check_tail(x0, (2,), "x0")
    _check_tail(x1, (2,), "x1")
    if x0.dim() < 2 or x0.shape[-2] != x1.shape[-2]:
        raise ValueError(
            "Expected 'x0' and 'x1' of shape (*, N, 2) with the same N "
            f"(got {tuple(x0.shape)} and {tuple(x1.shape)})"
        )
    M, x0, x1 = _common(M, x0, x1)
    h0 = torch.cat([x0, torch.ones_like(x0[..., :1])], dim=-1)
    h1 = torch.cat([x1, torch.ones_like(x1[..., :1])], dim=-1)
    Mx0 = h0 @ M.transpose(-1, -2)  # rows: M h0, the epipolar lines in image 1
    Mtx1 = h1 @ M  # rows: M^T h1, the epipolar lines in image 0
    r = (h1 * Mx0).sum(-1)
    return r, Mx0, Mtx1


def sampson_error(
    E_or_F: Any, x0: Any, x1: Any, squared: bool = True, eps: float = 1e-15
) -> torch.Tensor:
    """First-order geometric (Sampson) error of matches under ``x1^T M x0 = 0``.

    .. math::
        d^2 = \\frac{(x_1^T M x_0)^2}{(M x_0)_1^2 + (M x_0)_2^2 + (M^T x_1)_1^2 + (M^T x_1)_2^2}

    Units follow the input: pixels with a fundamental matrix ``F`` and pixel coordinates, or
    normalised units with an essential matrix ``E`` and normalised coordinates
    (:func:`normalize_points`). ``squared`` (default ``True``, as kornia) returns ``d^2``,
    otherwise ``d``.

    Args:
        E_or_F: ``(*, 3, 3)``.
        x0, x1: matched coordinates in image 0 and 1, shape ``(*, N, 2)``.

    Returns:
        errors, shape ``(*, N)``.
    """
    r, Mx0, Mtx1 = _epipolar_terms(E_or_F, x0, x1)
    den = Mx0[..., 0] ** 2 + Mx0[..., 1] ** 2 + Mtx1[..., 0] ** 2 + Mtx1[..., 1] ** 2
    d2 = r**2 / (den + eps)
    return d2 if squared else torch.sqrt(d2 + eps) - math.sqrt(eps)


def symmetric_epipolar_error(
    E_or_F: Any, x0: Any, x1: Any, squared: bool = True, eps: float = 1e-15
) -> torch.Tensor:
    """Sum of squared distances of each point to the epipolar line of its match.

    .. math::
        d^2 = (x_1^T M x_0)^2 \\left(\\frac{1}{(M x_0)_1^2 + (M x_0)_2^2}
              + \\frac{1}{(M^T x_1)_1^2 + (M^T x_1)_2^2}\\right)

    Same unit rules as :func:`sampson_error` (pixels with ``F``, normalised with ``E``).

    Args:
        E_or_F: ``(*, 3, 3)``.
        x0, x1: matched coordinates in image 0 and 1, shape ``(*, N, 2)``.
        squared: return ``d^2`` (default) or ``d``.

    Returns:
        errors, shape ``(*, N)``.
    """
    r, Mx0, Mtx1 = _epipolar_terms(E_or_F, x0, x1)
    d2 = r**2 * (
        1.0 / (Mx0[..., 0] ** 2 + Mx0[..., 1] ** 2 + eps)
        + 1.0 / (Mtx1[..., 0] ** 2 + Mtx1[..., 1] ** 2 + eps)
    )
    return d2 if squared else torch.sqrt(d2 + eps) - math.sqrt(eps)
