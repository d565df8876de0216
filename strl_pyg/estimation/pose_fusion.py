"""Uncertainty-aware fusion of the learned pose with the classical robust estimate.

(Not to be confused with :mod:`strl_pyg.nn.feature_fusion`, the paper's feature-weighted
fusion layer. The SO(3) and sphere maps of the chart live in
:mod:`strl_pyg.geometry.manifold` and are re-exported.)

Beyond the paper, in the spirit of UA-Fusion (Zhuang & Chandraker, CVPR 2021): both estimates
of ``T_0to1`` (``X1 = R X0 + t``) get a covariance in one minimal, 5-parameter tangent space
around the classical estimate ``(R_c, t_c)``, and are combined in information form.

Parameters ``x = (w, d)`` (order fixed everywhere):

* ``w`` (3): rotation increment on the left, ``R(x) = exp([w]_x) R_c``;
* ``d`` (2): translation direction on the unit sphere, ``t(x) = exp_{t_c}(B d)`` with the
  tangent basis ``B = [b1, b2]`` of :func:`~strl_pyg.geometry.tangent_basis`
  (``b1, b2 _|_ t_c``) and the sphere's exponential map ``exp_t(v) = cos|v| t + sin|v| v / |v|``.

Classical covariance: the signed Sampson residuals ``r_i = x1^T E x0 / sqrt(den)`` of the
inlier matches (normalised coordinates, ``r_i^2`` is :func:`~strl_pyg.geometry.sampson_error`)
are linearised at ``x = 0``, ``J = dr/dx`` ``[N, 5]``; the information is
``J^T J / sigma^2`` with ``sigma^2 = sum r_i^2 / (N - 5)``, corrected for the truncation of the
inlier set at the RANSAC threshold (:func:`truncated_sigma`) and floored by ``min_sigma_px``
(noise-free data would otherwise give an infinite information). Measured caveat: even so the
first-order covariance is optimistic for a RANSAC estimate (the estimate is not the
maximum-likelihood one over the full noise distribution); ``inflation`` scales it.

Network covariance: ``exp(log_var)`` gives independent variances of the 7 raw components
``(q_w, q_x, q_y, q_z, t_x, t_y, t_z)``. Approximations (first order, documented):

* rotation: a left increment moves the quaternion by ``dq = 1/2 G(q) w`` where
  ``G(q) w = (0, w) (x) q`` has orthonormal columns, so ``w = 2 G^T dq`` and
  ``Cov(w) = 4 G^T diag(var_q) G``; near the identity this is ``4 diag(var(q_xyz))``;
* translation: the per-component variance is projected onto the tangent basis,
  ``Cov(d) = B^T diag(var_t) B / |t|^2`` (``|t| = 1`` for direction models);
* the two blocks are independent (the network predicts a diagonal).

Fusion: ``Lambda = Lambda_c + Lambda_n``, ``x = Lambda^-1 Lambda_n x_n`` (the classical
estimate is ``x = 0``; ``x_n`` is the network pose in the same chart). This is per-parameter
inverse-variance weighting when both covariances are diagonal and handles a rank-deficient
classical information (e.g. pure rotation: the translation is then left to the network).
``mode="diagonal"`` uses only the diagonals (strict per-parameter weighting).

Translation sign: the classical direction comes from ``cv2.recoverPose`` / PoseLib after a
cheirality check, so its sign is taken as correct; it is ambiguous only if that check failed.
The network's direction is never flipped; ``FusedPose.info["sign_disagreement"]`` flags
``t_c . t_n < 0``. Scale: the fused translation is a unit vector times the network's norm
(1 for direction models, metric otherwise; the classical estimate has no scale).

Classical failure (``success=False`` or fewer than :data:`MIN_INLIERS` inliers: ``N - 5``
degrees of freedom are needed for ``sigma``) returns the network pose and covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import BaselineResult, normalised_matches
from strl_pyg.geometry import (
    Pose,
    as_tensor,
    pose_sampson,
    skew,
    so3_exp,
    so3_log,
    sphere_exp,
    sphere_log,
    tangent_basis,
)

__all__ = ["FusedPose", "FUSION_MODES", "MIN_INLIERS", "GATE_CHI2", "PARAMETER_NAMES",
           "pose_to_tangent", "tangent_to_pose", "sampson_residuals", "sampson_jacobian",
           "truncated_sigma", "classical_covariance", "network_covariance", "fuse_poses"]

#: Tangent parameters, in order.
PARAMETER_NAMES = ("w_x", "w_y", "w_z", "d_1", "d_2")
#: ``"information"`` (full covariances) or ``"diagonal"`` (per-parameter weighting).
FUSION_MODES = ("information", "diagonal")
#: Inliers needed for a classical covariance: 5 parameters plus one degree of freedom.
MIN_INLIERS = 6
#: 99 % quantile of the chi-square law with 5 degrees of freedom (the consistency gate).
GATE_CHI2 = 15.086


# ----------------------------------------------------------------------------- charts
def pose_to_tangent(pose: Pose, R_ref: torch.Tensor, t_ref: torch.Tensor,
                    basis: torch.Tensor) -> torch.Tensor:
    """Tangent coordinates ``x`` ``(*, 5)`` of ``pose`` (batched over leading dimensions) in
    the chart around ``(R_ref, t_ref)`` (unit ``t_ref``); the translation's norm is dropped."""
    w = so3_log(pose.R.to(R_ref) @ R_ref.T)
    d = sphere_log(t_ref, basis, pose.t.to(t_ref))
    return torch.cat([w, d], dim=-1)


def tangent_to_pose(x: torch.Tensor, R_ref: torch.Tensor, t_ref: torch.Tensor,
                    basis: torch.Tensor, scale: float = 1.0) -> Pose:
    """The pose ``(exp([w]_x) R_ref, scale * exp_{t_ref}(B d))`` of ``x`` ``(5,)``."""
    return Pose(so3_exp(x[:3]) @ R_ref, scale * sphere_exp(t_ref, basis, x[3:]))


# ----------------------------------------------------------------------------- classical
def sampson_residuals(x: torch.Tensor, R_ref: torch.Tensor, t_ref: torch.Tensor,
                      basis: torch.Tensor, x0: torch.Tensor, x1: torch.Tensor) -> torch.Tensor:
    """Signed Sampson residuals ``(N,)`` of the pose ``x`` ``(5,)`` (chart around
    ``(R_ref, t_ref)``) on normalised matches ``x0``, ``x1`` ``(N, 2)``; their squares equal
    :func:`~strl_pyg.geometry.sampson_error` of ``E = [t]_x R``."""
    R = so3_exp(x[:3]) @ R_ref
    t = sphere_exp(t_ref, basis, x[3:])
    return pose_sampson(R, t, x0, x1)


def sampson_jacobian(R_ref: torch.Tensor, t_ref: torch.Tensor, basis: torch.Tensor,
                     x0: torch.Tensor, x1: torch.Tensor) -> torch.Tensor:
    """Analytic Jacobian ``[N, 5]`` of :func:`sampson_residuals` at ``x = 0``.

    With ``E = [t]_x R``: ``dE/dw_k = [t]_x [e_k]_x R`` and ``dE/dd_j = [b_j]_x R``; then
    ``dr = dn / sqrt(den) - n d(den) / (2 den^(3/2))`` for ``n = x1^T E x0``.
    """
    E = skew(t_ref) @ R_ref
    eye = torch.eye(3, dtype=R_ref.dtype)
    dE = torch.cat([skew(t_ref) @ skew(eye) @ R_ref, skew(basis.T) @ R_ref])  # [5, 3, 3]
    h0 = torch.cat([x0, torch.ones_like(x0[:, :1])], dim=-1)
    h1 = torch.cat([x1, torch.ones_like(x1[:, :1])], dim=-1)
    a, b = h0 @ E.T, h1 @ E  # [N, 3]
    da = torch.einsum("kij,nj->nki", dE, h0)  # [N, 5, 3]
    db = torch.einsum("kji,nj->nki", dE, h1)
    num = (h1 * a).sum(-1)  # [N]
    dnum = (h1[:, None, :] * da).sum(-1)  # [N, 5]
    den = a[:, 0] ** 2 + a[:, 1] ** 2 + b[:, 0] ** 2 + b[:, 1] ** 2
    dden = 2.0 * (a[:, None, 0] * da[..., 0] + a[:, None, 1] * da[..., 1]
                  + b[:, None, 0] * db[..., 0] + b[:, None, 1] * db[..., 1])
    den = den + 1e-300
    return dnum / den.sqrt()[:, None] - 0.5 * (num / den**1.5)[:, None] * dden


def _normalised_inliers(matches: PairMatches, inliers: np.ndarray):
    x0, x1, _ = normalised_matches(matches)
    return x0[torch.as_tensor(inliers)], x1[torch.as_tensor(inliers)]


def truncated_sigma(s: float, threshold: float, max_ratio: float = 4.0) -> float:
    """Standard deviation ``sigma`` of a zero-mean Gaussian whose samples kept inside
    ``[-threshold, threshold]`` have standard deviation ``s``.

    Solves ``s^2 = sigma^2 (1 - 2 a phi(a) / (2 Phi(a) - 1))`` with ``a = threshold / sigma``
    by bisection; the ratio ``sigma / s`` is capped at ``max_ratio`` (samples nearly uniform in
    the window carry little information about ``sigma``).
    """
    if not (s > 0 and threshold > 0):
        return max(s, 0.0)

    def kept_std_over_threshold(a: float) -> float:
        phi = math.exp(-0.5 * a * a) / math.sqrt(2 * math.pi)
        mass = math.erf(a / math.sqrt(2))
        return math.sqrt(max(1.0 - 2.0 * a * phi / mass, 0.0)) / a

    target = s / threshold
    lo, hi = 1e-3, 50.0  # a; the ratio falls from 1/sqrt(3) towards 0 as a grows
    if target >= kept_std_over_threshold(lo):
        return s * max_ratio
    if target <= kept_std_over_threshold(hi):
        return s
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if kept_std_over_threshold(mid) > target:
            lo = mid
        else:
            hi = mid
    return min(threshold / (0.5 * (lo + hi)), s * max_ratio)


def classical_covariance(
    pose: Pose, matches: PairMatches, inliers: Any, min_sigma_px: float = 0.05,
    threshold_px: float | None = 1.0, inflation: float = 1.0,
) -> tuple[torch.Tensor, torch.Tensor, float]:
    """Information and covariance of a classical ``T_0to1`` from its inlier matches.

    Args:
        pose: unbatched ``T_0to1`` (translation of any non-zero norm).
        matches: the pair's matches (pixels, with ``K0``, ``K1``).
        inliers: boolean mask ``[Np]`` over the point matches.
        min_sigma_px: floor of the residual standard deviation, pixels (converted to
            normalised units with the mean focal length).
        threshold_px: the estimator's inlier threshold, pixels: the residuals of an inlier
            set selected at ``|r| < threshold`` are a truncated sample, whose standard
            deviation underestimates the noise (by ~2x at a threshold of 1 sigma);
            :func:`truncated_sigma` undoes that. ``None``: no correction.
        inflation: multiplies the covariance (divides the information); ``1`` is the
            first-order (Cramer-Rao-like) value, which is optimistic for RANSAC estimates
            (see ``benchmarks/studies/results_fusion.md``).

    Returns:
        ``(information [5, 5], covariance [5, 5], sigma_px)`` in float64; the covariance is a
        pseudo-inverse where the information is rank-deficient.
    """
    mask = np.asarray(inliers, dtype=bool).reshape(-1)
    if mask.shape != (matches.num_points,):
        raise ValueError(
            f"Expected an inlier mask of shape ({matches.num_points},) (got {mask.shape})"
        )
    n = int(mask.sum())
    if n < MIN_INLIERS:
        raise ValueError(f"Expected at least {MIN_INLIERS} inliers (got {n})")
    R_ref = pose.R.double()
    t_ref = pose.t.double() / pose.t.double().norm()
    basis = tangent_basis(t_ref)
    x0, x1 = _normalised_inliers(matches, mask)

    J = sampson_jacobian(R_ref, t_ref, basis, x0, x1)
    r = sampson_residuals(torch.zeros(5, dtype=torch.float64), R_ref, t_ref, basis, x0, x1)
    focal = float(np.mean([matches.K0[0, 0], matches.K0[1, 1], matches.K1[0, 0],
                           matches.K1[1, 1]]))
    sigma = math.sqrt(float((r**2).sum()) / (n - 5))
    if threshold_px is not None:
        sigma = truncated_sigma(sigma, threshold_px / focal)
    sigma2 = max(sigma, min_sigma_px / focal) ** 2
    info = J.T @ J / (sigma2 * inflation)
    cov = torch.linalg.pinv(info, hermitian=True)
    return info, cov, math.sqrt(sigma2) * focal


# ----------------------------------------------------------------------------- network
def network_covariance(quaternion: Any, translation: Any, log_var: Any,
                       basis: torch.Tensor) -> torch.Tensor:
    """Covariance ``[5, 5]`` of the network pose in the tangent parameters (module docstring).

    Args:
        quaternion: ``(w, x, y, z)`` ``(4,)`` of the network's rotation.
        translation: ``(3,)`` network translation (unit or metric).
        log_var: ``(7,)`` predicted log-variances, quaternion first.
        basis: ``(3, 2)`` tangent basis of the chart's translation.
    """
    q = as_tensor(quaternion, "quaternion").double()
    t = as_tensor(translation, "translation").double()
    lv = as_tensor(log_var, "log_var").double()
    var = torch.exp(lv)
    q = q / q.norm()
    w0, (x, y, z) = q[0], q[1:]
    # columns: d/dw of (0, w) (x) q (left increment), orthonormal for a unit q
    G = torch.stack([
        torch.stack([-x, -y, -z]),
        torch.stack([w0, z, -y]),
        torch.stack([-z, w0, x]),
        torch.stack([y, -x, w0]),
    ])
    cov = torch.zeros(5, 5, dtype=torch.float64)
    cov[:3, :3] = 4.0 * G.T @ torch.diag(var[:4]) @ G
    tn2 = float((t * t).sum())
    cov[3:, 3:] = basis.T.double() @ torch.diag(var[4:]) @ basis.double() / max(tn2, 1e-24)
    return cov


# ----------------------------------------------------------------------------- fusion
@dataclass
class FusedPose:
    """Result of :func:`fuse_poses`.

    Attributes:
        pose: fused ``T_0to1`` (unbatched, float64); unit translation for direction models,
            the network's norm for metric ones.
        covariance: ``[5, 5]`` covariance of the fused tangent parameters
            :data:`PARAMETER_NAMES` (rad for ``w``, rad on the sphere for ``d``).
        weights: ``[5]`` weight of the network per parameter (``diag(Lambda^-1 Lambda_n)``;
            the classical estimate gets ``1 - weights``): 1 = network only, 0 = classical.
        source: ``"fused"``; ``"network"`` when the classical estimate failed; ``"classical"``
            when the consistency gate refused to fuse (``info["gate"]`` says why).
        network_covariance, classical_covariance: ``[5, 5]`` inputs (``None`` on failure).
        info: ``num_inliers``, ``sigma_px``, ``sign_disagreement``, ``mode``.
    """

    pose: Pose
    covariance: torch.Tensor
    weights: torch.Tensor
    source: str
    network_covariance: torch.Tensor = field(repr=False)
    classical_covariance: torch.Tensor | None = field(default=None, repr=False)
    info: dict = field(default_factory=dict)

    @property
    def std(self) -> torch.Tensor:
        """Standard deviations ``[5]`` of the fused parameters."""
        return self.covariance.diagonal().clamp_min(0).sqrt()


def _network_inputs(net_pose: Any, net_log_var: Any) -> tuple[torch.Tensor, torch.Tensor,
                                                              torch.Tensor]:
    # a PoseOutput (strl_pyg.model) by what it holds: estimation does not import the model
    if all(hasattr(net_pose, k) for k in ("quaternion", "translation", "log_var")):
        if net_pose.quaternion.shape[0] != 1:
            raise ValueError(
                f"Expected a PoseOutput of one pair (got {net_pose.quaternion.shape[0]})"
            )
        q = net_pose.quaternion[0].detach().cpu().double()
        t = net_pose.translation[0].detach().cpu().double()
        if net_log_var is None:
            net_log_var = net_pose.log_var[0]
    elif isinstance(net_pose, Pose):
        if len(net_pose.shape) != 0:
            raise ValueError(f"Expected an unbatched Pose (got shape {tuple(net_pose.shape)})")
        q = net_pose.quaternion().detach().cpu().double()
        t = net_pose.t.detach().cpu().double()
    else:
        raise TypeError(f"Expected a Pose or a PoseOutput (got {type(net_pose).__name__})")
    if net_log_var is None:
        raise ValueError("Expected 'net_log_var' (7,) with a Pose (got None)")
    lv = as_tensor(net_log_var.detach().cpu() if isinstance(net_log_var, torch.Tensor)
                   else net_log_var, "net_log_var").double().reshape(-1)
    if lv.shape != (7,):
        raise ValueError(f"Expected 'net_log_var' with 7 values (got shape {tuple(lv.shape)})")
    if not bool(torch.isfinite(lv).all()) or not bool(torch.isfinite(q).all() & torch.isfinite(
            t).all()):
        raise ValueError("Expected a finite network pose and log-variance (got NaN or inf)")
    if float(t.norm()) < 1e-12:
        raise ValueError("Expected a non-zero network translation (got |t| = 0)")
    return q, t, lv


def fuse_poses(
    net_pose: Any,
    net_log_var: Any = None,
    classical: BaselineResult | None = None,
    matches: PairMatches | None = None,
    mode: str = "information",
    min_sigma_px: float = 0.05,
    threshold_px: float | None = 1.0,
    inflation: float = 1.0,
    gate_chi2: float | None = GATE_CHI2,
    network_scale: float = 1.0,
    network_extra: Any = None,
) -> FusedPose:
    """Fuses the network's ``T_0to1`` with a classical robust estimate (module docstring).

    Consistency gate: with the network pose ``x_n`` in the classical chart, the squared
    Mahalanobis distance ``d2 = x_n^T (Sigma_c + Sigma_n)^+ x_n`` follows a chi-square law with
    5 degrees of freedom when both estimates are right and their covariances honest. Where
    ``d2 > gate_chi2`` (default :data:`GATE_CHI2`, its 99 % quantile) the two disagree beyond
    their combined uncertainty, so nothing is fused: the classical estimate is returned with
    ``source = "classical"`` and ``info["gate"]`` holds ``d2``, the threshold and the reason.

    Args:
        net_pose: unbatched :class:`~strl_pyg.geometry.Pose`, or a ``PoseOutput`` of one pair.
        net_log_var: ``(7,)`` log-variances (quaternion first); taken from the ``PoseOutput``
            when omitted.
        classical: :class:`~strl_pyg.estimation.classical.BaselineResult` on the same matches.
        matches: the :class:`~strl_pyg.data.PairMatches` it was estimated from (pixels, with
            intrinsics).
        mode: ``"information"`` (default) or ``"diagonal"``.
        min_sigma_px: floor of the classical residual standard deviation, pixels.
        threshold_px: inlier threshold the classical estimate used (default 1.0, that of
            :func:`~strl_pyg.estimation.classical.estimate_relative_pose`); see
            :func:`classical_covariance`.
        inflation: variance multiplier of the classical covariance (default 1).
        gate_chi2: consistency-gate threshold on ``d2``; ``None`` fuses always.
        network_scale: variance multiplier of the network covariance (its calibration,
            e.g. the fitted scale a checkpoint stores; default 1).
        network_extra: ``[5, 5]`` covariance added to the network's own before the scale,
            isotropic in each block (so the same in any tangent basis): the swap check's
            disagreement term (:func:`strl_pyg.estimation.uncertainty.swap_covariance`).

    Returns:
        :class:`FusedPose`.
    """
    if mode not in FUSION_MODES:
        raise ValueError(f"Expected mode in {FUSION_MODES} (got {mode!r})")
    if not isinstance(classical, BaselineResult):
        raise TypeError(f"Expected a BaselineResult (got {type(classical).__name__})")
    if not isinstance(matches, PairMatches):
        raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
    if not matches.has_intrinsics:
        raise ValueError("Expected intrinsics K0 and K1 in the PairMatches (got none)")
    if not min_sigma_px > 0:
        raise ValueError(f"Expected min_sigma_px > 0 (got {min_sigma_px})")
    if not inflation > 0:
        raise ValueError(f"Expected inflation > 0 (got {inflation})")
    if threshold_px is not None and not threshold_px > 0:
        raise ValueError(f"Expected threshold_px > 0 or None (got {threshold_px})")
    q, t_net, lv = _network_inputs(net_pose, net_log_var)
    extra = torch.zeros(5, 5, dtype=torch.float64)
    if network_extra is not None:
        extra = torch.as_tensor(np.asarray(network_extra, dtype=np.float64))
        if extra.shape != (5, 5) or not bool(torch.isfinite(extra).all()):
            raise ValueError(f"Expected network_extra as a finite [5, 5] covariance (got "
                             f"shape {tuple(extra.shape)})")
    scale = float(t_net.norm())
    net = Pose.from_quaternion(q, t_net)
    inliers = np.asarray(classical.inliers, dtype=bool).reshape(-1)
    n_in = int(inliers.sum()) if inliers.shape == (matches.num_points,) else 0
    if classical.success and inliers.shape != (matches.num_points,):
        raise ValueError(
            f"Expected the classical inlier mask over the {matches.num_points} point matches "
            f"(got shape {inliers.shape}): was it estimated on these matches?"
        )
    t_c = classical.pose.t.double()
    if not classical.success or n_in < MIN_INLIERS or float(t_c.norm()) < 1e-12:
        basis = tangent_basis(t_net)
        cov = network_covariance(q, t_net, lv, basis) + extra
        return FusedPose(net.to(torch.float64), cov, torch.ones(5, dtype=torch.float64),
                         "network", cov, None,
                         {"num_inliers": n_in, "sigma_px": float("nan"),
                          "sign_disagreement": False, "mode": mode})
    R_c = classical.pose.R.double()
    t_c = t_c / t_c.norm()
    basis = tangent_basis(t_c)
    info_c, cov_c, sigma_px = classical_covariance(classical.pose, matches, inliers,
                                                   min_sigma_px, threshold_px, inflation)
    cov_n = (network_covariance(q, t_net, lv, basis) + extra) * network_scale
    x_n = pose_to_tangent(net, R_c, t_c, basis)
    d2 = float(x_n @ torch.linalg.pinv(cov_c + cov_n, hermitian=True) @ x_n)
    gate = {"d2": d2, "threshold": gate_chi2, "fused": True}
    if gate_chi2 is not None and not d2 <= gate_chi2:
        gate.update(fused=False, reason=(
            f"network and classical poses disagree beyond their combined uncertainty "
            f"(Mahalanobis d2 = {d2:.1f} > {gate_chi2:.1f}): classical estimate kept"))
        return FusedPose(
            Pose(R_c, t_c * scale), cov_c, torch.zeros(5, dtype=torch.float64), "classical",
            cov_n, cov_c,
            {"num_inliers": n_in, "sigma_px": sigma_px,
             "sign_disagreement": bool(float(t_net @ t_c) < 0), "mode": mode, "gate": gate},
        )
    if mode == "diagonal":
        info_c = torch.diag(1.0 / cov_c.diagonal().clamp_min(1e-300))
        info_n = torch.diag(1.0 / cov_n.diagonal().clamp_min(1e-300))
    else:
        info_n = torch.linalg.inv(cov_n)
    info = info_c + info_n
    cov = torch.linalg.inv(info)
    gain = cov @ info_n
    x = gain @ x_n
    pose = tangent_to_pose(x, R_c, t_c, basis, scale)
    return FusedPose(
        pose, cov, gain.diagonal().clone(), "fused", cov_n, cov_c,
        {"num_inliers": n_in, "sigma_px": sigma_px,
         "sign_disagreement": bool(float(t_net @ t_c) < 0), "mode": mode, "gate": gate},
    )
