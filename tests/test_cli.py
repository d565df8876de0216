"""End-to-end tests of the ``strl-pose`` command line (in-process, through ``main``)."""

import json

import cv2
import numpy as np
import pytest

from strl_pyg import cli
from strl_pyg.geometry import Pose
from strl_pyg.metrics import rotation_error_deg


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """The shipped weights when present; else a freshly initialised small model (the CLI's
    plumbing is what these tests check; the shipped model's accuracy is in the README)."""
    if cli.DEFAULT_WEIGHTS.is_file():
        return str(cli.DEFAULT_WEIGHTS)
    from strl_pyg.model import StrLPose, StrLPoseConfig

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
    assert "Str-L Pose" in out and "OpenCV MAGSAC" in out and "predicted sigma" in out
    result = json.loads(out.strip().splitlines()[-1])
    assert len(result["prediction"]["quaternion"]) == 4
    # the classical baseline on front-end matches of a generated pair is accurate
    assert result["errors"]["OpenCV MAGSAC"]["rot_err_deg"] < 1.0
    png = tmp_path / "demo_matches.png"
    img = cv2.imread(str(png))
    assert img is not None and img.shape[0] > 100 and img.std() > 5


def test_predict_real_kitti_pair_json(checkpoint, kitti_pair, capsys):
    img0, img1, calib, poses = kitti_pair
    code = cli.main(["predict", img0, img1, "--K", calib, "--checkpoint", checkpoint, "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["pose"]["status"] == "ok" and result["pose"]["method"] in result["methods"]
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
    from strl_pyg.model import StrLPose, StrLPoseConfig

    ckpt = tmp_path / "tiny.pt"
    StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1)).save(ckpt)
    assert cli.main(["bench", "--checkpoint", str(ckpt), "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    rows = [r for r in out.splitlines() if r.startswith("| ") and "ms" not in r.split("|")[2]]
    assert len(rows) == 4 and all(float(r.split("|")[2]) > 0 for r in rows)
