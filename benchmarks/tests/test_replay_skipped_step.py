"""benchmarks/studies/replay_skipped_step.py: a training step skipped for a non-finite gradient
is replayed from its ``skipped/stepN.pt`` under autograd's anomaly mode, which names the
operation whose backward first returned NaN. (That the step is skipped and its file rebuilds
the same forward pass is tests/training/test_training_safety.py.)"""

from __future__ import annotations

from dataclasses import replace

import pytest
import replay_skipped_step as replay
import torch

from strl_pyg.training import TrainConfig, train


def _tiny(out_dir, **kw):
    base = TrainConfig(
        train_pairs=6, val_pairs=3, batch_size=4, steps=4, val_every=2, num_points=32,
        num_lines=16, out_dir=str(out_dir), tensorboard=False, seed=3,
        scene={"image_size": [96, 256], "max_points": 64, "max_lines": 32},
        model_overrides={"hidden": 16, "layers": 1, "heads": 2, "patch_features": 1},
        lr_schedule="constant")
    return replace(base, **kw)



@pytest.mark.slow  # a training run: the slow tier
def test_the_replay_names_the_operation_whose_backward_gave_nan(tmp_path, plant_nan_gradients):
    plant_nan_gradients({2})
    train(_tiny(tmp_path / "run"), progress=False)
    files = sorted((tmp_path / "run" / "skipped").iterdir())
    assert [f.name for f in files] == ["step000002.pt"]
    plant_nan_gradients({-1})  # the replay's loss carries the planted term too
    # sqrt(0 * x): sqrt's backward gives inf, the product's backward 0 * inf = NaN
    with pytest.warns(UserWarning, match="Error detected in MulBackward0"):
        r = replay.replay(str(files[0]))
    assert r["step"] == 2 and "MulBackward0' returned nan" in r["anomaly"]
    assert r["grad_norm"] != r["grad_norm"]  # NaN


def test_a_file_that_is_not_a_skipped_step_is_one_line(tmp_path, capsys):
    torch.save({"step": 3}, tmp_path / "x.pt")
    assert replay.main([str(tmp_path / "x.pt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: Expected a skipped-step file") and "\n" not in err
