"""The estimator's one configuration (issue 'One record per method'): the user's options
checked once in :class:`EstimatorConfig`, the checkpoint's metadata read once into
:class:`CheckpointSettings`, and the recommended path run by one estimator."""

from __future__ import annotations

import numpy as np
import pytest

from strl_pyg.inference import CheckpointSettings, EstimatorConfig, PoseEstimator


@pytest.mark.parametrize("options, message", [
    ({"bootstrap": 2}, r"Expected bootstrap = 0 \(off\) or an integer >= 3 \(got 2\)"),
    ({"threshold_px": 0}, r"Expected threshold_px > 0 \(got 0\)"),
    ({"min_inlier_ratio": 1.0}, r"Expected min_inlier_ratio in \[0, 1\) \(got 1.0\)"),
    ({"min_inliers": True}, r"Expected min_inliers as an integer >= 0 \(got True\)"),
    ({"resample": (384,)}, r"Expected resample 'model', None or \(points, lines\)"),
    ({"seed": 1.5}, r"Expected seed as an integer \(got 1.5\)"),
])
def test_bad_options_are_one_line_errors_from_the_config_and_the_estimator(options, message):
    with pytest.raises(ValueError, match=message):
        EstimatorConfig(**options)
    with pytest.raises(ValueError, match=message):
        PoseEstimator(methods="poselib", **options)


def test_an_unknown_option_names_the_known_ones():
    with pytest.raises(TypeError, match=r"Expected options from \[.*'threshold_px'.*\] "
                                        r"\(got \['treshold_px'\]\)"):
        PoseEstimator(methods="poselib", treshold_px=2.0)


def test_options_override_a_given_config_and_are_read_from_it():
    base = EstimatorConfig(seed=7, bootstrap=0, resample=[100, 50])
    est = PoseEstimator(methods="opencv", config=base, threshold_px=2.0)
    assert est.config == EstimatorConfig(methods=("opencv",), seed=7, bootstrap=0,
                                         resample=(100, 50), threshold_px=2.0)
    assert not hasattr(est, "threshold_px")  # one read-only config, no forwarding copies
    assert base.methods is None  # the given config is not changed


def test_checkpoint_settings_read_what_the_metadata_says_and_default_the_rest():
    md = {"calibration": {"poselib": 2.0, "bad": "x"}, "calibration_bootstrap": 8,
          "recommended_order": ["guided", "poselib"], "fusion_inflation": -1}
    s = CheckpointSettings.from_metadata(md)
    assert s == CheckpointSettings({"poselib": 2.0}, 8, ("guided", "poselib"), 1.0,
                                   has_calibration=True)
    assert CheckpointSettings.from_metadata(None) == CheckpointSettings()
    # whether the entry exists at all decides the shipped fallback (stop 46)
    assert not CheckpointSettings.from_metadata({"recommended_order": []}).has_calibration
    assert CheckpointSettings.from_metadata({"calibration": {}}).has_calibration


def test_the_settings_are_read_once_per_estimator(monkeypatch, generated_pair):
    calls = []
    real = CheckpointSettings.of.__func__
    monkeypatch.setattr(CheckpointSettings, "of",
                        classmethod(lambda cls, m: calls.append(1) or real(cls, m)))
    est = PoseEstimator(methods=("opencv", "poselib"))
    for seed in (2_000_001, 2_000_002):
        assert est.estimate(generated_pair(seed).matches).status == "ok"
    assert len(calls) == 1


def test_a_subset_of_methods_runs_with_the_estimators_configuration(generated_pair):
    m = generated_pair(2_000_003).matches
    est = PoseEstimator(methods=("opencv", "poselib"), bootstrap=0, seed=3)
    sub = est.estimate(m, methods="poselib")
    assert list(sub.methods) == ["poselib"]
    alone = PoseEstimator(methods="poselib", bootstrap=0, seed=3).estimate(m)
    np.testing.assert_array_equal(sub.pose.T_0to1, alone.pose.T_0to1)
    np.testing.assert_array_equal(sub.pose.covariance, alone.pose.covariance)
    with pytest.raises(ValueError, match="Expected methods from"):
        est.estimate(m, methods="poselibb")


def test_swapped_matches_exchange_the_images_and_twice_is_the_pair(generated_pair):
    m = generated_pair(2_000_004).matches
    m = type(m)(**{**m.__dict__, "info": {**m.info, "fundamental": [[0.0] * 3] * 3,
                                          "fundamental_inliers": [0, 1], "source": "x"}})
    s = m.swapped()
    np.testing.assert_array_equal(s.points0, m.points1)
    np.testing.assert_array_equal(s.lines1, m.lines0)
    assert s.image_size0 == m.image_size1 and s.image1 is m.image0
    assert s.info == {k: v for k, v in m.info.items()
                      if k not in ("fundamental", "fundamental_inliers")}
    back = s.swapped()
    np.testing.assert_array_equal(back.points0, m.points0)
    np.testing.assert_array_equal(back.K1, m.K1)


def _assert_widened_by(on, off, key: str, covariance) -> None:
    """``on``'s record has the pose of ``off`` (the check leaves the forward pass's pose) and
    its covariance plus the check's term, ``covariance`` of the angles in ``info[key]``, times
    the calibration scale."""
    np.testing.assert_array_equal(on.T_0to1, off.T_0to1)
    d = on.info[key]
    assert key not in off.info
    assert 0.0 <= d["rotation"] <= 180.0 and 0.0 <= d["translation"] <= 180.0
    scale = on.info.get("calibration_scale", 1.0)
    np.testing.assert_allclose(
        on.covariance - off.covariance,
        scale * covariance(np.radians(d["rotation"]), np.radians(d["translation"])),
        atol=1e-12)


def test_the_swap_check_widens_the_regression_covariance_by_the_disagreement(generated_pair):
    from strl_pyg.estimation.uncertainty import swap_covariance

    m = generated_pair(2_000_005).matches
    on = PoseEstimator(methods="regression", data_check=False).estimate(m).methods["regression"]
    off = PoseEstimator(methods="regression", swap_check=False,
                        data_check=False).estimate(m).methods["regression"]
    _assert_widened_by(on, off, "swap_disagreement_deg", swap_covariance)
    # two independent errors of this covariance differ by the measured angles (mean square)
    cov = swap_covariance(0.6, 0.4)
    assert 2 * np.trace(cov[:3, :3]) == pytest.approx(0.6 ** 2)
    assert 2 * np.trace(cov[3:, 3:]) == pytest.approx(0.4 ** 2)
    assert np.count_nonzero(cov - np.diag(np.diag(cov))) == 0  # isotropic per block


def test_the_data_check_widens_the_regression_covariance_by_its_distance_to_the_classical(
        generated_pair):
    from strl_pyg.estimation.uncertainty import data_covariance

    m = generated_pair(2_000_005).matches
    on = PoseEstimator(methods="regression").estimate(m).methods["regression"]
    off = PoseEstimator(methods="regression", data_check=False).estimate(m).methods["regression"]
    _assert_widened_by(on, off, "data_disagreement_deg", data_covariance)
    assert "data_check_ms" in on.info
    # the distance to the classical pose stands for the network's own error (mean square)
    cov = data_covariance(0.6, 0.4)
    assert np.trace(cov[:3, :3]) == pytest.approx(0.6 ** 2)
    assert np.trace(cov[3:, 3:]) == pytest.approx(0.4 ** 2)
    with pytest.raises(ValueError, match="Expected data_check as a bool"):
        PoseEstimator(methods="regression", data_check="no")


def _ctx():
    from strl_pyg.inference.methods.context import MethodContext

    return MethodContext(EstimatorConfig(seed=0, threshold_px=1.0, bootstrap=0))


def test_the_data_check_measures_how_far_a_wrong_pose_is_from_what_the_matches_support(
        generated_pair):
    """A pose 6 deg off in rotation and 25 deg off in translation direction, on clean matches:
    the classical pose is the true one to a fraction of a degree, so the distance is the
    error itself; a backward translation (the network's typical failure on forward motion)
    is ~180 deg away."""
    import torch

    from strl_pyg.geometry import Pose, so3_exp
    from strl_pyg.inference.methods.regression import _data_disagreement
    from strl_pyg.synthetic import SceneConfig

    p = generated_pair(2_000_011, SceneConfig(kind="indoor", noise_px=0.3))
    true = Pose.from_matrix(torch.as_tensor(p.T_0to1, dtype=torch.float64))
    axis = torch.tensor([0.3, -0.8, 0.5], dtype=torch.float64)
    R = so3_exp((np.radians(6.0) * axis / axis.norm())[None])[0] @ true.R.double()
    t = true.t.double() / true.t.double().norm()
    side = torch.linalg.cross(t, torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64))
    t_off = np.cos(np.radians(25)) * t + np.sin(np.radians(25)) * side / side.norm()
    rot, trans = _data_disagreement(p.matches, Pose(R, t_off), _ctx())
    assert np.degrees(rot) == pytest.approx(6.0, abs=0.3)
    assert np.degrees(trans) == pytest.approx(25.0, abs=1.0)
    rot, trans = _data_disagreement(p.matches, Pose(true.R, -true.t), _ctx())
    assert np.degrees(trans) > 178.0 and np.degrees(rot) < 0.3
    rot, trans = _data_disagreement(p.matches, true, _ctx())
    assert np.degrees(rot) < 0.3 and np.degrees(trans) < 2.0


def test_the_data_check_and_the_classical_method_share_one_solve(monkeypatch, generated_pair):
    from strl_pyg.estimation.classical import have_poselib
    from strl_pyg.inference.methods import context as methods  # the pair's one solve

    calls = []
    real = methods.estimate_relative_pose

    def counting(m, name, *a, **k):
        calls.append(name)
        return real(m, name, *a, **k)

    monkeypatch.setattr(methods, "estimate_relative_pose", counting)
    name = "poselib" if have_poselib() else "opencv"
    est = PoseEstimator(methods=["regression", name], bootstrap=0).estimate(
        generated_pair(2_000_005).matches)
    assert calls == [name]
    reg, cls = est.methods["regression"], est.methods[name]
    d = reg.info["data_disagreement_deg"]
    R0, R1 = reg.as_pose().R.double(), cls.as_pose().R.double()
    expect = np.degrees(np.arccos(np.clip((float(np.trace(R0.T @ R1)) - 1) / 2, -1, 1)))
    assert d["rotation"] == pytest.approx(expect, abs=1e-6)


def test_the_data_check_says_why_it_did_not_run(generated_pair):
    from dataclasses import replace

    import torch

    from strl_pyg.geometry import Pose
    from strl_pyg.inference.methods.regression import _data_disagreement

    p = generated_pair(2_000_005)
    pose = Pose.from_matrix(torch.as_tensor(p.T_0to1, dtype=torch.float64))
    m = p.matches
    assert _data_disagreement(replace(m, K0=None, K1=None), pose, _ctx()) == "no intrinsics"
    few = replace(m, points0=m.points0[:5], points1=m.points1[:5])
    assert _data_disagreement(few, pose, _ctx()) == "5 distinct point matches (fewer than 8)"
    # repeated rows are not more matches
    rep = replace(m, points0=np.repeat(m.points0[:4], 3, axis=0),
                  points1=np.repeat(m.points1[:4], 3, axis=0))
    assert _data_disagreement(rep, pose, _ctx()) == "4 distinct point matches (fewer than 8)"


def test_the_regression_says_when_its_data_check_did_not_run(monkeypatch, generated_pair):
    from strl_pyg.inference.methods import regression as methods

    def broken(*args):
        raise RuntimeError("planted")

    monkeypatch.setattr(methods, "_data_disagreement", broken)
    rec = PoseEstimator(methods="regression").estimate(
        generated_pair(2_000_005).matches).methods["regression"]
    assert rec.status == "ok" and rec.info["data_check"] == "not run: RuntimeError: planted"
    assert any("no data check (RuntimeError: planted)" in w for w in rec.warnings)


def test_numpy_scalars_are_options_as_python_ones():
    """Review finding: the config refused numpy scalars the 0.3 constructor took."""
    cfg = EstimatorConfig(seed=np.int64(3), resample=(np.int64(10), np.int64(5)),
                          threshold_px=np.float32(1.5), raise_errors=np.True_,
                          bootstrap=np.int32(8), min_inliers=np.int64(4))
    assert cfg == EstimatorConfig(seed=3, resample=(10, 5), threshold_px=1.5,
                                  raise_errors=True, bootstrap=8, min_inliers=4)
    assert type(cfg.seed) is int and type(cfg.raise_errors) is bool
    with pytest.raises(ValueError, match="Expected methods from"):
        EstimatorConfig(methods=("poselibb",))


def test_a_failing_swap_pass_leaves_the_regression_with_a_warning(monkeypatch, generated_pair):
    import strl_pyg.inference.methods.regression as methods

    def boom(*a, **k):
        raise RuntimeError("out of memory\nmore")

    monkeypatch.setattr(methods, "_swap_disagreement", boom)
    m = generated_pair(2_000_005).matches
    rec = PoseEstimator(methods="regression").estimate(m).methods["regression"]
    off = PoseEstimator(methods="regression", swap_check=False).estimate(m).methods["regression"]
    assert rec.status == "ok" and "swap_disagreement_deg" not in rec.info
    assert any("raised RuntimeError: out of memory)" in w for w in rec.warnings)
    np.testing.assert_array_equal(rec.covariance, off.covariance)


def test_methods_all_and_comma_separated_as_the_cli_takes_them():
    # reproduction: PoseEstimator(methods="all") raised "Expected methods from ... (got
    # ['all'])" although `strl-pose predict --methods all` is the documented way
    from strl_pyg.inference.registry import checked_method_names

    assert PoseEstimator(methods="all").method_names == checked_method_names(None)
    assert PoseEstimator(methods="opencv, poselib").method_names == ("opencv", "poselib")
    with pytest.raises(ValueError, match=r"'all' or 'recommended' \(got \['opencv', 'nope'\]\)"):
        PoseEstimator(methods="opencv,nope")
