"""Training engine: data, deterministic batching, validation, checkpoints, resume and DDP.

The script ``examples/train.py`` is a thin command line over :class:`TrainConfig` and
:func:`train`. Everything that decides a run lives in the config, which is stored in every
checkpoint.

Determinism: the batch of global step ``s`` is a pure function of ``(seed, s)``: epoch
``e = s // steps_per_epoch`` visits the training set in the order of a permutation seeded by
``(seed, e)``, and the random resampling of each item is seeded by ``(seed, s, position)``.
So ``--resume`` continues exactly where a run stopped, whatever the number of data workers,
and every DDP rank computes its shard of the same global batch.

Modules: :mod:`strl_pyg.training.config` (the config and its flags, torch-free),
:mod:`strl_pyg.training.data` (datasets, resampling, the step sampler),
:mod:`strl_pyg.training.validation` (validation metrics),
:mod:`strl_pyg.training.checkpoints` (files),
:mod:`strl_pyg.training.log` (CSV log, curves), :mod:`strl_pyg.training.commandline` (the
flags) and this one (the loop).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch
from torch import Tensor
from torch.utils.data import DataLoader
from tqdm.auto import tqdm

from strl_pyg.data import keys as keys_
from strl_pyg.model.strl_pose import StrLPose
from strl_pyg.training.checkpoints import (
    CHECKPOINT_VERSION,
    inherit_policy,
    init_weights,
    load_checkpoint,
    rng_state,
    save_checkpoint,
    set_rng_state,
)
from strl_pyg.training.clip import GradientClip
from strl_pyg.training.config import TrainConfig
from strl_pyg.training.data import (
    build_datasets,
    check_graph_channels,
    collater,
    describe_data,
    fit_input_statistics,
    unaugmented_poses,
)
from strl_pyg.training.distributed import StopSignals, distributed_setup, seed_everything
from strl_pyg.training.log import TrainLogger
from strl_pyg.training.loss import GeometricLoss, PoseLoss
from strl_pyg.training.sampling import ResampledPairs, StepBatchSampler, _InMemory
from strl_pyg.training.skipped import keep_skipped
from strl_pyg.training.validation import evaluate_model, mean_pose

__all__ = ["train", "TrainingDiverged", "MAX_SKIPPED_STEPS", "check_run_folder",
           "RESUME_FREE_FIELDS", "best_value", "losses_for"]


# ----------------------------------------------------------------------------- the loop
#: TrainConfig fields that may differ between a checkpoint and the run that resumes it: they
#: do not change what is computed.
RESUME_FREE_FIELDS = ("steps", "out_dir", "num_workers", "device", "tensorboard", "val_every",
                      "checkpoint_every", "checkpoint_minutes", "budget_minutes")

#: Consecutive optimiser steps with a non-finite loss or gradient (each one skipped) after
#: which training stops with :class:`TrainingDiverged`: it is not one bad batch then.
MAX_SKIPPED_STEPS = 20



class TrainingDiverged(RuntimeError):
    """Training stopped: its losses, gradients or weights are no longer finite; ``last.pt``
    keeps the last state saved before that."""

#: Files whose presence marks a folder as holding a run.
_RUN_FILES = ("last.pt", "model.pt", "log.csv", "config.json")


def check_run_folder(out_dir: str | os.PathLike, overwrite: bool = False) -> None:
    """Refuses to start a fresh run in a folder that holds one (``last.pt``, ``model.pt``,
    ``log.csv`` or ``config.json``) unless ``overwrite``."""
    found = [name for name in _RUN_FILES if (Path(out_dir) / name).exists()]
    if found and not overwrite:
        raise ValueError(f"Expected an empty or new run folder, or --resume to continue / "
                         f"--overwrite to start afresh (got '{out_dir}' holding "
                         f"{', '.join(found)})")


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True,
          datasets: Sequence[Any] | None = None, overwrite: bool = False) -> dict[str, Any]:
    """Trains a :class:`~strl_pyg.StrLPose` as ``cfg`` says.

    With ``resume``, continues from ``<out_dir>/last.pt`` (model, optimiser, RNG states and
    step), which must have been written with the same config apart from
    :data:`RESUME_FREE_FIELDS` (``steps``, ``out_dir``, ...). Without it, a run folder that
    already holds a run is refused unless ``overwrite``.

    ``last.pt`` is written atomically at every validation, every ``cfg.checkpoint_every``
    steps, every ``cfg.checkpoint_minutes`` minutes and when SIGINT / SIGTERM arrives (the
    step in progress finishes first; a second signal stops at once). An interrupted run
    returns with ``result["interrupted"]`` set to the signal's name. Under
    ``torchrun`` (``WORLD_SIZE`` > 1), the process group is set up here (gloo on CPU, nccl on
    CUDA) and the model is wrapped in ``DistributedDataParallel``; only rank 0 writes files.

    Returns:
        A dict with the final validation metrics, the step reached, the validation history,
        the checkpoint path and the trained ``model`` (unwrapped from DDP).
    """
    rank, world, device, own_group = distributed_setup(cfg)
    out_dir = Path(cfg.out_dir)
    ckpt_path = out_dir / "last.pt"

    seed_everything(cfg.seed)
    model_cfg = cfg.model_config()
    model = StrLPose(model_cfg).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    loss_fn, geo_fn = losses_for(cfg, model_cfg)
    # trivial_buf: training poses, for the mean pose
    start_step, history, trivial_buf, clip = _start(cfg, model, optimizer, resume, overwrite,
                                                    rank)

    ddp_model = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model

    train_ds, val_ds = _datasets(cfg, model, datasets, fit=not resume and not cfg.init_from,
                                 progress=progress and rank == 0)
    loader, val_loader = _loaders(cfg, model_cfg, train_ds, val_ds, start_step, rank, world)

    logger = _logger(cfg, out_dir, rank, start_step, train_ds, val_ds)
    result: dict[str, Any] = {"step": start_step, "checkpoint": str(ckpt_path)}
    step = start_step
    t_start, pairs_seen = time.perf_counter(), 0

    def save_last(metrics_done: bool) -> None:
        if rank != 0:
            return
        _check_finite_weights(model, step, ckpt_path)
        save_checkpoint(ckpt_path, _checkpoint_payload(cfg, model, optimizer, step, history,
                                                       trivial_buf, clip))
        if metrics_done:
            model.save(out_dir / "model.pt")  # the weights alone, for StrLPose.load

    if start_step >= cfg.steps:
        result["already_finished"] = True
    stop = StopSignals() if rank == 0 and start_step < cfg.steps else None
    last_save = time.monotonic()
    bar = tqdm(total=cfg.steps, initial=start_step, desc="train", disable=not progress or rank)
    skipped_in_a_row = dumps = 0
    best = best_value(history, cfg.best_metric)
    for batch in loader:
        ddp_model.train()
        batch = batch.to(device)
        T_gt = batch[keys_.T_0TO1]
        if sum(t.shape[0] for t in trivial_buf) < 4096:
            trivial_buf.append(unaugmented_poses(batch).cpu())
        logs = _train_step(cfg, ddp_model, model, optimizer, (loss_fn, geo_fn), batch, step,
                           clip)
        dumps = keep_skipped(logs, dumps, bar, step + 1, cfg, model, batch, rank, world)
        skipped_in_a_row = _count_skipped(logs, skipped_in_a_row, step + 1, bar, ckpt_path)
        step += 1
        pairs_seen += T_gt.shape[0] * world
        bar.update(1)
        bar.set_postfix({k: f"{float(logs[v].detach()):.3g}" for k, v in _SHOWN.items()})
        logger.log(step, "train", {k: float(v.detach()) for k, v in logs.items()})
        over_budget = time.perf_counter() - t_start > 60.0 * cfg.budget_minutes
        if step % cfg.val_every == 0 or step == cfg.steps or over_budget:
            metrics = {}
            if rank == 0:
                metrics = {**evaluate_model(model, val_loader, loss_fn, mean_pose(torch.cat(
                    trivial_buf)[:4096], model_cfg.translation), device, geo_loss=geo_fn),
                    "pairs_per_s": pairs_seen / (time.perf_counter() - t_start)}
                logger.log(step, "val", metrics)
                history.append({"step": step, **metrics})
                save_last(metrics_done=True)
                last_save = time.monotonic()
                _write_validation(bar, step, metrics)
                best = _keep_best(model, out_dir, metrics, cfg.best_metric, best, bar, step)
            if world > 1:
                torch.distributed.barrier()
            result.update(metrics)
        elif rank == 0 and _checkpoint_due(cfg, step, last_save, stop):
            save_last(metrics_done=False)
            last_save = time.monotonic()
        if (stop is not None and stop.received) or over_budget:
            result.update({"interrupted": stop.received} if stop is not None and stop.received
                          else {"budget_reached": True})
            break
    _close(bar, stop, logger, own_group)
    return {**result, "step": step, "history": history, "model": model}


def _keep_best(model: StrLPose, out_dir: Path, metrics: dict[str, float], metric: str,
               best: float, bar: Any, step: int) -> float:
    """Writes ``best_model.pt`` when this validation's ``metric`` beats ``best``; returns the
    best value so far."""
    value = metrics.get(metric, math.nan)
    if not (math.isfinite(value) and value < best):
        return best
    model.save(out_dir / "best_model.pt")
    bar.write(f"step {step}: best {metric} so far ({value:.3g}): '{out_dir / 'best_model.pt'}'")
    return value


def best_value(history: Sequence[dict[str, Any]], metric: str) -> float:
    """The lowest finite ``metric`` among the validations of ``history`` (``inf``: none), the
    value a new validation must beat to replace ``best_model.pt``."""
    values = [float(h[metric]) for h in history
              if metric in h and math.isfinite(float(h[metric]))]
    return min(values, default=math.inf)


def _close(bar: Any, stop: Any, logger: Any, own_group: bool) -> None:
    """The end of a run: the progress bar, the signal handlers, the log, the process group."""
    bar.close()
    if stop is not None:
        stop.restore()
    logger.close()
    if own_group:
        torch.distributed.destroy_process_group()


# ----------------------------------------------------------------------------- command line
#: What the progress bar shows: its label -> the log key.
_SHOWN = {"loss": "loss", "rot": "rot_err_deg", "trans": "trans_err_deg"}


def _checkpoint_due(cfg: TrainConfig, step: int, last_save: float, stop: Any) -> bool:
    """``last.pt`` is written every ``checkpoint_every`` steps, every ``checkpoint_minutes``
    and when a signal arrived (besides every validation)."""
    return bool((cfg.checkpoint_every and step % cfg.checkpoint_every == 0)
                or (cfg.checkpoint_minutes
                    and time.monotonic() - last_save >= 60.0 * cfg.checkpoint_minutes)
                or (stop is not None and stop.received))


def _start(cfg: TrainConfig, model: StrLPose, optimizer: torch.optim.Optimizer, resume: bool,
           overwrite: bool, rank: int) -> tuple[int, list, list, GradientClip]:
    """Where a run starts: ``(step, validation history, mean-pose buffer, gradient clip)``,
    from ``last.pt`` when ``resume``; otherwise from ``cfg.init_from``'s weights if it is
    set, in a run folder that :func:`check_run_folder` accepts (on rank 0)."""
    step, history, trivial_buf, norms = 0, [], [], []
    if cfg.init_from and not resume:
        init_weights(model, cfg.init_from)
    if cfg.init_from:  # also on resume: last.pt holds the weights, not the metadata
        inherit_policy(model, cfg.init_from)
    if resume:
        step, history, trivial_buf, norms = _resume(cfg, Path(cfg.out_dir) / "last.pt", model,
                                                    optimizer)
    elif rank == 0:
        check_run_folder(cfg.out_dir, overwrite)
    return step, history, trivial_buf, GradientClip(cfg.grad_clip, cfg.grad_clip_relative, norms)


def _resume(cfg: TrainConfig, ckpt_path: Path, model: StrLPose,
            optimizer: torch.optim.Optimizer) -> tuple[int, list, list, list]:
    """Loads ``last.pt`` into the model, the optimiser and the RNGs after checking that it was
    written with this config (apart from :data:`RESUME_FREE_FIELDS`); returns ``(step,
    history, mean-pose buffer, the relative clip's recent gradient norms)``."""
    state = load_checkpoint(ckpt_path)
    saved = TrainConfig.from_dict(state["train_config"])
    # settings that do not change what is computed may differ (a moved run folder, more
    # steps, other workers or checkpoint intervals)
    # (the warm-up is compared by its length below: None's follows --steps)
    free = dict.fromkeys((*RESUME_FREE_FIELDS, "warmup_steps"))
    if {**asdict(saved), **free} != {**asdict(cfg), **free}:
        diff = {k: (v, getattr(cfg, k)) for k, v in asdict(saved).items()
                if k not in free and getattr(cfg, k) != v}
        raise ValueError(f"Expected the checkpoint's config to match this run "
                         f"(got differences {{key: (checkpoint, now)}} = {diff})")
    start_step = int(state["step"])
    if saved.lr_schedule != "constant" and cfg.steps != saved.steps:
        raise ValueError(f"Expected --steps {saved.steps} to resume: a {saved.lr_schedule} "
                         f"learning-rate schedule ends at the run's last step (got "
                         f"{cfg.steps}); to train on, start a new run with --init-from")
    # a warm-up of another length changes the rates still to come: inside the warm-up, or
    # anywhere on a cosine (which starts where the warm-up ends)
    if cfg.warmup != saved.warmup and (saved.lr_schedule != "constant"
                                       or start_step < max(cfg.warmup, saved.warmup)):
        raise ValueError(f"Expected a warm-up of {saved.warmup} steps to resume this run (got "
                         f"{cfg.warmup}; without --warmup-steps it follows --steps); give "
                         f"--warmup-steps {saved.warmup}")
    if cfg.steps < start_step:
        raise ValueError(f"Expected --steps of at least the checkpoint's step {start_step} "
                         f"to resume (got {cfg.steps})")
    model.load_state_dict(state["model"])
    optimizer.load_state_dict(model.upgrade_optimizer_state(state["optimizer"], state["model"]))
    trivial_buf = [state["trivial_T"]] if "trivial_T" in state else []
    set_rng_state(state["rng"])
    return start_step, state.get("history", []), trivial_buf, state.get("grad_norms", [])


def _loaders(cfg: TrainConfig, model_cfg: Any, train_ds: Any, val_ds: Any, start_step: int,
             rank: int, world: int) -> tuple[DataLoader, DataLoader]:
    """The training loader (resampled, swapped, from ``start_step`` on, this rank's share)
    and the validation loader (the same resampling for every validation)."""
    collate = collater(model_cfg)
    data_seed = cfg.resolved_data_seed
    sampler = StepBatchSampler(len(train_ds), cfg.batch_size, start_step, cfg.steps, data_seed,
                               rank, world)
    loader = DataLoader(ResampledPairs(train_ds, cfg.num_points, cfg.num_lines, data_seed,
                                   cfg.swap_prob, cfg.outlier_augment, cfg.roll_augment),
                        batch_sampler=sampler, collate_fn=collate, num_workers=cfg.num_workers)
    val_keys = [(i, -1, i) for i in range(len(val_ds))]
    val_loader = DataLoader(ResampledPairs(val_ds, cfg.num_points, cfg.num_lines, data_seed + 1),
                            batch_size=cfg.batch_size, collate_fn=collate,
                            sampler=val_keys, num_workers=cfg.num_workers)
    return loader, val_loader


def _datasets(cfg: TrainConfig, model: StrLPose, datasets: Sequence[Any] | None, fit: bool,
              progress: bool) -> tuple[Any, Any]:
    """The training and validation sets (built unless given), checked against the model;
    with ``fit``, the flow inputs' standardisation fitted on the training set."""
    if datasets is None:
        datasets = build_datasets(cfg, progress=progress)
    train_ds, val_ds = (_InMemory(d, cfg.in_memory) for d in datasets)
    if len(val_ds) == 0:  # refused here, not at the first validation after training steps
        raise ValueError("Expected a non-empty validation set (got 0 pairs): training "
                         f"validates every {cfg.val_every} steps and at the end")
    if len(train_ds):
        check_graph_channels(model.config, cfg.patch_size, train_ds[0])
        if cfg.roll_augment > 0 and not (keys_.K0 in train_ds[0] and keys_.K1 in train_ds[0]):
            raise ValueError("Expected training pairs with intrinsics K0 and K1 for "
                             "--roll-augment (got pairs without them)")
    if model.config.inputs != "paper" and fit and len(train_ds):
        fit_input_statistics(model, train_ds, cfg.swap_prob > 0, roll=cfg.roll_augment,
                             resample=(cfg.num_points, cfg.num_lines))
    return train_ds, val_ds


def _logger(cfg: TrainConfig, out_dir: Path, rank: int, start_step: int, train_ds: Any,
            val_ds: Any) -> TrainLogger:
    """The run's logger (rank 0 writes) and its ``config.json``: what was used ("tensorboard"
    is false when it was asked for but is not installed; "warmup_steps" is the warm-up's
    length, also where the config left it to the default, None), the settings the dataset
    ignores (``"ignored"``) and the items per source it loaded (``"data"``)."""
    if rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    logger = TrainLogger(out_dir, rank == 0, cfg.tensorboard, start_step)
    if rank == 0:
        (out_dir / "config.json").write_text(
            json.dumps({**asdict(cfg), "tensorboard": logger.tensorboard,
                        "warmup_steps": cfg.warmup, "ignored": cfg.ignored_fields(),
                        "data": {"training": describe_data(train_ds),
                                 "validation": describe_data(val_ds)}}, indent=2))
    return logger


def _checkpoint_payload(cfg: TrainConfig, model: StrLPose, optimizer: torch.optim.Optimizer,
                        step: int, history: list, trivial_buf: list,
                        clip: GradientClip) -> dict[str, Any]:
    """What ``last.pt`` holds: configs, model, optimiser, step, RNG states, validation
    history, up to 4096 training poses (the mean-pose baseline) and, with a relative clip,
    the gradient norms its median reads."""
    trivial = torch.cat(trivial_buf)[:4096] if trivial_buf else None
    return {
        "version": CHECKPOINT_VERSION,
        "train_config": asdict(cfg),
        "model_config": model.config.to_dict(),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "step": step,
        "rng": rng_state(),
        "history": history,
        **({"trivial_T": trivial} if trivial is not None else {}),
        **({"grad_norms": clip.state()} if clip.relative > 0 else {}),
    }


def _write_validation(bar: Any, step: int, metrics: dict[str, float]) -> None:
    """The validation's line (and the geometric head's) under the progress bar."""
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


def _check_finite_weights(model: StrLPose, step: int, ckpt_path: Path) -> None:
    """Never overwrite a good ``last.pt`` with weights that are not numbers."""
    bad = [n for n, t in model.state_dict().items()
           if t.is_floating_point() and not bool(torch.isfinite(t).all())]
    if bad:
        raise TrainingDiverged(f"Expected finite weights to checkpoint at step {step} (got "
                               f"non-finite values in {len(bad)} tensors, e.g. {bad[0]}); "
                               f"'{ckpt_path}' keeps the last good state")


def _count_skipped(logs: dict, in_a_row: int, step: int, bar: Any, ckpt_path: Path) -> int:
    """Steps skipped in a row (:func:`_train_step`'s ``logs["skipped"]``), said under the
    progress bar; :class:`TrainingDiverged` at :data:`MAX_SKIPPED_STEPS`."""
    in_a_row = in_a_row + 1 if float(logs["skipped"]) else 0
    if in_a_row:
        bar.write(f"step {step}: non-finite loss or gradient, optimiser step skipped "
                  f"({in_a_row} in a row)")
    if in_a_row >= MAX_SKIPPED_STEPS:
        raise TrainingDiverged(f"Expected finite losses and gradients (got {in_a_row} steps "
                               f"in a row without, up to step {step}); '{ckpt_path}' keeps "
                               "the last saved state")
    return in_a_row


def _train_step(cfg: TrainConfig, ddp_model: torch.nn.Module, model: StrLPose,
                optimizer: torch.optim.Optimizer, losses: tuple, batch: Any,
                step: int, clip: GradientClip) -> dict[str, Tensor]:
    """One optimiser step on ``batch``; the logs of its losses, the gradient norm, the clip's
    threshold and whether it was active (logged, so that a clip active on every step shows in
    the curves)."""
    loss_fn, geo_fn = losses
    T_gt = batch[keys_.T_0TO1]
    out = ddp_model(batch)
    logs = loss_fn(out, T_gt)
    if cfg.pose_weight != 1.0:
        logs["pose_loss"] = logs["loss"].detach()
        logs["loss"] = cfg.pose_weight * logs["loss"]
    if geo_fn is not None:
        geo_fn.ess_weight = cfg.geo_ess_weight if step >= cfg.geo_ess_start else 0.0
        geo_logs = geo_fn(out, T_gt)
        logs = {**logs, **{f"geo_{k}" if not k.startswith("geo_") else k: v
                           for k, v in geo_logs.items()}}
        logs["loss"] = logs["loss"] + geo_logs["loss"]
    optimizer.zero_grad(set_to_none=True)
    logs["loss"].backward()
    lr = cfg.learning_rate(step)
    for group in optimizer.param_groups:
        group["lr"] = lr
    logs["lr"] = torch.tensor(lr)
    threshold = clip.threshold()
    grad_norm = torch.nn.utils.clip_grad_norm_(
        model.parameters(), float("inf") if threshold is None else threshold)
    logs["grad_norm"] = grad_norm.detach()
    logs["clipped"] = torch.zeros(()) if threshold is None else (grad_norm > threshold).float()
    if threshold is not None and clip.relative > 0:
        logs["grad_clip"] = torch.tensor(float(threshold))
    norm = float(grad_norm)  # one device sync for the clip's history and the check below
    clip.record(norm)
    # a non-finite gradient (one bad batch: a degenerate solve in the geometric head; a
    # non-finite loss gives one too) would turn every weight into NaN for good: the step is
    # skipped and logged instead. Decided on the norm alone: under DDP it is of the
    # all-reduced gradients, so every rank skips the same steps (a rank's own loss is not).
    finite = math.isfinite(norm)
    logs["skipped"] = torch.tensor(0.0 if finite else 1.0)
    if finite:
        optimizer.step()
    else:
        optimizer.zero_grad(set_to_none=True)
    return logs


def losses_for(cfg: TrainConfig, model_cfg: Any) -> tuple[PoseLoss, GeometricLoss | None]:
    """The run's pose loss and, with the geometric head, its loss."""
    pose = PoseLoss(translation=model_cfg.translation, form=cfg.loss,
                    angle_weight=cfg.angle_weight, rot_weight=cfg.rot_weight,
                    beta=cfg.beta)
    geo = GeometricLoss(cfg.geo_threshold_px, cfg.geo_cls_weight,
                        cfg.geo_ess_weight) if model_cfg.geometric else None
    return pose, geo


