"""One record per method (issue "One record per method"): a method registered in one place is
in ``predict --methods``, ``evaluate``, the support check, the bootstrap list and the labels."""

from __future__ import annotations

import numpy as np
import pytest

import strl_pyg.inference as face
from strl_pyg.cli import main as cli_main
from strl_pyg.inference import estimator as est_mod
from strl_pyg.inference.record import MethodResult


@pytest.fixture()
def toy(method_registry):

    def identity(matches, ctx):
        return MethodResult("toy", "ok", np.eye(4))

    face.register_method("toy", identity, label="a toy that says identity",
                            depends_on=("classical",))
    return "toy"


def test_a_method_registered_once_is_everywhere(toy, tmp_path, capsys, generated_pair):
    assert toy in face.SUPPORT_CHECKED and toy not in face.BOOTSTRAPPED
    assert toy not in face.NETWORK_METHODS and face.DEPENDENCIES[toy] == ("classical",)
    from strl_pyg.inference import registry

    assert registry.METHOD_LABELS[toy] == "a toy that says identity"
    from strl_pyg.evaluation import run

    assert toy in run.registered_methods() and run.resolve_methods([toy], None) == (toy,)
    from strl_pyg.inference import methods_needed

    assert methods_needed([toy])[-1] == toy and len(methods_needed([toy])) == 2
    # predict --methods knows it, runs its dependency, checks its support, prints its label
    pair = generated_pair(2_000_017)
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
    with pytest.raises(ValueError, match="Expected method attributes from"):
        face.register_method("x", lambda m, c: None, lable="typo")


def test_a_classical_only_estimate_reads_the_calibration_without_building_the_network(
        generated_pair):
    """Before: PoseEstimator(methods="poselib") built the shipped network to read its
    calibration (one pass per pair: the network only when a method needs it)."""
    from strl_pyg.inference import PoseEstimator
    from strl_pyg.model import StrLPose

    pair = generated_pair(2_000_017)
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
    from strl_pyg.inference import estimator, methods, policy
    from strl_pyg.inference.methods import context, vanishing_point

    assert policy.POINT_POOR_MAX_POINTS is context.POINT_POOR_MAX_POINTS
    assert not hasattr(methods, "VP_CHECK_MAX_POINTS")
    assert not hasattr(vanishing_point, "VP_CHECK_MAX_POINTS")
    assert bootstrap_count(str(MIN_BOOTSTRAP)) == MIN_BOOTSTRAP
    with pytest.raises(argparse.ArgumentTypeError):
        bootstrap_count(str(MIN_BOOTSTRAP - 1))
    with pytest.raises(ValueError, match=f"integer >= {MIN_BOOTSTRAP}"):
        estimator.PoseEstimator(bootstrap=MIN_BOOTSTRAP - 1)


def test_a_pose_method_class_registers_with_its_own_spec(method_registry, tmp_path, generated_pair):
    from strl_pyg.inference import PoseEstimator
    from strl_pyg.inference.methods import PoseMethod

    class Identity(PoseMethod):
        name = "identity"
        label = "says identity"
        needs_intrinsics = False
        support_checked = False
        depends_on = ("classical",)

        def __call__(self, matches, ctx):
            assert "opencv" in ctx.results or "poselib" in ctx.results  # ran after its base
            return MethodResult(self.name, "ok", np.eye(4))

    face.register_method(Identity())
    spec = method_registry.METHODS["identity"]
    assert spec.label == "says identity" and spec.depends_on == ("classical",)
    assert not spec.needs_intrinsics and not spec.support_checked and spec.available()
    pair = generated_pair(2_000_017)
    est = PoseEstimator(methods=("identity",), bootstrap=0).estimate(pair.matches)
    rec = est.methods["identity"]
    assert rec.status == "ok", (rec.status, rec.warnings)
    np.testing.assert_array_equal(rec.T_0to1, np.eye(4))
    with pytest.raises(ValueError, match="already registered"):
        face.register_method(Identity())
    with pytest.raises(ValueError, match="Expected a PoseMethod alone"):
        face.register_method(Identity(), label="x")
    with pytest.raises(ValueError, match="Expected a PoseMethod with a name"):
        face.register_method(PoseMethod())
    with pytest.raises(NotImplementedError, match="runs no pose method"):
        PoseMethod()(pair.matches, None)
    with pytest.raises(TypeError, match="Expected fn"):
        face.register_method("nothing", None)


def test_the_built_in_methods_are_classes_with_their_needs():
    from strl_pyg.estimation.classical import have_poselib
    from strl_pyg.inference.methods import Classical, Regression, VanishingPointChecked

    specs = est_mod.METHODS
    assert isinstance(specs["regression"], Regression)
    assert not specs["regression"].needs_intrinsics and specs["regression"].uses_network
    assert isinstance(specs["opencv"], Classical) and specs["opencv"].label == "OpenCV MAGSAC"
    assert specs["poselib"].available() == have_poselib() and specs["opencv"].available()
    assert specs["vp_checked"].angle_deg == VanishingPointChecked.angle_deg
    with pytest.raises(ValueError, match="Expected a classical solver"):
        Classical.of("colmap")


def test_calibration_and_bad_intrinsics_are_typed_on_the_record(generated_pair):
    """Decisions read typed fields, never warning text: a covariance scaled by a measured
    calibration is ``calibrated=True``; one without a scale is ``calibrated=False`` with one
    warning; a pose computed with intrinsics that fail the checks is ``bad_intrinsics``."""
    import dataclasses

    from strl_pyg.inference import PoseEstimator
    from strl_pyg.model import StrLPose, StrLPoseConfig

    pair = generated_pair(2_000_017)
    rec = PoseEstimator(methods=("opencv",)).estimate(pair.matches).methods["opencv"]
    assert rec.status == "ok" and rec.calibrated is True and not rec.bad_intrinsics
    rec = PoseEstimator(methods=("opencv",), bootstrap=0).estimate(pair.matches).methods["opencv"]
    assert rec.calibrated is False  # the scale was fitted with the bootstrap: not this sigma
    assert sum("not calibrated" in w for w in rec.warnings) == 1
    tiny = StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=1))
    rec = PoseEstimator(tiny, methods=("regression",)).estimate(pair.matches).methods["regression"]
    assert rec.covariance is not None and rec.calibrated is False
    assert sum("not calibrated" in w for w in rec.warnings) == 1
    bad_K = pair.matches.K0.copy()
    bad_K[0, 0] = bad_K[1, 1] = 1.0  # a one-pixel focal length fails the plausibility check
    matches = dataclasses.replace(pair.matches, K0=bad_K, K1=bad_K)
    rec = PoseEstimator(methods=("opencv",), bootstrap=0).estimate(matches).methods["opencv"]
    assert rec.bad_intrinsics and rec.status == "unreliable"


def test_a_method_asked_for_alone_runs_with_the_methods_it_reads(generated_pair):
    """Before: ``PoseEstimator(methods=("fused",))`` ran fused without the regression and the
    classical pose it combines: always ``"failed"`` ("fused needs an 'ok' regression and an
    'ok' classical estimate")."""
    from strl_pyg.inference import PoseEstimator

    pair = generated_pair(2_000_017)
    est = PoseEstimator(methods=("fused",), bootstrap=0).estimate(pair.matches)
    assert list(est.methods) == ["fused"]  # what was asked for, in that order
    assert est.methods["fused"].status == "ok", est.methods["fused"].warnings


def test_a_classical_dependency_is_the_solver_asked_for():
    from strl_pyg.inference import methods_needed
    from strl_pyg.inference.registry import classical_method

    assert methods_needed(["opencv", "fused"]) == ("regression", "opencv", "fused")
    assert methods_needed(["fused"])[:2] == ("regression", classical_method())


@pytest.mark.slow
def test_the_face_gives_the_registry_with_its_built_in_methods():
    """Before: in a fresh process ``from strl_pyg.inference import METHODS`` was an empty
    registry and ``EstimatorConfig(methods="opencv")`` refused every name (the built-in
    methods are registered by the estimator module, which nothing had imported yet)."""
    import subprocess
    import sys

    code = ("from strl_pyg.inference import METHODS, EstimatorConfig\n"
            "assert list(METHODS)[:3] == ['regression', 'opencv', 'poselib'], list(METHODS)\n"
            "assert EstimatorConfig(methods='OpenCV').methods == ('opencv',)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]


def test_one_parser_of_method_names_with_a_suggestion():
    from strl_pyg.inference.registry import RECOMMENDED, checked_method_names

    assert checked_method_names("OpenCV, PoseLib") == ("opencv", "poselib")
    assert checked_method_names("Recommended") == RECOMMENDED
    assert checked_method_names("ALL") == checked_method_names(None)
    with pytest.raises(ValueError, match="did you mean 'poselib'"):
        checked_method_names("poselibb")


def test_a_classical_base_is_the_solver_of_the_run(generated_pair):
    """Before: with only OpenCV asked for, vp_checked (and guided, vp) solved PoseLib on their
    own, uncalibrated and with the support thresholds at 0, beside the OpenCV record."""
    from strl_pyg.inference import PoseEstimator

    pair = generated_pair(2_000_017)
    est = PoseEstimator(methods=("opencv", "vp_checked"), bootstrap=0).estimate(pair.matches)
    vc, cv = est.methods["vp_checked"], est.methods["opencv"]
    assert vc.info["classical"] == "opencv" and vc.info["source"] == "opencv"
    np.testing.assert_array_equal(vc.T_0to1, cv.T_0to1)
    assert vc.calibrated == cv.calibrated  # the record it takes, with its calibration
    assert sum("not calibrated" in w for w in vc.warnings) == sum(
        "not calibrated" in w for w in cv.warnings)


@pytest.mark.slow
def test_the_registry_fills_itself_without_the_estimator():
    """Before: the built-in methods were registered by importing the estimator, so the registry
    read alone (``strl_pyg.inference.registry.METHODS``) was empty. Now it holds them from its
    first read, and importing a module registers nothing."""
    import subprocess
    import sys

    code = ("import sys; from strl_pyg.inference.registry import METHODS; "
            "names = list(METHODS); "
            "assert 'strl_pyg.inference.estimator' not in sys.modules, 'estimator imported'; "
            "import strl_pyg.inference.estimator; assert list(METHODS) == names; print(names)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-500:]
    assert out.stdout.split() == ["['regression',", "'opencv',", "'poselib',", "'fused',",
                                  "'geometric',", "'guided',", "'vp',", "'vp_checked']"]


def test_method_names_come_from_the_classes():
    from strl_pyg.inference import methods, policy, registry

    assert [type(m).name for m in registry.METHODS.values()] == list(registry.METHODS)
    assert policy.RECOMMENDED_ORDER == (methods.PoseLib.name, methods.OpenCV.name,
                                        methods.Regression.name)
    assert methods.Classical.of("opencv").label == "OpenCV MAGSAC"


def test_the_docs_table_is_the_registry_table():
    """docs/methods.md's table of the built-in methods is what ``strl-pose methods`` prints
    for them (generated from the classes' attributes, so the two cannot drift)."""
    from pathlib import Path

    from strl_pyg.inference import methods, registry

    text = (Path(__file__).resolve().parents[2] / "docs" / "methods.md").read_text()
    start = text.index("| name | what it is | needs |")
    docs_table = text[start:text.index("\n\n", start)]
    builtin = [m.name for m in methods.builtin_methods()]
    assert docs_table == registry.methods_table(builtin)


PLUGIN = '''
"""A robust solver in one module: OpenCV's essential matrix at a fixed iteration budget."""
import numpy as np

from strl_pyg.estimation.classical import OPENCV, estimate_relative_pose
from strl_pyg.inference.methods import PoseMethod
from strl_pyg.inference.record import MethodResult


class QuickSolver(PoseMethod):
    name = "quick"
    label = "OpenCV, 200 iterations"
    summary = "OpenCV's essential matrix with a fixed budget of 200 RANSAC iterations"

    def __call__(self, matches, ctx):
        res = estimate_relative_pose(matches, OPENCV, ctx.config.threshold_px,
                                     max_iterations=200, seed=ctx.config.seed)
        if not res.success:
            return MethodResult(self.name, "failed", warnings=["quick found no pose"])
        return MethodResult(self.name, "ok", res.pose.matrix().numpy(),
                            num_inliers=res.num_inliers)
'''


@pytest.mark.slow
def test_a_new_solver_is_one_module(tmp_path, plugin_cli, generated_pair):
    """A package that declares one module in the ``strl-pyg.methods`` entry-point group adds
    a solver: ``strl-pose methods`` lists it, ``predict --methods`` runs it, its record is in
    the JSON, support-checked like the built-in solvers."""
    import json

    cli = plugin_cli("quick_solver", PLUGIN, "strl-pyg.methods",
                     "quick = quick_solver:QuickSolver")
    generated_pair(2_000_017).matches.save(tmp_path / "pair.npz")

    listed = cli("methods")
    assert "| `quick` | OpenCV's essential matrix with a fixed budget of 200 RANSAC" in listed
    # asked alone, its record is there; the recommended pose is the measured order's
    # methods' only, so none here (exit 1, and the pose says why)
    record = json.loads(cli("predict", "--matches", str(tmp_path / "pair.npz"), "--methods",
                            "quick", "--json", "--bootstrap", "0", code=1))
    quick = record["methods"]["quick"]
    assert quick["status"] == "ok" and quick["info"]["support_inliers"] > 100
    assert any("none of the recommended methods" in w for w in record["pose"]["warnings"])


def test_a_plugin_that_does_not_load_or_takes_a_name_is_named_and_left_out(monkeypatch):
    """A broken plugin, one named like a built-in, a second plugin of a taken name: each left
    out with a warning naming it (before, a taken name raised while the registry loaded, so
    the package did not import); the valid one is kept."""
    from importlib import metadata

    from strl_pyg.inference import registry
    from strl_pyg.inference.methods import PoseMethod

    def plugin(name):
        return type(f"Plugin_{name}", (PoseMethod,), {"name": name})

    class Entry:
        def __init__(self, name, obj=None, error=None):
            self.name, self.value, self.obj, self.error = name, f"pkg:{name}", obj, error

        def load(self):
            if self.error:
                raise self.error
            return self.obj

    entries = [Entry("broken", error=ImportError("No module named 'nowhere'")),
               Entry("opencv", plugin("opencv")), Entry("mine", plugin("mine")),
               Entry("mine_again", plugin("mine")), Entry("nameless", plugin(""))]
    monkeypatch.setattr(metadata, "entry_points", lambda group: entries)
    with pytest.warns(UserWarning) as record:
        kept = registry._installed_methods()
    assert [m.name for m in kept] == ["mine"]
    text = " | ".join(str(w.message) for w in record)
    for name in ("broken", "opencv", "mine_again", "nameless"):
        assert f"'{name}'" in text, text
    assert "already registered" in text and "another plugin" in text
