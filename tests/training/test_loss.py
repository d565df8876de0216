"""Pose parameterisation and the aleatoric loss."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
import torch

from strl_pyg.geometry import Pose, quaternion_to_rotation
from strl_pyg.training.loss import PoseLoss, aleatoric_loss, pose_targets


def axis_angle(axis, deg) -> torch.Tensor:
    axis = torch.as_tensor(axis, dtype=torch.float64)
    axis = axis / axis.norm()
    half = math.radians(deg) / 2
    return torch.cat([torch.tensor([math.cos(half)], dtype=torch.float64),
                      math.sin(half) * axis])


def pred(q, t, s=None):
    q, t = torch.as_tensor(q, dtype=torch.float64), torch.as_tensor(t, dtype=torch.float64)
    s = torch.zeros(q.shape[0], 7, dtype=torch.float64) if s is None else s
    return SimpleNamespace(quaternion=q, translation=t, log_var=s)


def T_of(q, t) -> torch.Tensor:
    return Pose(quaternion_to_rotation(q), t).matrix()


def test_aleatoric_formula_and_minimiser():
    mu, target = torch.tensor([0.3, -1.0]), torch.tensor([0.5, 2.0])
    torch.testing.assert_close(aleatoric_loss(mu, target, torch.zeros(2)), (target - mu) ** 2)
    # d/ds [s + e^2 exp(-s)] = 0 at s = log(e^2): the predicted variance is the squared error.
    s = torch.log((target - mu) ** 2).requires_grad_()
    aleatoric_loss(mu, target, s).sum().backward()
    torch.testing.assert_close(s.grad, torch.zeros(2), atol=1e-6, rtol=0)


def test_aleatoric_gradcheck():
    args = [torch.randn(3, 7, dtype=torch.float64, requires_grad=True) for _ in range(3)]
    assert torch.autograd.gradcheck(aleatoric_loss, args)


def test_pose_targets_canonical_and_direction():
    q = torch.stack([axis_angle([0, 1, 0], 200.0), axis_angle([1, 1, 0], 30.0)])  # w < 0 first
    t = torch.tensor([[0.0, 0.0, 4.0], [0.0, 0.0, 0.0]], dtype=torch.float64)
    q_gt, t_dir = pose_targets(T_of(q, t), "direction")
    assert (q_gt[:, 0] >= 0).all()
    torch.testing.assert_close(q_gt.norm(dim=-1), torch.ones(2, dtype=torch.float64))
    torch.testing.assert_close(q_gt[0], -q[0], atol=1e-6, rtol=0)
    torch.testing.assert_close(t_dir, torch.tensor([[0.0, 0, 1], [0, 0, 0]], dtype=torch.float64))
    _, t_metric = pose_targets(T_of(q, t), "metric")
    torch.testing.assert_close(t_metric, t)
    with pytest.raises(ValueError, match="Expected translation in"):
        pose_targets(T_of(q, t), "meters")


def test_perfect_prediction_zero_error():
    q = torch.stack([axis_angle([0.2, 1, 0.1], 12.0), axis_angle([1, 0, 0], 3.0)])
    t = torch.tensor([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0]], dtype=torch.float64)
    out = PoseLoss()(pred(q, t), T_of(q, t))
    assert abs(float(out["loss"])) < 1e-10
    assert float(out["rot_err_deg"]) < 1e-3 and float(out["trans_err_deg"]) < 1e-3


def test_quaternion_sign_does_not_matter():
    # A 180-degree rotation: w = 0, q and -q both canonical; the loss must treat them alike.
    q = axis_angle([0, 0, 1], 180.0)[None]
    t = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    T = T_of(q, t)
    a, b = PoseLoss()(pred(q, t), T), PoseLoss()(pred(-q, t), T)
    assert float(a["loss"]) < 1e-10 and float(b["loss"]) < 1e-10


def test_logged_errors_are_angles():
    q_gt = axis_angle([0, 1, 0], 5.0)[None]
    q_est = axis_angle([0, 1, 0], 15.0)[None]
    t_gt = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    t_est = torch.tensor([[1.0, 0.0, 1.0]], dtype=torch.float64) / math.sqrt(2)
    out = PoseLoss()(pred(q_est, t_est), T_of(q_gt, t_gt))
    assert float(out["rot_err_deg"]) == pytest.approx(10.0, abs=1e-4)
    assert float(out["trans_err_deg"]) == pytest.approx(45.0, abs=1e-4)
    expected = ((q_est - q_gt) ** 2).sum() + ((t_est - t_gt) ** 2).sum()
    assert float(out["loss"]) == pytest.approx(float(expected), rel=1e-6)


def test_metric_mode_and_weights_and_gradients():
    q = axis_angle([1, 0, 0], 4.0)[None]
    t_gt = torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64)
    p = pred(q.clone().requires_grad_(), torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64,
                                                      requires_grad=True))
    p.log_var.requires_grad_()
    out = PoseLoss("metric", rot_weight=0.0, trans_weight=2.0)(p, T_of(q, t_gt))
    assert float(out["loss"].detach()) == pytest.approx(2.0 * 1.0)  # (2 - 1)^2, weighted by 2
    out["loss"].backward()
    assert p.translation.grad[0, 2] < 0 and p.log_var.grad[0, 4:].abs().sum() > 0


def test_shape_validation():
    q = torch.zeros(2, 4, dtype=torch.float64)
    with pytest.raises(ValueError, match="Expected quaternion"):
        PoseLoss()(pred(q, torch.zeros(2, 2)), torch.eye(4).expand(2, 4, 4))
