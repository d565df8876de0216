"""Every checkpoint loads with ``torch.load(weights_only=True)``: model files, training
checkpoints (``--resume``), ``--init-from`` weights. A planted malicious pickle is refused with
a one-line error and never runs; no message advises turning safe loading off."""

import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from strl_pyg import cli
from strl_pyg.model import StrLPoseConfig
from strl_pyg.model.strl_pose import StrLPose
from strl_pyg.training import CHECKPOINT_VERSION, load_checkpoint, save_checkpoint
from strl_pyg.training.checkpoints import init_weights, rng_state, set_rng_state
from strl_pyg.utils.io import UnsafeFileError, one_line, safe_torch_load

REPO = Path(__file__).resolve().parents[2]
UNSAFE_ADVICE = ("weights_only", "allow_pickle", "safe_globals", "trust the source")


class _Planted:
    """Unpickling this object opens (creates) the marker file: code runs on load."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _plant(path: Path, marker: Path, wrap_as_training: bool = False) -> Path:
    payload = {"format": "strl_pyg.StrLPose", "version": 1, "config": {}, "state_dict": {},
               "evil": _Planted(marker)}
    if wrap_as_training:
        payload = {"version": CHECKPOINT_VERSION, "train_config": {}, "model_config": {},
                   "model": _Planted(marker), "optimizer": {}, "step": 0}
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(payload, path)
    return path


def _assert_clean_refusal(text: str) -> None:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    assert lines[0].startswith("error: Expected") and "refused" in lines[0], text
    assert not any(a in text for a in UNSAFE_ADVICE), text
    assert "Traceback" not in text


def tiny_model() -> StrLPose:
    return StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=1))


@pytest.mark.parametrize("loader", [StrLPose.load, load_checkpoint, safe_torch_load])
def test_library_loaders_refuse_a_planted_pickle(loader, tmp_path):
    marker = tmp_path / "marker"
    path = _plant(tmp_path / "evil.pt", marker)
    with pytest.raises(UnsafeFileError, match="refused, nothing was run") as exc:
        loader(path)
    assert "io.open" in str(exc.value) and "\n" not in str(exc.value)
    assert not any(a in str(exc.value) for a in UNSAFE_ADVICE)
    assert not marker.exists()


def test_init_weights_refuses_a_planted_pickle(tmp_path):
    marker = tmp_path / "marker"
    for wrap in (False, True):
        path = _plant(tmp_path / f"evil{wrap}.pt", marker, wrap_as_training=wrap)
        with pytest.raises(UnsafeFileError):
            init_weights(tiny_model(), path)
    assert not marker.exists()


@pytest.mark.parametrize("command", ["demo", "resume", "init-from", "bench", "evaluate"])
def test_cli_refuses_a_planted_pickle_in_one_line(command, tmp_path, capsys, monkeypatch):
    marker = tmp_path / "marker"
    evil = _plant(tmp_path / "evil.pt", marker)
    run = tmp_path / "run"
    train_fast = ["--train-pairs", "2", "--val-pairs", "1", "--batch-size", "1", "--steps", "1",
                  "--no-progress", "--no-tensorboard", "--out", str(run)]
    argv = {
        "demo": ["demo", "--checkpoint", str(evil), "--out", str(tmp_path / "o")],
        "resume": ["train", *train_fast, "--resume"],
        "init-from": ["train", *train_fast, "--init-from", str(evil)],
        "bench": ["bench", "--checkpoint", str(evil), "--repeat", "1"],
        "evaluate": ["evaluate", "--checkpoint", str(evil), "--num-pairs", "1"],
    }[command]
    if command == "resume":
        _plant(run / "last.pt", marker, wrap_as_training=True)
    assert cli.main(argv) == 2
    _assert_clean_refusal(capsys.readouterr().err)
    assert not marker.exists()


@pytest.mark.slow
def test_examples_train_refuses_a_planted_pickle_in_a_subprocess(tmp_path):
    marker = tmp_path / "marker"
    evil = _plant(tmp_path / "evil.pt", marker)
    proc = subprocess.run(
        [sys.executable, str(REPO / "examples" / "train.py"), "--init-from", str(evil),
         "--steps", "1", "--train-pairs", "2", "--val-pairs", "1", "--batch-size", "1",
         "--no-progress", "--no-tensorboard", "--out", str(tmp_path / "run")],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    _assert_clean_refusal(proc.stderr)
    assert not marker.exists()


def test_training_checkpoint_loads_with_weights_only_and_restores_rng(tmp_path, generated_pair):
    model = tiny_model()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    model(_one_graph(generated_pair)).quaternion.sum().backward()
    opt.step()
    torch.manual_seed(5)
    np.random.seed(6)  # noqa: NPY002
    random.seed(7)
    np.random.normal()  # noqa: NPY002  (sets numpy's cached-gaussian flag)
    state = {"version": CHECKPOINT_VERSION, "train_config": {"seed": 0}, "step": 3,
             "model_config": model.config.to_dict(), "model": model.state_dict(),
             "optimizer": opt.state_dict(), "rng": rng_state(), "history": [{"step": 3}]}
    expected = (torch.rand(3), np.random.rand(3), np.random.normal(), random.random())  # noqa: NPY002
    path = save_checkpoint(tmp_path / "last.pt", state)
    raw = torch.load(path, weights_only=True)  # the safe loader reads every value
    assert raw["step"] == 3 and raw["optimizer"]["param_groups"][0]["lr"] == 1e-3
    loaded = load_checkpoint(path)
    torch.rand(10), np.random.rand(10), random.random()  # noqa: NPY002  (move the generators)
    set_rng_state(loaded["rng"])
    got = (torch.rand(3), np.random.rand(3), np.random.normal(), random.random())  # noqa: NPY002
    assert torch.equal(got[0], expected[0]) and np.array_equal(got[1], expected[1])
    assert got[2] == expected[2] and got[3] == expected[3]
    opt2 = torch.optim.Adam(tiny_model().parameters(), lr=1e-3)
    opt2.load_state_dict(loaded["optimizer"])  # the optimiser state round-trips


def test_save_checkpoint_refuses_values_the_safe_loader_cannot_read(tmp_path):
    with pytest.raises(TypeError, match=r"numpy.ndarray at state\['rng'\]\['numpy'\]"):
        save_checkpoint(tmp_path / "last.pt", {"rng": {"numpy": np.zeros(3)}})
    assert not list(tmp_path.iterdir())


def test_version_1_training_checkpoint_gets_a_way_forward(tmp_path):
    path = tmp_path / "last.pt"
    torch.save({"version": 1, "rng": {"numpy": np.random.get_state()}}, path)  # noqa: NPY002
    with pytest.raises(UnsafeFileError, match="--init-from") as exc:
        load_checkpoint(path)
    assert not any(a in str(exc.value) for a in UNSAFE_ADVICE)


@pytest.mark.parametrize("content, message", [
    (b"", "readable"), (b"PK\x03\x04garbage", "readable"), (None, "folder"),
])
def test_corrupt_empty_and_folder_checkpoints_one_line(content, message, tmp_path):
    path = tmp_path / "x.pt"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    with pytest.raises((ValueError, OSError), match=message) as exc:
        StrLPose.load(path)
    assert "\n" not in str(exc.value)


def test_empty_npz_as_checkpoint_is_not_a_pickle_refusal(tmp_path):
    path = tmp_path / "m.npz"
    np.savez(path)
    with pytest.raises(ValueError, match="Expected a readable StrLPose checkpoint") as exc:
        StrLPose.load(path)
    assert not isinstance(exc.value, UnsafeFileError)


def test_one_line_drops_advice_to_disable_safe_loading():
    text = ("Weights only load failed. Re-running `torch.load` with `weights_only` set to "
            "`False` will likely succeed.\n\tmore")
    assert one_line(text) == "Weights only load failed."
    assert one_line(ValueError("")) == "ValueError"
    assert one_line("\x1b[1mbold\x1b[0m line\nsecond") == "bold line"


def _one_graph(generated_pair):
    from strl_pyg.data import FixedSizeResample, build_pair_graph

    return FixedSizeResample(32, 16, seed=0)(build_pair_graph(generated_pair(0).matches))


def test_a_damaged_copy_is_refused_not_loaded_with_changed_weights(tmp_path):
    # reproduction: one flipped bit in a weight tensor's bytes loaded silently (torch.load does
    # not check the archive's CRC-32), and predict gave an `ok` pose from changed weights
    import zipfile

    path = tmp_path / "model.pt"
    tiny_model().save(path)
    StrLPose.load(path)  # the intact file loads
    with zipfile.ZipFile(path) as z:
        info = max(z.infolist(), key=lambda i: i.file_size)  # the largest tensor record
        assert info.compress_type == zipfile.ZIP_STORED
        start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    raw = bytearray(path.read_bytes())
    raw[start + info.file_size // 2] ^= 0x01
    bad = tmp_path / "damaged.pt"
    bad.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"damaged file: record '.*' fails its checksum") as exc:
        StrLPose.load(bad)
    assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match=r"fails its checksum"):
        safe_torch_load(bad)


def test_an_empty_file_is_named_as_such(tmp_path):
    path = tmp_path / "model.pt"
    path.write_bytes(b"")
    with pytest.raises(ValueError, match=r"got an empty file, 0 bytes"):
        StrLPose.load(path)


def test_init_from_names_geometric_only_where_it_is_not_allowed(tmp_path):
    # adding the geometric head to regression-only weights is allowed, so that difference is
    # not listed; the other direction fails (the file's head has nowhere to go) and says why
    plain = tmp_path / "plain.pt"
    geo = tmp_path / "geo.pt"
    tiny_model().save(plain)
    StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=1,
                            geometric=True)).save(geo)
    init_weights(StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=1,
                                          geometric=True)), plain)  # allowed
    with pytest.raises(ValueError, match=r"geometric True vs False"):
        init_weights(tiny_model(), geo)
    wider = StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2, patch_features=1,
                                    geometric=True))
    with pytest.raises(ValueError, match=r"hidden 16 vs 32") as exc:
        init_weights(wider, plain)
    assert "geometric False vs True" not in str(exc.value)
