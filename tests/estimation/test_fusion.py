"""Tests of strl_pyg.estimation.pose_fusion on generated pairs with known poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from strl_pyg.estimation.classical import BaselineResult, estimate_relative_pose
from strl_pyg.estimation.pose_fusion import (
    GATE_CHI2,
    MIN_INLIERS,
    FusedPose,
    classical_covariance,
    fuse_poses,
    network_covariance,
    pose_to_tangent,
    sampson_jacobian,
    sampson_residuals,
    tangent_to_pose,
    truncated_sigma,
)
from strl_pyg.geometry import (
    Pose,
    essential_from_pose,
    normalize_points,
    sampson_error,
    so3_exp,
    so3_log,
    sphere_exp,
    sphere_log,
    tangent_basis,
)
from strl_pyg.metrics.two_view import relative_pose_error
from strl_pyg.synthetic import SceneConfig


@pytest.fixture(scope="module")
def noisy_pair(generated_pair):
    pair = generated_pair(7, SceneConfig(kind="indoor", noise_px=1.0, outlier_fraction=0.3))
    classical = estimate_relative_pose(pair.matches, "opencv", seed=0)
    assert classical.success and classical.num_inliers > 50
    return pair, classical


def _gt(pair) -> Pose:
    gt = Pose.from_matrix(pair.T_0to1)
    return Pose(gt.R, gt.t / gt.t.norm())


def test_manifold_maps_round_trip():
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        w = torch.randn(3, generator=gen, dtype=torch.float64)
        assert torch.allclose(so3_log(so3_exp(w)), w, atol=1e-9)
        R = so3_exp(w)
        assert torch.allclose(R @ R.T, torch.eye(3, dtype=torch.float64), atol=1e-12)
    t = torch.tensor([0.2, -0.1, 0.9], dtype=torch.float64)
    t = t / t.norm()
    B = tangent_basis(t)
    assert torch.allclose(B.T @ B, torch.eye(2, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(t @ B, torch.zeros(2, dtype=torch.float64), atol=1e-12)
    d = torch.tensor([0.3, -1.2], dtype=torch.float64)
    u = sphere_exp(t, B, d)
    assert math.isclose(float(u.norm()), 1.0, abs_tol=1e-12)
    assert torch.allclose(sphere_log(t, B, u), d, atol=1e-9)
    # at x = 0 the chart returns the reference pose itself
    R0 = so3_exp(torch.tensor([0.1, 0.2, -0.3], dtype=torch.float64))
    pose = tangent_to_pose(torch.zeros(5, dtype=torch.float64), R0, t, B)
    assert torch.allclose(pose.R, R0) and torch.allclose(pose.t, t)
    assert torch.allclose(pose_to_tangent(pose, R0, t, B), torch.zeros(5, dtype=torch.float64),
                          atol=1e-12)


def test_residuals_match_sampson_error_and_jacobian_matches_finite_differences(noisy_pair):
    pair, classical = noisy_pair
    m = pair.matches
    inl = classical.inliers
    x0 = normalize_points(m.points0[inl], m.K0).double()
    x1 = normalize_points(m.points1[inl], m.K1).double()
    R, t = classical.pose.R, classical.pose.t
    B = tangent_basis(t)
    zero = torch.zeros(5, dtype=torch.float64)
    r = sampson_residuals(zero, R, t, B, x0, x1)
    ref = sampson_error(essential_from_pose(R, t), x0, x1, squared=True)
    assert torch.allclose(r**2, ref, rtol=1e-9, atol=1e-20)
    J = sampson_jacobian(R, t, B, x0, x1)
    assert J.shape == (int(inl.sum()), 5)
    h = 1e-6
    for k in range(5):
        e = torch.zeros(5, dtype=torch.float64)
        e[k] = h
        fd = (sampson_residuals(e, R, t, B, x0, x1) - sampson_residuals(-e, R, t, B, x0, x1))
        fd = fd / (2 * h)
        assert torch.allclose(J[:, k], fd, rtol=1e-5, atol=1e-8), k


def test_classical_covariance_shape_and_sigma(noisy_pair):
    pair, classical = noisy_pair
    info, cov, sigma_px = classical_covariance(classical.pose, pair.matches, classical.inliers)
    assert info.shape == cov.shape == (5, 5)
    assert torch.allclose(cov, cov.T, atol=1e-15)
    assert bool((torch.linalg.eigvalsh(cov) > 0).all())
    _, _, raw = classical_covariance(classical.pose, pair.matches, classical.inliers,
                                     threshold_px=None)
    # inliers truncated at 1 px of 1 px noise: the raw std is ~0.54 px, the corrected larger
    assert 0.4 < raw < 0.65 and sigma_px > raw
    _, cov2, _ = classical_covariance(classical.pose, pair.matches, classical.inliers,
                                      inflation=4.0)
    assert torch.allclose(cov2, 4.0 * cov, rtol=1e-9)


def test_truncated_sigma_recovers_the_gaussian_std():
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 2.0, 400_000)
    # the inversion amplifies sampling noise as the window narrows (at 0.75 sigma: ~2.5 %)
    for threshold, tol in ((1.5, 0.05), (2.0, 0.02), (4.0, 0.01)):
        kept = x[np.abs(x) < threshold]
        assert truncated_sigma(float(kept.std()), threshold) == pytest.approx(2.0, rel=tol)
    # nothing truncated: unchanged
    assert truncated_sigma(1.0, 100.0) == pytest.approx(1.0, rel=1e-6)


def test_network_covariance_near_identity_is_four_times_quaternion_variance():
    var = torch.tensor([1e-3, 2e-4, 3e-4, 4e-4, 1e-2, 2e-2, 3e-2], dtype=torch.float64)
    t = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    B = tangent_basis(t)
    cov = network_covariance([1.0, 0.0, 0.0, 0.0], t, var.log(), B)
    assert torch.allclose(cov[:3, :3], torch.diag(4 * var[1:4]), atol=1e-15)
    assert torch.allclose(cov[3:, 3:], B.T @ torch.diag(var[4:]) @ B, atol=1e-15)
    # t along z: the tangent plane is x-y, so the z variance does not enter
    assert sorted(cov[3:, 3:].diagonal().tolist()) == pytest.approx([1e-2, 2e-2])


def test_tiny_network_variance_gives_the_network_pose(noisy_pair):
    pair, classical = noisy_pair
    gt = _gt(pair)
    net = Pose(so3_exp(torch.tensor([0.03, -0.01, 0.02], dtype=torch.float64)) @ gt.R, gt.t)
    f = fuse_poses(net, torch.full((7,), -40.0), classical, pair.matches, gate_chi2=None)
    assert isinstance(f, FusedPose) and f.source == "fused"
    r, t = relative_pose_error(f.pose, net)
    assert float(r) < 1e-4 and float(t) < 1e-4
    assert bool((f.weights > 0.999).all())


def test_huge_network_variance_gives_the_classical_pose(noisy_pair):
    pair, classical = noisy_pair
    gt = _gt(pair)
    net = Pose(so3_exp(torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64)) @ gt.R, -gt.t)
    f = fuse_poses(net, torch.full((7,), 40.0), classical, pair.matches)
    r, t = relative_pose_error(f.pose, classical.pose)
    assert float(r) < 1e-6 and float(t) < 1e-6
    assert bool((f.weights < 1e-6).all())
    assert f.info["sign_disagreement"]


@pytest.mark.parametrize("mode", ["information", "diagonal"])
def test_one_parameter_disagreement_lies_between(noisy_pair, mode):
    pair, classical = noisy_pair
    Rc, tc = classical.pose.R, classical.pose.t
    B = tangent_basis(tc)
    x_net = torch.tensor([0.0, 0.0, 0.0, 0.05, 0.0], dtype=torch.float64)  # d_1 only
    net = tangent_to_pose(x_net, Rc, tc, B)
    _, cov_c, _ = classical_covariance(classical.pose, pair.matches, classical.inliers)
    # the network as certain as the classical estimate on d_1 (q var = cov/4 at identity is
    # irrelevant here: only the disagreeing parameter matters)
    lv = torch.full((7,), math.log(float(cov_c[3, 3])))
    f = fuse_poses(net, lv, classical, pair.matches, mode=mode)
    x = pose_to_tangent(f.pose, Rc, tc, B)
    assert 0.0 < float(x[3]) < 0.05
    if mode == "diagonal":
        w = float(f.weights[3])
        assert 0.0 < w < 1.0
        assert float(x[3]) == pytest.approx(0.05 * w, rel=1e-6)
        assert torch.allclose(x[[0, 1, 2, 4]], torch.zeros(4, dtype=torch.float64), atol=1e-12)


def test_classical_failure_returns_network_pose(noisy_pair):
    pair, classical = noisy_pair
    net = _gt(pair)
    failed = BaselineResult(Pose.identity(), np.zeros(pair.matches.num_points, bool), 1.0,
                            "opencv", False)
    f = fuse_poses(net, torch.zeros(7), failed, pair.matches)
    assert f.source == "network" and f.classical_covariance is None
    assert torch.allclose(f.pose.matrix(), net.matrix())
    few = np.zeros(pair.matches.num_points, bool)
    few[: MIN_INLIERS - 1] = True
    f = fuse_poses(net, torch.zeros(7), BaselineResult(classical.pose, few, 1.0, "opencv"),
                   pair.matches)
    assert f.source == "network"


def test_degenerate_inputs_raise(noisy_pair):
    pair, classical = noisy_pair
    net = _gt(pair)
    with pytest.raises(ValueError, match="Expected 'net_log_var' with 7 values"):
        fuse_poses(net, torch.zeros(6), classical, pair.matches)
    with pytest.raises(ValueError, match="finite"):
        fuse_poses(net, torch.full((7,), float("nan")), classical, pair.matches)
    with pytest.raises(ValueError, match="non-zero network translation"):
        fuse_poses(Pose(net.R, torch.zeros(3)), torch.zeros(7), classical, pair.matches)
    with pytest.raises(TypeError, match="Expected a BaselineResult"):
        fuse_poses(net, torch.zeros(7), None, pair.matches)
    with pytest.raises(TypeError, match="Expected a Pose or a PoseOutput"):
        fuse_poses(net.matrix(), torch.zeros(7), classical, pair.matches)
    with pytest.raises(ValueError, match="unbatched Pose"):
        fuse_poses(Pose.stack([net, net]), torch.zeros(7), classical, pair.matches)
    with pytest.raises(ValueError, match="mode"):
        fuse_poses(net, torch.zeros(7), classical, pair.matches, mode="mean")
    with pytest.raises(ValueError, match="inlier mask"):
        bad = BaselineResult(classical.pose, classical.inliers[:-1], 1.0, "opencv")
        fuse_poses(net, torch.zeros(7), bad, pair.matches)
    with pytest.raises(ValueError, match="non-zero translation"):
        tangent_basis(torch.zeros(3))


def test_gate_refuses_a_planted_wrong_network_pose(noisy_pair):
    pair, classical = noisy_pair
    gt = _gt(pair)
    # 20 degrees off and reversed, but claiming ~1 degree of uncertainty
    net = Pose(so3_exp(torch.tensor([0.35, 0.0, 0.0], dtype=torch.float64)) @ gt.R, -gt.t)
    f = fuse_poses(net, torch.full((7,), -8.0), classical, pair.matches)
    assert f.source == "classical"
    assert f.info["gate"]["fused"] is False and f.info["gate"]["d2"] > GATE_CHI2
    assert "disagree" in f.info["gate"]["reason"]
    r, t = relative_pose_error(f.pose, classical.pose)
    assert float(r) < 1e-9 and float(t) < 1e-9
    # ungated, the same inputs do move the estimate towards the wrong pose
    g = fuse_poses(net, torch.full((7,), -8.0), classical, pair.matches, gate_chi2=None)
    assert g.source == "fused" and float(relative_pose_error(g.pose, classical.pose)[0]) > 0.1


def test_gate_fuses_a_consistent_network_pose(noisy_pair):
    pair, classical = noisy_pair
    # the network agrees with the classical estimate within its stated uncertainty
    net = Pose(so3_exp(torch.tensor([0.002, 0.0, 0.0], dtype=torch.float64))
               @ classical.pose.R, classical.pose.t)
    f = fuse_poses(net, torch.full((7,), -8.0), classical, pair.matches)
    assert f.source == "fused" and f.info["gate"]["fused"] is True
    assert f.info["gate"]["d2"] <= GATE_CHI2


def test_estimator_fusion_uses_the_checkpoints_inflation(generated_pair):
    """``metadata["fusion_inflation"]`` (fitted by bench_pose --calibrate) multiplies the
    regression's calibrated variance in the fused record; absent, it is 1."""
    import copy

    from strl_pyg.estimation.pose_fusion import fuse_poses
    from strl_pyg.estimation.uncertainty import swap_covariance
    from strl_pyg.inference.estimator import PoseEstimator
    from strl_pyg.inference.methods import swap_term
    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.synthetic import SceneConfig

    pair = generated_pair(2_000_004, SceneConfig(kind="indoor", noise_px=0.5))
    model = StrLPose.from_pretrained()
    s_reg = model.metadata["calibration"]["regression"]
    for k in (None, 8.0):
        m = copy.deepcopy(model)
        md = {key: v for key, v in m.metadata.items() if key != "fusion_inflation"}
        m.metadata = md if k is None else {**md, "fusion_inflation": k}
        est = PoseEstimator(m, methods=["regression", "opencv", "fused"], bootstrap=0)
        recs = est.estimate(pair.matches).methods
        scale = s_reg * (1.0 if k is None else k)
        assert recs["fused"].info["network_variance_scale"] == pytest.approx(scale)
        swap = recs["regression"].info["swap_disagreement_deg"]
        extra = swap_covariance(math.radians(swap["rotation"]),
                                math.radians(swap["translation"]))
        np.testing.assert_array_equal(swap_term(recs["regression"]), extra)
        ref = fuse_poses(recs["regression"].raw, None, recs["opencv"].raw, pair.matches,
                         network_scale=scale, network_extra=extra)
        np.testing.assert_allclose(recs["fused"].T_0to1, ref.pose.matrix().numpy(),
                                   rtol=0, atol=1e-12)


def test_the_swap_checks_extra_covariance_moves_the_fusion_towards_the_classical_pose(
        noisy_pair):
    pair, classical = noisy_pair
    Rc, tc = classical.pose.R, classical.pose.t
    B = tangent_basis(tc)
    x_net = torch.tensor([0.0, 0.0, 0.0, 0.05, 0.0], dtype=torch.float64)
    net = tangent_to_pose(x_net, Rc, tc, B)
    _, cov_c, _ = classical_covariance(classical.pose, pair.matches, classical.inliers)
    lv = torch.full((7,), math.log(float(cov_c[3, 3])))
    plain = fuse_poses(net, lv, classical, pair.matches)
    zero = fuse_poses(net, lv, classical, pair.matches, network_extra=np.zeros((5, 5)))
    assert torch.equal(plain.pose.t, zero.pose.t)
    assert torch.equal(plain.covariance, zero.covariance)
    extra = np.diag([0.0] * 3 + [9.0 * float(cov_c[3, 3])] * 2)
    wide = fuse_poses(net, lv, classical, pair.matches, network_extra=extra)
    d_plain = float(pose_to_tangent(plain.pose, Rc, tc, B)[3])
    d_wide = float(pose_to_tangent(wide.pose, Rc, tc, B)[3])
    assert 0.0 < d_wide < d_plain  # the network counts less
    torch.testing.assert_close(wide.network_covariance,
                               plain.network_covariance + torch.as_tensor(extra))
    with pytest.raises(ValueError, match=r"Expected network_extra as a finite \[5, 5\]"):
        fuse_poses(net, lv, classical, pair.matches, network_extra=np.eye(3))
