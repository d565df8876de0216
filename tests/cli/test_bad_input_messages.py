"""Messages that name the real cause ("First contact, round 3"), each in the house form
"Expected ... (got ...)": a training checkpoint where a model is expected, ``--init-from``
weights of another architecture, a method name given as a str, a closed stdout, ``--out`` a
folder, uint16 images, and the demo's sizes and method names."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from strl_pyg import cli
from strl_pyg.inference.estimator import PoseEstimator
from strl_pyg.model import StrLPoseConfig
from strl_pyg.model.strl_pose import StrLPose
from strl_pyg.training.checkpoints import (
    CHECKPOINT_VERSION,
    init_weights,
    load_training_model,
    save_checkpoint,
)
from strl_pyg.utils.images import check_image, read_image_file

REPO = Path(__file__).resolve().parents[2]


def tiny(**kw) -> StrLPose:
    return StrLPose(StrLPoseConfig(**{"hidden": 16, "layers": 1, "heads": 2,
                                      "patch_features": 1, **kw}))


def _last_pt(folder: Path, model: StrLPose, step: int = 7) -> Path:
    return save_checkpoint(folder / "last.pt", {
        "version": CHECKPOINT_VERSION, "train_config": {}, "model_config": model.config.to_dict(),
        "model": model.state_dict(), "optimizer": {}, "step": step})


# ----------------------------------------------------------------------------- checkpoints
def test_a_training_checkpoint_where_a_model_is_expected_says_how_to_get_the_model(tmp_path):
    """Before: "Expected a 'strl_pyg.StrLPose' checkpoint at .../last.pt (got None)"."""
    model = tiny()
    path = _last_pt(tmp_path, model)
    with pytest.raises(ValueError) as exc:
        StrLPose.load(path)
    text = str(exc.value)
    assert text.startswith("Expected a 'strl_pyg.StrLPose' checkpoint") and "\n" not in text
    assert "got a training checkpoint" in text and "step 7" in text and "got None" not in text
    assert "model.pt" in text and "load_training_model" in text
    # the way it names works, and gives the same weights
    built = load_training_model(path)
    for k, v in model.state_dict().items():
        assert (built.state_dict()[k] == v).all()
    # with the run's model.pt beside it, the message names that file
    model.save(tmp_path / "model.pt")
    with pytest.raises(ValueError, match=r"pass '.*model\.pt' \(the same run's model\)"):
        PoseEstimator(str(path))


def test_a_training_checkpoint_for_predict_is_one_line(tmp_path, capsys, generated_pair):
    path = _last_pt(tmp_path, tiny())
    pair = generated_pair(0)
    for name, img in (("a.png", pair.image0), ("b.png", pair.image1)):
        cv2.imwrite(str(tmp_path / name), img)
    argv = ["predict", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "--checkpoint",
            str(path)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "got a training checkpoint" in err


def test_init_from_another_architecture_names_the_mismatch(tmp_path):
    """Before: "(got Error(s) in loading state_dict for StrLPose:)", nothing named."""
    small = tiny()
    small.save(tmp_path / "model.pt")
    _last_pt(tmp_path, small)
    for name in ("model.pt", "last.pt"):
        with pytest.raises(ValueError) as exc:
            init_weights(tiny(hidden=32, layers=2), tmp_path / name)
        text = str(exc.value)
        assert text.startswith("Expected weights matching this run's model config")
        assert "\n" not in text and "Error(s) in loading" not in text
        assert "config fields (file vs model) hidden 16 vs 32, layers 1 vs 2" in text
        assert "mis-shaped (file vs model) keys sce.mlp.0.weight [8, 8] vs [16, 8]" in text
        assert "missing keys layers.1." in text and "in all)" in text
    # the same architecture loads; a geometric head may start from regression-only weights
    init_weights(tiny(), tmp_path / "model.pt")
    init_weights(tiny(geometric=True), tmp_path / "model.pt")
    with pytest.raises(ValueError, match="unexpected keys inlier_head"):
        init_weights(tiny(), _save(tiny(geometric=True), tmp_path / "geo.pt"))


def _save(model, path):
    model.save(path)
    return path


# ----------------------------------------------------------------------------- estimator
def test_one_method_name_as_a_str_is_one_method():
    """Before: ``methods="poselib"`` was read letter by letter: (got ['p', 'o', 's', ...])."""
    assert PoseEstimator(methods="opencv").method_names == ("opencv",)
    with pytest.raises(ValueError, match=r"Expected methods from .* \(got \['nope'\]\)"):
        PoseEstimator(methods="nope")


# ----------------------------------------------------------------------------- command line
@pytest.mark.slow
def test_a_closed_stdout_ends_quietly(tmp_path, generated_pair):
    """Before: ``strl-pose predict --json | head`` ended with "error: Expected a usable path
    (got Broken pipe)", blaming a path. (A match file: the output path is what is tested, and
    it skips the front end.)"""
    path = generated_pair(2_000_017).matches.save(tmp_path / "m.npz")
    for extra in (["--json"], []):
        proc = subprocess.Popen(
            [sys.executable, "-m", "strl_pyg.cli.commands", "predict", "--matches", str(path),
             "--bootstrap", "0", "--methods", "poselib", *extra],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
        proc.stdout.close()  # the reader is gone before anything is written
        code = proc.wait(timeout=300)
        err = proc.stderr.read().decode()
        proc.stderr.close()
        assert code == 141, err
        assert "Broken pipe" not in err and "error" not in err and "Traceback" not in err


def test_run_guarded_maps_a_broken_pipe_to_141(capsys):
    def writes_to_a_closed_pipe():
        raise BrokenPipeError(32, "Broken pipe")

    assert cli.run_guarded(writes_to_a_closed_pipe) == 141
    assert capsys.readouterr().err == ""


@pytest.fixture
def no_frontend(monkeypatch):
    import strl_pyg.frontend

    def boom(*a, **k):
        raise AssertionError("the front end ran before the output was checked")

    monkeypatch.setattr(strl_pyg.frontend, "match_images", boom)


@pytest.mark.parametrize("flag", ["--out", "--png"])
def test_match_out_naming_a_folder_is_refused_with_the_file_to_add(flag, tmp_path, capsys,
                                                                   monkeypatch, no_frontend):
    """Before: ``--out outdir/`` (not existing) wrote a file named ``outdir``."""
    monkeypatch.chdir(tmp_path)
    img = tmp_path / "img.png"
    cv2.imwrite(str(img), np.random.default_rng(0).integers(0, 255, (60, 80), np.uint8))
    outputs = ["--out", "outdir/"] if flag == "--out" else ["--out", "m.npz", "--png", "outdir/"]
    argv = ["match", str(img), str(img), *outputs]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: Expected a file path for {flag}")
    name = "matches.npz" if flag == "--out" else "matches.png"
    assert f"(got 'outdir/', which names a folder; e.g. 'outdir/{name}')" in err
    assert not (tmp_path / "outdir").exists()


def test_uint16_images_agree_between_the_command_line_and_the_api(tmp_path, generated_pair):
    """Before: a 16-bit PNG was read (scaled to 8 bits) by the CLI and a uint16 array refused
    by the API (PairMatches, the front end): now both scale alike, v // 257."""
    rng = np.random.default_rng(0)
    deep = rng.integers(0, 65536, (48, 64), dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "deep.png"), deep)
    from_file = read_image_file(tmp_path / "deep.png")
    from_array = check_image(deep, "image0")
    assert from_file.dtype == from_array.dtype == np.uint8
    np.testing.assert_array_equal(from_file, from_array)
    np.testing.assert_array_equal(from_array, (deep // 257).astype(np.uint8))
    assert check_image(np.full((4, 4), 65535, np.uint16), "x").max() == 255
    rgb = rng.integers(0, 65536, (48, 64, 3), dtype=np.uint16)
    assert check_image(rgb, "x", grayscale=True).shape == (48, 64)
    # a pair given as uint16 arrays is matched like its 8-bit files
    pair = generated_pair(2_000_017)
    est = PoseEstimator(methods="opencv").estimate_images(
        pair.image0.astype(np.uint16) * 257, pair.image1.astype(np.uint16) * 257, K0=pair.K)
    ref = PoseEstimator(methods="opencv").estimate_images(pair.image0, pair.image1, K0=pair.K)
    assert est.status == ref.status == "ok"
    np.testing.assert_allclose(est.T_0to1, ref.T_0to1, atol=1e-12)
    with pytest.raises(TypeError, match=r"Expected 'x' of dtype uint8, float32 or float64, or "
                                        r"uint16 \(got int32\)"):
        check_image(np.zeros((4, 4), np.int32), "x")
