"""Bootstrap covariance of the classical poses (strl_pyg.pose_uncertainty)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from strl_pyg.baselines import estimate_relative_pose
from strl_pyg.inference import PoseEstimator
from strl_pyg.pose_uncertainty import bootstrap_covariance
from strl_pyg.synthetic import SceneConfig, generate_pair


@pytest.fixture(scope="module")
def pair():
    return generate_pair(2_200_000, SceneConfig(kind="indoor", noise_px=0.5))


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
    from strl_pyg.model import StrLPose

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
