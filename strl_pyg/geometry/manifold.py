"""SO(3) and unit-sphere maps: ``[w]_x``, the rotation exponential and logarithm, tangent
bases of translation directions and the sphere's exponential and logarithm.

These give the minimal 5-parameter charts of a relative pose up to scale used by the pose
fusion (:mod:`strl_pyg.estimation.pose_fusion`) and the weighted refinement
(:func:`strl_pyg.geometry.essential.refine_pose`): a left rotation increment
``R(w) = exp([w]_x) R_ref`` and a translation direction ``t(d) = exp_{t_ref}(B d)`` with the
basis ``B = [b1, b2]`` of :func:`tangent_basis`.
"""

from __future__ import annotations

from typing import Any

import torch

from strl_pyg.geometry.pose import as_tensor, check_tail, rotation_to_quaternion

__all__ = ["skew", "so3_exp", "so3_log", "tangent_basis", "sphere_exp", "sphere_log"]


def skew(v: Any) -> torch.Tensor:
    """Cross-product matrices ``[v]_x`` with ``[v]_x w = v x w``: ``(*, 3) -> (*, 3, 3)``."""
    v = as_tensor(v, "v")
    check_tail(v, (3,), "v")
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], dim=-1).reshape(*v.shape[:-1], 3, 3)


def _small(v: torch.Tensor, eps: float = 1e-12) -> tuple[torch.Tensor, torch.Tensor]:
    theta2 = (v * v).sum(-1)
    return theta2, theta2 < eps


def so3_exp(w: Any) -> torch.Tensor:
    """Rodrigues' formula ``exp([w]_x)``: ``(*, 3) -> (*, 3, 3)``; smooth (and differentiable)
    at ``w = 0`` through a Taylor branch."""
    w = as_tensor(w, "w")
    theta2, small = _small(w)
    t2 = torch.where(small, torch.ones_like(theta2), theta2)
    theta = torch.sqrt(t2)
    a = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(theta)) / t2)
    W = skew(w)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand_as(W)
    return eye + a[..., None, None] * W + b[..., None, None] * (W @ W)


def so3_log(R: Any) -> torch.Tensor:
    """Rotation vector of ``R`` (angle in ``[0, pi]``): ``(*, 3, 3) -> (*, 3)``; via the
    canonical quaternion, accurate near 0 and 180 degrees."""
    q = rotation_to_quaternion(R)
    v = q[..., 1:]
    n = v.norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(n, q[..., :1])
    scale = torch.where(n < 1e-12, 2.0 * torch.ones_like(n), angle / n.clamp_min(1e-300))
    return v * scale


def tangent_basis(t: Any) -> torch.Tensor:
    """Orthonormal bases ``[b1, b2]`` ``(*, 3, 2)`` of the planes orthogonal to ``t``
    ``(*, 3)``; ``(t, b1, b2)`` is right-handed and the basis is a deterministic function of
    the direction of ``t``. Raises ``ValueError`` for a zero translation."""
    t = as_tensor(t, "t")
    check_tail(t, (3,), "t")
    n = t.norm(dim=-1, keepdim=True)
    if t.numel() and not bool((n > 1e-12).all()):
        raise ValueError("Expected a non-zero translation for a tangent basis (got |t| = 0)")
    u = t / n
    helper = torch.zeros_like(u).scatter_(-1, u.abs().argmin(-1, keepdim=True), 1.0)
    b1 = torch.linalg.cross(u, helper)
    b1 = b1 / b1.norm(dim=-1, keepdim=True)
    b2 = torch.linalg.cross(u, b1)
    return torch.stack([b1, b2], dim=-1)


def sphere_exp(t: torch.Tensor, basis: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """``exp_t(B d) = cos|v| t + sin|v| v / |v|`` with ``v = B d``: unit ``t`` ``(3,)``,
    ``basis`` ``(3, 2)``, ``d`` ``(*, 2)`` -> unit vectors ``(*, 3)``."""
    v = d @ basis.T
    theta2, small = _small(v)
    t2 = torch.where(small, torch.ones_like(theta2), theta2)
    theta = torch.sqrt(t2)
    c = torch.where(small, 1.0 - theta2 / 2.0, torch.cos(theta))
    s = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    return c[..., None] * t + s[..., None] * v


def sphere_log(t: torch.Tensor, basis: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`sphere_exp`: the tangent coordinates ``(*, 2)`` of the vectors ``u``
    ``(*, 3)`` (normalised here; batched over leading dimensions). ``u = t`` gives zero;
    ``u = -t``, where every direction is a shortest path, gives pi along the first basis
    direction."""
    u = u / u.norm(dim=-1, keepdim=True)
    c = (u * t).sum(-1).clamp(-1.0, 1.0)
    perp = u - c[..., None] * t
    s = perp.norm(dim=-1)
    angle = torch.atan2(s, c)
    flat = s < 1e-15
    direction = torch.where(flat[..., None],
                            torch.where(c[..., None] < 0, basis[:, 0], torch.zeros_like(t)),
                            perp / torch.where(flat, 1.0, s)[..., None])
    return (direction @ basis) * angle[..., None]
