"""The inlier head's validation metric (per-pair ROC-AUC of its logits against the true
labels) and the pose loss's weight, from the command line to the config."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from strl_pyg.metrics.stats import roc_auc
from strl_pyg.training import TrainConfig
from strl_pyg.training.config import BEST_METRICS
from strl_pyg.training.validation import inlier_ranking_auc


def test_roc_auc_shares_ties_and_checks_lengths():
    y = np.array([True, False, True, False])
    assert roc_auc(np.array([3.0, 1.0, 3.0, 2.0]), y) == 1.0
    assert roc_auc(np.array([3.0, 3.0, 1.0, 2.0]), y) == 0.375  # (0.5 + 1 + 0 + 0) / 4
    assert roc_auc(np.array([2.0, 2.0, 1.0, 1.0]), y) == 0.5  # ties count half
    with pytest.raises(ValueError, match=r"Expected score and label of one length"):
        roc_auc(np.ones(3), y)


def _pairs(flip: bool):
    """Two pairs under a sideways translation: inliers move along x only (y equal), outliers
    jump in y; logits +1 for inliers (or -1 with ``flip``)."""
    rng = np.random.default_rng(0)
    coords, batch, logits = [], [], []
    for b in range(2):
        x0 = rng.uniform(-0.5, 0.5, (30, 2))
        x1 = x0.copy()
        x1[:, 0] += 0.1
        out = np.arange(30) % 3 == 0
        x1[out, 1] += rng.uniform(0.05, 0.2, out.sum())
        coords.append(np.c_[x0, x1])
        batch += [b] * 30
        logits.append(np.where(out, -1.0, 1.0) * (-1 if flip else 1))
    geo = SimpleNamespace(coords=torch.tensor(np.concatenate(coords)),
                          batch=torch.tensor(batch), focal=torch.tensor([500.0, 500.0],
                                                                        dtype=torch.float64),
                          logits=torch.tensor(np.concatenate(logits)))
    T = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
    T[:, 0, 3] = 1.0
    return geo, T


def test_inlier_ranking_auc_known_answers():
    geo, T = _pairs(flip=False)
    assert inlier_ranking_auc(geo, T) == [1.0, 1.0]
    geo, T = _pairs(flip=True)
    assert inlier_ranking_auc(geo, T) == [0.0, 0.0]
    geo.logits = torch.zeros_like(geo.logits)  # no ranking at all: chance
    assert inlier_ranking_auc(geo, T) == [0.5, 0.5]


def test_pose_weight_and_the_ranking_metric_are_settings():
    assert "inlier_rank_err" in BEST_METRICS
    cfg = TrainConfig(pose_weight=0.01, best_metric="inlier_rank_err")
    from dataclasses import asdict

    assert TrainConfig.from_dict(asdict(cfg)).pose_weight == 0.01
    with pytest.raises(ValueError, match=r"Expected pose_weight >= 0 \(got -1"):
        TrainConfig(pose_weight=-1.0)


def test_pose_weight_flag(tmp_path):
    import argparse

    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ap = argparse.ArgumentParser()
    add_train_arguments(ap)
    args = ap.parse_args(["--pose-weight", "0.05", "--out", str(tmp_path / "r")])
    assert config_from_args(args, ap).pose_weight == 0.05


def test_a_run_from_shipped_weights_keeps_their_recommended_order(tmp_path):
    """Before: a model.pt trained from shipped:geometric carried none of its metadata, so the
    estimator fell back to the default order (poselib, opencv, regression) and the run was
    not comparable with the weights it started from."""
    from strl_pyg.model import StrLPose, StrLPoseConfig
    from strl_pyg.training.checkpoints import inherit_policy

    shipped = StrLPose.from_pretrained("geometric")
    model = StrLPose(shipped.config)
    inherit_policy(model, "shipped:geometric")
    md = model.metadata
    assert md["recommended_order"] == shipped.metadata["recommended_order"]
    assert "calibration" not in md and md["recommended_order_from"].endswith(".pt")
    model.save(tmp_path / "m.pt")
    assert StrLPose.load(tmp_path / "m.pt").metadata["recommended_order"] == \
        shipped.metadata["recommended_order"]
    plain = StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2))
    plain.save(tmp_path / "plain.pt")
    other = StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2))
    inherit_policy(other, tmp_path / "plain.pt")  # nothing to keep
    assert "recommended_order" not in other.metadata
