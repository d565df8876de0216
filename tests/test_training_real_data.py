"""Training on the real data slices (KITTI 06 frames 0-50, one DeMoN test sequence):
validation sources that do not exist fail before any training, and the default model trains
on each dataset's graphs. Tiny step counts; each test skips where its slice is absent."""

from __future__ import annotations

import warnings

import pytest
import torch

from strl_pyg.train_config import TrainConfig
from strl_pyg.train_data import build_datasets
from strl_pyg.training import train

TINY = {"hidden": 16, "layers": 1, "heads": 2}


def real_config(tmp_path, **kw) -> TrainConfig:
    base = dict(limit=2, batch_size=2, steps=2, val_every=2, num_points=32, num_lines=16,
                out_dir=str(tmp_path / "run"), cache_dir=str(tmp_path / "cache"),
                tensorboard=False, model_overrides=dict(TINY))
    return TrainConfig(**{**base, **kw})


def test_kitti_absent_validation_sequences_fail_before_any_matching(kitti_root, tmp_path):
    cfg = real_config(tmp_path, dataset="kitti", data_root=str(kitti_root))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the skipped training sequences 00-05, 07, 08
        with pytest.raises(ValueError) as exc:
            build_datasets(cfg)
    msg = str(exc.value)
    assert "09" in msg and "10" in msg and "--val-sequences" in msg and "06" in msg
    assert not (tmp_path / "cache").exists()  # refused before matching a single pair


def test_kitti_trains_and_validates_on_the_sequences_that_exist(kitti_root, tmp_path):
    cfg = real_config(tmp_path, dataset="kitti", data_root=str(kitti_root),
                      train_sequences=["06"], val_sequences=["06"])
    with pytest.warns(UserWarning, match="both the training and the validation"):
        result = train(cfg, progress=False)
    assert result["step"] == 2 and result["history"]
    assert (tmp_path / "run" / "model.pt").is_file()


def test_an_empty_validation_set_is_refused_before_the_first_step(tmp_path):
    from strl_pyg.data.datasets import SyntheticPairs

    cfg = TrainConfig(train_pairs=2, batch_size=2, steps=2, val_every=1, num_points=16,
                      num_lines=8, out_dir=str(tmp_path / "run"), tensorboard=False,
                      model_overrides=dict(TINY))
    sets = (SyntheticPairs(2, seed=0), torch.utils.data.Subset(SyntheticPairs(1, seed=9), []))
    with pytest.raises(ValueError, match="validation"):
        train(cfg, datasets=sets, progress=False)
    assert not (tmp_path / "run" / "log.csv").exists()
