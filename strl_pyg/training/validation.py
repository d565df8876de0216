"""Validation during training: the trivial mean-pose predictor and the errors and pose AUC
of a model over a loader (the summary keys are those of the training log and history)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import Tensor
from tqdm.auto import tqdm

from strl_pyg.data import keys as keys_
from strl_pyg.geometry import Pose, rotation_to_quaternion
from strl_pyg.metrics.stats import pose_error_stats
from strl_pyg.metrics.two_view import relative_pose_error
from strl_pyg.training.loss import PoseLoss

__all__ = ["mean_pose", "evaluate_model"]


def mean_pose(T_0to1: Tensor, translation: str = "direction") -> tuple[Tensor, Tensor]:
    """The trivial predictor: the chordal mean rotation (mean of the rotation matrices,
    projected back to SO(3)) and the mean translation (re-normalised for directions) of
    ``T_0to1`` ``[N, 4, 4]``. Returns a quaternion ``[4]`` and a translation ``[3]``."""
    pose = Pose.from_matrix(T_0to1.double())
    U, _, Vh = torch.linalg.svd(pose.R.mean(0))
    d = torch.sign(torch.det(U @ Vh))
    R = U @ torch.diag(torch.stack([torch.ones_like(d), torch.ones_like(d), d])) @ Vh
    t = pose.t
    if translation == "direction":
        t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        t = t.mean(0)
        t = t / t.norm().clamp_min(1e-12)
    else:
        t = t.mean(0)
    return rotation_to_quaternion(R).float(), t.float()


def _errors(q: Tensor, t: Tensor, T_gt: Tensor) -> tuple[Tensor, Tensor]:
    return relative_pose_error(Pose.from_quaternion(q, t), T_gt)


def _summary(rot: Tensor, trans: Tensor, prefix: str) -> dict[str, float]:
    """:func:`~strl_pyg.metrics.stats.pose_error_stats` under the training log's key names
    (``{prefix}rot_err_deg``: mean, ``..._med``: median, ``{prefix}auc5/10/20``, and
    ``{prefix}failures``: the pairs without a finite rotation error, e.g. a NaN network
    output, which the means and medians leave out and the AUCs count as failed)."""
    s = pose_error_stats(rot, trans)
    return {
        f"{prefix}rot_err_deg": s["rot_mean"],
        f"{prefix}rot_err_med": s["rot_median"],
        f"{prefix}trans_err_deg": s["trans_mean"],
        f"{prefix}trans_err_med": s["trans_median"],
        f"{prefix}auc5": s["auc5"],
        f"{prefix}auc10": s["auc10"],
        f"{prefix}auc20": s["auc20"],
        f"{prefix}failures": float(s["failures"]),
    }


def pose_error_median(rot: Tensor, trans: Tensor) -> float:
    """The median over pairs of the larger of the rotation and translation errors (a missing
    translation direction counts as 180 deg): what ``best_model.pt`` is kept by."""
    pose = torch.maximum(rot.double(), torch.nan_to_num(trans.double(), nan=180.0))
    pose = pose[torch.isfinite(pose)]
    return float(np.median(pose.numpy())) if pose.numel() else float("nan")


@torch.no_grad()
def evaluate_model(model: torch.nn.Module, loader, loss_fn: PoseLoss | None = None,
                   trivial: tuple[Tensor, Tensor] | None = None, device: str = "cpu",
                   progress: bool = False, geo_loss: Any = None) -> dict[str, float]:
    """Mean / median rotation and translation-direction errors (degrees), the median of the
    larger of the two (``pose_err_med``) and pose AUC at 5/10/20 degrees of ``model`` over
    ``loader``; with ``trivial`` (a mean pose), the same
    metrics of that constant predictor, prefixed ``trivial_``. With the geometric head, its
    decomposed pose's errors (``geo_``) and its inlier ranking (``inlier_auc_med``, the
    median per-pair ROC-AUC, labels by ``geo_loss.threshold_px`` (default 2 px), and
    ``inlier_rank_err`` = 1 - that)."""
    model.eval()
    rots, transs, t_rots, t_transs, losses, ranks = [], [], [], [], [], []
    g_rots, g_transs = [], []
    for batch in tqdm(loader, desc="validate", disable=not progress, leave=False):
        batch = batch.to(device)
        T_gt = batch[keys_.T_0TO1]
        out = model(batch)
        if loss_fn is not None:
            losses.append(float(loss_fn(out, T_gt)["loss"]))
        r, t = _errors(out.quaternion, out.translation, T_gt)
        rots.append(r.cpu())
        transs.append(t.cpu())
        if getattr(out, "geometric", None) is not None:
            geo = out.geometric
            ranks.extend(inlier_ranking_auc(geo, T_gt, getattr(geo_loss, "threshold_px", 2.0)))
            r, t = relative_pose_error(Pose(geo.R, geo.t), T_gt.double())
            bad = geo.status.cpu() != 0
            g_rots.append(torch.where(bad, torch.full_like(r.cpu(), 180.0), r.cpu()))
            g_transs.append(torch.where(bad, torch.full_like(t.cpu(), 180.0), t.cpu()))
        if trivial is not None:
            q0 = trivial[0].to(T_gt).expand(T_gt.shape[0], 4)
            t0 = trivial[1].to(T_gt).expand(T_gt.shape[0], 3)
            r, t = _errors(q0, t0, T_gt)
            t_rots.append(r.cpu())
            t_transs.append(t.cpu())
    if not rots:
        raise ValueError("Expected at least one validation batch (got an empty loader)")
    res = _summary(torch.cat(rots), torch.cat(transs), "")
    res["pose_err_med"] = pose_error_median(torch.cat(rots), torch.cat(transs))
    if losses:
        res["loss"] = float(np.mean(losses))
    if trivial is not None:
        res.update(_summary(torch.cat(t_rots), torch.cat(t_transs), "trivial_"))
    if g_rots:
        res.update(_summary(torch.cat(g_rots), torch.cat(g_transs), "geo_"))
    ranks = [a for a in ranks if np.isfinite(a)]
    if ranks:  # the inlier head's ranking: 1 - the median per-pair ROC-AUC (lower is better)
        res["inlier_auc_med"] = float(np.median(ranks))
        res["inlier_rank_err"] = 1.0 - res["inlier_auc_med"]
    return res


def inlier_ranking_auc(geo: Any, T_gt: Tensor, threshold_px: float = 2.0) -> list[float]:
    """Per pair, the ROC-AUC (:func:`~strl_pyg.metrics.stats.roc_auc`) of the geometric head's
    inlier logits against the true labels (:func:`~strl_pyg.training.loss.inlier_labels`, as
    its loss labels them); NaN for a pair with only inliers or only outliers."""
    from strl_pyg.metrics.stats import roc_auc
    from strl_pyg.training.loss import inlier_labels

    label = inlier_labels(geo, Pose.from_matrix(T_gt.double()), threshold_px).cpu().numpy()
    score = geo.logits.detach().double().cpu().numpy()
    bn = geo.batch.cpu().numpy()
    return [roc_auc(score[bn == k], label[bn == k]) for k in range(int(T_gt.shape[0]))]
