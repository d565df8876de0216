"""Bootstrap covariance of the classical poses (strl_pyg.estimation.uncertainty)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from strl_pyg.estimation.classical import estimate_relative_pose
from strl_pyg.estimation.uncertainty import MAX_SIGMA_DEG, bootstrap_covariance, cap_covariance
from strl_pyg.inference.estimator import PoseEstimator
from strl_pyg.synthetic import SceneConfig


@pytest.fixture(scope="module")
def pair(generated_pair):
    return generated_pair(2_200_000, SceneConfig(kind="indoor", noise_px=0.5))


def _psd(c):
    return np.allclose(c, c.T) and np.linalg.eigvalsh(c).min() > -1e-15


def test_bootstrap_is_seeded_psd_and_grows_with_the_noise(pair):
    m = pair.matches
    res = estimate_relative_pose(m, "opencv")
    a = bootstrap_covariance(m, res.pose, "opencv", n=6, seed=3)
    b = bootstrap_covariance(m, res.pose, "opencv", n=6, seed=3)
    assert a.shape == (5, 5) and a.dtype == np.float64 and _psd(a)
    assert np.array_equal(a, b)
    rng = np.random.default_rng(0)
    H, W = m.image_size1
    p1 = np.clip(m.points1 + rng.normal(0, 3.0, m.points1.shape), 0, [W - 1, H - 1])
    noisy = replace(m, points1=p1)
    res_n = estimate_relative_pose(noisy, "opencv", threshold_px=4.0)
    c = bootstrap_covariance(noisy, res_n.pose, "opencv", n=6, threshold_px=4.0, seed=3)
    assert np.trace(c) > 5 * np.trace(a)  # 6x the pixel noise: a much less stable solution


def _serial_bootstrap(m, pose, method, n, thr, seed):
    """The bootstrap as one loop of PairMatches resamples (the code before the resamples were
    threaded and, for PoseLib, cut from the pair normalised once): the reference path."""
    from strl_pyg.estimation.pose_fusion import pose_to_tangent
    from strl_pyg.geometry import tangent_basis

    R0, t0 = pose.R.double(), pose.t.double() / pose.t.double().norm()
    basis, rng, xs = tangent_basis(t0), np.random.default_rng(seed), []
    for b in range(n):
        idx = rng.integers(0, m.num_points, m.num_points)
        sample = replace(m, points0=m.points0[idx], points1=m.points1[idx],
                         point_scores=None if m.point_scores is None else m.point_scores[idx],
                         lines0=None, lines1=None, line_scores=None, image0=None, image1=None)
        res = estimate_relative_pose(sample, method, thr, seed=seed + b + 1)
        if res.success:
            xs.append(pose_to_tangent(res.pose, R0, t0, basis).numpy())
    X = np.asarray(xs)
    return X.T @ X / len(X)


@pytest.mark.parametrize("method", ["opencv", "poselib"])
def test_bootstrap_in_threads_equals_the_serial_loop(pair, method):
    if method == "poselib":
        pytest.importorskip("poselib")
    rng = np.random.default_rng(1)
    m = pair.matches
    H, W = m.image_size1
    m = replace(m, points1=np.clip(m.points1 + rng.normal(0, 2.0, m.points1.shape), 0,
                                   [W - 1, H - 1]))  # noisy: the resamples disagree
    res = estimate_relative_pose(m, method, threshold_px=3.0)
    ref = _serial_bootstrap(m, res.pose, method, 8, 3.0, 5)
    assert np.trace(ref) > 1e-7  # the resamples disagree (rad^2; identical poses would give 0)
    first = bootstrap_covariance(m, res.pose, method, 8, 3.0, seed=5, workers=1)
    # the serial loop's chart coordinates one by one, ours batched: equal up to rounding
    np.testing.assert_allclose(first, ref, rtol=1e-10, atol=0)
    for workers in (None, 2, 3, 8, 20):  # and the same solves whatever the thread count
        got = bootstrap_covariance(m, res.pose, method, 8, 3.0, seed=5, workers=workers)
        assert np.array_equal(got, first), workers
    with pytest.raises(ValueError, match=r"Expected workers as an integer >= 1 or None \(got 0\)"):
        bootstrap_covariance(m, res.pose, method, 8, workers=0)


def test_bootstrap_errors_and_no_pose(pair):
    m = pair.matches
    res = estimate_relative_pose(m, "opencv")
    with pytest.raises(ValueError, match=r"Expected n as an integer >= 3 \(got 2\)"):
        bootstrap_covariance(m, res.pose, "opencv", n=2)
    with pytest.raises(TypeError, match="Expected a PairMatches"):
        bootstrap_covariance({"points0": 1}, res.pose)
    # one match repeated 6 times: no resample determines a pose
    few = replace(m, points0=np.repeat(m.points0[:1], 6, 0), points1=np.repeat(m.points1[:1], 6, 0),
                  point_scores=None, lines0=None, lines1=None, line_scores=None)
    assert bootstrap_covariance(few, res.pose, "opencv", n=3) is None


def test_estimator_adds_the_bootstrap_to_the_first_order_covariance(pair):
    first = PoseEstimator(methods=["opencv"], bootstrap=0).estimate(pair.matches).methods
    both = PoseEstimator(methods=["opencv"], bootstrap=5).estimate(pair.matches).methods
    c1, c2 = first["opencv"].covariance, both["opencv"].covariance
    assert np.array_equal(first["opencv"].T_0to1, both["opencv"].T_0to1)
    assert _psd(c2 - c1) and np.trace(c2) > np.trace(c1)
    assert both["opencv"].info["covariance"] == "first-order + bootstrap (5)"
    assert first["opencv"].info["covariance"] == "first-order"
    for bad in (-1, 2, 1.5, True):
        with pytest.raises(ValueError, match="Expected bootstrap = 0"):
            PoseEstimator(methods=["opencv"], bootstrap=bad)



def test_calibration_applies_on_the_lazy_path_and_only_to_the_fitted_bootstrap(pair):
    """The default predict path runs PoseLib alone: its covariance must still be calibrated,
    and equal to the one of the run of every method; a scale fitted with bootstrap=8 is not
    applied to a bootstrap=0 covariance (it says so)."""
    from strl_pyg.model.strl_pose import StrLPose

    model = StrLPose.from_pretrained()
    fitted = model.metadata.get("calibration_bootstrap")
    assert fitted == 8 and "opencv" in model.metadata["calibration"]
    alone = PoseEstimator(model, methods=["opencv"]).estimate(pair.matches).methods["opencv"]
    with_net = PoseEstimator(model, methods=["opencv", "regression"]).estimate(
        pair.matches).methods["opencv"]
    assert alone.info["calibration_scale"] == model.metadata["calibration"]["opencv"]
    np.testing.assert_allclose(alone.covariance, with_net.covariance, rtol=1e-12)
    off = PoseEstimator(model, methods=["opencv"], bootstrap=0).estimate(pair.matches)
    rec = off.methods["opencv"]
    assert "calibration_scale" not in rec.info
    assert any("not calibrated" in w and "bootstrap=8" in w for w in rec.warnings)


def test_fused_covariance_takes_its_calibration_scale(pair):
    """Before, the fused record's covariance was never scaled (bench_pose measured its 2-sigma
    coverage at 0-53 %); now a checkpoint's ``calibration["fused"]`` applies like the others',
    and the fused pose itself does not change."""
    import copy

    from strl_pyg.model.strl_pose import StrLPose

    model = StrLPose.from_pretrained()
    scaled = copy.deepcopy(model)
    cal = {k: v for k, v in model.metadata["calibration"].items() if k != "fused"}
    model.metadata = {**model.metadata, "calibration": cal}
    scaled.metadata = {**scaled.metadata, "calibration": {**cal, "fused": 7.0}}
    methods = ["regression", "opencv", "fused"]
    plain = PoseEstimator(model, methods=methods).estimate(pair.matches).methods["fused"]
    fused = PoseEstimator(scaled, methods=methods).estimate(pair.matches).methods["fused"]
    assert plain.status == fused.status == "ok"
    np.testing.assert_array_equal(plain.T_0to1, fused.T_0to1)
    np.testing.assert_allclose(fused.covariance, 7.0 * plain.covariance, rtol=1e-12)
    assert fused.info["calibration_scale"] == 7.0 and "calibration_scale" not in plain.info


@pytest.mark.parametrize("kind,seed", [("indoor", 2_200_000), ("indoor", 2_200_001)])
def test_guided_covariance_is_first_order_plus_the_bootstrap_of_its_solve(kind, seed,
                                                                          generated_pair):
    """Before, the guided record had the first-order covariance only (2-sigma coverage
    55-66 % on dino, object, low texture in bench_pose); now it adds the bootstrap of the solve
    it kept, like the classical records: on all matches it is the base method's own bootstrap
    (computed once), on the network's top matches the bootstrap of that subset."""
    from strl_pyg.estimation.classical import have_poselib
    from strl_pyg.inference import BOOTSTRAPPED
    from strl_pyg.model.strl_pose import StrLPose

    assert "guided" in BOOTSTRAPPED
    pair = generated_pair(seed, SceneConfig(kind=kind, noise_px=1.0, outlier_fraction=0.5))
    model = StrLPose.from_pretrained()
    base = "poselib" if have_poselib() else "opencv"
    est = PoseEstimator(model, methods=[base, "guided"]).estimate(pair.matches).methods
    off = PoseEstimator(model, methods=[base, "guided"], bootstrap=0).estimate(
        pair.matches).methods
    g, g0 = est["guided"], off["guided"]
    assert g.status == g0.status == "ok"
    np.testing.assert_array_equal(g.T_0to1, g0.T_0to1)
    assert g.info["covariance"] == "first-order + bootstrap (8)"
    assert g0.info["covariance"] == "first-order"
    assert _psd(g.covariance - g0.covariance) and np.trace(g.covariance) > np.trace(g0.covariance)
    raw = g.raw
    # which hypothesis wins ("all" or "top") is an MSAC-cost comparison on rendered pixels
    # (the network reads them): another CPU's OpenCV paths flipped it for seed 2200001, so the
    # test checks the covariance of whichever candidate was kept
    assert g.info["candidate"] in ("all", "top", "prosac")
    subset = raw.info["point_index"]
    assert (subset is None) == (g.info["candidate"] != "top")
    sub = pair.matches if subset is None else pair.matches.select(point_index=subset)
    boot = bootstrap_covariance(sub, raw.pose, base, 8, 1.0, 0)
    scale = g.info.get("calibration_scale", 1.0)
    # the estimator's record is the sum, calibrated, then capped at 180 deg RMS per block
    uncapped = g0.info.get("calibration_scale", 1.0)
    expected = scale * (g0.covariance / uncapped + boot)
    assert not g0.info.get("sigma_capped")
    np.testing.assert_allclose(g.covariance, cap_covariance(expected)[0], rtol=1e-9)
    assert g.info.get("sigma_capped", False) == cap_covariance(expected)[1]


def test_fused_covariance_adds_the_classical_bootstrap(pair):
    """Found by a newcomer trial: on a dino pair PoseLib said sigma 66 deg (its bootstrap saw
    the unstable solve) and the fused pose, 0.1 deg from it, said 1.2 deg: the information form
    only knew PoseLib's first-order covariance. Now the classical bootstrap term is added."""
    import copy

    from strl_pyg.model.strl_pose import StrLPose

    model = StrLPose.from_pretrained()
    bare = copy.deepcopy(model)
    bare.metadata = {k: v for k, v in model.metadata.items() if k != "calibration"}
    methods = ["regression", "opencv", "fused"]
    with_boot = PoseEstimator(bare, methods=methods).estimate(pair.matches).methods["fused"]
    first = PoseEstimator(bare, methods=methods, bootstrap=0).estimate(pair.matches)
    f0 = first.methods["fused"]
    np.testing.assert_array_equal(with_boot.T_0to1, f0.T_0to1)
    raw = first.methods["opencv"].raw
    boot = bootstrap_covariance(pair.matches, raw.pose, "opencv", 8, 1.0, 0)
    np.testing.assert_allclose(with_boot.covariance, f0.covariance + boot, rtol=1e-9,
                               atol=1e-18)
    assert with_boot.info["covariance"] == "information form + opencv bootstrap (8)"
    assert f0.info["covariance"] == "information form"


def test_pose_to_tangent_batched_equals_one_by_one():
    import torch

    from strl_pyg.estimation.pose_fusion import pose_to_tangent
    from strl_pyg.geometry import Pose, sphere_log, tangent_basis
    from strl_pyg.geometry.manifold import so3_exp

    g = torch.Generator().manual_seed(0)
    R0 = so3_exp(torch.randn(3, generator=g, dtype=torch.float64))
    t0 = torch.tensor([0.3, -0.2, 0.9], dtype=torch.float64)
    t0 = t0 / t0.norm()
    basis = tangent_basis(t0)
    R = so3_exp(0.1 * torch.randn(7, 3, generator=g, dtype=torch.float64)) @ R0
    t = torch.randn(7, 3, generator=g, dtype=torch.float64)
    t[5], t[6] = 2.0 * t0, -3.0 * t0  # on the reference direction, and opposite to it
    got = pose_to_tangent(Pose(R, t), R0, t0, basis)
    ref = torch.stack([pose_to_tangent(Pose(R[i], t[i]), R0, t0, basis) for i in range(7)])
    assert got.shape == (7, 5)
    torch.testing.assert_close(got, ref, rtol=1e-12, atol=1e-14)
    assert float(got[5, 3:].norm()) < 1e-12  # on t0: zero translation coordinates
    # -t0: pi along the first basis direction, batched and one by one
    torch.testing.assert_close(got[6, 3:], torch.tensor([torch.pi, 0.0], dtype=torch.float64))
    torch.testing.assert_close(sphere_log(t0, basis, -t0), got[6, 3:])
    assert sphere_log(t0, basis, t[:3].reshape(3, 1, 3)).shape == (3, 1, 2)


def test_cap_covariance_bounds_each_block_at_180_degrees():
    """Before: 'ok', 2.1 / 1.5 deg off, sigma 203 / 127 deg (a Strecha wide pair)."""
    cov = np.diag([4.0, 4.0, 4.0, 0.01, 0.01])  # rotation RMS ~ 198 deg
    cov[0, 3] = cov[3, 0] = 0.1
    capped, was = cap_covariance(cov)
    assert was
    assert math.degrees(math.sqrt(np.trace(capped[:3, :3]))) == pytest.approx(MAX_SIGMA_DEG)
    np.testing.assert_allclose(capped[3:, 3:], cov[3:, 3:])  # the other block unchanged
    assert np.all(np.linalg.eigvalsh(capped) >= -1e-12)
    small = np.diag([1e-4] * 5)
    np.testing.assert_array_equal(cap_covariance(small)[0], small)
    assert not cap_covariance(small)[1]


def test_a_clean_pair_has_no_far_bootstrap_resamples(held_out_pair):
    est = PoseEstimator(methods="poselib").estimate(held_out_pair.matches)
    assert est.pose.info["bootstrap_far"] == 0
    assert not any("resamples found another pose" in w for w in est.warnings)

