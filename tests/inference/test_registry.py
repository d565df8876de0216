"""One record per method (issue "One record per method"): a method registered in one place is
in ``predict --methods``, ``evaluate``, the support check, the bootstrap list and the labels."""

from __future__ import annotations

import numpy as np
import pytest

import strl_pyg.inference as face
from strl_pyg.cli import main as cli_main
from strl_pyg.inference import estimator as est_mod
from strl_pyg.inference.record import MethodResult
from strl_pyg.synthetic import generate_pair


@pytest.fixture()
def toy(method_registry):

    def identity(matches, ctx):
        return MethodResult("toy", "ok", np.eye(4))

    est_mod.register_method("toy", identity, label="a toy that says identity",
                            depends_on=("classical",))
    return "toy"


def test_a_method_registered_once_is_everywhere(toy, tmp_path, capsys):
    assert toy in face.SUPPORT_CHECKED and toy not in face.BOOTSTRAPPED
    assert toy not in face.NETWORK_METHODS and face.DEPENDENCIES[toy] == ("classical",)
    assert est_mod.METHOD_LABELS[toy] == "a toy that says identity"
    from strl_pyg.evaluation import run

    assert toy in run.METHODS and run.resolve_methods([toy], None) == (toy,)
    from strl_pyg.inference.recommended import methods_needed

    assert methods_needed([toy])[-1] == toy and len(methods_needed([toy])) == 2
    # predict --methods knows it, runs its dependency, checks its support, prints its label
    pair = generate_pair(2_000_017)
    path = pair.matches.save(tmp_path / "m.npz")
    code = cli_main(["predict", "--matches", str(path), "--methods", f"{toy},opencv",
                     "--bootstrap", "0"])
    out = capsys.readouterr().out
    assert code == 0 and "toy" in out
    assert "the matches do not support this pose" in out  # identity on a moving pair


def test_derived_tables_follow_the_specs():
    specs = est_mod.METHODS
    assert set(face.NETWORK_METHODS) == {"regression", "geometric", "guided", "fused"}
    assert set(face.BOOTSTRAPPED) == {"poselib", "opencv", "guided", "fused"}
    assert "regression" not in face.SUPPORT_CHECKED and "vp" in face.SUPPORT_CHECKED
    assert all(specs[m].reads_lines for m in face.NETWORK_METHODS)
    with pytest.raises(ValueError, match="Expected MethodSpec fields"):
        est_mod.register_method("x", lambda m, c: None, lable="typo")


def test_a_classical_only_estimate_reads_the_calibration_without_building_the_network():
    """Before: PoseEstimator(methods="poselib") built the shipped network to read its
    calibration (one pass per pair: the network only when a method needs it)."""
    from strl_pyg.inference import PoseEstimator
    from strl_pyg.model import StrLPose

    pair = generate_pair(2_000_017)
    light = PoseEstimator(methods="poselib")
    est = light.estimate(pair.matches)
    assert light._model is None and est.status == "ok"
    full = PoseEstimator(StrLPose.from_pretrained(), methods="poselib").estimate(pair.matches)
    assert est.pose.info["calibration_scale"] == full.pose.info["calibration_scale"]
    np.testing.assert_array_equal(est.pose.covariance, full.pose.covariance)
    assert est.pose.method == full.pose.method


def test_one_name_per_regime_and_per_bound():
    """POINT_POOR_MAX_POINTS and VP_CHECK_MAX_POINTS were one regime under two names; the
    bootstrap minimum was written in three places."""
    import argparse

    from strl_pyg.cli.readers import bootstrap_count
    from strl_pyg.estimation.uncertainty import MIN_BOOTSTRAP
    from strl_pyg.inference import estimator, methods

    assert estimator.POINT_POOR_MAX_POINTS is methods.POINT_POOR_MAX_POINTS
    assert not hasattr(methods, "VP_CHECK_MAX_POINTS")
    assert bootstrap_count(str(MIN_BOOTSTRAP)) == MIN_BOOTSTRAP
    with pytest.raises(argparse.ArgumentTypeError):
        bootstrap_count(str(MIN_BOOTSTRAP - 1))
    with pytest.raises(ValueError, match=f"integer >= {MIN_BOOTSTRAP}"):
        estimator.PoseEstimator(bootstrap=MIN_BOOTSTRAP - 1)
