"""Training engine: data, deterministic batching, validation, checkpoints, resume and DDP.

The script ``examples/train.py`` is a thin command line over :class:`TrainConfig` and
:func:`train`. Everything that decides a run lives in the config, which is stored in every
checkpoint.

Determinism: the batch of global step ``s`` is a pure function of ``(seed, s)``: epoch
``e = s // steps_per_epoch`` visits the training set in the order of a permutation seeded by
``(seed, e)``, and the random resampling of each item is seeded by ``(seed, s, position)``.
So ``--resume`` continues exactly where a run stopped, whatever the number of data workers,
and every DDP rank computes its shard of the same global batch.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
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
from torch.utils.data import ConcatDataset, DataLoader, Dataset, Sampler
from torch_geometric.data import HeteroData
from torch_geometric.loader.dataloader import Collater
from tqdm.auto import tqdm

from strl_pyg.data import keys as K
from strl_pyg.data.transforms import FixedSizeResample, RandomSwap
from strl_pyg.geometry import Pose, rotation_to_quaternion
from strl_pyg.io import UnsafeFileError, atomic_open, safe_torch_load
from strl_pyg.loss import GeometricLoss, PoseLoss
from strl_pyg.metrics import pose_auc, relative_pose_error
from strl_pyg.model import StrLPose
from strl_pyg.train_config import DATASETS, TrainConfig, add_train_arguments  # noqa: F401

__all__ = [
    "TrainConfig",
    "train",
    "evaluate_model",
    "mean_pose",
    "build_datasets",
    "load_checkpoint",
    "save_checkpoint",
    "StepBatchSampler",
    "add_train_arguments",
    "run_from_args",
    "plot_history",
]

CHECKPOINT_VERSION = 2  # 2: every value loads with torch.load(weights_only=True)


# ----------------------------------------------------------------------------- data
class _InMemory(Dataset):
    """Caches the items of a dataset after their first access (generation is the slow part)."""

    def __init__(self, base: Any, enabled: bool) -> None:
        self.base, self.enabled, self.items = base, enabled, {}

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, i: int) -> HeteroData:
        if not self.enabled:
            return self.base[i]
        if i not in self.items:
            self.items[i] = self.base[i]
        return self.items[i]


class _Resampled(Dataset):
    """Applies :class:`FixedSizeResample` and :class:`RandomSwap`, seeded by the key
    ``(index, step, position)``."""

    def __init__(self, base: Dataset, num_points: int, num_lines: int, seed: int,
                 swap_prob: float = 0.0, outlier_max: float = 0.0) -> None:
        self.base, self.num_points, self.num_lines, self.seed = base, num_points, num_lines, seed
        self.swap_prob = swap_prob
        self.outlier_max = outlier_max

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, key: tuple[int, int, int]) -> HeteroData:
        index, step, position = key
        seed = (self.seed * 1_000_003 + step * 4099 + position) % (2**63)
        data = FixedSizeResample(self.num_points, self.num_lines, seed=seed)(self.base[index])
        if self.swap_prob > 0:
            data = RandomSwap(self.swap_prob, seed=seed + 1)(data)
        if self.outlier_max > 0:
            data = shuffle_point_matches(data, self.outlier_max, seed + 2)
        return data


def shuffle_point_matches(data: HeteroData, max_fraction: float, seed: int) -> HeteroData:
    """Training augmentation: a fraction ``U(0, max_fraction)`` of the point matches get the
    image-1 side of another point match (``pos1``, ``kpts1``, ``patch1`` permuted together), so
    they become realistic outliers (a real feature of image 1, consistent patch) whose label
    the geometric loss recomputes from the true pose. Returns a shallow copy."""
    gen = torch.Generator().manual_seed(int(seed) % (2**63))
    store = data[K.POINT]
    n = store[K.POS1].shape[0]
    m = int(float(torch.rand(1, generator=gen)) * max_fraction * n)
    if m < 2:
        return data
    out = data.clone()  # small per-pair tensors; keeps the cached graph untouched
    idx = torch.randperm(n, generator=gen)[:m]
    perm = idx[torch.roll(torch.arange(m), 1)]
    for key in (K.POS1, K.KPTS1, K.PATCH1):
        if key in store:
            x = store[key].clone()
            x[idx] = store[key][perm]
            out[K.POINT][key] = x
    return out


class StepBatchSampler(Sampler):
    """Yields, for steps ``start .. stop - 1``, the keys ``(index, step, position)`` of this
    rank's shard of each global batch. The order is a pure function of ``(seed, step)``."""

    def __init__(self, num_items: int, batch_size: int, start: int, stop: int, seed: int,
                 rank: int = 0, world_size: int = 1) -> None:
        if num_items < 1:
            raise ValueError("Expected a non-empty training set (got 0 pairs)")
        if batch_size % world_size:
            raise ValueError(
                f"Expected batch_size divisible by the number of processes "
                f"(got {batch_size} and {world_size})"
            )
        self.n, self.bs, self.start, self.stop = num_items, batch_size, start, stop
        self.seed, self.rank, self.world = seed, rank, world_size
        self.per_epoch = max(1, num_items // batch_size)
        self._perm_epoch, self._perm = -1, None

    def global_batch(self, step: int) -> list[int]:
        epoch, k = divmod(step, self.per_epoch)
        if epoch != self._perm_epoch:
            g = torch.Generator().manual_seed(self.seed * 7919 + epoch)
            self._perm = torch.randperm(self.n, generator=g)
            self._perm_epoch = epoch
        idx = self._perm[k * self.bs:(k + 1) * self.bs]
        if len(idx) < self.bs:  # fewer items than a batch: wrap around
            idx = self._perm[torch.arange(k * self.bs, (k + 1) * self.bs) % self.n]
        return idx.tolist()

    def __iter__(self):
        for step in range(self.start, self.stop):
            batch = self.global_batch(step)
            yield [(i, step, pos) for pos, i in enumerate(batch)][self.rank::self.world]

    def __len__(self) -> int:
        return self.stop - self.start


def build_datasets(cfg: TrainConfig) -> tuple[Any, Any]:
    """Training and validation datasets of pair graphs (without resampling)."""
    from strl_pyg.data import datasets as D

    if cfg.dataset == "synthetic" and cfg.scene_mix is not None:
        return _mixed_datasets(cfg)
    if cfg.dataset == "synthetic":
        from strl_pyg.synthetic import SceneConfig

        keep = cfg.model_config().visual == "cnn"
        kinds = cfg.scene_kinds or [SceneConfig().kind]

        def part(total: int, base: int) -> ConcatDataset:
            # kind j gets seeds base + j * 100_000 + i; sizes split as evenly as possible
            sizes = [total // len(kinds) + (j < total % len(kinds)) for j in range(len(kinds))]
            return ConcatDataset([
                D.SyntheticPairs(n, seed=base + j * 100_000,
                                 scene_config=SceneConfig(**{**cfg.scene, "kind": kind}),
                                 patch_size=cfg.patch_size, keep_images=keep)
                for j, (kind, n) in enumerate(zip(kinds, sizes, strict=True)) if n > 0
            ])

        return part(cfg.train_pairs, cfg.seed * 10_000_000), part(
            cfg.val_pairs, 1_000_000 + cfg.seed * 10_000_000)
    keep = cfg.model_config().visual == "cnn"
    common = dict(cache_dir=cfg.cache_dir, patch_size=cfg.patch_size, keep_images=keep,
                  limit=cfg.limit, on_missing="skip")
    if cfg.dataset == "kitti":
        train = D.KITTIOdometry(cfg.data_root, split="train", sequences=cfg.train_sequences,
                                frame_gap=cfg.kitti_k, **common)
        val = D.KITTIOdometry(cfg.data_root, split="test", sequences=cfg.val_sequences,
                              frame_gap=cfg.kitti_k, **common)
    else:
        train = D.DeMoNFolder(cfg.data_root, split="train", **common)
        val = D.DeMoNFolder(cfg.data_root, split="test", **common)
    for ds in (train, val):
        ds.build_cache(num_workers=max(1, cfg.num_workers))
    return train, val


def _mixed_datasets(cfg: TrainConfig) -> tuple[Any, Any]:
    """Training / validation sets drawn from a named scene distribution
    (:func:`strl_pyg.synthetic.scene_distribution`: one scene configuration per seed)."""
    from strl_pyg.data import datasets as D
    from strl_pyg.synthetic.distributions import DISTRIBUTIONS, scene_distribution

    if cfg.scene_mix not in DISTRIBUTIONS:
        raise ValueError(f"Expected scene_mix in {tuple(DISTRIBUTIONS)} (got {cfg.scene_mix!r})")
    dist = scene_distribution(cfg.scene_mix)
    keep = cfg.model_config().visual == "cnn"
    kw = dict(matches="frontend", cache_dir=cfg.cache_dir) if cfg.matches == "frontend" else {}
    sets = []
    for n, base in ((cfg.train_pairs, cfg.seed * 10_000_000),
                    (cfg.val_pairs, 1_000_000 + cfg.seed * 10_000_000)):
        ds = D.SyntheticPairs(n, seed=base, scene_config=dist, patch_size=cfg.patch_size,
                              keep_images=keep, **kw)
        if kw:
            ds.build_cache(num_workers=cfg.num_workers)
        sets.append(ds)
    return sets[0], sets[1]


# ----------------------------------------------------------------------------- metrics
def mean_pose(T_0to1: Tensor, translation: str = "direction") -> tuple[Tensor, Tensor]:
    """The trivial predictor: the chordal mean rotation (mean of the rotation matrices,
    projected back to SO(3)) and the mean translation (re-normalised for directions) of
    ``T_0to1`` ``[N, 4, 4]``. Returns a quaternion ``[4]`` and a translation ``[3]``."""
    pose = Pose.from_matrix(T_0to1.double())
    U, _, Vh = torch.linalg.svd(pose.R.mean(0))
    d = torch.sign(torch.det(U @ Vh))
    R = U @ torch.diag(torch.stack([torch.ones_like(d), torch.ones_like(d), d])) @ Vh
    t = pose.t
    if translation == "direction":
        t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        t = t.mean(0)
        t = t / t.norm().clamp_min(1e-12)
    else:
        t = t.mean(0)
    return rotation_to_quaternion(R).float(), t.float()


def _errors(q: Tensor, t: Tensor, T_gt: Tensor) -> tuple[Tensor, Tensor]:
    return relative_pose_error(Pose.from_quaternion(q, t), T_gt)


def _summary(rot: Tensor, trans: Tensor, prefix: str) -> dict[str, float]:
    rot, trans = rot.double(), trans.double()
    worst = torch.maximum(rot, torch.nan_to_num(trans, nan=180.0))
    auc = pose_auc(worst.numpy(), (5.0, 10.0, 20.0))
    return {
        f"{prefix}rot_err_deg": float(rot.mean()),
        f"{prefix}rot_err_med": float(rot.median()),
        f"{prefix}trans_err_deg": float(torch.nanmean(trans)),
        f"{prefix}trans_err_med": float(torch.nanmedian(trans)),
        f"{prefix}auc5": float(auc[0]),
        f"{prefix}auc10": float(auc[1]),
        f"{prefix}auc20": float(auc[2]),
    }


@torch.no_grad()
def evaluate_model(model: torch.nn.Module, loader, loss_fn: PoseLoss | None = None,
                   trivial: tuple[Tensor, Tensor] | None = None, device: str = "cpu",
                   progress: bool = False) -> dict[str, float]:
    """Mean / median rotation and translation-direction errors (degrees) and pose AUC at
    5/10/20 degrees of ``model`` over ``loader``; with ``trivial`` (a mean pose), the same
    metrics of that constant predictor, prefixed ``trivial_``."""
    model.eval()
    rots, transs, t_rots, t_transs, losses = [], [], [], [], []
    g_rots, g_transs = [], []
    for batch in tqdm(loader, desc="validate", disable=not progress, leave=False):
        batch = batch.to(device)
        T_gt = batch[K.T_0TO1]
        out = model(batch)
        if loss_fn is not None:
            losses.append(float(loss_fn(out, T_gt)["loss"]))
        r, t = _errors(out.quaternion, out.translation, T_gt)
        rots.append(r.cpu())
        transs.append(t.cpu())
        if getattr(out, "geometric", None) is not None:
            geo = out.geometric
            r, t = relative_pose_error(Pose(geo.R, geo.t), T_gt.double())
            bad = geo.status.cpu() != 0
            g_rots.append(torch.where(bad, torch.full_like(r.cpu(), 180.0), r.cpu()))
            g_transs.append(torch.where(bad, torch.full_like(t.cpu(), 180.0), t.cpu()))
        if trivial is not None:
            q0 = trivial[0].to(T_gt).expand(T_gt.shape[0], 4)
            t0 = trivial[1].to(T_gt).expand(T_gt.shape[0], 3)
            r, t = _errors(q0, t0, T_gt)
            t_rots.append(r.cpu())
            t_transs.append(t.cpu())
    res = _summary(torch.cat(rots), torch.cat(transs), "")
    if losses:
        res["loss"] = float(np.mean(losses))
    if trivial is not None:
        res.update(_summary(torch.cat(t_rots), torch.cat(t_transs), "trivial_"))
    if g_rots:
        res.update(_summary(torch.cat(g_rots), torch.cat(g_transs), "geo_"))
    return res


# ----------------------------------------------------------------------------- checkpoints
def _check_plain(value: Any, where: str = "state") -> None:
    """Raises ``TypeError`` unless ``value`` holds only what ``torch.load(weights_only=True)``
    reads back: tensors, numbers, strings, ``None`` and lists / tuples / dicts of them."""
    if value is None or isinstance(value, (Tensor, bool, int, float, str, torch.device,
                                           torch.dtype)):
        return
    if isinstance(value, dict):
        for k, v in value.items():
            _check_plain(k, f"{where} key")
            _check_plain(v, f"{where}[{k!r}]")
        return
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_plain(v, f"{where}[{i}]")
        return
    raise TypeError(f"Expected tensors, numbers, strings and plain containers in a checkpoint "
                    f"(got {type(value).__module__}.{type(value).__qualname__} at {where})")


def save_checkpoint(path: str | os.PathLike, state: dict[str, Any]) -> Path:
    """Writes a training checkpoint atomically (temporary file in the same folder, then
    rename). ``state`` must hold only tensors, numbers, strings and plain containers, so that
    :func:`load_checkpoint` reads it back with ``weights_only=True`` (``TypeError`` otherwise,
    before anything is written)."""
    _check_plain(state)
    path = Path(path)
    with atomic_open(path) as f:
        torch.save(state, f)
    return path


def load_checkpoint(path: str | os.PathLike) -> dict[str, Any]:
    """Loads a training checkpoint (``last.pt``) safely: ``torch.load(weights_only=True)``,
    so a file that would run code is refused (:class:`~strl_pyg.io.UnsafeFileError`) and never
    executed. Clear one-line errors for missing, corrupt, foreign or old files."""
    path = Path(path)
    try:
        state = safe_torch_load(path, "checkpoint")
    except UnsafeFileError as err:
        if "numpy" in str(err):  # version 1 stored numpy's RNG state as an array
            raise UnsafeFileError(f"{err}; training checkpoints before version "
                                  f"{CHECKPOINT_VERSION} cannot be continued: start from that "
                                  "run's model.pt with --init-from") from None
        raise
    need = {"version", "train_config", "model_config", "model", "optimizer", "step"}
    if not isinstance(state, dict) or not need <= set(state):
        got = sorted(state) if isinstance(state, dict) else type(state).__name__
        raise ValueError(f"Expected a training checkpoint with keys {sorted(need)} in '{path}' "
                         f"(got {got})")
    if state["version"] != CHECKPOINT_VERSION:
        raise ValueError(f"Expected training checkpoint version {CHECKPOINT_VERSION} in "
                         f"'{path}' (got {state['version']!r})")
    return state


def _rng_state() -> dict[str, Any]:
    # the legacy global numpy state is what third-party augmentation code draws from; it is
    # stored as a tensor and numbers so the checkpoint loads with weights_only=True
    kind, keys, pos, has_gauss, cached = np.random.get_state()  # noqa: NPY002
    return {"torch": torch.get_rng_state(),
            "numpy": {"kind": str(kind), "keys": torch.from_numpy(keys.astype(np.int64)),
                      "pos": int(pos), "has_gauss": int(has_gauss), "cached": float(cached)},
            "python": random.getstate()}


def _set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state((n["kind"], n["keys"].numpy().astype(np.uint32), n["pos"],  # noqa: NPY002
                         n["has_gauss"], n["cached"]))
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))


# ----------------------------------------------------------------------------- the loop
class _Logger:
    def __init__(self, out_dir: Path, enabled: bool, tensorboard: bool, resume_step: int):
        self.enabled = enabled
        self.csv_path = out_dir / "log.csv"
        self.tb = None
        if not enabled:
            return
        if resume_step > 0 and self.csv_path.exists():  # drop rows past the resumed step
            with open(self.csv_path) as f:
                rows = [r for r in csv.DictReader(f) if int(r["step"]) <= resume_step]
            with open(self.csv_path, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["step", "split", "key", "value"])
                w.writerows([[r["step"], r["split"], r["key"], r["value"]] for r in rows])
        elif not self.csv_path.exists() or resume_step == 0:
            with open(self.csv_path, "w", newline="") as f:
                csv.writer(f).writerow(["step", "split", "key", "value"])
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.tb = SummaryWriter(str(out_dir / "tb"), purge_step=resume_step or None)
            except ImportError:
                self.tb = None

    def log(self, step: int, split: str, values: dict[str, float]) -> None:
        if not self.enabled:
            return
        with open(self.csv_path, "a", newline="") as f:
            w = csv.writer(f)
            for k, v in values.items():
                w.writerow([step, split, k, f"{float(v):.6g}"])
        if self.tb is not None:
            for k, v in values.items():
                self.tb.add_scalar(f"{split}/{k}", float(v), step)

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()


def _unaugmented_poses(batch: HeteroData) -> Tensor:
    """Ground-truth poses with the swap augmentation undone (the trivial predictor is the mean
    pose of the data as it comes, not of the augmented data)."""
    T = batch[K.T_0TO1].detach()
    if K.SWAPPED not in batch:
        return T
    swapped = batch[K.SWAPPED].bool()
    T = T.clone()
    T[swapped] = torch.linalg.inv(T[swapped])
    return T


def _init_weights(model: StrLPose, path: str | os.PathLike) -> None:
    """Loads the weights of a model checkpoint (``model.pt``) or training checkpoint
    (``last.pt``) into ``model``; the architectures must match. Both load with
    ``weights_only=True`` (a file that would run code is refused)."""
    path = Path(path)
    payload = safe_torch_load(path, "weights file (model.pt or last.pt)")
    if isinstance(payload, dict) and "format" in payload:
        state = StrLPose.load(path).state_dict()
    else:
        state = load_checkpoint(path)["model"]
    # A model that adds the geometric head may start from regression-only weights: the new
    # head's parameters are the only ones allowed to be missing.
    try:
        missing, unexpected = model.load_state_dict(state, strict=False)
    except RuntimeError as err:
        raise ValueError(f"Expected weights matching this run's model config in '{path}' "
                         f"(got {str(err).splitlines()[0]})") from err
    missing = [k for k in missing if not k.startswith("inlier_head.")]
    if missing or unexpected:
        raise ValueError(f"Expected weights matching this run's model config in '{path}' "
                         f"(got missing keys {missing[:5]}, unexpected keys {unexpected[:5]})")


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
        _init_weights(model, cfg.init_from)
    if resume:
        state = load_checkpoint(ckpt_path)
        saved = TrainConfig.from_dict(state["train_config"])
        if {**asdict(saved), "steps": 0} != {**asdict(cfg), "steps": 0}:
            diff = {k: (v, getattr(cfg, k)) for k, v in asdict(saved).items()
                    if k != "steps" and getattr(cfg, k) != v}
            raise ValueError(f"Expected the checkpoint's config to match this run "
                             f"(got differences {{key: (checkpoint, now)}} = {diff})")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        start_step = int(state["step"])
        history = state.get("history", [])
        trivial_buf = [state["trivial_T"]] if "trivial_T" in state else []
        _set_rng_state(state["rng"])

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
    logger = _Logger(out_dir, rank == 0, cfg.tensorboard, start_step)
    if rank == 0:
        (out_dir / "config.json").write_text(json.dumps(asdict(cfg), indent=2))
    result: dict[str, Any] = {"step": start_step, "checkpoint": str(ckpt_path)}
    step = start_step
    t_start, pairs_seen = time.perf_counter(), 0
    bar = tqdm(total=cfg.steps, initial=start_step, desc="train", disable=not progress or rank)
    for batch in loader:
        ddp_model.train()
        batch = batch.to(device)
        T_gt = batch[K.T_0TO1]
        if sum(t.shape[0] for t in trivial_buf) < 4096:
            trivial_buf.append(_unaugmented_poses(batch).cpu())
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
                    "rng": _rng_state(),
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


def plot_history(history: list[dict[str, Any]], path: str | os.PathLike,
                 marks: Sequence[tuple[int, str]] = ()) -> Path:
    """Validation error curves (model against the trivial mean-pose predictor) as a PNG;
    ``marks`` draws labelled vertical lines, e.g. where a run was continued with new settings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from strl_pyg.viz.plots import save_figure

    steps = [h["step"] for h in history]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, key, title in zip(axes, ("rot_err_deg", "trans_err_deg", "auc10"),
                              ("rotation error (deg)", "translation-direction error (deg)",
                               "pose AUC@10"), strict=True):
        ax.plot(steps, [h[key] for h in history], "o-", label="Str-L Pose")
        ax.plot(steps, [h["trivial_" + key] for h in history], "--", label="mean pose")
        for step, label in marks:
            ax.axvline(step, color="grey", lw=0.8, ls=":")
            ax.text(step, ax.get_ylim()[1], f" {label}", va="top", fontsize=7, color="grey")
        ax.set_xlabel("step")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        if not math.isnan(history[-1][key]):
            ax.legend()
    fig.tight_layout()
    return save_figure(fig, path)


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
            tensorboard=not args.no_tensorboard,
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
