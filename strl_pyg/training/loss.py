"""Pose parameterisation and the aleatoric (heteroscedastic) pose loss.

Parameterisation (the paper leaves it open):

* rotation: unit quaternion ``(w, x, y, z)`` with canonical sign ``w >= 0``. ``q`` and ``-q``
  are the same rotation; the target is flipped to the sign closer to the prediction, so the
  loss is continuous across ``w = 0``;
* translation: ``"direction"`` (unit vector; scale-free data such as DeMoN, where only the
  direction is observable from two views) or ``"metric"`` (as given; driving data such as
  KITTI with a known scale).

Convention: ``T_0to1`` maps camera-0 points into camera 1, ``X1 = R X0 + t``.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor, nn

from strl_pyg.geometry import Pose, quaternion_to_rotation, rotation_to_quaternion
from strl_pyg.metrics.two_view import rotation_error_deg, translation_angle_error_deg

__all__ = ["aleatoric_loss", "beta_nll", "angle_between", "pose_targets", "PoseLoss",
           "inlier_labels",
           "GeometricLoss", "LOSS_FORMS"]

TRANSLATION_MODES = ("direction", "metric")
#: ``"paper"``: the aleatoric loss on all 7 components; ``"balanced"``: beta-NLL on the
#: rotation's vector part and the translation, the quaternion's ``w`` variance fitted without
#: moving the pose, and an angular translation term (:class:`PoseLoss`).
LOSS_FORMS = ("paper", "balanced")


def aleatoric_loss(mu: Tensor, target: Tensor, log_var: Tensor) -> Tensor:
    r"""Per-component aleatoric loss :math:`\log\sigma^2 + (\theta - \mu)^2 / \sigma^2`
    (Kendall & Gal, 2017), with :math:`s = \log\sigma^2` predicted for stability.

    Args:
        mu: predictions, shape ``(*, K)``.
        target: ground truth :math:`\theta`, shape ``(*, K)``.
        log_var: :math:`\log\sigma^2`, shape ``(*, K)``.

    Returns:
        the loss of every component, shape ``(*, K)``.
    """
    return log_var + (target - mu).square() * torch.exp(-log_var)


def beta_nll(mu: Tensor, target: Tensor, log_var: Tensor, beta: float = 0.5) -> Tensor:
    r"""beta-NLL (Seitzer et al., ICLR 2022): the aleatoric loss of every component weighted by
    :math:`\mathrm{sg}[\sigma^{2\beta}]` (no gradient through the weight). With
    :math:`\beta = 0.5` the gradient on :math:`\mu` is :math:`2 r / \sigma`, about 2 for a
    calibrated residual whatever the component's scale, so a component predicted with a
    small variance (the rotation) no longer outweighs a large one (the translation);
    :math:`\beta = 0` is :func:`aleatoric_loss`. Shapes as :func:`aleatoric_loss`."""
    weight = torch.exp(beta * log_var.detach())
    return weight * aleatoric_loss(mu, target, log_var)


def angle_between(a: Tensor, b: Tensor, eps: float = 1e-12) -> Tensor:
    """Angle (radians) between vectors ``(*, 3)``, as ``atan2(|a x b|, a . b)``: its gradient
    has magnitude ``1 / |a|`` at every angle, also near 180 deg where ``1 - cos`` has none."""
    cross = torch.linalg.cross(a, b, dim=-1)
    return torch.atan2((cross.square().sum(-1) + eps).sqrt(), (a * b).sum(-1))


def pose_targets(T_0to1: Any, translation: str = "direction") -> tuple[Tensor, Tensor]:
    """Ground-truth quaternions ``[B, 4]`` (``w >= 0``) and translations ``[B, 3]`` (unit
    directions for ``translation="direction"``; a zero translation stays zero) from
    ``T_0to1`` ``[B, 4, 4]``, ``[B, 3, 4]`` or a :class:`~strl_pyg.geometry.Pose`."""
    if translation not in TRANSLATION_MODES:
        raise ValueError(f"Expected translation in {TRANSLATION_MODES} (got {translation!r})")
    pose = T_0to1 if isinstance(T_0to1, Pose) else Pose.from_matrix(T_0to1)
    q = rotation_to_quaternion(pose.R)
    t = pose.t
    if translation == "direction":
        t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return q, t


class PoseLoss(nn.Module):
    r"""The aleatoric pose loss of Str-L Pose over the 7 pose components,

    .. math::
        \mathcal{L} = \frac{1}{B} \sum_b \Big( w_R \sum_{k=1}^{4} \ell_{b,k}
        + w_t \sum_{k=5}^{7} \ell_{b,k} \Big), \qquad
        \ell_{b,k} = s_{b,k} + (\theta_{b,k} - \mu_{b,k})^2 e^{-s_{b,k}}

    with the ground-truth quaternion sign-aligned to the prediction (``form="paper"``).

    ``form="balanced"`` (beyond the paper, the training default) keeps the predicted variances
    but changes three things that starved the translation in the paper's form (see
    ``benchmarks/studies/results_pose_recipe.md``): every component's term is weighted by
    :func:`beta_nll` (``beta``), so the rotation's collapsing variances do not multiply its
    gradient in the shared layers; the quaternion's ``w``, whose error is second order in the
    angle, fits its variance on a detached residual (the pose gets no gradient from it, the
    variance stays honest for fusion); and ``angle_weight`` times the translation's angle
    error (radians, :func:`angle_between`) is added, whose gradient does not vanish at a
    flipped direction as :math:`\lVert t - \hat t \rVert^2 = 2 - 2\cos` does.

    Rotation and translation angle errors (degrees, not differentiated) are logged alongside.

    Args:
        translation (str, optional): ``"direction"`` or ``"metric"``; must match the model.
            (default: :obj:`"direction"`)
        rot_weight (float, optional): :math:`w_R`. (default: :obj:`1.0`)
        trans_weight (float, optional): :math:`w_t`. (default: :obj:`1.0`)
        form (str, optional): ``"paper"`` or ``"balanced"``. (default: :obj:`"paper"`)
        beta (float, optional): beta of ``"balanced"``. (default: :obj:`0.5`)
        angle_weight (float, optional): weight of the angular translation term of
            ``"balanced"`` (direction models only). (default: :obj:`1.0`)

    Shapes:
        - **input:** a prediction with ``quaternion`` :math:`(B, 4)`, ``translation``
          :math:`(B, 3)`, ``log_var`` :math:`(B, 7)` (a :class:`~strl_pyg.model.PoseOutput`)
          and ``T_0to1`` :math:`(B, 4, 4)`
        - **output:** a dict of scalars: ``loss`` (differentiable), ``loss_rot``,
          ``loss_trans``, ``rot_err_deg``, ``trans_err_deg`` (batch means; the translation
          error ignores pairs without a ground-truth direction), ``log_var_rot``,
          ``log_var_trans``
    """

    def __init__(self, translation: str = "direction", rot_weight: float = 1.0,
                 trans_weight: float = 1.0, form: str = "paper", beta: float = 0.5,
                 angle_weight: float = 1.0) -> None:
        super().__init__()
        if translation not in TRANSLATION_MODES:
            raise ValueError(f"Expected translation in {TRANSLATION_MODES} (got {translation!r})")
        if form not in LOSS_FORMS:
            raise ValueError(f"Expected form in {LOSS_FORMS} (got {form!r})")
        if not 0.0 <= beta <= 1.0:
            raise ValueError(f"Expected beta in [0, 1] (got {beta!r})")
        if not angle_weight >= 0.0:
            raise ValueError(f"Expected angle_weight >= 0 (got {angle_weight!r})")
        self.form, self.beta, self.angle_weight = form, beta, angle_weight
        self.translation = translation
        self.rot_weight = rot_weight
        self.trans_weight = trans_weight

    def forward(self, pred: Any, T_0to1: Any) -> dict[str, Tensor]:
        q, t, s = pred.quaternion, pred.translation, pred.log_var
        if q.dim() != 2 or q.shape[1] != 4 or t.shape != (q.shape[0], 3) or \
                s.shape != (q.shape[0], 7):
            raise ValueError(
                "Expected quaternion [B, 4], translation [B, 3], log_var [B, 7] "
                f"(got {tuple(q.shape)}, {tuple(t.shape)}, {tuple(s.shape)})"
            )
        q_gt, t_gt = pose_targets(T_0to1, self.translation)
        if q_gt.shape[0] != q.shape[0]:
            raise ValueError(f"Expected {q.shape[0]} ground-truth poses (got {q_gt.shape[0]})")
        q_gt, t_gt = q_gt.to(q), t_gt.to(t)
        sign = torch.where((q * q_gt).sum(-1, keepdim=True) < 0, -1.0, 1.0)
        q_gt = sign * q_gt
        if self.form == "paper":
            l_rot = aleatoric_loss(q, q_gt, s[:, :4]).sum(-1).mean()
            l_trans = aleatoric_loss(t, t_gt, s[:, 4:]).sum(-1).mean()
        else:
            l_rot = (beta_nll(q[:, 1:], q_gt[:, 1:], s[:, 1:4], self.beta).sum(-1)
                     + beta_nll(q[:, :1].detach(), q_gt[:, :1], s[:, :1], self.beta)[:, 0]
                     ).mean()
            l_trans = beta_nll(t, t_gt, s[:, 4:], self.beta).sum(-1)
            if self.translation == "direction" and self.angle_weight:
                has_t = t_gt.norm(dim=-1) > 0.5  # a zero translation has no direction
                ang = angle_between(t, t_gt)
                l_trans = l_trans + self.angle_weight * torch.where(has_t, ang, 0.0)
            l_trans = l_trans.mean()
        loss = self.rot_weight * l_rot + self.trans_weight * l_trans
        with torch.no_grad():
            R = quaternion_to_rotation(q.detach())
            rot_err = rotation_error_deg(R, quaternion_to_rotation(q_gt)).mean()
            trans_err = torch.nanmean(translation_angle_error_deg(t.detach(), t_gt))
        return {
            "loss": loss,
            "loss_rot": l_rot.detach(),
            "loss_trans": l_trans.detach(),
            "rot_err_deg": rot_err,
            "trans_err_deg": trans_err,
            "log_var_rot": s[:, :4].detach().mean(),
            "log_var_trans": s[:, 4:].detach().mean(),
        }

    def __repr__(self) -> str:
        extra = (f", beta={self.beta}, angle_weight={self.angle_weight}"
                 if self.form == "balanced" else "")
        return (f"{self.__class__.__name__}(translation={self.translation!r}, "
                f"rot_weight={self.rot_weight}, trans_weight={self.trans_weight}, "
                f"form={self.form!r}{extra})")


def inlier_labels(geo: Any, pose: Pose, threshold_px: float) -> Tensor:
    """Per match of a geometric head's output ``geo``, whether it is a true inlier: Sampson
    distance under the true ``pose`` (one per pair) below ``threshold_px`` (in each pair's
    normalised units: divided by its focal length). Bool ``[N]``."""
    from strl_pyg.geometry import essential_from_pose
    from strl_pyg.geometry.essential import sampson_sq

    b = geo.batch
    t = pose.t.to(geo.coords)
    E = essential_from_pose(pose.R.to(geo.coords),
                            t / t.norm(dim=-1, keepdim=True).clamp_min(1e-12))
    d = sampson_sq(E[b], geo.coords[:, None, :2], geo.coords[:, None, 2:])[:, 0].sqrt()
    return d < threshold_px / geo.focal[b]


class GeometricLoss(nn.Module):
    r"""Loss of the geometric head (beyond the paper; :class:`~strl_pyg.model.GeometricOutput`).

    * **classification**: every node's ground-truth label is "inlier" when its Sampson
      distance under the true essential matrix is below ``threshold_px`` (pixels, converted
      with each pair's focal length); binary cross-entropy on the inlier logits, positives and
      negatives weighted to contribute equally in every pair;
    * **essential**: the Sampson distance of the ground-truth inlier nodes under the *predicted*
      essential matrix, in units of the threshold, capped at ``cap`` (robust to a wrong early
      solve), averaged over the non-degenerate pairs that have a non-zero translation.

    .. math::
        \mathcal{L} = w_c \mathcal{L}_{\mathrm{BCE}} + w_e \frac{1}{|\mathcal{I}|}
        \sum_{i \in \mathcal{I}} \min(d_i / \tau, c)

    Args:
        threshold_px (float): inlier threshold (default 2.0).
        cls_weight (float): :math:`w_c` (default 1.0).
        ess_weight (float): :math:`w_e` (default 0.5); ``0`` trains only the classifier.
        cap (float): :math:`c` (default 5.0).

    Shapes:
        - **input:** a ``PoseOutput`` with ``geometric`` set, ``T_0to1`` :math:`(B, 4, 4)`
        - **output:** a dict of scalars: ``loss``, ``loss_cls``, ``loss_ess``, ``inlier_acc``
          (classification accuracy at 0.5), ``inlier_frac`` (fraction of true inliers),
          ``geo_rot_err_deg``, ``geo_trans_err_deg`` (errors of the decomposed pose, means
          over the ok pairs)
    """

    def __init__(self, threshold_px: float = 2.0, cls_weight: float = 1.0,
                 ess_weight: float = 0.5, cap: float = 5.0) -> None:
        super().__init__()
        if not threshold_px > 0:
            raise ValueError(f"Expected threshold_px > 0 (got {threshold_px!r})")
        self.threshold_px = threshold_px
        self.cls_weight = cls_weight
        self.ess_weight = ess_weight
        self.cap = cap

    def forward(self, pred: Any, T_0to1: Any) -> dict[str, Tensor]:
        from strl_pyg.geometry.essential import sampson_sq

        geo = getattr(pred, "geometric", None)
        if geo is None:
            raise ValueError("Expected a PoseOutput of a model with geometric=True (got none)")
        pose = T_0to1 if isinstance(T_0to1, Pose) else Pose.from_matrix(T_0to1)
        B = geo.E.shape[0]
        if pose.R.shape[0] != B:
            raise ValueError(f"Expected {B} ground-truth poses (got {pose.R.shape[0]})")
        b = geo.batch
        x0, x1 = geo.coords[:, None, :2], geo.coords[:, None, 2:]  # [N, 1, 2]
        t = pose.t.to(geo.coords)
        has_t = t.norm(dim=-1) > 1e-9
        thr = self.threshold_px / geo.focal[b]
        label = inlier_labels(geo, pose, self.threshold_px).to(geo.logits)
        bce = nn.functional.binary_cross_entropy_with_logits(geo.logits, label,
                                                             reduction="none")
        pos = torch.zeros(B, device=bce.device, dtype=bce.dtype)
        npos = pos.index_add(0, b, label)
        nneg = pos.index_add(0, b, 1 - label)
        lpos = pos.index_add(0, b, bce * label) / npos.clamp_min(1)
        lneg = pos.index_add(0, b, bce * (1 - label)) / nneg.clamp_min(1)
        has_both = (npos > 0).to(bce) + (nneg > 0).to(bce)
        l_cls = ((lpos + lneg) / has_both.clamp_min(1)).mean()
        valid = (geo.status == 0) & has_t
        # sampson_sq divides in float64: a node on both epipoles of a near-rank-1 E no longer
        # gives a NaN gradient (step 569 of a 3000-pair run)
        d_pred = sampson_sq(geo.E[b], x0, x1)[:, 0].clamp_min(1e-30).sqrt()
        per = torch.clamp(d_pred / thr, max=self.cap) * label * valid[b].to(label)
        denom = (label * valid[b].to(label)).sum()
        l_ess = per.sum() / denom.clamp_min(1)
        loss = self.cls_weight * l_cls + self.ess_weight * l_ess
        with torch.no_grad():
            acc = ((geo.logits > 0).to(label) == label).to(label).mean()
            ok = valid  # non-degenerate, with a ground-truth direction
            if bool(ok.any()):
                r_err = rotation_error_deg(geo.R[ok].to(pose.R), pose.R[ok]).mean()
                t_err = torch.nanmean(translation_angle_error_deg(geo.t[ok].to(t), t[ok]))
            else:
                r_err = t_err = torch.tensor(float("nan"))
        return {"loss": loss, "loss_cls": l_cls.detach(), "loss_ess": l_ess.detach(),
                "inlier_acc": acc, "inlier_frac": label.mean(), "geo_rot_err_deg": r_err,
                "geo_trans_err_deg": t_err, "geo_ok": valid.to(label).mean()}

    def __repr__(self) -> str:
        return (f"{self.__class__.__name__}(threshold_px={self.threshold_px}, "
                f"cls_weight={self.cls_weight}, ess_weight={self.ess_weight})")
