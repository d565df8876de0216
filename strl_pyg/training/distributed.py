"""The processes of a training run: ``torchrun``'s process group and this rank's device, the
seeds, and SIGINT / SIGTERM turned into a checkpoint-and-stop."""

from __future__ import annotations

import os
import random
import signal
import threading
from typing import Any

import numpy as np
import torch

from strl_pyg.training.config import TrainConfig

__all__ = ["StopSignals", "dist_info", "distributed_setup", "seed_everything"]


class StopSignals:
    """Turns the first SIGINT / SIGTERM into a flag (the loop checkpoints and stops after the
    step in progress); a second one raises KeyboardInterrupt as usual."""

    def __init__(self) -> None:
        self.received: str | None = None
        self._old: dict[int, Any] = {}
        if threading.current_thread() is not threading.main_thread():
            return  # signal handlers can only be set from the main thread
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self._handle)

    def _handle(self, signum: int, frame: Any) -> None:
        if self.received is not None:
            self.restore()
            raise KeyboardInterrupt
        self.received = signal.Signals(signum).name

    def restore(self) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old = {}


def dist_info() -> tuple[int, int]:
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return torch.distributed.get_rank(), torch.distributed.get_world_size()
    return 0, 1


def seed_everything(seed: int) -> None:
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002
    random.seed(seed)


def distributed_setup(cfg: TrainConfig) -> tuple[int, int, str, bool]:
    """Under ``torchrun`` (``WORLD_SIZE`` > 1) the process group (gloo on CPU, nccl on CUDA)
    and this rank's device; ``(rank, world, device, whether the group is this run's own)``."""
    own_group = False
    if int(os.environ.get("WORLD_SIZE", "1")) > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if cfg.device.startswith("cuda") else "gloo"
        torch.distributed.init_process_group(backend)
        own_group = True
    rank, world = dist_info()
    device = cfg.device
    if device.startswith("cuda") and world > 1:
        device = f"cuda:{int(os.environ.get('LOCAL_RANK', 0))}"
        torch.cuda.set_device(device)
    return rank, world, device, own_group
