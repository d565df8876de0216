"""A scene run split across ``torchrun`` ranks (torch.distributed, gloo).

``torchrun --nproc-per-node N -m strl_pyg.cli scene IMAGES --out DIR`` (or several machines
sharing ``DIR``) runs :func:`~strl_pyg.collection.scene.run_scene` on every rank with a
:class:`CollectiveRunner`: rank ``r`` of ``W`` computes the features of images ``r, r + W,
...`` and the pairs ``r, r + W, ...`` of each phase's list, in rounds; each round's results
are gathered to rank 0 (``gather_object``), which alone writes the store, the matches, the
table and the database. During a pair phase every rank reads the feature store read-only
(HDF5 allows many readers and no writer then); rank 0 writes it only between phases, while
the others wait at a barrier. A kill and a rerun resume as a one-process run does (rank 0's
table marks what is done; ranks agree on it by a broadcast).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from strl_pyg.collection.images import CollectionImage
from strl_pyg.collection.pairs import Pair
from strl_pyg.collection.scene import (
    SceneOptions,
    SceneSummary,
    check_settings,
    pair_task_of,
    run_scene,
)
from strl_pyg.collection.work import features_task, init_worker, pair_task
from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.store import FeatureStore

__all__ = ["CollectiveRunner", "run_scene_distributed", "ROUND"]

#: Items each rank computes between two gathers.
ROUND = 4


class CollectiveRunner:
    """The :class:`~strl_pyg.collection.scene.PoolRunner` interface over the ranks of an
    initialised ``torch.distributed`` process group (module docstring)."""

    def __init__(self, options: SceneOptions, threads: int = 1) -> None:
        import torch.distributed as dist

        self.dist = dist
        self.rank, self.world = dist.get_rank(), dist.get_world_size()
        self.writer = self.rank == 0
        init_worker(options.methods, options.model, threads=threads)
        self._store: FeatureStore | None = None
        self._writing = False

    def agree(self, value: Any) -> Any:
        """Rank 0's ``value`` on every rank."""
        box = [value]
        self.dist.broadcast_object_list(box, src=0)
        return box[0]

    def store(self, root: Path, writing: bool) -> FeatureStore:
        """Rank 0 writes the store between phases (the others wait); every rank reads it
        during a pair phase."""
        if self._store is not None and self._writing == writing:
            return self._store
        if self._store is not None:
            self._store.close()
        self.dist.barrier()  # every rank has closed its handle
        if writing and self.writer:
            self._store = FeatureStore(root)
        elif writing:
            self._store = _Reading(root)
        else:
            self._store = FeatureStore(root, writable=False)
        self.dist.barrier()  # rank 0 has created the files before any rank reads them
        self._writing = writing
        return self._store

    def _rounds(self, fn: Any, items: list) -> Iterator:
        mine = items[self.rank::self.world]
        rounds = -(-len(items) // (ROUND * self.world)) if items else 0
        for r in range(rounds):
            out = [fn(x) for x in mine[r * ROUND:(r + 1) * ROUND]]
            gathered: list | None = [None] * self.world if self.writer else None
            self.dist.gather_object(out, gathered, dst=0)
            if self.writer:
                for part in gathered or []:
                    yield from part

    def features(self, tasks: list[tuple[CollectionImage, list]]) -> Iterator:
        return self._rounds(lambda t: features_task(*t), tasks)

    def pairs(self, pairs: list[Pair], images: list[CollectionImage], store: FeatureStore,
              cfg: FrontendConfig) -> Iterator:
        return self._rounds(lambda p: pair_task(pair_task_of(p, images, store, cfg)), pairs)

    def shutdown(self) -> None:
        if self._store is not None:
            self._store.close()
            self._store = None


class _Reading(FeatureStore):
    """What a rank other than 0 holds while rank 0 writes: nothing open, nothing stored."""

    def __init__(self, root: Path) -> None:  # noqa: D107 - no file is opened
        self.root, self.writable, self._files = Path(root), False, {}
        self.computed = {"points": 0, "lines": 0}

    def put(self, *args: Any, **kwargs: Any) -> None:
        pass


def run_scene_distributed(images: list[CollectionImage], pairs: list[Pair],
                          out_dir: str | os.PathLike, options: SceneOptions | None = None
                          ) -> SceneSummary | None:
    """:func:`run_scene` on every rank of ``torchrun`` (gloo; the group is made here when it
    does not exist, and destroyed after); the summary on rank 0, ``None`` elsewhere."""
    import torch.distributed as dist

    options = options or SceneOptions()
    made = not dist.is_initialized()
    if made:
        dist.init_process_group("gloo")
    try:
        out = Path(out_dir)
        runner = CollectiveRunner(options)
        error = None
        if runner.writer:
            try:
                out.mkdir(parents=True, exist_ok=True)
                check_settings(out, options)
            except (OSError, ValueError) as err:
                error = str(err)
        error = runner.agree(error)
        if error is not None:  # every rank stops with rank 0's one line
            raise ValueError(error)
        return run_scene(images, pairs, out, options, runner=runner)
    finally:
        if made:
            dist.destroy_process_group()
