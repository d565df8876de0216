"""Per-step sampling of training pairs: in-memory caching, seeded resampling and
augmentation (:class:`ResampledPairs`, keyed by ``(index, step, position)``), the outlier
shuffle, and the deterministic step batch sampler (the batch of global step ``s`` is a pure
function of ``(seed, s)``, so a resumed run draws what it would have drawn)."""

from __future__ import annotations

import copy
from typing import Any

import torch
from torch.utils.data import Dataset, Sampler
from torch_geometric.data import HeteroData

from strl_pyg.data import keys as keys_
from strl_pyg.data.transforms import FixedSizeResample, RandomRoll, RandomSwap

__all__ = ["ResampledPairs", "StepBatchSampler", "shuffle_point_matches"]


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


class ResampledPairs(Dataset):
    """Applies :class:`FixedSizeResample`, :class:`RandomSwap`, the outlier shuffle and
    :class:`RandomRoll` (each when asked for), seeded by the key
    ``(index, step, position)``."""

    def __init__(self, base: Dataset, num_points: int, num_lines: int, seed: int,
                 swap_prob: float = 0.0, outlier_max: float = 0.0, roll_max: float = 0.0) -> None:
        self.base, self.num_points, self.num_lines, self.seed = base, num_points, num_lines, seed
        self.swap_prob = swap_prob
        self.outlier_max = outlier_max
        self.roll_max = roll_max

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
        if self.roll_max > 0:
            data = RandomRoll(self.roll_max, seed=seed + 3)(data)
        return data


def shuffle_point_matches(data: HeteroData, max_fraction: float, seed: int) -> HeteroData:
    """Training augmentation: a fraction ``U(0, max_fraction)`` of the point matches get the
    image-1 side of another point match (``pos1``, ``kpts1``, ``patch1`` permuted together), so
    they become realistic outliers (a real feature of image 1, consistent patch) whose label
    the geometric loss recomputes from the true pose. Returns a shallow copy."""
    gen = torch.Generator().manual_seed(int(seed) % (2**63))
    store = data[keys_.POINT]
    n = store[keys_.POS1].shape[0]
    m = int(float(torch.rand(1, generator=gen)) * max_fraction * n)
    if m < 2:
        return data
    out = copy.copy(data)  # attributes are reassigned below, never modified in place
    idx = torch.randperm(n, generator=gen)[:m]
    perm = idx[torch.roll(torch.arange(m), 1)]
    for key in (keys_.POS1, keys_.KPTS1, keys_.PATCH1):
        if key in store:
            out[keys_.POINT][key] = store[key].index_copy(0, idx, store[key][perm])
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



class _Cycled(Dataset):
    """``length`` items cycling through ``base`` (item ``i`` is ``base[i % len(base)]``)."""

    def __init__(self, base: Any, length: int) -> None:
        self.base, self.length = base, length

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, i: int) -> HeteroData:
        if not 0 <= i < self.length:
            raise IndexError(f"Expected an index in [0, {self.length}) (got {i})")
        return self.base[i % len(self.base)]
