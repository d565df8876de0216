"""Skipped training steps kept for replay: the first few steps the gradient guard skips keep
their batch and the weights before the step (``benchmarks/studies/replay_skipped_step.py``
replays one)."""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

from strl_pyg.model.strl_pose import StrLPose
from strl_pyg.training.checkpoints import save_checkpoint
from strl_pyg.training.config import TrainConfig
from strl_pyg.training.data import collater

__all__ = ["MAX_SKIPPED_DUMPS", "keep_skipped", "save_skipped_step", "load_skipped_step"]


#: At most this many skipped steps per run keep their batch and weights (``skipped/``).
MAX_SKIPPED_DUMPS = 3


def keep_skipped(logs: dict, dumps: int, bar: Any, step: int, cfg: TrainConfig,
                  model: StrLPose, batch: Any, rank: int, world: int) -> int:
    """The first :data:`MAX_SKIPPED_DUMPS` skipped steps of a run keep their batch and weights
    (:func:`save_skipped_step`); returns how many were kept."""
    if not float(logs["skipped"]) or dumps >= MAX_SKIPPED_DUMPS:
        return dumps
    # every rank keeps its own shard: the skip was decided on the all-reduced norm
    try:
        kept = save_skipped_step(cfg.out_dir, step, cfg, model, batch,
                                 rank=rank if world > 1 else None)
        bar.write(f"step {step}: its batch and weights are kept in '{kept}'")
    except (OSError, TypeError, RuntimeError) as err:  # the run goes on without it
        bar.write(f"step {step}: its batch could not be kept ({err})")
    return dumps + 1


def save_skipped_step(out_dir: str | os.PathLike, step: int, cfg: TrainConfig,
                      model: StrLPose, batch: Any, rank: int | None = None) -> Path:
    """Keeps what a skipped step needs to be replayed: ``<out_dir>/skipped/step<N>.pt``
    (``step<N>_rank<r>.pt`` for a DDP rank's shard) with the run's config, the weights before
    the step and the batch, one graph per entry (plain values, read back by
    :func:`load_skipped_step` with safe loading)."""
    graphs = [g.cpu().to_dict() for g in batch.to_data_list()]  # copies: the batch stays
    name = f"step{step:06d}" + ("" if rank is None else f"_rank{rank}")
    path = Path(out_dir) / "skipped" / f"{name}.pt"
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_checkpoint(path, {"step": step, "config": json.loads(json.dumps(asdict(cfg))),
                                  "model": model.state_dict(), "graphs": graphs})


def load_skipped_step(path: str | os.PathLike) -> tuple[int, TrainConfig, StrLPose, Any]:
    """Reads a :func:`save_skipped_step` file: ``(step, config, model, batch)``, the model with
    the weights before the step and the batch collated as the training loop did, to replay
    the step (``benchmarks/studies/replay_skipped_step.py``)."""
    from torch_geometric.data import HeteroData

    from strl_pyg.utils.io import safe_torch_load

    need = {"step", "config", "model", "graphs"}
    state = safe_torch_load(Path(path), "skipped training step")
    if not isinstance(state, dict) or not need <= set(state):
        got = sorted(state) if isinstance(state, dict) else type(state).__name__
        raise ValueError(f"Expected a skipped-step file with keys {sorted(need)} in '{path}' "
                         f"(got {got})")
    cfg = TrainConfig.from_dict(state["config"])
    model = StrLPose(cfg.model_config())
    model.load_state_dict(state["model"])
    graphs = [HeteroData.from_dict(g) for g in state["graphs"]]
    return state["step"], cfg, model, collater(model.config)(graphs)
