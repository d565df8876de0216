"""The training recipe beyond the paper (issue "A network that learns its pose"): the flow
node inputs and the balanced pose loss; the paper's own recipe stays available."""

from __future__ import annotations

import pytest
import torch

from strl_pyg.model import StrLPose, StrLPoseConfig
from strl_pyg.model.config import PAPER
from strl_pyg.nn import SpatialCoordinateEncoder, flow_features
from strl_pyg.training.config import TrainConfig
from strl_pyg.training.loss import PoseLoss, angle_between, beta_nll


class _Pred:
    def __init__(self, q, t, s):
        self.quaternion, self.translation, self.log_var = q, t, s


def _T(t):
    T = torch.eye(4, dtype=torch.float64).repeat(len(t), 1, 1)
    T[:, :3, 3] = t
    return T


def test_flow_features_know_expansion_and_rotation():
    # forward motion: points flow outward, x0 . u > 0, no curl
    x0 = torch.tensor([[0.2, 0.1], [-0.3, 0.2]])
    f = flow_features(torch.cat([x0, 1.1 * x0], -1))
    torch.testing.assert_close(f[:, 4:6], 0.1 * x0)
    torch.testing.assert_close(f[:, 6], 0.1 * (x0 ** 2).sum(-1))
    torch.testing.assert_close(f[:, 7], torch.zeros(2), atol=1e-7, rtol=0)
    # a rotation about the optical axis: u perpendicular to x0, curl > 0 (counter-clockwise)
    u = torch.stack([-x0[:, 1], x0[:, 0]], -1) * 0.05
    f = flow_features(torch.cat([x0, x0 + u], -1))
    torch.testing.assert_close(f[:, 6], torch.zeros(2), atol=1e-7, rtol=0)
    torch.testing.assert_close(f[:, 7], 0.05 * (x0 ** 2).sum(-1))


def test_fit_standardisation_gives_unit_features_and_lives_in_the_state_dict():
    torch.manual_seed(0)
    enc = SpatialCoordinateEncoder(16, inputs="flow")
    x0 = 0.3 * torch.randn(500, 2)
    coords = torch.cat([x0, x0 * 1.05 + 0.01 * torch.randn(500, 2)], -1)
    enc.fit_standardisation(coords, symmetric=False)
    z = (flow_features(coords) - enc.feature_mean) / enc.feature_std
    torch.testing.assert_close(z.mean(0), torch.zeros(8), atol=1e-5, rtol=0)
    torch.testing.assert_close(z.std(0), torch.ones(8), atol=1e-5, rtol=0)
    assert {"feature_mean", "feature_std"} <= set(enc.state_dict())
    with pytest.raises(ValueError, match="inputs='flow'"):
        SpatialCoordinateEncoder(16).fit_standardisation(coords)
    with pytest.raises(ValueError, match="Expected inputs in"):
        SpatialCoordinateEncoder(16, inputs="pixels")
    assert "feature_mean" not in SpatialCoordinateEncoder(16).state_dict()


def test_checkpoints_without_the_inputs_key_load_as_the_paper(tmp_path):
    paper = StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1, **PAPER))
    d = paper.config.to_dict()
    del d["inputs"]  # as saved before the key existed
    assert StrLPoseConfig.from_dict(d).inputs == "paper"
    assert StrLPoseConfig().inputs == "flow"
    # the shipped weights predate the flow inputs
    assert StrLPose.from_pretrained().config.inputs == "paper"
    # a flow model round-trips with its fitted statistics
    flow = StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1))
    flow.sce.feature_std.mul_(2.0)
    back = StrLPose.load(flow.save(tmp_path / "m.pt"))
    torch.testing.assert_close(back.sce.feature_std, flow.sce.feature_std)
    old = TrainConfig.from_dict({k: v for k, v in TrainConfig().__dict__.items()
                                 if k != "loss"})
    assert old.loss == "paper" and old.model_config().inputs == "paper"
    assert TrainConfig().loss == "balanced" and TrainConfig().model_config().inputs == "flow"


def test_the_balanced_loss_pulls_a_flipped_translation_back():
    """The paper's squared error of unit vectors (2 - 2 cos) has no gradient at a flip; the
    angular term has one of magnitude 1 per radian."""
    t_gt = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    t = torch.tensor([[1e-4, 0.0, -1.0]], dtype=torch.float64)
    t = (t / t.norm()).requires_grad_(True)
    q = torch.tensor([[1.0, 0.0, 0.0, 0.0]], dtype=torch.float64)
    s = torch.zeros(1, 7, dtype=torch.float64)
    grads = {}
    for form in ("paper", "balanced"):
        t.grad = None
        PoseLoss(form=form)(_Pred(q, t, s), _T(t_gt))["loss"].backward()
        tangent = t.grad - (t.grad * t).sum() * t  # what moves the unit vector
        grads[form] = float(tangent.norm())
    assert grads["paper"] < 1e-3 and grads["balanced"] > 0.9


def test_beta_nll_weights_and_the_detached_w():
    mu = torch.tensor([0.1], requires_grad=True)
    s = torch.tensor([-4.0], requires_grad=True)
    beta_nll(mu, torch.zeros(1), s, beta=0.5).sum().backward()
    # gradient on mu: exp(0.5 s) * 2 r / exp(s) = 2 r / sigma
    torch.testing.assert_close(mu.grad, torch.tensor([2 * 0.1 / torch.exp(torch.tensor(-2.0))]))
    torch.testing.assert_close(beta_nll(mu, torch.zeros(1), s, beta=0.0),
                               s + mu ** 2 * torch.exp(-s))
    # the quaternion's w fits its variance but sends the pose no gradient
    q = torch.tensor([[0.9, 0.3, 0.3, 0.1]], dtype=torch.float64)
    q = (q / q.norm()).requires_grad_(True)
    lv = torch.zeros(1, 7, dtype=torch.float64, requires_grad=True)
    T = _T(torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64))
    out = PoseLoss(form="balanced", rot_weight=1.0, trans_weight=0.0)(
        _Pred(q, torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64), lv), T)
    out["loss"].backward()
    assert q.grad[0, 0] == 0 and q.grad[0, 1:].abs().sum() > 0 and lv.grad[0, 0] != 0
    assert torch.isclose(angle_between(torch.tensor([1.0, 0, 0]), torch.tensor([-1.0, 0, 0])),
                         torch.tensor(torch.pi))
    with pytest.raises(ValueError, match="Expected form in"):
        PoseLoss(form="huber")


def test_second_order_flow_products_give_back_a_small_rotation():
    """inputs="flow2": (r_x, r_y, -curl) is A(x)^T u for the small-rotation flow u = A(x) w,
    so the least squares over the matches gives w back; a translation parallel to the image
    (the same u everywhere) leaves a different signature than a rotation about y."""
    g = torch.Generator().manual_seed(0)
    x0 = (torch.rand(200, 2, generator=g, dtype=torch.float64) - 0.5) * 0.8
    x, y = x0[:, 0], x0[:, 1]
    A = torch.stack([torch.stack([x * y, -(1 + x * x), y], -1),
                     torch.stack([1 + y * y, -x * y, -x], -1)], 1)  # [N, 2, 3]
    w = torch.tensor([0.01, -0.02, 0.015], dtype=torch.float64)
    u = A @ w
    f = flow_features(torch.cat([x0, x0 + u], -1), order=2)
    assert f.shape == (200, 10)
    torch.testing.assert_close(f[:, :8], flow_features(torch.cat([x0, x0 + u], -1)))
    rhs = torch.stack([f[:, 8], f[:, 9], -f[:, 7]], -1).sum(0)
    torch.testing.assert_close(torch.linalg.solve((A.transpose(1, 2) @ A).sum(0), rhs), w)
    with pytest.raises(ValueError, match="order 1 or 2"):
        flow_features(torch.cat([x0, x0 + u], -1), order=3)


def test_flow2_encoder_fits_ten_features_and_round_trips(tmp_path):
    torch.manual_seed(0)
    enc = SpatialCoordinateEncoder(16, inputs="flow2")
    assert enc.feature_mean.shape == (10,)
    x0 = 0.3 * torch.randn(500, 2)
    coords = torch.cat([x0, x0 * 1.05 + 0.01 * torch.randn(500, 2)], -1)
    enc.fit_standardisation(coords, symmetric=True)
    both = torch.cat([coords, coords[:, [2, 3, 0, 1]]])
    z = (flow_features(both, order=2) - enc.feature_mean) / enc.feature_std
    torch.testing.assert_close(z.mean(0), torch.zeros(10), atol=1e-5, rtol=0)
    assert enc(coords).shape == (500, 16)
    model = StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1, inputs="flow2"))
    model.sce.feature_std.mul_(3.0)
    back = StrLPose.load(model.save(tmp_path / "m.pt"))
    assert back.config.inputs == "flow2"
    torch.testing.assert_close(back.sce.feature_std, model.sce.feature_std)
