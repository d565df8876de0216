"""The inference API (strl_pyg.inference.estimator): one call from matches or images to a pose
record
with a status, every method by name, checkpoint metadata, dtypes, and ``strl-pose predict``."""

import json
import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from strl_pyg import cli
from strl_pyg.data import PairMatches
from strl_pyg.estimation.classical import BaselineResult
from strl_pyg.geometry import Pose
from strl_pyg.inference import (
    METHODS,
    MethodResult,
    forward_pose,
    policy,
    prepare_graph,
    register_method,
)
from strl_pyg.inference import estimator as inference
from strl_pyg.inference import methods as pose_methods
from strl_pyg.inference.estimator import PoseEstimator
from strl_pyg.metrics.two_view import relative_pose_error
from strl_pyg.model import StrLPoseConfig
from strl_pyg.model.strl_pose import StrLPose

REPO_ROOT = Path(__file__).resolve().parents[2]
SEED = 2_000_017  # held out from training
HAVE_POSELIB = METHODS["poselib"].available()
KEYS = {"method", "status", "rule", "T_0to1", "sigma", "sigma_with_focal", "covariance",
        "warnings", "time_ms", "num_inliers", "info", "verdicts", "inliers", "rotation"}

def readme_python_block(must_contain: str) -> str:
    """The first ```python block of README.md that contains ``must_contain``."""
    text = (REPO_ROOT / "README.md").read_text()
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, re.S) if must_contain in b]
    assert blocks, f"no python block with {must_contain!r} in README.md"
    return blocks[0]


# The README's "Using it" snippet, run verbatim (test_readme_snippet_runs_from_another_directory)
SNIPPET = readme_python_block("PoseEstimator")


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def pair(generated_pair):
    return generated_pair(SEED)


@pytest.fixture(scope="module")
def estimate(model, pair):
    return PoseEstimator(model).estimate(pair.matches)


def tiny(**kw):
    return StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=1, **kw))


# ----------------------------------------------------------------------------- checkpoints
def test_from_pretrained_does_not_depend_on_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    m = StrLPose.from_pretrained("synthetic")
    assert not m.training
    md = m.metadata
    assert md["resample"] == [384, 192] and md["patch_channels"] == 1 and md["patch_size"] == 1
    assert "generated" in md["training_data"]
    with pytest.raises(ValueError, match="Expected a pretrained name"):
        StrLPose.from_pretrained("kitti-2030")


def test_metadata_round_trips_through_a_checkpoint(tmp_path):
    m = tiny()
    path = m.save(tmp_path / "m.pt", metadata={"resample": (100, 50), "training_data": "x",
                                               "steps": 10})
    payload = torch.load(path, weights_only=True)
    assert payload["version"] == 2
    md = StrLPose.load(path).metadata
    assert md == {"resample": [100, 50], "patch_channels": 1, "patch_size": 1,
                  "training_data": "x", "steps": 10}


def test_version_1_checkpoints_load_with_documented_defaults(tmp_path):
    m = tiny(visual="pixel")
    payload = {"format": "strl_pyg.StrLPose", "version": 1, "config": m.config.to_dict(),
               "state_dict": m.state_dict()}
    torch.save(payload, tmp_path / "v1.pt")
    md = StrLPose.load(tmp_path / "v1.pt").metadata
    assert md == {"resample": [384, 192], "patch_channels": 1, "patch_size": 1,
                  "training_data": None}
    rgb = StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=27))
    assert (rgb.metadata["patch_channels"], rgb.metadata["patch_size"]) == (3, 3)
    torch.save({**payload, "version": 7}, tmp_path / "v7.pt")
    with pytest.raises(ValueError, match="Expected checkpoint version"):
        StrLPose.load(tmp_path / "v7.pt")


@pytest.mark.parametrize("md, message", [
    ({"resample": [384]}, "resample"),
    ({"patch_channels": 3}, "patch_channels"),
    ({"training_data": 5}, "training_data"),
])
def test_bad_metadata_is_refused(md, message, tmp_path):
    with pytest.raises(ValueError, match=f"Expected metadata '{message}'"):
        tiny().save(tmp_path / "m.pt", metadata=md)


def test_the_graph_follows_the_stored_resample_counts(pair):
    m = tiny()
    m.metadata = {"resample": [50, 20]}
    g = prepare_graph(pair.matches, m)
    assert g["point"].num_nodes == 50 and g["endpoint"].num_nodes == 40
    assert g["point"].patch0.shape == (50, 1)  # grey patches, as the checkpoint stores
    from strl_pyg.evaluation.run import predict_pose

    out = predict_pose(m, pair.matches, resample="model")
    ref = forward_pose(m, g)
    assert torch.equal(out.quaternion, ref.quaternion)


# ----------------------------------------------------------------------------- the estimate
def test_estimate_gives_a_recommended_pose_and_every_method(estimate, pair, model):
    names = ["regression", "opencv"] + (["poselib"] if HAVE_POSELIB else []) + [
        "fused", "geometric", "guided", "vp", "vp_checked"]
    assert list(estimate.methods) == names
    pose = estimate.pose
    assert pose.status == "ok" and not pose.warnings
    assert pose.method == ("poselib" if HAVE_POSELIB else "opencv")
    assert pose.T_0to1.shape == (4, 4) and pose.T_0to1.dtype == np.float64
    np.testing.assert_array_equal(pose.T_0to1, estimate.methods[pose.method].T_0to1)
    R = pose.T_0to1[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert pose.covariance.shape == (5, 5) and set(pose.sigma) == {"rotation_deg",
                                                                   "translation_deg"}
    head = model.config.geometric
    for name, r in estimate.methods.items():
        if name in ("geometric", "guided") and not head:
            # a regression-only checkpoint says so instead of answering
            assert r.status == "failed" and "geometric head" in r.warnings[0]
            continue
        assert r.status == "ok", (name, r.warnings)
        rot, tr = relative_pose_error(r.T_0to1[None], pair.T_0to1[None])
        limit = (2.0, 10.0) if name == "regression" else (0.5, 3.0)
        assert float(rot[0]) < limit[0] and float(tr[0]) < limit[1], name
        assert r.sigma["rotation_deg"] > 0
    assert len(estimate.methods["regression"].info["log_var"]) == 7


def test_identical_images_are_degenerate_not_a_confident_motion(model, pair):
    est = PoseEstimator(model).estimate_images(pair.image0, pair.image0, K0=pair.K)
    assert est.num_points > 100  # the front end matches everything, at zero displacement
    assert est.status == "degenerate" and est.T_0to1 is None and est.pose.method is None
    assert any("zero parallax" in w for w in est.warnings)
    assert all(r.status == "degenerate" and r.T_0to1 is None for r in est.methods.values())


def test_fewer_matches_than_the_solvers_need_is_degenerate(model, pair):
    m = pair.matches
    few = PairMatches(m.points0[:3], m.points1[:3], K0=pair.K, K1=pair.K,
                      image0=pair.image0, image1=pair.image1)
    est = PoseEstimator(model).estimate(few)
    assert est.status == "degenerate" and est.T_0to1 is None
    assert any("too few point matches" in w for w in est.warnings)
    tiny_imgs = PoseEstimator(model).estimate_images(pair.image0[:16, :16],
                                                     pair.image1[:16, :16])
    assert tiny_imgs.status == "degenerate" and tiny_imgs.T_0to1 is None


def test_a_failed_classical_solver_is_failed_and_not_used(model, pair, monkeypatch):
    def no_model(matches, method, *args, **kwargs):
        n = matches.num_points
        return BaselineResult(Pose.identity(), np.zeros(n, bool), 1.0, method, False)

    import strl_pyg.estimation.guided as guided

    monkeypatch.setattr(pose_methods.context, "estimate_relative_pose", no_model)
    monkeypatch.setattr(guided, "estimate_relative_pose", no_model)
    monkeypatch.setattr(guided, "_opencv_prosac", lambda *a, **k: None)
    est = PoseEstimator(model).estimate(pair.matches)
    classical = ["opencv"] + (["poselib"] if HAVE_POSELIB else [])
    for name in classical:
        r = est.methods[name]
        assert r.status == "failed" and r.T_0to1 is None and "found no pose" in r.warnings[0]
    assert est.methods["fused"].status == "failed"
    assert est.methods["guided"].status == "failed"
    # the first method of the recommended order that still answers: a network-only one
    fallback = [m for m in inference.recommended_order(model) if est.methods[m].status == "ok"]
    assert est.status == "ok" and est.pose.method == fallback[0]
    assert fallback[0] in ("geometric", "regression")
    assert any(w.startswith("opencv failed") for w in est.warnings)


def test_all_methods_failing_gives_status_failed(pair, monkeypatch):
    monkeypatch.setattr(pose_methods.context, "estimate_relative_pose",
                        lambda m, method, *a, **k: BaselineResult(
                            Pose.identity(), np.zeros(m.num_points, bool), 1.0, method, False))
    est = PoseEstimator(methods=("opencv",)).estimate(pair.matches)
    assert est.status == "failed" and est.T_0to1 is None and est.to_dict()["pose"]["T_0to1"] is None


def test_one_K_for_images_of_different_sizes_warns(pair):
    big = cv2.resize(pair.image1, (1280, 384), interpolation=cv2.INTER_LINEAR)
    est = PoseEstimator(methods=("opencv",))
    one_K = est.estimate_images(pair.image0, big, K0=pair.K)
    assert any("different sizes" in w for w in one_K.warnings)
    assert one_K.status == "unreliable"  # was "ok" with a tight sigma
    S = np.diag([2.0, 2.0, 1.0])
    S[:2, 2] = 0.5  # x' = 2 (x + 0.5) - 0.5
    own = est.estimate_images(pair.image0, big, K0=pair.K, K1=S @ pair.K)
    assert own.status == "ok" and not own.warnings


@pytest.mark.parametrize("change, message", [
    (lambda K: K.__setitem__((0, 2), 5000.0), "principal point"),
    (lambda K: K.__setitem__((0, 0), 1e5), "focal length"),
    (lambda K: K.__setitem__((1, 1), 10.0), "focal length"),
])
def test_an_implausible_K_warns(pair, change, message):
    K = pair.K.copy()
    change(K)
    est = PoseEstimator(methods=("opencv",)).estimate(replace(pair.matches, K0=K, K1=K))
    assert any(message in w for w in est.warnings), est.warnings


def test_no_intrinsics_gives_no_plain_ok_and_a_fundamental_matrix(model, pair):
    # was: "ok" from the regression, with a sigma calibrated on K-normalised pairs (a
    # Strecha pair without --K: 10.6 deg off, sigma 2.3 deg)
    m = replace(pair.matches, K0=None, K1=None)
    est = PoseEstimator(model).estimate(m)
    assert est.methods["opencv"].status == "failed"
    assert est.status == "unreliable" and est.T_0to1 is None and est.pose.sigma is None
    assert est.methods["regression"].status == "unreliable"
    assert any("no metric pose without intrinsics" in w for w in est.warnings)
    # the route without intrinsics: the fundamental matrix of the pixels, x1^T F x0 = 0
    F = est.pose.info["fundamental_matrix"]
    K, T = pair.K, pair.T_0to1
    t = T[:3, 3]
    E_gt = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ T[:3, :3]
    E = K.T @ F @ K
    E, E_gt = E / np.linalg.norm(E), E_gt / np.linalg.norm(E_gt)
    assert min(np.abs(E - E_gt).max(), np.abs(E + E_gt).max()) < 1e-2
    assert est.pose.info["fundamental_inliers"] > 0.8 * m.num_points
    assert est.to_dict()["pose"]["info"]["fundamental_matrix"] is not None


@pytest.mark.parametrize("dtype, tol", [(torch.bfloat16, 2.0), (torch.float64, 1e-3)])
def test_low_and_high_precision_models_run_on_the_float32_graph(pair, dtype, tol):
    ref = StrLPose.from_pretrained()
    m = StrLPose.from_pretrained().to(dtype)
    g = prepare_graph(pair.matches, m)
    from torch_geometric.data import Batch

    with torch.no_grad():  # the model casts its inputs (used to be a raw dtype error)
        raw = m(Batch.from_data_list([g]))
    assert raw.quaternion.dtype == dtype and torch.isfinite(raw.quaternion.float()).all()
    est = PoseEstimator(m, methods=("regression",)).estimate(pair.matches)
    r = est.methods["regression"]
    assert r.status == "ok" and np.isfinite(r.T_0to1).all()
    base = PoseEstimator(ref, methods=("regression",)).estimate(pair.matches)
    rot, _ = relative_pose_error(r.T_0to1[None], base.methods["regression"].T_0to1[None])
    assert float(rot[0]) < tol


def test_a_model_of_mixed_dtypes_errors_in_one_line(pair):
    m = tiny()
    m.fusion.double()
    with pytest.raises(TypeError, match=r"Expected model parameters of one floating dtype"):
        forward_pose(m, prepare_graph(pair.matches, m))


def test_a_new_method_is_one_registration(pair, monkeypatch, method_registry):
    def identity_guess(matches, context):
        assert "opencv" in context.results  # runs after the ones registered before it
        return MethodResult("guess", "ok", context.results["opencv"].T_0to1)

    # a method that is not support-checked (a learned one) is recommended only where the
    # matches support its pose: this one repeats OpenCV's
    register_method("guess", identity_guess, support_checked=False)
    monkeypatch.setattr(policy, "RECOMMENDED_ORDER", ("guess", "opencv"))
    # a model without a measured order (the shipped one records its own)
    est = PoseEstimator(tiny(), methods=("opencv", "guess")).estimate(pair.matches)
    assert est.pose.method == "guess" and list(est.methods) == ["opencv", "guess"]
    with pytest.raises(ValueError, match="already registered"):
        register_method("guess", identity_guess)


def test_an_unsupported_learned_pose_is_not_recommended(pair, monkeypatch, method_registry):
    """Before: a method without the support check (the network) filled the recommended pose
    with its own pose and status "ok" whatever the matches said."""
    register_method("guess", lambda m, c: MethodResult("guess", "ok", np.eye(4)),
                              support_checked=False)
    monkeypatch.setattr(policy, "RECOMMENDED_ORDER", ("guess",))
    est = PoseEstimator(tiny(), methods=("guess",)).estimate(pair.matches)
    assert est.methods["guess"].status == "ok"  # the method's own record is its answer
    assert est.pose.status == "unreliable" and est.pose.T_0to1 is None
    assert any("stands in for no solver" in w for w in est.pose.warnings)


def test_the_method_registry_order():
    from strl_pyg.inference import registry

    assert list(registry.METHODS) == ["regression", "opencv", "poselib", "fused", "geometric",
                                      "guided", "vp", "vp_checked"]
    assert isinstance(registry.METHODS["fused"], pose_methods.Fused)
    assert [type(s).__name__ for s in registry.METHODS.values()] == [
        "Regression", "OpenCV", "PoseLib", "Fused", "Geometric", "Guided", "VanishingPoint",
        "VanishingPointChecked"]


def test_method_results_hold_a_pose_only_when_ok():
    assert MethodResult("x", "failed", np.eye(4)).T_0to1 is None
    with pytest.raises(ValueError, match="Expected a finite T_0to1"):
        MethodResult("x", "ok", None)
    with pytest.raises(ValueError, match="Expected status"):
        MethodResult("x", "fine", np.eye(4))
    # "unreliable": no pose either; the computed one stays in info, for inspection only
    assert MethodResult("x", "unreliable", np.eye(4), np.eye(5)).sigma is None
    marked = MethodResult("x", "ok", np.eye(4), np.eye(5)).unreliable(["why"], rule="mine",
                                                                      evidence={"n": 3})
    assert marked.status == "unreliable" and marked.T_0to1 is None and marked.sigma is None
    assert marked.rule == "mine" and marked.verdicts[-1].evidence == {"n": 3}
    assert marked.to_dict()["rule"] == "mine"
    assert marked.to_dict()["verdicts"][0]["action"] == "refused"
    assert marked.info["unreliable"] == ["why"] and "why" in marked.warnings
    np.testing.assert_array_equal(marked.info["unreliable_T_0to1"], np.eye(4))
    again = marked.unreliable(["and this"], rule="theirs")
    assert again.info["unreliable"] == ["why", "and this"] and "unreliable_T_0to1" in again.info
    assert again.rule == "theirs" and [v.rule for v in again.verdicts] == ["mine", "theirs"]
    assert MethodResult("x", "ok", np.eye(4)).rule is None


def test_to_dict_is_json_with_the_documented_keys(estimate):
    d = json.loads(json.dumps(estimate.to_dict(), allow_nan=False))
    assert set(d) == {"pose", "methods", "num_points", "num_lines", "two_view"}
    assert d["two_view"]["configuration"] == "general"
    assert set(d["pose"]) == KEYS and np.asarray(d["pose"]["T_0to1"]).shape == (4, 4)
    assert all(set(v) == KEYS for v in d["methods"].values())


# ----------------------------------------------------------------------------- command line
@pytest.fixture(scope="module")
def pngs(pair, tmp_path_factory):
    d = tmp_path_factory.mktemp("imgs")
    for name, img in (("a.png", pair.image0), ("b.png", pair.image1)):
        cv2.imwrite(str(d / name), img)
    cv2.imwrite(str(d / "big.png"), cv2.resize(pair.image1, (1280, 384)))
    K = pair.K
    return d, f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}"


@pytest.mark.slow  # images to every method through the command line: the fast tier's JSON
# guards are test_to_dict_is_json_with_the_documented_keys and (images, --json)
# tests/cli/test_cli.py::test_the_default_predict_does_not_build_the_network
def test_predict_json_round_trips_with_the_pose_record(pngs, capsys):
    d, K = pngs
    code = cli.main(["predict", str(d / "a.png"), str(d / "b.png"), "--K", K, "--json",
                     "--methods", "all"])  # every method (the default stops at the first ok)
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert set(out["pose"]) == KEYS and out["pose"]["status"] == "ok"
    assert out["pose"]["method"] == ("poselib" if HAVE_POSELIB else "opencv")
    assert np.asarray(out["pose"]["T_0to1"]).shape == (4, 4)
    assert set(out["pose"]["sigma"]) == {"rotation_deg", "translation_deg"}
    assert {"regression", "opencv", "fused"} <= set(out["methods"])
    assert out["translation_kind"] == "direction" and out["intrinsics"] is True


def test_predict_identical_images_is_degenerate_with_exit_status_1(pngs, capsys):
    d, K = pngs
    code = cli.main(["predict", str(d / "a.png"), str(d / "a.png"), "--K", K, "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["pose"]["status"] == "degenerate" and out["pose"]["T_0to1"] is None


def test_predict_text_says_status_method_and_warnings(pngs, capsys):
    d, K = pngs
    code = cli.main(["predict", str(d / "a.png"), str(d / "big.png"), "--K", K,
                     "--methods", "all"])
    out = capsys.readouterr().out
    # one K for two image sizes: a pose to look at, not to use (exit code 3)
    assert code == 3 and re.search(r"pose: unreliable, no pose given .* (poselib|opencv) ", out)
    assert "warning: the images have different sizes" in out and "regression" in out
    code = cli.main(["predict", str(d / "a.png"), str(d / "b.png"), "--K", K])
    out = capsys.readouterr().out
    assert code == 0 and re.search(r"pose: ok, from (poselib|opencv)", out)
    # the sigma line names the covariance it prints (before: always "1st order", also for
    # the first-order + bootstrap ones)
    assert "sigma (first-order + bootstrap (8), calibrated): rotation" in out


# ----------------------------------------------------------------------------- README
@pytest.mark.slow
def test_readme_snippet_runs_from_another_directory(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    res = subprocess.run([sys.executable, "-c", SNIPPET], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.splitlines()
    assert lines[0].startswith("ok ") and lines[-2] == "ok"  # the regression's status
    # the recommended pose alone: the same method, and only what it needs ran
    method = lines[0].split()[1]
    assert lines[-1] == f"{method} {[method]}", lines[-1]


@pytest.mark.parametrize("row", ["baseline", "LP", "R", "LP+V", "full"])
def test_forward_pose_of_one_graph_equals_the_batch_of_it(pair, row):
    from torch_geometric.data import Batch

    from strl_pyg.model import ABLATIONS

    torch.manual_seed(0)
    m = tiny(**ABLATIONS[row])
    g = prepare_graph(pair.matches, m, resample=(48, 16))
    a = forward_pose(m, g)  # one graph straight in (no Batch.from_data_list)
    b = forward_pose(m, Batch.from_data_list([g]))
    for x, y in ((a.quaternion, b.quaternion), (a.translation, b.translation),
                 (a.log_var, b.log_var)):
        torch.testing.assert_close(x, y, rtol=1e-5, atol=1e-6)
    # a float64 model casts a copy: the caller's graph (or batch, which was cast in place
    # before) keeps its float32 tensors
    bb = Batch.from_data_list([g])

    def tensors(graph):
        return {(i, k): v.clone() for i, store in enumerate(graph.stores)
                for k, v in store.items() if torch.is_tensor(v)}

    before = {id(g): tensors(g), id(bb): tensors(bb)}
    assert any(v.dtype == torch.float32 for v in before[id(g)].values())
    m.double()
    assert forward_pose(m, g).quaternion.dtype == torch.float64
    assert forward_pose(m, bb).quaternion.dtype == torch.float64
    for graph in (g, bb):
        after = tensors(graph)
        assert after.keys() == before[id(graph)].keys()
        for k, v in before[id(graph)].items():
            assert after[k].dtype == v.dtype and torch.equal(after[k], v), k


def test_a_record_keeps_the_methods_pose_object(monkeypatch, generated_pair):
    """Poses went Pose -> 4x4 -> Pose between a method and the support check (10
    Pose.from_matrix calls on `predict --methods all`); a record now keeps the method's Pose."""
    import numpy as np
    import torch

    from strl_pyg.geometry import Pose
    from strl_pyg.inference.record import MethodResult
    from strl_pyg.inference.support import check_support
    from strl_pyg.synthetic import SceneConfig

    pair = generated_pair(5, SceneConfig(kind="indoor", noise_px=0.5))
    T = np.asarray(pair.T_0to1, dtype=np.float64)
    t = T[:3, 3] / np.linalg.norm(T[:3, 3])
    pose = Pose(torch.from_numpy(T[:3, :3]), torch.from_numpy(t))
    rec = MethodResult("poselib", "ok", pose)
    assert isinstance(rec.T_0to1, np.ndarray) and rec.T_0to1.shape == (4, 4)
    np.testing.assert_array_equal(rec.T_0to1, pose.matrix().numpy())
    assert rec.as_pose() is not None and torch.equal(rec.as_pose().R, pose.R)
    calls = []
    real = Pose.from_matrix.__func__
    monkeypatch.setattr(Pose, "from_matrix",
                        classmethod(lambda cls, T: calls.append(1) or real(cls, T)))
    checked = check_support(rec, pair.matches, 1.0)
    assert checked.status == "ok" and checked.info["support_inliers"] > 0 and calls == []
    # a record given as a matrix, or whose T_0to1 was set anew, builds its Pose from it once
    moved = T.copy()
    moved[:3, 3] = -t
    rec.T_0to1 = moved
    assert torch.equal(rec.as_pose().t, torch.from_numpy(-t)) and len(calls) == 1
    assert MethodResult("x", "failed", pose).as_pose() is None
    # found in review: the record shared the caller's tensors, and an edit of T_0to1 in place
    # went unseen
    R = torch.from_numpy(T[:3, :3].copy())
    own = MethodResult("x", "ok", Pose(R, torch.from_numpy(t)))
    R[0, 0] = 5.0
    assert float(own.as_pose().R[0, 0]) == float(own.T_0to1[0, 0]) != 5.0
    own.T_0to1[0, 3] = 5.0
    assert float(own.as_pose().t[0]) == 5.0
    with pytest.raises(ValueError, match="Expected one pose"):
        MethodResult("x", "ok", Pose(pose.R.expand(2, 3, 3), pose.t.expand(2, 3)))


def _pm(pair, p0, p1, **kw):
    return PairMatches(p0, p1, K0=pair.K, K1=pair.K, image_size0=pair.image0.shape[:2],
                       image_size1=pair.image1.shape[:2], **kw)


def _pm_with_lines(pair, **kw):
    m = pair.matches
    return PairMatches(m.points0, m.points1, m.lines0, m.lines1, K0=pair.K, K1=pair.K,
                       image_size0=pair.image0.shape[:2], image_size1=pair.image1.shape[:2],
                       **kw)


@pytest.mark.parametrize("unique, times", [(1, 100), (3, 30)])
def test_repeated_matches_are_one_correspondence(pair, unique, times):
    """Before: one match x100 -> 'ok' from poselib, sigma 0.002 deg, 124 / 175 deg wrong;
    3 unique x30 -> 'ok', 9 / 92 deg wrong."""
    m = pair.matches
    p0 = np.tile(m.points0[:unique], (times, 1))
    p1 = np.tile(m.points1[:unique], (times, 1))
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, p0, p1))
    assert est.status == "degenerate" and est.T_0to1 is None
    assert any(f"{unique * times - unique} repeated point matches removed" in w
               for w in est.warnings)
    assert est.num_points == unique


def test_repeating_every_match_does_not_shrink_sigma(pair):
    """Before: every match x5 shrank sigma by ~sqrt(5)."""
    m = pair.matches
    once = PoseEstimator(methods="poselib").estimate(_pm(pair, m.points0, m.points1))
    five = PoseEstimator(methods="poselib").estimate(
        _pm(pair, np.tile(m.points0, (5, 1)), np.tile(m.points1, (5, 1))))
    assert once.status == five.status == "ok"
    np.testing.assert_allclose(five.pose.covariance, once.pose.covariance, rtol=1e-9)
    assert five.pose.inliers.shape == (5 * m.num_points,)
    np.testing.assert_array_equal(five.pose.inliers, np.tile(once.pose.inliers, 5))


def test_the_inlier_mask_marks_an_outlier_per_input_row(pair):
    m = pair.matches
    p1 = m.points1.copy()
    p1[10] += 40.0
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, m.points0, p1))
    assert est.pose.inliers.dtype == bool and est.pose.inliers.shape == (m.num_points,)
    assert not est.pose.inliers[10] and est.pose.inliers.sum() >= m.num_points - 3
    assert len(est.to_dict()["pose"]["inliers"]) == m.num_points


def test_normalised_coordinates_with_a_pixel_K_are_named(pair):
    """Before: 'degenerate', 'zero parallax'."""
    m = pair.matches
    Ki = np.linalg.inv(pair.K)
    n0 = (np.c_[m.points0, np.ones(m.num_points)] @ Ki.T)[:, :2]
    n1 = (np.c_[m.points1, np.ones(m.num_points)] @ Ki.T)[:, :2]
    keep = (n0.min(1) > -3) & (n1.min(1) > -3)  # the in-image check allows 4 px outside
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, n0[keep], n1[keep]))
    assert est.status == "degenerate"
    assert any("Expected pixel coordinates" in w and "from_normalized" in w
               for w in est.warnings)
    pm = PairMatches.from_normalized(n0, n1, pair.K, pair.K, pair.image0.shape[:2],
                                     pair.image1.shape[:2])
    np.testing.assert_allclose(pm.points0, m.points0, atol=1e-9)
    assert PoseEstimator(methods="poselib").estimate(pm).status == "ok"
    with pytest.raises(ValueError, match="Expected K0 and K1"):
        PairMatches.from_normalized(n0, n1, None, None, (10, 10), (10, 10))


def test_methods_that_read_images_are_skipped_without_them(pair):
    """Before: 'failed' (found no pose) for the network's methods on a match file without
    images; they did not run at all."""
    no_images = replace(pair.matches, image0=None, image1=None,
                        image_size0=pair.image0.shape[:2], image_size1=pair.image1.shape[:2])
    est = PoseEstimator(methods=("regression", "poselib", "fused"), bootstrap=0).estimate(
        no_images)
    reg, fused = est.methods["regression"], est.methods["fused"]
    assert reg.status == fused.status == "skipped" and reg.T_0to1 is None
    assert "attach them" in reg.warnings[0] and "visual='pixel'" in reg.warnings[0]
    assert est.status == "ok" and est.pose.method == "poselib"
    with_images = PoseEstimator(methods="regression", bootstrap=0).estimate(pair.matches)
    assert with_images.methods["regression"].status == "ok"


def test_the_fundamental_inlier_mask_follows_the_input_rows(pair):
    """Before: with repeated matches the mask had one entry per distinct match, not per input
    row as every other mask of the record."""
    m = pair.matches
    twice = PairMatches(np.tile(m.points0, (2, 1)), np.tile(m.points1, (2, 1)),
                        image_size0=m.image_size0, image_size1=m.image_size1)
    est = PoseEstimator(methods="poselib").estimate(twice)
    mask = est.pose.info["fundamental_inlier_mask"]
    assert mask.shape == (2 * m.num_points,) and mask.dtype == bool
    np.testing.assert_array_equal(mask[:m.num_points], mask[m.num_points:])
    assert est.pose.info["fundamental_inliers"] == int(mask[:m.num_points].sum())


def test_inliers_of_matches_index_the_matches_the_methods_ran_on(pair):
    m = pair.matches
    idx = np.r_[np.arange(m.num_points), np.arange(10)]
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, m.points0[idx], m.points1[idx]))
    assert est.status == "ok" and est.matches.num_points == m.num_points
    np.testing.assert_array_equal(est.point_rows, np.r_[np.arange(m.num_points),
                                                        np.arange(10)])
    on_matches = est.inliers_of_matches()
    assert on_matches.shape == (m.num_points,)
    np.testing.assert_array_equal(on_matches[est.point_rows], est.pose.inliers)


def test_the_point_poor_regime_counts_distinct_matches(pair, monkeypatch):
    """Before: the recommended order read num_points (rows, one-to-many included) while the
    methods' minimum counts read the distinct ones."""
    import strl_pyg.inference.pick as pick

    m = pair.matches
    # 25 distinct correspondences, then 15 rows reusing keypoints of image 1 (one-to-many)
    p0 = np.r_[m.points0[:25], m.points0[25:40]]
    p1 = np.r_[m.points1[:25], m.points1[:15]]
    pm = _pm(pair, p0, p1)
    assert pm.num_points == 40 and pm.num_distinct_points == 25
    seen = []
    real = pick.recommended_order
    monkeypatch.setattr(pick, "recommended_order",
                        lambda model, n=None: seen.append(n) or real(model, n))
    PoseEstimator(methods="poselib").estimate(pm)
    assert seen == [25]


def test_own_checkpoint_keeps_poselib_calibrated(pair, tmp_path):
    """Before: `--checkpoint runs/tiny/model.pt` (a 20-step run, no --calibrate) shrank
    PoseLib's sigma on a KITTI pair from 0.027 / 0.334 to 0.006 / 0.077 deg (its error
    0.14 / 0.59): PoseLib's calibration was read from the given checkpoint, which has none.
    PoseLib's covariance does not read the network: the shipped scale applies."""
    own = StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2))
    path = tmp_path / "own.pt"
    own.save(path)
    m = _pm_with_lines(pair)
    shipped = PoseEstimator(methods="poselib").estimate(m).pose
    mine = PoseEstimator(path, methods="poselib").estimate(m).pose
    assert shipped.status == mine.status == "ok"
    np.testing.assert_allclose(mine.covariance, shipped.covariance, rtol=1e-9)
    assert mine.info["calibration_from"] == "shipped"
    assert "calibration_from" not in shipped.info
    # a checkpoint that says "calibration: none yet" (benchmarks/bench_pose.py --calibrate
    # while it fits) gets the raw covariance: the fit must not read the shipped scale
    own.metadata = {**own.metadata, "calibration": {}}
    # (the focal sensitivity, added after the calibration, is left out of this comparison)
    raw = PoseEstimator(own, methods="poselib", focal_sensitivity=False).estimate(m).pose
    scaled = PoseEstimator(methods="poselib", focal_sensitivity=False).estimate(m).pose
    assert "calibration_scale" not in raw.info
    np.testing.assert_allclose(raw.covariance * scaled.info["calibration_scale"],
                               scaled.covariance, rtol=1e-9)
    # a method that reads the network keeps only the checkpoint's own scale: none here
    reg = PoseEstimator(own, methods="regression").estimate(
        _pm_with_lines(pair, image0=pair.image0, image1=pair.image1)).methods["regression"]
    assert "calibration_scale" not in reg.info
    assert any("regression: covariance not calibrated" in w for w in reg.warnings)


def test_uncalibrated_sigma_is_named_in_the_python_record(pair):
    """Before: `vp`'s covariance is not calibrated (docs/methods.md said "the pose's
    warnings say so"), yet `est.pose.warnings == []`: only the CLI printed it."""
    est = PoseEstimator(methods=("poselib", "vp")).estimate(_pm_with_lines(pair))
    vp = est.methods["vp"]
    assert vp.status == "ok" and "calibration_scale" not in vp.info
    assert any(w.startswith("vp: covariance not calibrated") for w in vp.warnings)
    assert not any("not calibrated" in w for w in est.methods["poselib"].warnings)
    # vp_checked carries a classical record's calibrated covariance: no such warning
    # (found in review)
    chk = PoseEstimator(methods=("poselib", "vp", "vp_checked")).estimate(
        _pm_with_lines(pair)).methods["vp_checked"]
    assert chk.info.get("calibration_scale") is not None  # PoseLib's record, kept here
    assert not any("not calibrated" in w for w in chk.warnings)

