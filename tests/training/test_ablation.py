"""The training package's side of the ablation study (Table 3): every row trains and infers
on one shared front-end cache, a second run does not recompute it, rows of other seeds train on
the same pairs in the same order. The study's script (benchmarks/ablation.py: its plan, the
workers' claims, the report) is tested in benchmarks/tests/test_ablation.py."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from strl_pyg.datasets import synthetic as synthetic_ds
from strl_pyg.inference.network import network_pose
from strl_pyg.model import ABLATIONS
from strl_pyg.synthetic.distributions import scene_distribution
from strl_pyg.training import TrainConfig, train
from strl_pyg.training.sampling import StepBatchSampler


def _tiny(row: str, tmp_path: Path, **kw) -> TrainConfig:
    return TrainConfig(scene_mix="lines_small", matches="frontend",
                       cache_dir=str(tmp_path / "cache"), train_pairs=4, val_pairs=2, steps=2,
                       val_every=2, batch_size=2, num_points=32, num_lines=16, model=row,
                       model_overrides=dict(hidden=16, layers=1, heads=2), tensorboard=False,
                       out_dir=str(tmp_path / "runs" / row.replace("+", "p")), **kw)


@pytest.mark.slow
def test_every_row_trains_and_infers_on_one_shared_cache(tmp_path, monkeypatch, generated_pair):
    first = train(_tiny("full", tmp_path), progress=False)
    folders = list((tmp_path / "cache").iterdir())
    assert len(folders) == 1  # one fingerprint: the rows share the matches

    def no_matching(*args, **kwargs):
        raise AssertionError("the front end ran again: the cache was not reused")

    monkeypatch.setattr(synthetic_ds, "_match_synthetic", no_matching)
    pair = generated_pair(7, scene_distribution("lines_small").config(7))
    for row in ABLATIONS:
        res = first if row == "full" else train(_tiny(row, tmp_path), progress=False)
        assert res["step"] == 2 and torch.isfinite(torch.tensor(res["rot_err_deg"]))
        out = network_pose(res["model"], pair.matches, resample=(32, 16))
        assert out.quaternion.shape == (1, 4) and torch.isfinite(out.translation).all()
    assert list((tmp_path / "cache").iterdir()) == folders


def test_seeds_vary_the_initialisation_not_the_data():
    a = TrainConfig(seed=0, data_seed=0)
    b = TrainConfig(seed=2, data_seed=0)
    assert a.resolved_data_seed == b.resolved_data_seed == 0
    assert TrainConfig(seed=2).resolved_data_seed == 2  # without data_seed: as before
    s0 = StepBatchSampler(100, 16, 0, 10, a.resolved_data_seed)
    s1 = StepBatchSampler(100, 16, 0, 10, b.resolved_data_seed)
    assert [s0.global_batch(k) for k in range(10)] == [s1.global_batch(k) for k in range(10)]
    with pytest.raises(ValueError, match="data_seed"):
        TrainConfig(data_seed=-1)
