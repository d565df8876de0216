"""Tests of strl_pyg.evaluation.run and examples/evaluate.py."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from strl_pyg.evaluation import EvalPair, EvalReport, PairResult, synthetic_eval_pairs
from strl_pyg.evaluation.run import available_methods, evaluate_pairs
from strl_pyg.model import StrLPoseConfig
from strl_pyg.model.strl_pose import StrLPose

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory) -> Path:
    torch.manual_seed(0)
    model = StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1))
    return model.save(tmp_path_factory.mktemp("ckpt") / "tiny.pt")


#: Pairs of the evaluated report: one of each kind is what its rows and columns need (every
#: method runs on each pair, vp's line solve included: ~1 s a pair).
N_PAIRS = 2


@pytest.fixture(scope="module")
def synthetic_report(tiny_checkpoint) -> EvalReport:
    pairs = synthetic_eval_pairs(N_PAIRS, seed=2_000_000, kinds=("indoor", "boxes"))
    return evaluate_pairs(StrLPose.load(tiny_checkpoint), pairs, progress=False)


def _script():
    spec = importlib.util.spec_from_file_location("evaluate_script",
                                                  REPO / "examples" / "evaluate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_report_rows_columns_and_classical_accuracy(synthetic_report):
    rep = synthetic_report
    # what the tiny model cannot run (no geometric head) is left out by default, not scored
    # as "fail 4/4" (issue: 'fail 60/60' for methods a model lacks)
    assert rep.methods == tuple(m for m in available_methods()
                                if m not in ("geometric", "guided"))
    assert len(rep.results) == N_PAIRS * len(rep.methods)
    summary = rep.summary()
    assert list(summary) == ["synthetic/indoor", "synthetic/boxes", "all"]
    for per in summary.values():
        assert list(per) == list(rep.methods)
    keys = {"n", "failures", "rot_mean", "rot_median", "trans_mean", "trans_median", "auc5",
            "auc10", "auc20", "time_ms"}
    assert set(summary["all"]["regression"]) == keys
    assert summary["all"]["regression"]["n"] == N_PAIRS
    # noise-free generated matches: the classical estimates are essentially exact
    for m in ("opencv", "poselib"):
        if m in rep.methods:
            s = summary["all"][m]
            assert s["failures"] == 0 and s["rot_mean"] < 1.0 and s["trans_mean"] < 1.0
            assert s["auc5"] > 0.8
    # an untrained network is far off; the fusion follows the exact classical estimate
    assert summary["all"]["regression"]["rot_mean"] > 1.0
    assert summary["all"]["fused"]["rot_mean"] < 1.0
    assert "geometric" not in summary["all"] and "vp" in summary["all"]


def test_markdown_and_json_render(synthetic_report, tmp_path):
    md = synthetic_report.to_markdown()
    lines = md.splitlines()
    header = next(ln for ln in lines if ln.startswith("| subset"))
    assert "AUC@5" in header and "rot med" in header and "trans mean" in header
    rows = [ln for ln in lines if ln.startswith("| synthetic/") or ln.startswith("| all")]
    assert len(rows) == 3 * len(synthetic_report.methods)
    paths = synthetic_report.save(tmp_path)
    assert [p.name for p in paths] == ["results.md", "results.json"]  # no frames, no chain
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["summary"]["all"]["opencv"]["n"] == N_PAIRS


def test_trajectory_metrics_on_a_known_chain():
    # ground truth: the camera moves 1 m along +z per frame (X1 = X0 - (0, 0, 1)); the
    # estimate has the exact rotation and a translation direction 2 degrees off in x-z
    a = math.radians(2.0)
    T_gt = np.eye(4)
    T_gt[2, 3] = -1.0
    T_est = np.eye(4)
    T_est[:3, 3] = [-math.sin(a), 0.0, -math.cos(a)]
    n = 4
    results = [PairResult(f"s/{i}", "seq", "opencv", 0.0, 2.0, 1.0, True, T_est)
               for i in range(n)]
    pairs = {f"s/{i}": ("seq", T_gt, (i, i + 1)) for i in range(n)}
    pairs["s/x"] = ("seq", T_gt, (10, 11))  # not consecutive: outside the longest chain
    rep = EvalReport(results, ("opencv",), pairs)
    trajs = rep.trajectories()["seq"]
    assert torch.allclose(trajs["ground truth"].t[-1],
                          torch.tensor([0.0, 0.0, float(n)], dtype=torch.float64))
    assert torch.allclose(trajs["opencv"].t[-1], torch.tensor(
        [n * math.sin(a), 0.0, n * math.cos(a)], dtype=torch.float64), atol=1e-12)
    k = rep.kitti_summary()["seq"]["opencv"]
    assert k["num_pairs"] == n and k["length_m"] == pytest.approx(float(n))
    assert math.isnan(k["t_rel"]) and k["num_segments"] == 0  # no 100 m segment
    assert k["rmse_trans_m"] == pytest.approx(2 * math.sin(a / 2), rel=1e-9)
    assert k["rmse_rot_deg"] == 0.0
    # 10-50 m segments do not fit either in 4 m
    assert k["num_short_segments"] == 0
    assert "| seq | opencv | 4 | 4.0 | - | - |" in rep.to_markdown()


def test_evaluate_pairs_rejects_bad_arguments(tiny_checkpoint):
    with pytest.raises(ValueError, match="Expected methods"):
        evaluate_pairs(None, [], methods=("magic",))
    with pytest.raises(ValueError, match="Expected a model"):
        evaluate_pairs(None, [], methods=("regression",))
    with pytest.raises(ValueError, match="Expected intrinsics"):
        from strl_pyg.data.matches import PairMatches

        EvalPair(PairMatches(np.zeros((5, 2)), np.zeros((5, 2)), image_size0=(10, 10),
                             image_size1=(10, 10)), np.eye(4), "s", "p")


def _one_error_line(capsys, expected: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: Expected"), err
    assert expected in err, err
    return err


def test_script_errors_for_missing_checkpoint_and_root(tiny_checkpoint, tmp_path, capsys):
    script = _script()
    assert script.main(["--checkpoint", str(tmp_path / "nope.pt")]) == 2
    _one_error_line(capsys, "Expected a checkpoint file")
    assert script.main(["--checkpoint", str(tiny_checkpoint), "--dataset", "kitti"]) == 2
    _one_error_line(capsys, "Expected --data-root")
    assert script.main(["--checkpoint", str(tiny_checkpoint), "--dataset", "demon",
                        "--data-root", str(tmp_path / "missing")]) == 2
    _one_error_line(capsys, "Expected a data folder")


@pytest.mark.parametrize("flags, expected", [
    (["--num-pairs", "x"], "--num-pairs: Expected an integer >= 1 (got 'x')"),
    (["--num-pairs", "0"], "--num-pairs: Expected an integer >= 1 (got '0')"),
    (["--threshold-px", "nan"], "--threshold-px: Expected a finite number > 0"),
    (["--outlier-fraction", "1"], "--outlier-fraction: Expected a fraction in [0, 1)"),
    (["--dataset", "mnist"], "invalid choice: 'mnist'"),
    (["--bogus"], "unrecognized arguments: --bogus"),
    (["--num-pairs"], "expected one argument"),
    (["--device", "warp9"], "Expected a torch device"),
])
def test_evaluate_user_errors_are_one_line_and_exit_2(flags, expected, tiny_checkpoint,
                                                      capsys):
    """`strl-pose evaluate` used argparse's two-line usage error (SystemExit) where every other
    command prints one 'error: Expected ...' line and returns 2."""
    from strl_pyg import cli

    argv = ["--checkpoint", str(tiny_checkpoint), *flags]
    assert cli.main(["evaluate", *argv]) == 2
    err = _one_error_line(capsys, expected)
    if not flags[0] == "--device":
        assert "see 'strl-pose evaluate --help'" in err
    assert _script().main(argv) == 2  # the example script alike
    _one_error_line(capsys, expected)


def test_evaluate_shares_the_cli_parser_and_suggests_a_flag(tiny_checkpoint, capsys):
    """`strl-pose evaluate` kept its own near-copy of the one-line parser, without the other
    commands' "did you mean" for a mistyped flag; one parser and one UsageError now."""
    from strl_pyg import cli, utils
    from strl_pyg.evaluation import run

    assert isinstance(run.build_parser(), utils.OneLineArgumentParser)
    argv = ["--checkpoint", str(tiny_checkpoint), "--num-piars", "3"]
    assert cli.main(["evaluate", *argv]) == 2
    _one_error_line(capsys, "did you mean --num-pairs?")
    assert _script().main(argv) == 2
    _one_error_line(capsys, "did you mean --num-pairs?")


def test_evaluate_refuses_a_corrupt_checkpoint_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    assert _script().main(["--checkpoint", str(bad)]) == 2
    err = _one_error_line(capsys, str(bad))
    assert "weights_only" not in err and "allow_pickle" not in err


@pytest.mark.slow
def test_python_dash_m_runs_the_command_line(tmp_path):
    res = subprocess.run([sys.executable, "-m", "strl_pyg.evaluation.run", "--checkpoint",
                          str(tmp_path / "nope.pt")], capture_output=True, text=True,
                         cwd=REPO, timeout=300)
    assert res.returncode == 2 and res.stdout == ""
    # OpenCV's own notice when OPENCV_CPU_DISABLE names a feature this CPU lacks is not ours
    err = "".join(line for line in res.stderr.splitlines(keepends=True)
                  if not line.startswith("OPENCV:"))
    assert err.startswith("error: Expected a checkpoint file") and err.count("\n") == 1, err


@pytest.mark.slow
def test_script_end_to_end_on_kitti_slice(kitti_root, tiny_checkpoint, tmp_path, capsys):
    out = tmp_path / "out"
    rc = _script().main([
        "--checkpoint", str(tiny_checkpoint), "--dataset", "kitti",
        "--data-root", str(kitti_root), "--sequences", "06", "--limit", "2",
        "--cache-dir", str(tmp_path / "cache"), "--out", str(out), "--no-progress",
        "--methods", "regression", "opencv", "fused",
    ])
    assert rc == 0
    md = (out / "results.md").read_text()
    assert "| KITTI/06 | opencv | 2 |" in md and "RMSE rot deg" in md
    png = out / "trajectory_KITTI_06.png"
    assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG"
    assert "| KITTI/06 | fused |" in capsys.readouterr().out


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA device")
def test_evaluate_cuda_on_a_cpu_machine_says_the_device_is_unavailable(tiny_checkpoint, capsys):
    """It blamed the checkpoint ('Expected a readable StrLPose checkpoint ... Attempting to
    deserialize object on a CUDA device')."""
    from strl_pyg import cli

    argv = ["--checkpoint", str(tiny_checkpoint), "--device", "cuda"]
    for run in (_script().main, lambda a: cli.main(["evaluate", *a])):
        assert run(argv) == 2
        err = _one_error_line(capsys, "--device")
        assert "no CUDA device" in err and "checkpoint" not in err


def test_evaluate_defaults_to_front_end_matches(tiny_checkpoint, capsys):
    """Ground-truth matches (the former default) gave the classical methods 0.00 deg."""
    from strl_pyg.evaluation.run import build_parser

    assert build_parser().parse_args([]).matches == "frontend"
    assert build_parser().parse_args(["--matches", "ground_truth"]).matches == "ground_truth"
    assert _script().main(["--checkpoint", str(tiny_checkpoint), "--num-pairs", "1",
                           "--kinds", "boxes", "--methods", "opencv", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "frontend" in out


def test_evaluate_runs_the_registry_and_scores_what_pose_estimator_gives(tiny_checkpoint):
    """Before, evaluate had its own runner (strl, opencv, poselib, fused_opencv,
    fused_poselib) and could not score the geometric head or the guided method; now it runs
    PoseEstimator's registry by the same names, so the numbers are the estimator's."""
    from strl_pyg.inference import PoseEstimator
    from strl_pyg.metrics import relative_pose_error

    model = StrLPose.load(tiny_checkpoint)
    pairs = synthetic_eval_pairs(3, seed=2_000_010, kinds=("boxes",), progress=False)
    rep = evaluate_pairs(model, pairs, methods=["geometric,guided", "opencv"], progress=False)
    assert rep.methods == ("geometric", "guided", "opencv")
    est = PoseEstimator(model, methods=["geometric", "guided", "opencv"], bootstrap=0)
    for pair in pairs:
        e = est.estimate(pair.matches)
        for r in (r for r in rep.results if r.pair_id == pair.pair_id):
            m = e.methods[r.method]
            assert r.success == (m.status == "ok"), (r.method, m.status)
            if r.success:
                rot, tr = relative_pose_error(m.T_0to1[None], pair.T_0to1[None])
                assert r.rot_err == pytest.approx(float(rot[0]), abs=1e-9)
                assert r.trans_err == pytest.approx(float(tr[0]), abs=1e-9)


def test_old_method_names_are_refused_with_their_new_name():
    """0.3 accepted them with a DeprecationWarning that Python hid: '--methods strl' ran
    without a word. 0.4 refuses them and names the registry's method."""
    from strl_pyg.evaluation import resolve_methods

    with pytest.raises(ValueError, match="0.2's 'strl' is 'regression'"):
        resolve_methods(["strl", "opencv"], object())
    with pytest.raises(ValueError, match="0.2's 'fused_opencv' is 'fused'"):
        resolve_methods("fused_opencv,poselib", object())
    assert resolve_methods("regression,opencv", object()) == ("regression", "opencv")
    with pytest.raises(ValueError, match="Expected methods from"):
        resolve_methods(["magic"], object())


def test_evaluation_reads_method_names_like_the_estimator():
    """``evaluate --methods`` had a parser of its own that refused 'OpenCV' (the estimator
    and ``predict`` take any case) and suggested nothing for a misspelt name."""
    from strl_pyg.evaluation import resolve_methods

    assert resolve_methods("OpenCV, Regression", object()) == ("opencv", "regression")
    assert resolve_methods(["opencv", "OPENCV,geometric"], object()) == ("opencv", "geometric")
    with pytest.raises(ValueError, match="did you mean 'opencv'"):
        resolve_methods("opencvv", object())
    with pytest.raises(ValueError, match="0.2's 'STRL' is 'regression'"):
        resolve_methods("STRL", object())
    with pytest.raises(ValueError, match="evaluate scores every available method"):
        resolve_methods("all", object())
    with pytest.raises(ValueError, match=r"Expected methods from \(.*\) \(got"):
        resolve_methods("all,opencv", object())  # not "..., 'all' or 'recommended'"
    with pytest.raises(ValueError, match="Expected methods from"):
        resolve_methods(" , ", object())


def test_command_line_takes_comma_separated_registry_names(tiny_checkpoint, capsys):
    rc = _script().main(["--checkpoint", str(tiny_checkpoint), "--num-pairs", "2",
                         "--kinds", "boxes", "--methods", "geometric,guided,opencv",
                         "--no-progress"])
    assert rc == 0
    out = capsys.readouterr().out
    for name in ("geometric", "guided", "opencv"):
        assert f"| {name} |" in out


def test_sequences_take_commas_as_train_sequences_do(tiny_checkpoint):
    # reproduction: `--sequences 06,07` looked for a KITTI sequence named '06,07' and found no
    # pairs, while train.py's --train-sequences takes the comma-separated form
    from strl_pyg.evaluation import run

    for given in (["06,07"], ["06", "07"], ["06,", "07"], ["06, 07"]):
        args = run.build_parser(None).parse_args(
            ["--checkpoint", str(tiny_checkpoint), "--sequences", *given])
        run._checked(args)
        assert args.sequences == ["06", "07"], given


@pytest.mark.slow
def test_evaluate_on_posed_photographs(shared_data, tiny_checkpoint, tmp_path, capsys):
    """Before: `strl-pose evaluate --dataset posed` was refused ('invalid choice')."""
    from strl_pyg import cli

    root = shared_data / "real_scenes"
    if not (root / "office_drink" / "cameras.json").is_file():
        pytest.skip("real_scenes not present")
    common = ["evaluate", "--checkpoint", str(tiny_checkpoint), "--dataset", "posed",
              "--data-root", str(root), "--cache-dir", str(tmp_path / "cache"),
              "--no-progress", "--methods", "poselib"]
    assert cli.main([*common, "--scenes", "office_drink", "--stride", "30"]) == 0
    out = capsys.readouterr().out
    assert "dataset: posed, pairs: 3" in out and "| office_drink | poselib | 3 |" in out
    assert cli.main([*common, "--scenes", "no_such_scene"]) == 2
    err = capsys.readouterr().err
    assert "no_such_scene not there" in err and err.count("\n") == 1
