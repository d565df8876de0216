"""End-to-end tests of the ``strl-pose`` command line (in-process, through ``main``)."""

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from strl_pyg import cli
from strl_pyg.cli import main as cli_main
from strl_pyg.geometry import Pose
from strl_pyg.metrics.two_view import rotation_error_deg
from strl_pyg.utils import UsageError

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """The shipped weights when present; else a freshly initialised small model (the CLI's
    plumbing is what these tests check; the shipped model's accuracy is in the README)."""
    from strl_pyg.training.checkpoints import DEFAULT_WEIGHTS

    if DEFAULT_WEIGHTS.is_file():
        return str(DEFAULT_WEIGHTS)
    from strl_pyg.model import StrLPoseConfig
    from strl_pyg.model.strl_pose import StrLPose

    path = tmp_path_factory.mktemp("ckpt") / "tiny.pt"
    StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1)).save(path)
    return str(path)


@pytest.fixture(scope="module")
def kitti_pair(kitti_root):
    seq = kitti_root / "sequences" / "06"
    return (str(seq / "image_0" / "000000.png"), str(seq / "image_0" / "000001.png"),
            str(seq / "calib.txt"), kitti_root / "poses" / "06.txt")


def test_demo_prints_pose_and_writes_png(checkpoint, tmp_path, capsys):
    code = cli.main(["demo", "--checkpoint", checkpoint, "--out", str(tmp_path), "--json"])
    out = capsys.readouterr().out
    assert code == 0
    # one method, one name: the registry's (before: "Str-L Pose" for the regression)
    assert "Str-L Pose" not in out and "\nregression " in out and "\nopencv " in out
    assert "predicted sigma (regression)" in out
    assert "192x640 px (H x W" in out  # sizes as (H, W), like the rest of the package
    # the recommended pose's own uncertainty too (before: only the network's)
    assert "recommended pose: ok" in out and "recommended pose's sigma (" in out
    result = json.loads(out.strip().splitlines()[-1])
    assert len(result["prediction"]["quaternion"]) == 4
    # the classical baseline on front-end matches of a generated pair is accurate
    assert result["errors"]["opencv"]["rot_err_deg"] < 1.0
    png = tmp_path / "demo_matches.png"
    img = cv2.imread(str(png))
    assert img is not None and img.shape[0] > 100 and img.std() > 5


@pytest.mark.slow
def test_predict_real_kitti_pair_json(checkpoint, kitti_pair, capsys):
    img0, img1, calib, poses = kitti_pair
    code = cli.main(["predict", img0, img1, "--K", calib, "--checkpoint", checkpoint, "--json",
                     "--methods", "all"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["pose"]["status"] == "ok" and result["pose"]["method"] in result["methods"]
    # the default runs only what the recommended pose needs, and gives the same pose
    assert cli.main(["predict", img0, img1, "--K", calib, "--checkpoint", checkpoint,
                     "--json"]) == 0
    default = json.loads(capsys.readouterr().out)
    assert default["pose"]["method"] == result["pose"]["method"]
    assert set(default["methods"]) < set(result["methods"])
    np.testing.assert_allclose(default["pose"]["T_0to1"], result["pose"]["T_0to1"], atol=1e-9)
    # --bootstrap 0: the same pose, the first-order covariance only (smaller)
    assert cli.main(["predict", img0, img1, "--K", calib, "--checkpoint", checkpoint,
                     "--json", "--bootstrap", "0"]) == 0
    first = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(first["pose"]["T_0to1"], default["pose"]["T_0to1"], atol=1e-9)
    assert np.trace(first["pose"]["covariance"]) < np.trace(default["pose"]["covariance"])
    T = np.asarray(result["methods"]["regression"]["T_0to1"])
    assert T.shape == (4, 4) and np.allclose(T[3], [0, 0, 0, 1])
    R = T[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-4)
    assert len(result["methods"]["regression"]["info"]["sigma_components"]) == 7
    assert result["num_points"] > 50
    # the classical estimate on the same matches agrees with KITTI's ground truth
    rows = np.loadtxt(poses)[:2]
    c2w = Pose.from_kitti_row(rows)
    T_gt = (c2w[1].inv() @ c2w[0]).matrix()
    T_cv = np.asarray(result["methods"]["opencv"]["T_0to1"])
    assert float(rotation_error_deg(T_cv[:3, :3], T_gt[:3, :3])) < 1.0


def test_match_writes_npz_and_png(kitti_pair, tmp_path, capsys):
    img0, img1, calib, _ = kitti_pair
    out, png = tmp_path / "m.npz", tmp_path / "m.png"
    assert cli.main(["match", img0, img1, "--K", calib, "--out", str(out), "--png", str(png)]) == 0
    from strl_pyg.data import PairMatches

    m = PairMatches.load(out)
    assert m.num_points > 50 and m.has_intrinsics
    assert cv2.imread(str(png)) is not None


@pytest.mark.parametrize(
    "argv, message",
    [
        (["predict", "nope0.png", "nope1.png"], "no such file"),
        (["predict", "{bad}", "{img}"], "cannot decode"),
        (["predict", "{img}", "{img}", "--K", "1,2,3"], "4 (fx,fy,cx,cy)"),
        (["predict", "{img}", "{img}", "--K", "0,100,50,50"], "positive focal"),
        (["predict", "{img}", "{img}", "--K", "not/a/file"], "neither an existing file"),
        (["predict", "{img}", "{img}", "--bootstrap", "2"], "0 or an integer >= 3"),
        (["predict", "{img}", "{img}", "--bootstrap", "-1"], "integer >= 0"),
        (["demo", "--checkpoint", "{missing}"], "model checkpoint"),
        (["demo", "--checkpoint", "{bad}"], "readable StrLPose checkpoint"),
    ],
)
def test_bad_inputs_exit_non_zero_with_clear_error(argv, message, tmp_path, capsys):
    img = tmp_path / "img.png"
    cv2.imwrite(str(img), np.random.default_rng(0).integers(0, 255, (60, 80), np.uint8))
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    subs = {"{img}": str(img), "{bad}": str(bad), "{missing}": str(tmp_path / "none.pt")}
    argv = [subs.get(a, a) for a in argv]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: Expected") and message in err


def test_read_intrinsics_formats(tmp_path):
    K = cli.read_intrinsics("100,110,50,40")
    assert np.allclose(K, [[100, 0, 50], [0, 110, 40], [0, 0, 1]])
    f = tmp_path / "cam.txt"
    f.write_text("100 0 50\n0 110 40\n0 0 1\n")
    assert np.allclose(cli.read_intrinsics(str(f)), K)
    f.write_text("P0: 100 0 50 0 0 110 40 0 0 0 1 0\nP1: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    assert np.allclose(cli.read_intrinsics(str(f)), K)


def test_console_script_entry_point_help():
    with pytest.raises(SystemExit) as exc:
        cli.main(["--help"])
    assert exc.value.code == 0


def test_bench_prints_a_timing_table(tmp_path, capsys):
    from strl_pyg.model import StrLPoseConfig
    from strl_pyg.model.strl_pose import StrLPose

    ckpt = tmp_path / "tiny.pt"
    StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1)).save(ckpt)
    assert cli.main(["bench", "--checkpoint", str(ckpt), "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    rows = [r for r in out.splitlines() if r.startswith("| ") and "ms" not in r.split("|")[2]]
    assert len(rows) == 4 and all(float(r.split("|")[2]) > 0 for r in rows)


# ----------------------------------------------------------------------------- start-up time
def _run_python(code: str) -> tuple[str, float]:
    import subprocess
    import sys
    import time

    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout, time.perf_counter() - t0


HEAVY = ("torch", "torch_geometric", "cv2", "kornia", "strl_pyg.training.loop")


def _in_a_subprocess_slow(*argv_code):
    """A new interpreter per case (~0.4 s each): the fast tier runs ``--help`` and one argument
    error, the slow tier every case."""
    return pytest.param(*argv_code, marks=pytest.mark.slow)


@pytest.mark.parametrize("argv, code", [
    (["--help"], 0), _in_a_subprocess_slow(["train", "--help"], 0),
    _in_a_subprocess_slow(["predict", "--help"], 0),
    _in_a_subprocess_slow(["bench", "--repeat", "x"], 2), (["predict"], 2),
    _in_a_subprocess_slow(["frobnicate"], 2), _in_a_subprocess_slow(["train", "--steps", "ten"], 2),
    _in_a_subprocess_slow(["match", "a.png", "b.png", "--max-side", "-1"], 2),
])
def test_help_and_argument_errors_do_not_import_torch(argv, code):
    out, seconds = _run_python(
        "import contextlib, io, sys\nfrom strl_pyg.cli.commands import main\n"
        "err = io.StringIO()\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):\n"
        f"    try:\n        rc = main({argv!r})\n    except SystemExit as e:\n"
        "        rc = e.code\n"
        f"print(rc, [m for m in {HEAVY!r} if m in sys.modules], repr(err.getvalue()))")
    rc, heavy, err = out.split(" ", 2)
    assert int(rc) == code and heavy == "[]", out
    if code == 2:  # one line, no usage block, no traceback
        assert eval(err).count("\n") == 1 and eval(err).startswith("error: Expected")
    del seconds  # start-up time is measured by benchmarks/bench_startup.py, not here


@pytest.mark.slow
def test_import_strl_pyg_is_light_and_names_resolve_lazily():
    out, _ = _run_python(
        f"import sys, strl_pyg\nprint([m for m in {HEAVY!r} if m in sys.modules])\n"
        "from strl_pyg import StrLPose, PairMatches\nfrom strl_pyg import datasets\n"
        "from strl_pyg.data import keys\n"
        "print(StrLPose.__module__, PairMatches.__module__, datasets.__name__, keys.__name__)")
    first, second = out.splitlines()
    assert first == "[]"
    assert second == ("strl_pyg.model.strl_pose strl_pyg.data.matches strl_pyg.datasets "
                      "strl_pyg.data.keys")


def test_train_choices_match_the_model_ablations():
    from strl_pyg.model import ABLATIONS
    from strl_pyg.training.config import ABLATION_NAMES

    assert tuple(ABLATIONS) == ABLATION_NAMES


# ----------------------------------------------------------------------------- outputs first
@pytest.fixture
def no_frontend(monkeypatch):
    """Makes any matching fail loudly: the checks under test must come before the work."""
    import strl_pyg.frontend

    def boom(*a, **k):
        raise AssertionError("the front end ran before the output was checked")

    monkeypatch.setattr(strl_pyg.frontend, "match_images", boom)


@pytest.mark.parametrize("case", ["out_is_dir", "out_under_file", "png_is_dir"])
def test_match_checks_outputs_before_any_work(case, tmp_path, capsys, no_frontend):
    img = tmp_path / "img.png"
    cv2.imwrite(str(img), np.random.default_rng(0).integers(0, 255, (60, 80), np.uint8))
    (tmp_path / "file").write_text("x")
    out, png = str(tmp_path / "m.npz"), None
    if case == "out_is_dir":
        out = str(tmp_path)
    elif case == "out_under_file":
        out = str(tmp_path / "file" / "m.npz")
    else:
        png = str(tmp_path)
    argv = ["match", str(img), str(img), "--out", out] + (["--png", png] if png else [])
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: Expected") and ".tmp" not in err
    assert ("folder" in err) if case != "out_under_file" else ("is a file" in err)


@pytest.mark.parametrize("argv", [
    ["demo", "--out", "{file}"],
    ["train", "--out", "{file}", "--steps", "1"],
    ["evaluate", "--out", "{file}", "--num-pairs", "1"],
])
def test_other_commands_check_out_before_any_work(argv, tmp_path, capsys, no_frontend):
    (tmp_path / "file").write_text("x")
    argv = [str(tmp_path / "file") if a == "{file}" else a for a in argv]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: Expected") and "which is a file" in err


@pytest.mark.skipif(__import__("os").geteuid() == 0, reason="root writes to read-only folders")
def test_unwritable_out_folder(tmp_path, capsys, no_frontend):
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o555)
    img = tmp_path / "img.png"
    cv2.imwrite(str(img), np.zeros((20, 20), np.uint8))
    assert cli.main(["match", str(img), str(img), "--out", str(ro / "m.npz")]) == 2
    assert "writable" in capsys.readouterr().err


def test_atomic_writer_names_the_target_not_a_temporary(tmp_path):
    from strl_pyg.utils.io import atomic_open

    (tmp_path / "file").write_text("x")
    with pytest.raises(OSError, match="Expected to write") as exc:
        with atomic_open(tmp_path / "file" / "m.npz"):
            pass
    assert ".tmp" not in str(exc.value)


@pytest.mark.parametrize("make, message", [
    (lambda p: p.mkdir(), "got a folder"),
    (lambda p: p.write_bytes(b""), "empty file"),
    (lambda p: cv2.imwrite(str(p.with_suffix(".tiff")), np.zeros((8, 8), np.float32))
     and p.with_suffix(".tiff").rename(p), "8- or 16-bit"),
])
def test_bad_image_files_get_their_own_message(make, message, tmp_path, capsys):
    bad = tmp_path / "bad.png"
    make(bad)
    assert cli.main(["match", str(bad), str(bad), "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_folder_as_intrinsics_and_nan_intrinsics(tmp_path):
    with pytest.raises(UsageError, match="folder"):
        cli.read_intrinsics(str(tmp_path))
    with pytest.raises(UsageError, match="finite"):
        cli.read_intrinsics("nan,100,50,50")


def test_library_key_error_becomes_one_line(capsys, monkeypatch):
    def fail(args):
        raise KeyError("Expected keys ['points0'] in match file 'm.npz' (got [])")

    from strl_pyg.cli import bench

    monkeypatch.setattr(bench, "cmd_bench", fail)
    assert cli.main(["bench"]) == 2
    assert capsys.readouterr().err == "error: Expected keys ['points0'] in match file " \
                                      "'m.npz' (got [])\n"


# ----------------------------------------------------------------------------- --max-side
def test_downscale_scales_K_under_the_pixel_centre_convention():
    K = np.array([[500.0, 0, 319.5], [0, 480.0, 239.5], [0, 0, 1]])
    img = np.zeros((480, 640), np.uint8)
    small, Ks, (sx, sy) = cli.downscale_for_matching(img, K, 320)
    assert small.shape == (240, 320) and (sx, sy) == (0.5, 0.5)
    # a 3D point projects to x in the full image and to (x + 0.5) s - 0.5 in the small one
    X = np.array([0.3, -0.2, 2.0])
    x_full, x_small = (K @ X)[:2] / X[2], (Ks @ X)[:2] / X[2]
    assert np.allclose(x_small, (x_full + 0.5) * 0.5 - 0.5)
    assert np.allclose(Ks[:2, 2], [159.5, 119.5])  # the centre stays the centre
    same, K_same, s = cli.downscale_for_matching(img, K, 0)
    assert same is img and K_same is K and s == (1.0, 1.0)


@pytest.mark.slow  # two front-end passes on real frames, one 3x upscaled: the fast tier's
# guards are test_downscale_scales_K_under_the_pixel_centre_convention and
# test_a_downscaled_pair_checks_its_intrinsics_once_in_the_users_frame
def test_match_of_a_large_pair_reports_the_original_frame(kitti_pair, tmp_path, capsys):
    """KITTI frames upscaled 3x (nearest) are downscaled back exactly by --max-side: the
    matches equal those of the original frames, mapped as x_big = 3 x + 1."""
    img0, img1, calib, _ = kitti_pair
    big = []
    for i, src in enumerate((img0, img1)):
        g = cv2.imread(src, cv2.IMREAD_GRAYSCALE)
        path = tmp_path / f"big{i}.png"
        cv2.imwrite(str(path), cv2.resize(g, None, fx=3, fy=3, interpolation=cv2.INTER_NEAREST))
        big.append(str(path))
        w = g.shape[1]
    K = cli.read_intrinsics(calib)
    K_big = np.array([[3, 0, 1.0], [0, 3, 1.0], [0, 0, 1]]) @ K
    k_big = ",".join(str(v) for v in (K_big[0, 0], K_big[1, 1], K_big[0, 2], K_big[1, 2]))
    k = ",".join(str(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    assert cli.main(["match", img0, img1, "--K", k, "--out", str(tmp_path / "a.npz")]) == 0
    assert cli.main(["match", *big, "--K", k_big, "--max-side", str(w),
                     "--out", str(tmp_path / "b.npz")]) == 0
    assert "downscaled for matching" in capsys.readouterr().err
    from strl_pyg.data import PairMatches

    a, b = PairMatches.load(tmp_path / "a.npz"), PairMatches.load(tmp_path / "b.npz")
    assert b.image_size0 == (3 * a.image_size0[0], 3 * a.image_size0[1])
    assert np.allclose(b.K0, K_big) and b.image0.shape == tuple(b.image_size0)
    assert a.num_points > 50 and b.num_points == a.num_points
    assert np.allclose(b.points0, 3 * a.points0 + 1, atol=1e-6)
    assert np.allclose(b.lines1, 3 * a.lines1 + 1, atol=1e-6)


# ----------------------------------------------------------------------------- training default
def test_default_train_config_model_accepts_its_default_data():
    """The default model config takes its patch channels from the data (generated scenes
    are grey): the default model runs on a default training graph."""
    from dataclasses import replace

    from torch_geometric.loader.dataloader import Collater

    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.training import build_datasets
    from strl_pyg.training.config import DATA_CHANNELS, TrainConfig

    cfg = replace(TrainConfig(), train_pairs=1, val_pairs=1)
    g = build_datasets(cfg)[0][0]
    assert g["point"].patch0.shape[1] == DATA_CHANNELS["synthetic"] * cfg.patch_size ** 2
    out = StrLPose(cfg.model_config())(Collater(None)([g]))
    assert out.quaternion.shape == (1, 4)
    assert TrainConfig(dataset="demon", data_root="x").model_config().patch_features == 3
    assert TrainConfig(patch_size=3).model_config().patch_features == 9
    assert TrainConfig(model_overrides={"patch_features": 3}).model_config().patch_features == 3


@pytest.mark.slow
def test_training_command_runs_on_the_default_settings(tmp_path):
    """``examples/train.py`` with every setting at its default but the counts: 3 steps, 32
    training pairs (the input statistics are fitted on the first 128, so on all 32) and 8
    validation pairs. At the default counts the pairs' generation alone took ~3 min (128 for
    the statistics, 128 for validation: ~0.4 s each, the rendering and the textures); the
    code run is the same."""
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "examples" / "train.py"
    proc = subprocess.run([sys.executable, str(script), "--steps", "3", "--train-pairs", "32",
                           "--val-pairs", "8", "--out", "run"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=850)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["step"] == 3 and np.isfinite(result["rot_err_deg"])
    assert (tmp_path / "run" / "last.pt").is_file() and (tmp_path / "run" / "model.pt").is_file()
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["train_pairs"] == 32 and config["val_pairs"] == 8


@pytest.mark.slow  # two predicts on a real KITTI pair: the fast tier's case is
# test_predict_on_a_match_file_says_when_the_given_checkpoint_was_not_run
def test_predict_says_when_the_given_checkpoint_was_not_run(checkpoint, kitti_pair, capsys):
    # reproduction: `predict ... --checkpoint MY_RUN/model.pt` printed PoseLib's pose alone and
    # nothing said the user's network had not been run
    img0, img1, calib, _ = kitti_pair
    assert cli.main(["predict", img0, img1, "--K", calib, "--checkpoint", checkpoint]) == 0
    out = capsys.readouterr().out
    assert "note: the recommended pose did not need the network" in out and checkpoint in out
    assert cli.main(["predict", img0, img1, "--K", calib, "--checkpoint", checkpoint,
                     "--methods", "regression"]) in (0, 3)
    assert "note:" not in capsys.readouterr().out


def test_predict_on_a_match_file_says_when_the_given_checkpoint_was_not_run(
        checkpoint, held_out_pair, tmp_path, capsys):
    """The fast tier's case of test_predict_says_when_the_given_checkpoint_was_not_run: the
    held-out pair's match file instead of a KITTI pair's images (no front end)."""
    path = held_out_pair.matches.save(tmp_path / "m.npz")
    assert cli.main(["predict", "--matches", str(path), "--checkpoint", checkpoint]) == 0
    out = capsys.readouterr().out
    assert "note: the recommended pose did not need the network" in out and checkpoint in out
    assert cli.main(["predict", "--matches", str(path), "--checkpoint", checkpoint,
                     "--methods", "regression"]) in (0, 3)
    assert "note:" not in capsys.readouterr().out


@pytest.mark.slow
def test_python_dash_m_evaluation_and_the_console_script_entry_point():
    res = subprocess.run([sys.executable, "-m", "strl_pyg.evaluation", "--help"],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert res.returncode == 0 and "--methods" in res.stdout, res.stderr[-1000:]
    res = subprocess.run([sys.executable, "-c", "from strl_pyg.cli import main; "
                          "raise SystemExit(main(['--help']))"],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert res.returncode == 0 and "predict" in res.stdout, res.stderr[-1000:]


def test_a_wrong_case_flag_gets_a_suggestion(capsys):
    assert cli_main(["predict", "a.png", "b.png", "--k", "1,1,1,1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "did you mean --K?" in err


def test_an_unknown_method_fails_before_anything_is_loaded(capsys, monkeypatch):
    """Before: '--methods poselibb' failed after 6 s of loading."""
    import strl_pyg.cli.predict as predict

    def boom(*a, **k):
        raise AssertionError("read before the method names were checked")

    monkeypatch.setattr(predict, "load_model", boom)
    monkeypatch.setattr(predict, "read_pair", boom)
    assert cli_main(["predict", "a.png", "b.png", "--methods", "poselibb"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'poselib'?" in err and err.count("\n") == 1


def test_a_folder_as_checkpoint_says_folder(tmp_path, held_out_pair, capsys):
    path = held_out_pair.matches.save(tmp_path / "m.npz")
    assert cli_main(["predict", "--matches", str(path), "--checkpoint", str(tmp_path)]) == 2
    assert "(got a folder)" in capsys.readouterr().err
    assert cli_main(["predict", "--matches", str(tmp_path)]) == 2
    assert "(got a folder)" in capsys.readouterr().err


def test_a_missing_data_root_is_one_line(capsys):
    """Before: two UserWarnings blaming the sequences."""
    import warnings

    from strl_pyg.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["train", "--dataset", "kitti", "--data-root", "/nonexistent/kitti",
                     "--steps", "1", "--out", "/tmp/never_written_run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no such folder" in err


def test_the_default_predict_does_not_build_the_network(tmp_path, held_out_pair, capsys,
                                                        monkeypatch):
    """Before: predict loaded the model (~80 ms a process) for the default recommended pose,
    which on a pair with enough points is PoseLib's."""
    import json

    import cv2

    from strl_pyg.model import StrLPose

    def refuse(*a, **k):
        raise AssertionError("the network was built")

    monkeypatch.delenv("STRL_POSE_WEIGHTS", raising=False)
    monkeypatch.setattr(StrLPose, "from_pretrained", classmethod(refuse))
    monkeypatch.setattr(StrLPose, "load", classmethod(refuse))
    for i, img in enumerate((held_out_pair.image0, held_out_pair.image1)):
        cv2.imwrite(str(tmp_path / f"{i}.png"), img)
    K = held_out_pair.K
    code = cli_main(["predict", str(tmp_path / "0.png"), str(tmp_path / "1.png"), "--K",
                     f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["pose"]["status"] == "ok" and out["pose"]["method"] == "poselib"
    assert out["translation_kind"] == StrLPose.pretrained_header()[0].translation


def test_predict_on_a_match_file_runs_the_recommended_methods_only(tmp_path, held_out_pair, capsys):
    """Before, `predict --matches` with the default '--methods recommended' ran every method
    (the image path ran only the ones the recommended pose needs); the pose is the same."""
    import json

    path = held_out_pair.matches.save(tmp_path / "m.npz")
    runs = {}
    for methods in ("recommended", "all"):
        assert cli_main(["predict", "--matches", str(path), "--methods", methods,
                         "--json"]) == 0
        runs[methods] = json.loads(capsys.readouterr().out)
    lazy, full = runs["recommended"], runs["all"]
    assert lazy["pose"]["method"] == full["pose"]["method"]
    np.testing.assert_allclose(lazy["pose"]["T_0to1"], full["pose"]["T_0to1"], atol=1e-12)
    assert list(lazy["methods"]) == [lazy["pose"]["method"]]
    assert len(full["methods"]) > 1



def test_predict_no_baseline_runs_the_regression_alone(tmp_path, held_out_pair, capsys):
    """``--no-baseline`` raised a NameError (the regression's name read from a class the
    command line had not imported)."""
    import json

    path = held_out_pair.matches.save(tmp_path / "m.npz")
    cli_main(["predict", "--matches", str(path), "--no-baseline", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert list(out["methods"]) == ["regression"]
    assert out["methods"]["regression"]["status"] == "ok"


def test_the_command_line_runs_as_a_module():
    """``python -m strl_pyg.cli`` was 'No module named strl_pyg.cli.__main__'."""
    proc = subprocess.run([sys.executable, "-m", "strl_pyg.cli", "predict", "--help"],
                          capture_output=True, text=True, cwd=REPO, timeout=120)
    assert proc.returncode == 0 and "usage: strl-pose predict" in proc.stdout


def test_a_downscaled_pair_checks_its_intrinsics_once_in_the_users_frame(tmp_path,
                                                                        held_out_pair, capsys,
                                                                        monkeypatch):
    """Before: the CLI ran the check twice more (both frames) and replaced the warnings' text
    (and before that the warning quoted fx=153.8 at 1600 px, numbers the user never gave);
    now the estimator renders the one check in the frame the user gave."""
    import cv2

    from strl_pyg.inference import checks, pair

    calls = []
    real = checks.intrinsics_problems

    def counted(*args):
        calls.append(args[0])
        return real(*args)

    monkeypatch.setattr(pair, "intrinsics_problems", counted)
    monkeypatch.setattr(checks, "intrinsics_problems", counted)
    for name, img in (("a.png", held_out_pair.image0), ("b.png", held_out_pair.image1)):
        cv2.imwrite(str(tmp_path / name), cv2.resize(img, (3200, 960)))
    code = cli_main(["predict", str(tmp_path / "a.png"), str(tmp_path / "b.png"),
                     "--K", "100000,100000,1600,480", "--methods", "opencv",
                     "--bootstrap", "0"])
    out = capsys.readouterr().out
    assert code == 3 and "fx=1e+05" in out and "(3200 px)" in out and "1600 px)" not in out
    assert [tuple(c) for c in calls] == [(960, 3200)]  # once, the original size
