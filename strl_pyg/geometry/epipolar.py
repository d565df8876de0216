"""Epipolar geometry: essential and fundamental matrices, pixel normalisation, projection,
and the Sampson and symmetric epipolar errors (conventions: :mod:`strl_pyg.geometry`).

:func:`signed_sampson` is the one Sampson residual of the package: :func:`sampson_error` is
its square (or absolute value), and the pose fusion, the weighted essential solve and the
guided estimator all call it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from strl_pyg.geometry.manifold import skew
from strl_pyg.geometry.pose import Pose, _common, as_tensor, check_tail

__all__ = [
    "essential_from_pose",
    "fundamental_from_essential",
    "normalize_points",
    "project_points",
    "signed_sampson",
    "pose_sampson",
    "sampson_error",
    "symmetric_epipolar_error",
    "fundamental_from_pose",
    "epipolar_residuals",
]


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
        check_tail(a, (3, 3), n)
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
    check_tail(x, (2,), "x")
    check_tail(K, (3, 3), "K")
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
    check_tail(X, (3,), "X")
    check_tail(K, (3, 3), "K")
    X, K = _common(X, K)
    p = X @ K.transpose(-1, -2)
    return p[..., :2] / p[..., 2:3]


def _epipolar_terms(M: Any, x0: Any, x1: Any):
    M, x0, x1 = as_tensor(M, "E_or_F"), as_tensor(x0, "x0"), as_tensor(x1, "x1")
    check_tail(M, (3, 3), "E_or_F")
    check_tail(x0, (2,), "x0")
    check_tail(x1, (2,), "x1")
    if x0.dim() < 2 or x0.shape[-2] != x1.shape[-2]:
        raise ValueError(
            "Expected 'x0' and 'x1' of shape (*, N, 2) with the same N "
            f"(got {tuple(x0.shape)} and {tuple(x1.shape)})"
        )
    M, x0, x1 = _common(M, x0, x1)
    h0 = torch.cat([x0, torch.ones_like(x0[..., :1])], dim=-1)
    h1 = torch.cat([x1, torch.ones_like(x1[..., :1])], dim=-1)
    # products with a 3x3 matrix as broadcast sums, not matmul: a (N, 3) @ (3, 3) product goes
    # through the intra-op thread pool, which took 16 ms instead of 0.03 ms for 745 points
    # whenever another process kept one of two cores busy (the threads wait on each other)
    Ms = M.unsqueeze(-3)  # (*, 1, 3, 3)
    Mx0 = (Ms * h0.unsqueeze(-2)).sum(-1)  # rows: M h0, the epipolar lines in image 1
    Mtx1 = (Ms * h1.unsqueeze(-1)).sum(-2)  # rows: M^T h1, the epipolar lines in image 0
    r = (h1 * Mx0).sum(-1)
    return r, Mx0, Mtx1


def _sampson_terms(M: Any, x0: Any, x1: Any) -> tuple[torch.Tensor, torch.Tensor]:
    """The epipolar residual ``x1^T M x0`` and the Sampson denominator, both ``(*, N)``."""
    r, Mx0, Mtx1 = _epipolar_terms(M, x0, x1)
    return r, Mx0[..., 0] ** 2 + Mx0[..., 1] ** 2 + Mtx1[..., 0] ** 2 + Mtx1[..., 1] ** 2


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
    r, den = _sampson_terms(E_or_F, x0, x1)
    d2 = r**2 / (den + eps)
    return d2 if squared else torch.sqrt(d2 + eps) - math.sqrt(eps)


def signed_sampson(E_or_F: Any, x0: Any, x1: Any, eps: float = 1e-300) -> torch.Tensor:
    """Signed Sampson residual ``r = x1^T M x0 / sqrt(den + eps)`` (``den`` the denominator of
    :func:`sampson_error`, so ``r^2`` is the squared Sampson error): the residual to linearise
    or weight in least squares, where the sign matters. ``eps`` (default ``1e-300``) keeps a
    match on the epipole finite in float64; pass a larger one for float32.

    Args:
        E_or_F: ``(*, 3, 3)`` (``E`` with normalised coordinates, ``F`` with pixels).
        x0, x1: matched coordinates in image 0 and 1, shape ``(*, N, 2)``.

    Returns:
        residuals, shape ``(*, N)``.
    """
    r, den = _sampson_terms(E_or_F, x0, x1)
    return r / torch.sqrt(den + eps)


def pose_sampson(R: Any, t: Any, x0: Any, x1: Any) -> torch.Tensor:
    """Signed Sampson residuals of the pose ``(R, t)`` (``X1 = R X0 + t``) on normalised
    matches: :func:`signed_sampson` of ``E = [t]_x R``, the package's one Sampson residual
    under a pose (its absolute value is the Sampson distance).

    Args:
        R: rotations, shape ``(*, 3, 3)``; t: translations, shape ``(*, 3)`` (the scale of
            ``t`` scales the residuals: pass a unit direction for distances).
        x0, x1: normalised points, shape ``(*, N, 2)``.

    Returns:
        residuals, shape ``(*, N)``.
    """
    return signed_sampson(skew(as_tensor(t)) @ as_tensor(R), x0, x1)


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


# ----------------------------------------------------------------------------- numpy helpers
def fundamental_from_pose(T_0to1: Any, K0: Any, K1: Any) -> np.ndarray:
    """``F [3, 3]`` (float64 numpy) with ``x1^T F x0 = 0`` for ``T_0to1`` ``[4, 4]`` and
    intrinsics ``K0``, ``K1`` ``[3, 3]``."""
    T = np.asarray(T_0to1, dtype=np.float64)
    E = essential_from_pose(T[:3, :3], T[:3, 3])
    F = fundamental_from_essential(E, np.asarray(K0, np.float64), np.asarray(K1, np.float64))
    return F.detach().cpu().numpy().astype(np.float64)


def epipolar_residuals(matches: Any, T_0to1: Any) -> tuple[np.ndarray, np.ndarray]:
    """Sampson errors (pixels, not squared) of a pair's matches under a pose.

    Args:
        matches: a :class:`~strl_pyg.data.PairMatches` (or anything with ``points0/1``
            ``[Np, 2]``, ``lines0/1`` ``[Nl, 2, 2]``, ``K0``, ``K1``), with intrinsics.
        T_0to1: ``[4, 4]``, ``X1 = R X0 + t``.

    Returns:
        ``point_err [Np]`` and ``line_err [Nl]``, the larger of the two endpoints' errors
        (float64 numpy). ``line_err`` is NaN where the lines' endpoints do not correspond
        (``matches.line_endpoints_correspond`` is ``False``: descriptor-matched segments as
        detected); an endpoint then has no epipolar residual.
    """
    if getattr(matches, "K0", None) is None or getattr(matches, "K1", None) is None:
        raise ValueError("Expected matches with K0 and K1 (got none)")
    F = fundamental_from_pose(T_0to1, matches.K0, matches.K1)

    def err(x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
        if len(x0) == 0:
            return np.zeros(0)
        return sampson_error(F, x0, x1, squared=False).detach().cpu().numpy()

    pe = err(matches.points0, matches.points1)
    if not getattr(matches, "line_endpoints_correspond", True):
        return pe, np.full(len(np.asarray(matches.lines0).reshape(-1, 2, 2)), np.nan)
    le = err(np.asarray(matches.lines0).reshape(-1, 2), np.asarray(matches.lines1).reshape(-1, 2))
    return pe, le.reshape(-1, 2).max(1)
