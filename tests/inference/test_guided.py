"""Network-guided robust estimation (strl_pyg.estimation.guided) and the geometric head of the
model."""

import numpy as np
import pytest
import torch

from strl_pyg.data import build_pair_graph
from strl_pyg.data.transforms import FixedSizeResample
from strl_pyg.estimation.classical import estimate_relative_pose, normalised_matches
from strl_pyg.estimation.guided import guided_estimate, msac_cost
from strl_pyg.geometry import epipolar_residuals
from strl_pyg.metrics.two_view import relative_pose_error
from strl_pyg.model import ABLATIONS, StrLPoseConfig
from strl_pyg.model.strl_pose import StrLPose
from strl_pyg.synthetic import SceneConfig
from strl_pyg.training.loss import GeometricLoss


@pytest.fixture(scope="module")
def outlier_pair(generated_pair):
    p = generated_pair(2_000_100, SceneConfig(noise_px=1.0, outlier_fraction=0.5))
    return p, estimate_relative_pose(p.matches, "opencv")


@pytest.mark.parametrize("weights", ["uniform", "oracle", "adversarial"])
def test_guided_never_scores_worse_than_the_classical_estimate(outlier_pair, weights):
    p, base = outlier_pair
    m = p.matches
    inl = epipolar_residuals(m, p.T_0to1)[0] < 2.0
    w = {"uniform": np.ones(m.num_points), "oracle": 0.05 + 0.9 * inl,
         "adversarial": 0.05 + 0.9 * ~inl}[weights]
    g = guided_estimate(m, w, "opencv", classical=base)
    x0, x1, f = normalised_matches(m)
    assert g.success and g.method == "guided_opencv"
    assert msac_cost(g.pose, x0, x1, 1.0 / f) <= msac_cost(base.pose, x0, x1, 1.0 / f) + 1e-12
    assert g.info["candidate"] in ("all", "top", "prosac")


def test_guided_with_oracle_weights_is_accurate(outlier_pair):
    p, base = outlier_pair
    m = p.matches
    inl = epipolar_residuals(m, p.T_0to1)[0] < 2.0
    g = guided_estimate(m, 0.05 + 0.9 * inl, "opencv", classical=base, refine_iterations=10)
    r, t = relative_pose_error(g.pose.matrix()[None].numpy(), p.T_0to1[None])
    assert float(r[0]) < 0.5 and float(t[0]) < 5.0


def test_guided_rejects_bad_weights(outlier_pair):
    p, _ = outlier_pair
    n = p.matches.num_points
    with pytest.raises(ValueError, match="one weight per point match"):
        guided_estimate(p.matches, np.ones(n - 1))
    with pytest.raises(ValueError, match="non-negative"):
        guided_estimate(p.matches, np.full(n, np.nan))
    with pytest.raises(ValueError, match="keep"):
        guided_estimate(p.matches, np.ones(n), keep=0.0)


def _graph(generated_pair, seed=3, **scene):
    p = generated_pair(seed, SceneConfig(**scene))
    return p, build_pair_graph(p.matches, T_0to1=p.T_0to1)


def test_geometric_head_recovers_the_exact_pose_with_uniform_weights(generated_pair):
    p, g = _graph(generated_pair)
    cfg = StrLPoseConfig.ablation("full", hidden=16, layers=1, patch_features=1, geometric=True)
    model = StrLPose(cfg).eval()
    with torch.no_grad():  # constant logit: every node weighs the same
        last = model.inlier_head[-1]
        last.weight.zero_()
        last.bias.fill_(3.0)
        out = model(g)
    geo = out.geometric
    assert int(geo.status[0]) == 0
    # points carry exact matches; line endpoints of generated lines are exact too
    r, t = relative_pose_error(geo.T_0to1.numpy(), p.T_0to1[None])
    assert float(r[0]) < 1e-3 and float(t[0]) < 1e-2
    assert geo.point_logits.shape == (p.matches.num_points,)
    assert geo.endpoint_logits.shape == (2 * p.matches.num_lines,)


def test_geometric_head_storage_order_survives_batching(generated_pair):
    gs = [FixedSizeResample(40 + 10 * i, 8, seed=i)(_graph(generated_pair, seed=i)[1])
          for i in range(3)]
    from torch_geometric.loader.dataloader import Collater

    b = Collater(None)(gs)
    cfg = StrLPoseConfig.ablation("full", hidden=16, layers=1, patch_features=1, geometric=True)
    model = StrLPose(cfg).eval()
    with torch.no_grad():
        out_b = model(b).geometric
        singles = [model(g).geometric for g in gs]
    assert torch.allclose(out_b.point_logits, torch.cat([s.point_logits for s in singles]),
                          atol=1e-5)
    assert torch.allclose(out_b.R, torch.cat([s.R for s in singles]), atol=1e-6)


def test_geometric_head_reports_too_few_matches_as_degenerate(generated_pair):
    p, g = _graph(generated_pair)
    g = FixedSizeResample(5, 1, seed=0)(g)  # 5 points + 2 endpoints < 8
    cfg = StrLPoseConfig.ablation("baseline", hidden=16, layers=1, geometric=True)
    out = StrLPose(cfg)(g)
    assert int(out.geometric.status[0]) == 1
    assert torch.isfinite(out.geometric.E).all() and torch.isfinite(out.quaternion).all()


@pytest.mark.parametrize("row", list(ABLATIONS))
def test_every_ablation_row_trains_with_and_without_the_geometric_head(row, generated_pair):
    _, g = _graph(generated_pair, seed=5, noise_px=1.0, outlier_fraction=0.3)
    g = FixedSizeResample(64, 16, seed=0)(g)
    if row in ("R", "LP+R"):
        p = generated_pair(5, SceneConfig(noise_px=1.0, outlier_fraction=0.3))
        g = FixedSizeResample(64, 16, seed=0)(build_pair_graph(
            p.matches, T_0to1=p.T_0to1, keep_images=True))
    for geometric in (False, True):
        extra = {"image_channels": 1} if row in ("R", "LP+R") else {}
        cfg = StrLPoseConfig.ablation(row, hidden=16, layers=1, patch_features=1,
                                      geometric=geometric, **extra)
        model = StrLPose(cfg)
        out = model(g)
        assert (out.geometric is not None) == geometric
        loss = out.quaternion.sum() + out.translation.sum()
        if geometric:
            loss = loss + GeometricLoss()(out, g["T_0to1"])["loss"]
        loss.backward()
        grads = [q.grad for q in model.parameters() if q.grad is not None]
        assert grads and all(torch.isfinite(x).all() for x in grads)


def test_regression_checkpoint_loads_without_the_geometric_head(tmp_path):
    model = StrLPose(StrLPoseConfig.ablation("full", hidden=16, layers=1, patch_features=1))
    path = model.save(tmp_path / "m.pt")
    again = StrLPose.load(path)
    assert again.inlier_head is None and again.config.geometric is False


def test_geometric_loss_labels_follow_the_true_epipolar_error(generated_pair):
    p, g = _graph(generated_pair, seed=7, noise_px=0.5, outlier_fraction=0.4)
    cfg = StrLPoseConfig.ablation("baseline", hidden=16, layers=1, geometric=True)
    model = StrLPose(cfg)
    out = model(g)
    logs = GeometricLoss(threshold_px=2.0)(out, g["T_0to1"])
    # 40 % of the point and line matches were replaced by wrong ones
    assert 0.4 < float(logs["inlier_frac"]) < 0.75
    with pytest.raises(ValueError, match="geometric=True"):
        GeometricLoss()(StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1))(g),
                        g["T_0to1"])


def test_geometric_loss_gradient_is_finite_at_a_node_on_both_epipoles():
    """Step 569 of a 3000-pair run (issue 30): a near-rank-1 E from the weighted solve had a
    node with Sampson denominator 0 in float32; its capped term passes no gradient, but the
    division's backward computed 0 * r^2 / (1e-30)^2 = 0 / 0 (1e-60 is 0 in float32): NaN in
    every weight. Planted here with E = e3 e3^T (den = 0 at every node, r = 1)."""
    from types import SimpleNamespace

    from strl_pyg.geometry import Pose

    n = 12
    g = torch.Generator().manual_seed(0)
    coords = 0.3 * torch.randn(n, 4, generator=g)
    E = torch.zeros(1, 3, 3)
    E[0, 2, 2] = 1.0
    E.requires_grad_()
    logits = torch.zeros(n, requires_grad=True)
    geo = SimpleNamespace(logits=logits, batch=torch.zeros(n, dtype=torch.long), coords=coords,
                          E=E, status=torch.zeros(1, dtype=torch.long),
                          R=torch.eye(3)[None].double(), t=torch.tensor([[1.0, 0, 0]]).double(),
                          focal=torch.full((1,), 500.0))
    # the truth: pure sideways motion, so that half the nodes are labelled inliers
    T = Pose(torch.eye(3), torch.tensor([1.0, 0.0, 0.0])).matrix()[None]
    coords[: n // 2, 2:] = coords[: n // 2, :2]  # x1 = x0 fits x1^T [t]x x0 = 0 for these
    logs = GeometricLoss(ess_weight=1.0)(SimpleNamespace(geometric=geo), T)
    assert float(logs["loss_ess"]) == pytest.approx(GeometricLoss().cap, rel=1e-6)
    logs["loss"].backward()
    assert torch.isfinite(E.grad).all() and torch.isfinite(logits.grad).all()


@pytest.mark.parametrize("weighting", ["network", "blend", "uniform"])
def test_guided_refinement_weightings_never_raise_the_msac_cost(outlier_pair, weighting):
    p, base = outlier_pair
    m = p.matches
    w = np.random.default_rng(0).random(m.num_points)
    g = guided_estimate(m, w, "opencv", classical=base, refine_iterations=10,
                        refine_weighting=weighting)
    x0, x1, f = normalised_matches(m)
    assert msac_cost(g.pose, x0, x1, 1.0 / f) <= msac_cost(base.pose, x0, x1, 1.0 / f) + 1e-12
    with pytest.raises(ValueError, match="refine_weighting"):
        guided_estimate(m, w, "opencv", classical=base, refine_iterations=10,
                        refine_weighting="nope")


def test_guided_without_any_hypothesis_reports_failure(outlier_pair):
    """No classical pose, too few matches for a 'top' subset and no PROSAC (PoseLib): an
    explicit failure with the identity pose and no inliers, never a confident pose."""
    from strl_pyg.estimation.classical import BaselineResult
    from strl_pyg.geometry import Pose

    pm = outlier_pair[0].matches.select(point_index=np.arange(8))
    failed = BaselineResult(Pose.identity(), np.zeros(8, dtype=bool), 0.0, "poselib", False)
    g = guided_estimate(pm, np.ones(8), method="poselib", keep=1.0, classical=failed)
    assert not g.success and g.method == "guided_poselib"
    assert g.info == {"candidate": None, "refined": False}
    assert g.inliers.dtype == bool and g.inliers.shape == (8,) and not g.inliers.any()
    np.testing.assert_array_equal(g.pose.R.numpy(), np.eye(3))
    assert g.pose.t.abs().sum() == 0 and g.time_ms >= 0
