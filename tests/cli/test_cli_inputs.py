"""strl-pose inputs that other tools write: KITTI's calib.txt without its labels, method
names in any case."""

from __future__ import annotations

import numpy as np
import pytest

from strl_pyg.cli import main as cli_main
from strl_pyg.cli.predict import _check_methods, _method_names
from strl_pyg.cli.readers import read_intrinsics
from strl_pyg.utils import UsageError

P0 = "7.188560e+02 0 6.071928e+02 0 0 7.188560e+02 1.852157e+02 0 0 0 1 0"
P1 = "7.188560e+02 0 6.071928e+02 -3.861448e+02 0 7.188560e+02 1.852157e+02 0 0 0 1 0"


def test_kitti_calib_without_labels_reads_as_kitti(tmp_path):
    """Before: two rows of 12 numbers were refused with "got 24"."""
    bare, labelled = tmp_path / "bare.txt", tmp_path / "calib.txt"
    bare.write_text(f"{P0}\n{P1}\n")
    labelled.write_text(f"P0: {P0}\nP1: {P1}\n")
    np.testing.assert_array_equal(read_intrinsics(str(bare)), read_intrinsics(str(labelled)))
    assert read_intrinsics(str(bare))[0, 0] == pytest.approx(718.856)
    odd = tmp_path / "odd.txt"
    odd.write_text("1 2 3 4 5\n6 7 8 9 10\n")
    with pytest.raises(UsageError, match=r"Expected 4 \(fx,fy,cx,cy\), 9 \(3x3\) or 12"):
        read_intrinsics(str(odd))


def test_method_names_ignore_case():
    """Before: --methods OpenCV got no suggestion and no run."""
    assert _method_names("OpenCV, PoseLib") == ("opencv", "poselib")
    _check_methods("OpenCV")
    _check_methods("ALL")
    with pytest.raises(UsageError, match="did you mean 'poselib'"):
        _check_methods("poselibb")


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory, generated_pair):
    import cv2

    from strl_pyg.synthetic import SceneConfig

    d = tmp_path_factory.mktemp("imgs")
    p = generated_pair(7, SceneConfig(kind="street"))
    cv2.imwrite(str(d / "a.png"), p.image0)
    cv2.imwrite(str(d / "b.png"), p.image1)
    K = p.K
    return d, f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}"


@pytest.mark.slow
def test_predict_pairs_gives_one_json_line_per_pair_and_goes_on(image_dir, capsys):
    """What hloc users reach for: a pairs file over an image folder; one bad pair (a missing
    image) is its error line and the others still run."""
    import json

    from strl_pyg import cli

    d, K = image_dir
    (d / "pairs.txt").write_text("a.png b.png\n# a comment\na.png nope.png\nb.png a.png\n")
    code = cli.main(["predict", "--pairs", str(d / "pairs.txt"), "--image-dir", str(d),
                     "--K", K, "--methods", "opencv", "--bootstrap", "0"])
    lines = [json.loads(ln) for ln in capsys.readouterr().out.splitlines()]
    assert code == 1 and len(lines) == 3
    assert lines[0]["pose"]["status"] == "ok" and lines[2]["pose"]["status"] == "ok"
    assert lines[1]["image1"].endswith("nope.png") and "Expected an image file" in lines[1][
        "error"]
    (d / "bad.txt").write_text("a.png\n")
    assert cli.main(["predict", "--pairs", str(d / "bad.txt"), "--K", K]) == 2
    assert "Expected 'image0 image1' on line 1" in capsys.readouterr().err


@pytest.mark.slow
def test_predict_png_colours_the_support_and_threshold_is_a_flag(image_dir, tmp_path, capsys):
    """Before: the drawing coloured every match green, with no legend; no --threshold-px."""
    from strl_pyg import cli

    d, K = image_dir
    out = tmp_path / "pose.png"
    code = cli.main(["predict", str(d / "a.png"), str(d / "b.png"), "--K", K, "--methods",
                     "opencv", "--bootstrap", "0", "--png", str(out), "--threshold-px", "2"])
    text = capsys.readouterr().out
    assert code == 0 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "two-view configuration: general" in text and f"drawing -> {out}" in text
    assert cli.main(["predict", str(d / "a.png"), str(d / "b.png"), "--K", K,
                     "--threshold-px", "0"]) == 2
    assert "Expected a positive --threshold-px" in capsys.readouterr().err


def test_predict_reads_a_match_file(tmp_path, held_out_pair, capsys):
    path = held_out_pair.matches.save(tmp_path / "m.npz")
    code = cli_main(["predict", "--matches", str(path), "--methods", "poselib",
                     "--bootstrap", "0", "--json"])
    import json

    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["pose"]["status"] == "ok" and out["pose"]["method"] == "poselib"
    assert out["num_points"] == held_out_pair.matches.num_points
    assert cli_main(["predict", "a.png", "--matches", str(path)]) == 2
    assert "either two images or --matches" in capsys.readouterr().err


def test_intrinsics_from_colmap_and_strecha_files(tmp_path):
    (tmp_path / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n"
        "1 PINHOLE 3072 2048 2759.48 2764.16 1520.69 1006.81\n")
    K = read_intrinsics(str(tmp_path / "cameras.txt"))
    # COLMAP's pixel centres are at +0.5: this package's (OpenCV's) are at 0
    np.testing.assert_allclose(K, [[2759.48, 0, 1520.19], [0, 2764.16, 1006.31], [0, 0, 1]])
    (tmp_path / "one.txt").write_text("1 SIMPLE_RADIAL 640 480 500 320.5 240.5 0.01\n")
    np.testing.assert_allclose(read_intrinsics(str(tmp_path / "one.txt")),
                               [[500, 0, 320], [0, 500, 240], [0, 0, 1]])
    (tmp_path / "two.txt").write_text("1 PINHOLE 640 480 500 500 320 240\n"
                                      "2 PINHOLE 640 480 600 600 320 240\n")
    with pytest.raises(UsageError, match="Expected one camera"):
        read_intrinsics(str(tmp_path / "two.txt"))
    (tmp_path / "0004.jpg.camera").write_text(
        "2759.48 0 1520.69\n0 2764.16 1006.81\n0 0 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
        "-7.2 -7.5 0.2\n3072 2048\n")
    np.testing.assert_allclose(read_intrinsics(str(tmp_path / "0004.jpg.camera")),
                               [[2759.48, 0, 1520.69], [0, 2764.16, 1006.81], [0, 0, 1]])


def test_match_file_without_k_prints_one_line_each(held_out_pair, tmp_path, capsys):
    """Before: `strl-pose predict --matches lg.npz` (a LightGlue file whose matches reuse
    keypoints of image 1, no K, no images) printed Python's warning with its source line
    (`.../formats.py:174: UserWarning: ...` then `kw = READERS[fmt](...)`), said
    `regression skipped: regression skipped: ...` and warned that "the network's coordinates
    are normalised by the image size" though the network did not run."""
    from strl_pyg.cli import main as cli_main

    m = held_out_pair.matches
    n = 200
    idx = np.stack([np.arange(n), np.arange(n)], 1)
    idx[150:, 1] = idx[:50, 1]  # 50 matches onto keypoints of image 1 already matched
    path = tmp_path / "lg.npz"
    size = np.array(held_out_pair.image0.shape[:2][::-1])  # LightGlue's image_size is (W, H)
    np.savez(path, keypoints0=m.points0[:n], keypoints1=m.points1[:n], matches=idx,
             scores=np.ones(n), image_size0=size, image_size1=size)
    rc = cli_main(["predict", "--matches", str(path)])
    out, err = capsys.readouterr()
    assert rc == 1 and "pose: failed" in out and "fundamental matrix" in out
    assert "UserWarning" not in err and "formats.py" not in err and "READERS" not in err
    assert "warning: Expected one-to-one matches in 'matches'" in err
    assert "regression skipped: regression skipped" not in err + out
    assert "regression skipped: the model reads the images" in out + err
    assert "the network's coordinates are normalised" not in out + err



def test_intrinsics_of_each_image_from_a_posed_scene(tmp_path):
    """``--K transforms.json`` was parsed as a KITTI calib ('Expected a P0: row ... got keys
    ['"cx"', ...]'); now each image's K is looked up by file name, in the package's pixel
    convention (NeRF's cx / cy are pixel corners: -0.5 px)."""
    import argparse
    import json

    import cv2

    from strl_pyg.cli.readers import intrinsics_from_args, scene_intrinsics

    (tmp_path / "images").mkdir()
    for n in ("0001.png", "0002.png"):
        cv2.imwrite(str(tmp_path / "images" / n), np.zeros((40, 60), np.uint8))
    pose = np.eye(4).tolist()
    (tmp_path / "transforms.json").write_text(json.dumps({
        "fl_x": 50.0, "fl_y": 52.0, "cx": 30.0, "cy": 20.0, "w": 60, "h": 40, "frames": [
            {"file_path": "images/0001", "transform_matrix": pose},
            {"file_path": "images/0002.png", "transform_matrix": pose, "fl_x": 70.0}]}))
    args = argparse.Namespace(K=str(tmp_path / "transforms.json"), K0=None, K1=None,
                              image0=str(tmp_path / "images" / "0001.png"),
                              image1="elsewhere/0002.png")
    K0, K1 = intrinsics_from_args(args)
    np.testing.assert_allclose(K0, [[50, 0, 29.5], [0, 52, 19.5], [0, 0, 1]])
    np.testing.assert_allclose(K1[0, 0], 70.0)  # the frame's own focal length
    args.image1 = "0003.png"
    with pytest.raises(UsageError, match=r"Expected the image '0003.png' among the cameras of "
                                         r".*transforms.json' \(got 2 others: 0001, 0002.png"):
        intrinsics_from_args(args)
    (tmp_path / "other.json").write_text(json.dumps({"a": 1}))
    args.K = str(tmp_path / "other.json")
    with pytest.raises(UsageError, match="Expected a NeRF transforms.json"):
        intrinsics_from_args(args)
    # a list of images in a file not named cameras.json: not read as the folder's cameras.json
    (tmp_path / "mine.json").write_text(json.dumps({"images": []}))
    args.K = str(tmp_path / "mine.json")
    with pytest.raises(UsageError, match=r"Expected a NeRF .* \(got \['images'\] in 'mine.json'"):
        intrinsics_from_args(args)
    # an image read at half the stored size: K scaled to it (pixel centres)
    args.K, args.image1 = str(tmp_path / "transforms.json"), str(tmp_path / "images" / "0002.png")
    K0, _ = intrinsics_from_args(args, sizes=((20, 30), (40, 60)))
    np.testing.assert_allclose(K0, [[25, 0, 14.5], [0, 26, 9.5], [0, 0, 1]])  # (c + .5) s - .5
    with pytest.raises(UsageError, match=r"\(40x60 px, H x W\) \(got 40x30 px\)"):
        intrinsics_from_args(args, sizes=((40, 30), (40, 60)))
    # two cameras with one file name: the image's own path decides, a bare name is refused
    frames = [{"file_path": f"{cam}/0001.png", "transform_matrix": pose, "fl_x": f}
              for cam, f in (("cam0", 40.0), ("cam1", 80.0))]
    for cam in ("cam0", "cam1"):
        (tmp_path / cam).mkdir()
        cv2.imwrite(str(tmp_path / cam / "0001.png"), np.zeros((40, 60), np.uint8))
    (tmp_path / "transforms.json").write_text(json.dumps({"w": 60, "h": 40, "frames": frames}))
    args.image0, args.image1 = str(tmp_path / "cam1" / "0001.png"), "0001.png"
    assert scene_intrinsics(args.K, args.image0)[0, 0] == 80.0
    with pytest.raises(UsageError, match="Expected one camera for '0001.png'"):
        scene_intrinsics(args.K, args.image1)


def test_scene_cameras_read_once_per_source(tmp_path, monkeypatch):
    """``predict --pairs`` with ``--K SCENE`` looked up two images a pair and re-read the
    scene's cameras for each; now a source is read once while it is unchanged, each image
    still gets its own camera, and a changed source is read again."""
    import json
    import os

    import cv2

    from strl_pyg.cli import readers
    from strl_pyg.datasets import camera_files

    (tmp_path / "images").mkdir()
    for n in ("a.png", "b.png"):
        cv2.imwrite(str(tmp_path / "images" / n), np.zeros((40, 60), np.uint8))

    def write(f):  # image a's focal length f, b's f + 10
        (tmp_path / "cameras.json").write_text(json.dumps({"images": [
            {"file": f"images/{n}", "K": [[f + d, 0, 29.5], [0, f + d, 19.5], [0, 0, 1]],
             "T_cam_to_world": np.eye(4).tolist(), "width": 60, "height": 40}
            for n, d in (("a.png", 0.0), ("b.png", 10.0))]}))

    reads = []
    real = camera_files.read_posed_folder
    monkeypatch.setattr(camera_files, "read_posed_folder",
                        lambda path: reads.append(path) or real(path))

    def fx(n):
        return readers.scene_intrinsics(str(tmp_path), tmp_path / "images" / n)[0, 0]

    write(50.0)
    for _ in range(3):
        assert (fx("a.png"), fx("b.png")) == (50.0, 60.0)
    assert len(reads) == 1
    write(70.0)  # the same size, a new modification time: the source changed
    st = (tmp_path / "cameras.json").stat()
    os.utime(tmp_path / "cameras.json", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert (fx("a.png"), fx("b.png")) == (70.0, 80.0)
    assert len(reads) == 2


def test_nerf_cameras_named_cameras_json_read_frame_by_frame(tmp_path):
    """A NeRF file is read one frame at a time: the memo keeps each frame apart, whatever the
    file's name (a NeRF ``cameras.json`` gave the second image 'not among the cameras')."""
    import json

    from strl_pyg.cli.readers import scene_intrinsics

    pose = np.eye(4).tolist()
    (tmp_path / "cameras.json").write_text(json.dumps({
        "fl_x": 50.0, "fl_y": 50.0, "cx": 30.0, "cy": 20.0, "w": 60, "h": 40, "frames": [
            {"file_path": "images/a.png", "transform_matrix": pose},
            {"file_path": "images/b.png", "transform_matrix": pose, "fl_x": 90.0}]}))
    source = str(tmp_path / "cameras.json")
    assert scene_intrinsics(source, "a.png")[0, 0] == 50.0
    assert scene_intrinsics(source, "b.png")[0, 0] == 90.0
    assert scene_intrinsics(source, "a.png")[0, 0] == 50.0
