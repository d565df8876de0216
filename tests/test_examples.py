"""The example scripts run (each is one runnable script with --help)."""

import importlib.util
import re
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", ["train", "evaluate", "pose_from_matches", "reuse_layers"])
def test_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        load(name).main(["--help"])
    assert exc.value.code == 0 and "usage" in capsys.readouterr().out


def test_reuse_layers_dense_equals_explicit(capsys):
    assert load("reuse_layers").main(["--steps", "5"]) == 0
    out = capsys.readouterr().out
    diff = float(re.search(r"difference\| of the logits: (\S+)", out).group(1))
    assert diff < 1e-5


def test_pose_from_matches_on_a_saved_file(tmp_path, capsys, generated_pair):
    from strl_pyg.model import StrLPoseConfig
    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.synthetic import SceneConfig

    ckpt = tmp_path / "tiny.pt"
    StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1)).save(ckpt)
    pair = generated_pair(5, SceneConfig(kind="boxes", image_size=(96, 128)))
    npz = pair.matches.save(tmp_path / "m.npz")
    assert load("pose_from_matches").main(["--npz", str(npz), "--checkpoint", str(ckpt)]) == 0
    out = capsys.readouterr().out
    assert "T_0to1 (Str-L Pose)" in out and "T_0to1 (OpenCV MAGSAC)" in out


@pytest.fixture(scope="module")
def generated_pair_files(tmp_path_factory, generated_pair):
    """A generated pair written as another tool would: images as PNG, a SuperGlue
    ``match_pairs.py`` npz (no sizes) and a LightGlue dict (batched, sizes as (W, H))."""
    import cv2
    import numpy as np

    from strl_pyg.model import StrLPoseConfig
    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.synthetic import SceneConfig

    root = tmp_path_factory.mktemp("pair")
    pair = generated_pair(5, SceneConfig(kind="boxes", image_size=(96, 128)))
    m = pair.matches
    for i, img in enumerate((m.image0, m.image1)):
        cv2.imwrite(str(root / f"im{i}.png"), img)
    n = m.num_points
    order = np.random.default_rng(0).permutation(n)  # keypoints1 in another order
    kp1 = np.empty_like(m.points1)
    kp1[order] = m.points1
    extra = np.array([[3.0, 4.0]])  # an unmatched keypoint in image 0
    np.savez(root / "superglue.npz", keypoints0=np.concatenate([m.points0, extra]),
             keypoints1=kp1, matches=np.append(order, -1),
             match_confidence=np.append(np.full(n, 0.9), 0.0))
    lightglue = dict(keypoints0=m.points0[None], keypoints1=kp1[None],
                     matches=np.stack([np.arange(n), order], 1)[None], scores=np.ones((1, n)),
                     image_size0=np.array([[128, 96]]), image_size1=np.array([[128, 96]]))
    np.savez(root / "lightglue.npz", **lightglue)
    ckpt = root / "tiny.pt"
    StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1,
                            visual="pixel")).save(ckpt)
    K = m.K0
    return dict(root=root, ckpt=str(ckpt), lightglue=lightglue,
                K=f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}")


def _run_pfm(files, *argv):
    return load("pose_from_matches").main(["--checkpoint", files["ckpt"], "--K", files["K"],
                                           *argv])


def test_pose_from_matches_superglue_with_images(generated_pair_files, capsys):
    f = generated_pair_files
    assert _run_pfm(f, "--npz", str(f["root"] / "superglue.npz"), "--image0",
                    str(f["root"] / "im0.png"), "--image1", str(f["root"] / "im1.png")) == 0
    out = capsys.readouterr().out
    assert "T_0to1 (Str-L Pose)" in out and "T_0to1 (PoseLib)" in out and "note:" not in out


def test_pose_from_matches_superglue_sizes_only_falls_back(generated_pair_files, capsys):
    f = generated_pair_files
    assert _run_pfm(f, "--npz", str(f["root"] / "superglue.npz"), "--size", "96", "128") == 0
    out = capsys.readouterr().out
    assert "Str-L Pose skipped, classical methods only" in out and "--image0" in out
    assert "T_0to1 (Str-L Pose)" not in out and "T_0to1 (OpenCV MAGSAC)" in out


def test_pose_from_matches_superglue_without_sizes_says_what_to_give(generated_pair_files,
                                                                     capsys):
    # reproduction (stop 46): it printed argparse's usage block before its error line, where
    # its docstring and docs/bad_input.md promise one line
    f = generated_pair_files
    assert _run_pfm(f, "--npz", str(f["root"] / "superglue.npz")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: Expected")
    assert "--size0 H W" in err and "--image0" in err
    assert "Traceback" not in err and "usage:" not in err


def test_pose_from_matches_lightglue_dict(generated_pair_files, capsys):
    f = generated_pair_files
    assert _run_pfm(f, "--npz", str(f["root"] / "lightglue.npz"), "--image0",
                    str(f["root"] / "im0.png"), "--image1", str(f["root"] / "im1.png")) == 0
    out = capsys.readouterr().out
    assert "T_0to1 (Str-L Pose)" in out and "T_0to1 (OpenCV MAGSAC)" in out
    # the same dict in memory reads to the same matches (sizes from its (W, H) image_size)
    from strl_pyg.data.external import load_external_matches

    m = load_external_matches(f["lightglue"])
    assert m.image_size0 == (96, 128) and m.num_points == len(f["lightglue"]["scores"][0])


def test_pose_from_matches_matched_file_with_per_image_sizes(generated_pair_files, tmp_path,
                                                             capsys):
    import numpy as np

    f = generated_pair_files
    sg = np.load(f["root"] / "superglue.npz")
    keep = sg["matches"] >= 0
    np.savez(tmp_path / "mk.npz", mkpts0=sg["keypoints0"][keep],
             mkpts1=sg["keypoints1"][sg["matches"][keep]])
    assert _run_pfm(f, "--npz", str(tmp_path / "mk.npz"), "--size0", "96", "128",
                    "--size1", "96", "128") == 0
    out = capsys.readouterr().out
    assert "classical methods only" in out and "T_0to1 (PoseLib)" in out


@pytest.mark.parametrize("argv, needle", [
    (["--stpes", "3"], "did you mean --steps?"),
    (["--model", "Full"], "invalid choice: 'Full'"),
    (["--set", "hidden"], "Expected --set KEY=VALUE (got 'hidden')"),
    (["--lr", "abc"], "invalid float value: 'abc'"),
])
def test_train_example_bad_flags_are_one_line_like_strl_pose_train(argv, needle, capsys):
    # reproduction: examples/train.py printed argparse's usage block before its error line,
    # where docs/bad_input.md promises one line (strl-pose train already gave one)
    assert load("train").main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: Expected") and needle in err
    assert "usage:" not in err
