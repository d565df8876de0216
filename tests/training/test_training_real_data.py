"""Training on the real data slices (KITTI 06 frames 0-50, one DeMoN test sequence):
validation sources that do not exist fail before any training, and the default model trains
on each dataset's graphs. Tiny step counts; each test skips where its slice is absent."""

from __future__ import annotations

import warnings

import pytest
import torch

from strl_pyg.data import keys as keys_
from strl_pyg.training.config import TrainConfig
from strl_pyg.training.data import build_datasets
from strl_pyg.training.loop import train

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


@pytest.mark.slow
def test_kitti_trains_and_validates_on_the_sequences_that_exist(kitti_root, tmp_path):
    cfg = real_config(tmp_path, dataset="kitti", data_root=str(kitti_root),
                      train_sequences=["06"], val_sequences=["06"])
    with pytest.warns(UserWarning, match="both the training and the validation"):
        result = train(cfg, progress=False)
    assert result["step"] == 2 and result["history"]
    assert (tmp_path / "run" / "model.pt").is_file()


def test_an_empty_validation_set_is_refused_before_the_first_step(tmp_path):
    from strl_pyg.datasets import SyntheticPairs

    cfg = TrainConfig(train_pairs=2, batch_size=2, steps=2, val_every=1, num_points=16,
                      num_lines=8, out_dir=str(tmp_path / "run"), tensorboard=False,
                      model_overrides=dict(TINY))
    sets = (SyntheticPairs(2, seed=0), torch.utils.data.Subset(SyntheticPairs(1, seed=9), []))
    with pytest.raises(ValueError, match="validation"):
        train(cfg, datasets=sets, progress=False)
    assert not (tmp_path / "run" / "log.csv").exists()


@pytest.fixture
def demon_train_root(demon_root, tmp_path):
    """The shipped DeMoN slice has only ``test/``: its one sequence serves as ``train/`` too
    (links, nothing copied)."""
    seq = next((demon_root / "test").glob("mvs_test_*"), None)
    if seq is None:
        pytest.skip(f"no DeMoN test sequence under {demon_root / 'test'}")
    root = tmp_path / "demon"
    for split in ("train", "test"):
        (root / split).mkdir(parents=True)
        (root / split / seq.name).symlink_to(seq, target_is_directory=True)
    return root


@pytest.mark.slow
def test_demon_trains_on_defaults_with_rgb_patches(demon_train_root, tmp_path):
    cfg = real_config(tmp_path, dataset="demon", data_root=str(demon_train_root), limit=None,
                      batch_size=1)
    assert cfg.model_config().patch_features == 3  # DeMoN is RGB (DATA_CHANNELS)
    train_ds, _ = build_datasets(cfg)
    assert train_ds[0][keys_.POINT][keys_.PATCH0].shape[1] == 3
    result = train(cfg, progress=False, datasets=(train_ds, _))
    assert result["step"] == 2 and (tmp_path / "run" / "model.pt").is_file()


@pytest.mark.slow
def test_demon_grey_model_gets_grey_patches(demon_train_root, tmp_path):
    """A grey model (e.g. fine-tuning the shipped weights) gets grey DeMoN graphs."""
    cfg = real_config(tmp_path, dataset="demon", data_root=str(demon_train_root), limit=None,
                      batch_size=1, model_overrides={**TINY, "patch_features": 1,
                                                     "image_channels": 1})
    train_ds, val_ds = build_datasets(cfg)
    assert train_ds[0][keys_.POINT][keys_.PATCH0].shape[1] == 1
    assert train(cfg, progress=False, datasets=(train_ds, val_ds))["step"] == 2


def test_patch_channels_that_do_not_fit_the_data_fail_before_the_first_step(tmp_path):
    from strl_pyg.datasets import SyntheticPairs

    cfg = TrainConfig(train_pairs=2, val_pairs=1, batch_size=2, steps=2, num_points=16,
                      num_lines=8, out_dir=str(tmp_path / "run"), tensorboard=False,
                      model_overrides={**TINY, "patch_features": 3})
    with pytest.raises(ValueError, match="patch_features=1 --set image_channels=1"):
        train(cfg, progress=False)
    assert not (tmp_path / "run" / "log.csv").exists()
    from strl_pyg.training.data import check_graph_channels

    cnn = TrainConfig(model="R", model_overrides={**TINY, "image_channels": 3}).model_config()
    graph = SyntheticPairs(1, seed=0, keep_images=True)[0]
    with pytest.raises(ValueError, match="image_channels=1"):
        check_graph_channels(cnn, 1, graph)
