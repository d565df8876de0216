"""Training engine: data, deterministic batching, validation, checkpoints, resume and DDP.

The script ``examples/train.py`` is a thin command line over :class:`TrainConfig` and
:func:`train`. Everything that decides a run lives in the config, which is stored in every
checkpoint.

Determinism: the batch of global step ``s`` is a pure function of ``(seed, s)``: epoch
``e = s // steps_per_epoch`` visits the training set in the order of a permutation seeded by
``(seed, e)``, and the random resampling of each item is seeded by ``(seed, s, position)``.
So ``--resume`` continues exactly where a run stopped, whatever the number of data workers,
and every DDP rank computes its shard of the same global batch.

Modules: :mod:`strl_pyg.train_config` (the config and its flags, torch-free),
:mod:`strl_pyg.train_data` (datasets, resampling, the step sampler),
:mod:`strl_pyg.validation` (validation metrics), :mod:`strl_pyg.checkpoints` (files),
:mod:`strl_pyg.train_log` (CSV log, curves) and this one (the loop and its command line).
Their public names are re-exported here.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import DataLoader
from torch_geometric.loader.dataloader import Collater
from tqdm.auto import tqdm

from strl_pyg.checkpoints import (
    CHECKPOINT_VERSION,
    init_weights,
    load_checkpoint,
    rng_state,
    save_checkpoint,
    set_rng_state,
)
from strl_pyg.data import keys as keys_
from strl_pyg.loss import GeometricLoss, PoseLoss
from strl_pyg.model import StrLPose
from strl_pyg.train_config import DATASETS, TrainConfig, add_train_arguments  # noqa: F401
from strl_pyg.train_data import (
    StepBatchSampler,
    _InMemory,
    _Resampled,
    build_datasets,
    shuffle_point_matches,
    unaugmented_poses,
)
from strl_pyg.train_log import TrainLogger, plot_history
from strl_pyg.validation import evaluate_model, mean_pose

__all__ = [
    "TrainConfig",
    "train",
    "evaluate_model",
    "mean_pose",
    "build_datasets",
    "shuffle_point_matches",
    "load_checkpoint",
    "save_checkpoint",
    "StepBatchSampler",
    "add_train_arguments",
    "run_from_args",
    "plot_history",
]

# former private names, kept for callers of this module
_init_weights = init_weights
_rng_state, _set_rng_state = rng_state, set_rng_state
_unaugmented_poses = unaugmented_poses
_Logger = TrainLogger


# ----------------------------------------------------------------------------- the loop
def _dist_info() -> tuple[int, int]:
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return torch.distributed.get_rank(), torch.distributed.get_world_size()
    return 0, 1


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True,
          datasets: Sequence[Any] | None = None) -> dict[str, Any]:
    """Trains a :class:`~strl_pyg.StrLPose` as ``cfg`` says.

    With ``resume``, continues from ``<out_dir>/last.pt`` (model, optimiser, RNG states and
    step), which must have been written with the same config apart from ``steps``. Under
    ``torchrun`` (``WORLD_SIZE`` > 1), the process group is set up here (gloo on CPU, nccl on
    CUDA) and the model is wrapped in ``DistributedDataParallel``; only rank 0 writes files.

    Returns:
        A dict with the final validation metrics, the step reached, the validation history,
        the checkpoint path and the trained ``model`` (unwrapped from DDP).
    """
    world_env = int(os.environ.get("WORLD_SIZE", "1"))
    own_group = False
    if world_env > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if cfg.device.startswith("cuda") else "gloo"
        torch.distributed.init_process_group(backend)
        own_group = True
    rank, world = _dist_info()
    device = cfg.device
    if device.startswith("cuda") and world > 1:
        device = f"cuda:{int(os.environ.get('LOCAL_RANK', 0))}"
        torch.cuda.set_device(device)
    out_dir = Path(cfg.out_dir)
    ckpt_path = out_dir / "last.pt"

    torch.manual_seed(cfg.seed)
    np.random.seed(cfg.seed % 2**32)  # noqa: NPY002
    random.seed(cfg.seed)
    model_cfg = cfg.model_config()
    model = StrLPose(model_cfg).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    loss_fn = PoseLoss(translation=model_cfg.translation)
    geo_fn = GeometricLoss(cfg.geo_threshold_px, cfg.geo_cls_weight,
                           cfg.geo_ess_weight) if model_cfg.geometric else None
    start_step, history = 0, []
    trivial_buf: list[Tensor] = []
    if cfg.init_from and not resume:
        init_weights(model, cfg.init_from)
    if resume:
        state = load_checkpoint(ckpt_path)
        saved = TrainConfig.from_dict(state["train_config"])
        if {**asdict(saved), "steps": 0} != {**asdict(cfg), "steps": 0}:
            diff = {k: (v, getattr(cfg, k)) for k, v in asdict(saved).items()
                    if k != "steps" and getattr(cfg, k) != v}
            raise ValueError(f"Expected the checkpoint's config to match this run "
                             f"(got differences {{key: (checkpoint, now)}} = {diff})")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(model.upgrade_optimizer_state(state["optimizer"], state["model"]))
        start_step = int(state["step"])
        history = state.get("history", [])
        trivial_buf = [state["trivial_T"]] if "trivial_T" in state else []
        set_rng_state(state["rng"])

    ddp_model = model
    if world > 1:
        ddp_model = torch.nn.parallel.DistributedDataParallel(model)

    if datasets is None:
        datasets = build_datasets(cfg)
    train_ds, val_ds = (_InMemory(d, cfg.in_memory) for d in datasets)
    collate = Collater(None)
    sampler = StepBatchSampler(len(train_ds), cfg.batch_size, start_step, cfg.steps, cfg.seed,
                               rank, world)
    loader = DataLoader(_Resampled(train_ds, cfg.num_points, cfg.num_lines, cfg.seed,
                                   cfg.swap_prob, cfg.outlier_augment),
                        batch_sampler=sampler, collate_fn=collate, num_workers=cfg.num_workers)
    val_keys = [(i, -1, i) for i in range(len(val_ds))]
    val_loader = DataLoader(_Resampled(val_ds, cfg.num_points, cfg.num_lines, cfg.seed + 1),
                            batch_size=cfg.batch_size, collate_fn=collate,
                            sampler=val_keys, num_workers=cfg.num_workers)

    if rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    logger = TrainLogger(out_dir, rank == 0, cfg.tensorboard, start_step)
    if rank == 0:
        (out_dir / "config.json").write_text(json.dumps(asdict(cfg), indent=2))
    result: dict[str, Any] = {"step": start_step, "checkpoint": str(ckpt_path)}
    step = start_step
    t_start, pairs_seen = time.perf_counter(), 0
    bar = tqdm(total=cfg.steps, initial=start_step, desc="train", disable=not progress or rank)
    for batch in loader:
        ddp_model.train()
        batch = batch.to(device)
        T_gt = batch[keys_.T_0TO1]
        if sum(t.shape[0] for t in trivial_buf) < 4096:
            trivial_buf.append(unaugmented_poses(batch).cpu())
        out = ddp_model(batch)
        logs = loss_fn(out, T_gt)
        if geo_fn is not None:
            geo_fn.ess_weight = cfg.geo_ess_weight if step >= cfg.geo_ess_start else 0.0
            geo_logs = geo_fn(out, T_gt)
            logs = {**logs, **{f"geo_{k}" if not k.startswith("geo_") else k: v
                               for k, v in geo_logs.items()}}
            logs["loss"] = logs["loss"] + geo_logs["loss"]
        optimizer.zero_grad(set_to_none=True)
        logs["loss"].backward()
        if cfg.grad_clip:
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        optimizer.step()
        step += 1
        pairs_seen += T_gt.shape[0] * world
        bar.update(1)
        bar.set_postfix(loss=f"{float(logs['loss'].detach()):.3f}",
                        rot=f"{float(logs['rot_err_deg']):.2f}",
                        trans=f"{float(logs['trans_err_deg']):.1f}")
        logger.log(step, "train", {k: float(v.detach()) for k, v in logs.items()})
        if step % cfg.val_every == 0 or step == cfg.steps:
            trivial_T = torch.cat(trivial_buf)[:4096]
            metrics = {}
            if rank == 0:
                trivial = mean_pose(trivial_T, model_cfg.translation)
                metrics = evaluate_model(model, val_loader, loss_fn, trivial, device)
                metrics["pairs_per_s"] = pairs_seen / (time.perf_counter() - t_start)
                logger.log(step, "val", metrics)
                history.append({"step": step, **metrics})
                save_checkpoint(ckpt_path, {
                    "version": CHECKPOINT_VERSION,
                    "train_config": asdict(cfg),
                    "model_config": model_cfg.to_dict(),
                    "model": model.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "step": step,
                    "rng": rng_state(),
                    "history": history,
                    "trivial_T": trivial_T,
                })
                model.save(out_dir / "model.pt")  # the weights alone, for StrLPose.load
                bar.write(f"step {step}: val rot {metrics['rot_err_deg']:.2f} deg "
                          f"(trivial {metrics['trivial_rot_err_deg']:.2f}), trans "
                          f"{metrics['trans_err_deg']:.2f} deg "
                          f"(trivial {metrics['trivial_trans_err_deg']:.2f}), "
                          f"AUC@10 {metrics['auc10']:.3f}")
                if "geo_rot_err_med" in metrics:
                    bar.write(f"step {step}: geometric head median rot "
                              f"{metrics['geo_rot_err_med']:.2f} deg, trans "
                              f"{metrics['geo_trans_err_med']:.2f} deg, "
                              f"AUC@10 {metrics['geo_auc10']:.3f}")
            if world > 1:
                torch.distributed.barrier()
            result.update(metrics)
    bar.close()
    logger.close()
    result["step"] = step
    result["history"] = history
    result["model"] = model
    if own_group:
        torch.distributed.destroy_process_group()
    return result


# ----------------------------------------------------------------------------- command line
def _parse_value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def run_from_args(args: argparse.Namespace, ap: argparse.ArgumentParser) -> int:
    """Runs training from parsed :func:`add_train_arguments` flags; returns an exit code."""
    def pairs(items):
        out = {}
        for item in items:
            if "=" not in item:
                ap.error(f"expected KEY=VALUE (got {item!r})")
            k, v = item.split("=", 1)
            out[k] = _parse_value(v)
        return out

    split = lambda s: None if s is None else [x.strip() for x in s.split(",")]  # noqa: E731
    try:
        cfg = TrainConfig(
            dataset=args.dataset, data_root=args.data_root, cache_dir=args.cache_dir,
            scene=pairs(args.scene), scene_kinds=split(args.scene_kinds),
            train_pairs=args.train_pairs, val_pairs=args.val_pairs, kitti_k=args.kitti_k,
            train_sequences=split(args.train_sequences), val_sequences=split(args.val_sequences),
            limit=args.limit, model=args.model, model_overrides=pairs(args.set), lr=args.lr,
            batch_size=args.batch_size, steps=args.steps, val_every=args.val_every,
            num_points=args.num_points, num_lines=args.num_lines, patch_size=args.patch_size,
            swap_prob=args.swap_prob, init_from=args.init_from,
            seed=args.seed, out_dir=args.out, num_workers=args.workers, device=args.device,
            tensorboard=not args.no_tensorboard, scene_mix=args.scene_mix,
            matches=args.matches, outlier_augment=args.outlier_augment,
            geo_ess_start=args.geo_ess_start,
        )
        cfg.model_config()  # validate the model overrides before any work
    except (ValueError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    result = train(cfg, resume=args.resume, progress=not args.no_progress)
    if result.get("history"):
        png = plot_history(result["history"], Path(cfg.out_dir) / "curves.png")
        print(f"curves: {png}")
    keys = ("rot_err_deg", "trans_err_deg", "auc10", "trivial_rot_err_deg",
            "trivial_trans_err_deg", "pairs_per_s")
    print(json.dumps({"step": result["step"], **{k: result[k] for k in keys if k in result}}))
    return 0
