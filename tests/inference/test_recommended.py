"""strl-pose predict's default: the recommended pose with only the methods (and the line
matching) it needs, equal to the pose of the run of every method."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from strl_pyg.frontend import FrontendConfig, match_images
from strl_pyg.inference import methods_needed
from strl_pyg.inference.estimator import PoseEstimator
from strl_pyg.inference.methods import FunctionMethod
from strl_pyg.inference.recommended import estimate_methods, estimate_recommended
from strl_pyg.synthetic import SceneConfig


@pytest.fixture(scope="module")
def model():
    from strl_pyg.model.strl_pose import StrLPose

    return StrLPose.from_pretrained()


@pytest.fixture(scope="module")
def pair(generated_pair):
    return generated_pair(3, SceneConfig(kind="street", image_size=(192, 320)))


def _with_order(model, order):
    m = copy.copy(model)  # shares the weights; only the metadata differs
    m.metadata = {**model.metadata, "recommended_order": list(order)}
    return m


def test_points_only_front_end(generated_pair):
    p = generated_pair(0, SceneConfig(kind="street", image_size=(192, 320)))
    full = match_images(p.image0, p.image1)
    pts = match_images(p.image0, p.image1, config=FrontendConfig(lines=False))
    assert full.num_lines > 0 and pts.num_lines == 0
    assert pts.info["lines_status"].startswith("skipped") and pts.info["segments0"] == 0
    np.testing.assert_array_equal(pts.points1, full.points1)  # points do not depend on lines


@pytest.mark.parametrize("order", [
    None,  # the shipped order: the fast tier's case
    # other orders run the front end and every method again (~3 s each): the slow tier
    pytest.param(("fused", "opencv"), marks=pytest.mark.slow),
    pytest.param(("geometric", "regression"), marks=pytest.mark.slow),
])
def test_same_pose_as_every_method(model, pair, order):
    mdl = model if order is None else _with_order(model, order)
    lazy = estimate_recommended(mdl, pair.image0, pair.image1, pair.K, pair.K)
    full = PoseEstimator(mdl).estimate_images(pair.image0, pair.image1, pair.K, pair.K)
    assert lazy.status == full.status == "ok" and lazy.pose.method == full.pose.method
    np.testing.assert_allclose(lazy.T_0to1, full.T_0to1, atol=1e-9)
    chosen = lazy.pose.method
    assert set(methods_needed([chosen])) <= set(lazy.methods)
    assert set(lazy.methods) < set(full.methods)
    reads_lines = any(m in ("regression", "geometric", "guided", "fused") for m in lazy.methods)
    assert (lazy.num_lines > 0) == reads_lines and full.num_lines > 0


def test_few_points_put_the_line_solver_first_with_the_same_pose(model, generated_pair):
    """At most 30 point matches (the front end limited to 40 keypoints): the lazy path matches
    the points first, then the lines for vp, and gives the pose of the run of every method."""
    import torch

    import strl_pyg.frontend as frontend
    from strl_pyg.frontend import pipeline
    from strl_pyg.geometry.pose import rotation_angle_deg
    from strl_pyg.inference import POINT_POOR_MAX_POINTS

    p = generated_pair(2, SceneConfig(kind="street", image_size=(240, 320)))
    cfg = FrontendConfig.preset("legacy", max_keypoints=40)
    calls = []
    real = pipeline.match_images

    def counted(*a, **k):
        calls.append(k.get("config", a[4] if len(a) > 4 else None))
        return real(*a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(frontend, "match_images", counted)
        lazy = estimate_recommended(model, p.image0, p.image1, p.K, p.K, cfg)
    assert len(calls) == 1  # one pass per pair: the lines join the points (was 2 passes)
    full = PoseEstimator(model).estimate_images(p.image0, p.image1, p.K, p.K, cfg)
    assert lazy.num_points <= POINT_POOR_MAX_POINTS and lazy.num_lines > 0
    assert lazy.pose.method == full.pose.method == "vp" and lazy.status == "ok"
    np.testing.assert_allclose(lazy.T_0to1, full.T_0to1, atol=1e-9)
    assert set(lazy.methods) < set(full.methods)
    R = np.asarray(p.T_0to1, float)[:3, :3]
    err = float(rotation_angle_deg(torch.from_numpy(np.asarray(lazy.T_0to1)[:3, :3].T @ R)))
    assert err < 2.0, err


def test_default_order_runs_the_classical_solver_only(model, pair):
    est = estimate_recommended(model, pair.image0, pair.image1, pair.K, pair.K)
    assert list(est.methods) == [model.metadata["recommended_order"][0]]


def test_methods_argument(model, pair):
    est = estimate_methods(model, pair.image0, pair.image1, pair.K, pair.K, FrontendConfig(),
                           "regression, opencv")
    assert list(est.methods) == ["regression", "opencv"]
    with pytest.raises(ValueError, match="Expected methods from"):
        estimate_methods(model, pair.image0, pair.image1, pair.K, pair.K, FrontendConfig(),
                         "nope")
    with pytest.raises(TypeError, match="Expected a FrontendConfig"):
        estimate_recommended(model, pair.image0, pair.image1, pair.K, pair.K, {})


def test_no_matches_is_degenerate(model):
    black = np.zeros((96, 128), np.uint8)
    est = estimate_recommended(model, black, black)
    assert est.status == "degenerate" and est.T_0to1 is None


def test_without_poselib_opencv_takes_its_place_and_the_record_says_so(monkeypatch, generated_pair):
    """Found by a newcomer trial: a plain `pip install -e .` has no PoseLib, and the shipped
    order ['poselib', 'fused', ...] then recommended `fused` (measured with PoseLib as its base,
    and within the noise of PoseLib on the calibration pairs) without a word."""
    from strl_pyg import inference
    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.synthetic import SceneConfig

    model = StrLPose.from_pretrained()
    assert model.metadata["recommended_order"][0] == "poselib"
    spec = inference.METHODS["poselib"]
    monkeypatch.setitem(inference.METHODS, "poselib",
                        FunctionMethod.like(spec, available=lambda: False))
    order = inference.recommended_order(model)
    assert order[0] == "opencv" and "poselib" not in order and order.count("opencv") == 1
    rest = [m for m in model.metadata["recommended_order"] if m not in ("poselib", "opencv")]
    assert [m for m in order if m != "opencv"] == rest
    pair = generated_pair(2_000_001, SceneConfig(kind="indoor", noise_px=0.5))
    est = inference.PoseEstimator(model).estimate(pair.matches)
    assert est.pose.status == "ok" and est.pose.method == "opencv"
    assert inference.POSELIB_MISSING in est.pose.warnings
    # guided and fused run on OpenCV here: their PoseLib-fitted scales are not applied
    for name in ("guided", "fused"):
        rec = est.methods[name]
        assert rec.status == "ok" and rec.covariance is not None
        assert "calibration_scale" not in rec.info
        assert any("PoseLib as its classical base" in w for w in rec.warnings)
    assert est.methods["opencv"].info["calibration_scale"] == \
        model.metadata["calibration"]["opencv"]
    # an uncalibrated model (no measured order) falls back quietly, as before
    plain = StrLPose(model.config)
    assert inference.recommended_order(plain)[0] == "opencv"
    est = inference.PoseEstimator(plain, methods=["opencv"]).estimate(pair.matches)
    assert inference.POSELIB_MISSING not in est.pose.warnings


def test_the_recommended_path_runs_each_method_at_most_once(model, pair, monkeypatch):
    """Before, every prefix of the order got a fresh PoseEstimator that re-ran the methods of
    the earlier prefixes (fused failing -> regression and opencv ran again for 'opencv')."""
    from strl_pyg.inference import METHODS
    from strl_pyg.inference.methods import FunctionMethod
    from strl_pyg.inference.record import MethodResult

    calls: dict[str, int] = {}

    def counted(name, fn):
        def run(matches, ctx):
            calls[name] = calls.get(name, 0) + 1
            if name == "fused":  # planted failure: the path moves on to the next method
                return MethodResult("fused", "failed", warnings=["planted"])
            return fn(matches, ctx)
        return run

    for name, spec in list(METHODS.items()):
        monkeypatch.setitem(METHODS, name, FunctionMethod.like(spec, counted(name, spec)))
    mdl = _with_order(model, ("fused", "opencv"))
    est = estimate_recommended(mdl, pair.image0, pair.image1, pair.K, pair.K)
    assert est.status == "ok" and est.pose.method == "opencv"
    assert calls.get("fused") == 1 and calls.get("opencv") == 1, calls
    assert max(calls.values()) == 1, calls


# ----------------------------------------------------------------------------- one pass per pair
def _counting(monkeypatch, module, name):
    """Counts the calls of ``module.name`` (patched where it is defined)."""
    calls = []
    real = getattr(module, name)

    def counted(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(module, name, counted)
    return calls


def test_a_pair_is_normalised_once_on_the_default_path(model, pair, monkeypatch):
    """Before, the classical solve, its covariance, its bootstrap and the support check each
    normalised the pair again (8 normalize_points calls on every default predict)."""
    from strl_pyg.estimation import classical
    from strl_pyg.inference.registry import classical_method

    m = match_images(pair.image0, pair.image1, pair.K, pair.K, FrontendConfig(lines=False))
    calls = _counting(monkeypatch, classical, "normalize_points")
    est = PoseEstimator(model, methods=classical_method(), bootstrap=8,
                        focal_sensitivity=False).estimate(m)
    rec = est.methods[classical_method()]
    assert rec.status == "ok" and "bootstrap (8)" in rec.info["covariance"]
    # PoseLib: the pair's one normalisation (one call per image); OpenCV solves in pixels
    # and normalises image 1's points of each of its 8 bootstrap resamples itself; the
    # MULTIPLE check solves the matches the pose leaves out (other arrays: one more each)
    second = 2 if est.geometry.second_motion_inliers or _outliers_checked(est) else 0
    assert len(calls) == (2 if classical_method() == "poselib" else 3 + 8) + second, len(calls)
    # the focal sensitivity solves the pair at two other K: two images each, once
    calls.clear()
    PoseEstimator(model, methods=classical_method(), bootstrap=8).estimate(m)
    assert len(calls) == (2 if classical_method() == "poselib" else 3 + 8) + second + 4


def _outliers_checked(est) -> bool:
    """Whether the MULTIPLE check had enough of the pose's outliers to solve them."""
    from strl_pyg.inference.evidence import MULTIPLE_MIN_INLIERS, MULTIPLE_SHARE

    inl = est.pose.inliers
    if inl is None:
        return False
    inl = np.asarray(inl, bool)
    need = max(MULTIPLE_MIN_INLIERS, MULTIPLE_SHARE * int(inl.sum()), 8)
    return int((~inl).sum()) >= need


def test_the_recommended_path_checks_a_point_poor_pair_once(model, monkeypatch, generated_pair):
    """The point-poor pair used to be checked (deduplicated, intrinsics) once per method
    tried: with vp not "ok", again for PoseLib, the next of the order."""
    from strl_pyg.data.matches import PairMatches
    from strl_pyg.inference import estimator
    from strl_pyg.inference.record import MethodResult

    p = generated_pair(2, SceneConfig(kind="street", image_size=(240, 320)))
    monkeypatch.setitem(estimator.METHODS, "vp", FunctionMethod.like(
        estimator.METHODS["vp"], lambda m, ctx: MethodResult("vp", "failed",
                                                             warnings=["planted"])))
    dedup = _counting(monkeypatch, PairMatches, "deduplicated")
    from strl_pyg.inference import pair as pair_run

    problems = _counting(monkeypatch, pair_run, "intrinsics_problems")
    est = estimate_recommended(model, p.image0, p.image1, p.K, p.K,
                               FrontendConfig.preset("legacy", max_keypoints=40))
    assert est.methods["vp"].status == "failed" and est.num_lines > 0
    from strl_pyg.inference.registry import classical_method

    assert est.pose.method == classical_method() and est.status == "ok"
    assert len(dedup) == 1 and len(problems) == 1, (len(dedup), len(problems))


def test_recommended_is_a_methods_value_of_the_estimator(model, pair):
    """The recommended walk on given matches: the pose of the run of every method, with only
    the methods it needs; 'recommended' is no method name."""
    from strl_pyg.inference import RECOMMENDED, register_method
    from strl_pyg.inference.config import EstimatorConfig

    m = match_images(pair.image0, pair.image1, pair.K, pair.K)
    lazy = PoseEstimator(model, methods=RECOMMENDED).estimate(m)
    full = PoseEstimator(model).estimate(m)
    assert lazy.pose.method == full.pose.method and lazy.status == "ok"
    np.testing.assert_allclose(lazy.T_0to1, full.T_0to1, atol=1e-12)
    assert set(lazy.methods) < set(full.methods)
    assert EstimatorConfig(methods="recommended").methods == RECOMMENDED
    with pytest.raises(ValueError, match="other than 'recommended'"):
        register_method("recommended", lambda matches, ctx: None)


def test_lines_join_a_pair_without_its_check_or_its_point_results_again(model, pair):
    """PairRun.add_lines: the points' results stay, repeated line matches count once, other
    points are refused."""
    from strl_pyg.frontend.pipeline import add_lines
    from strl_pyg.inference.registry import classical_method
    from strl_pyg.inference.running import run_methods

    cfg = FrontendConfig(lines=False)
    pts = match_images(pair.image0, pair.image1, pair.K, pair.K, cfg)
    lined = add_lines(pts, FrontendConfig())
    assert lined.num_lines > 0
    est = PoseEstimator(model)
    run = est._pair(pts)
    run_methods(run, (classical_method(),))
    kept = run.ctx.results[classical_method()]
    twice = lined.select(None, np.r_[np.arange(lined.num_lines), 0])  # one line match twice
    points = run.matches.points0
    run.add_lines(twice)
    assert run.matches.num_lines == lined.num_lines
    assert any("1 repeated line matches removed" in w for w in run.warnings)
    assert run.ctx.results[classical_method()] is kept
    assert run.matches.points0 is points  # the same arrays: their normalisation is reused
    with pytest.raises(ValueError, match="Expected the pair's [0-9]+ point matches"):
        run.add_lines(lined.select(np.arange(1, lined.num_points)))


def test_the_walk_gives_the_full_runs_pose_when_the_regression_stands_in(model, pair,
                                                                         monkeypatch):
    """Found in review: the walk stopped at a regression it then refused (no supported solver
    yet), where running every method lets a supported solver outside the order (vp) keep it."""
    import torch

    from strl_pyg.geometry import Pose
    from strl_pyg.inference import estimator
    from strl_pyg.inference.record import MethodResult

    T = np.asarray(pair.T_0to1, dtype=np.float64)
    true = Pose(torch.from_numpy(T[:3, :3]), torch.from_numpy(T[:3, 3] / np.linalg.norm(T[:3, 3])))

    def planted(name):
        if name in ("regression", "vp"):
            return lambda m, ctx: MethodResult(name, "ok", true)
        if name in ("poselib", "opencv"):
            return lambda m, ctx: MethodResult(name, "failed", unsupported=True)
        return lambda m, ctx: MethodResult(name, "failed", warnings=["planted"])

    for name, spec in list(estimator.METHODS.items()):
        monkeypatch.setitem(estimator.METHODS, name, FunctionMethod.like(spec, planted(name)))
    mdl = _with_order(model, ("poselib", "regression"))
    full = PoseEstimator(mdl).estimate(pair.matches)
    lazy = PoseEstimator(mdl, methods="recommended").estimate(pair.matches)
    assert full.status == "ok" and full.pose.method == "regression"
    assert lazy.status == "ok" and lazy.pose.method == "regression", lazy.pose.warnings
    np.testing.assert_array_equal(lazy.T_0to1, full.T_0to1)


def test_known_results_are_taken_by_the_recommended_walk(model, pair, monkeypatch):
    from strl_pyg.inference import estimator
    from strl_pyg.inference.registry import classical_method

    m = match_images(pair.image0, pair.image1, pair.K, pair.K, FrontendConfig(lines=False))
    first = PoseEstimator(model, methods="recommended").estimate(m)
    base = classical_method()
    assert first.pose.method == base
    spec = estimator.METHODS[base]
    monkeypatch.setitem(estimator.METHODS, base, FunctionMethod.like(
        spec, lambda *a: (_ for _ in ()).throw(AssertionError("ran again"))))
    again = PoseEstimator(model, methods="recommended").estimate(
        m, known={base: first.methods[base]})
    np.testing.assert_array_equal(again.T_0to1, first.T_0to1)
    walk = PoseEstimator(model, methods="recommended")
    assert isinstance(walk.method_names, tuple) and base in walk.method_names
    with pytest.raises(ValueError, match="Expected no methods for estimate_recommended"):
        estimate_recommended(model, pair.image0, pair.image1, pair.K, pair.K,
                             methods=("opencv",))


def test_the_normalisation_memo_hands_out_copies(generated_pair):
    """Found in review: a method writing into the normalised points changed every later
    method's input inside the pair's scope."""
    from strl_pyg.estimation.classical import normalisation_scope, normalised_matches

    p = generated_pair(1, SceneConfig(kind="indoor"))
    m = p.matches
    ref0, ref1, ref_f = normalised_matches(m)  # the reference path: no scope, no memo
    with normalisation_scope() as memo:
        x0, _, _ = normalised_matches(m)
        x0 *= 100.0
        again, again1, again_f = normalised_matches(m)
        assert len(memo) == 1
    assert torch_equal(again, ref0) and torch_equal(again1, ref1) and again_f == ref_f
    own: dict = {}
    with normalisation_scope(), normalisation_scope(own):  # an explicit memo is its own
        normalised_matches(m)
    assert len(own) == 1


def torch_equal(a, b) -> bool:
    import torch

    return bool(torch.equal(a, b))


def test_decisions_read_typed_fields_not_info_keys(monkeypatch, generated_pair):
    """A method that raises is ``failed`` with ``raised`` set (and ``info["raised"]`` in the
    JSON record); the recommended pose names it, whatever its message says."""
    from strl_pyg.inference.methods import FunctionMethod
    from strl_pyg.inference.record import MethodResult
    from strl_pyg.inference.registry import METHODS

    def boom(matches, ctx):
        raise RuntimeError("unsupported and raised are words, not decisions")

    monkeypatch.setitem(METHODS, "opencv", FunctionMethod.like(METHODS["opencv"], boom))
    m = generated_pair(2).matches
    est = PoseEstimator(methods=("opencv", "poselib")).estimate(m)
    rec = est.methods["opencv"]
    assert rec.status == "failed" and rec.raised == "RuntimeError" and not rec.unsupported
    assert rec.to_dict()["info"]["raised"] == "RuntimeError"
    assert any(w.startswith("opencv could not run") for w in est.pose.warnings)
    assert MethodResult("x", "failed", info={"raised": "Fake"}).raised is None
