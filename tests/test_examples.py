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


def test_pose_from_matches_on_a_saved_file(tmp_path, capsys):
    from strl_pyg.model import StrLPose, StrLPoseConfig
    from strl_pyg.synthetic import SceneConfig, generate_pair

    ckpt = tmp_path / "tiny.pt"
    StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1)).save(ckpt)
    pair = generate_pair(5, SceneConfig(kind="boxes", image_size=(96, 128)))
    npz = pair.matches.save(tmp_path / "m.npz")
    assert load("pose_from_matches").main(["--npz", str(npz), "--checkpoint", str(ckpt)]) == 0
    out = capsys.readouterr().out
    assert "T_0to1 (Str-L Pose)" in out and "T_0to1 (OpenCV MAGSAC)" in out
