"""A relative pose for every pair of a photo collection: :func:`run_scene`.

Phases, each resumable after a kill (a rerun with the same output folder repeats nothing that
was finished):

1. **Features**, once per image and setting, into ``<out>/features`` (:class:`~strl_pyg.
   frontend.store.FeatureStore`, hloc's HDF5 layout); an image whose features are stored is
   not read again.
2. **Pairs**: each pair matched from the stored features and given the recommended pose, its
   status and sigma (:meth:`~strl_pyg.inference.PoseEstimator.estimate_images`). Its matches
   go to ``<out>/matches.h5``, then its line to ``<out>/pairs.jsonl`` (the line marks the pair
   done). A pair whose adaptive second pass needs features not stored yet waits; those
   features are computed once per image and the waiting pairs run again.
3. **Outputs**: ``<out>/pairs.csv`` and a COLMAP database ``<out>/database.db``
   (:func:`~strl_pyg.collection.database.write_database`), written to a temporary file and
   renamed, and ``<out>/summary.json``.

Work runs in ``workers`` processes (each one thread); this process alone writes the files.
Under ``torchrun``, :mod:`strl_pyg.collection.distributed` splits the images and the pairs
across ranks instead.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import nullcontext
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.collection.files import STATUS_TO_VERIFY, pair_key, read_done
from strl_pyg.collection.images import CollectionImage
from strl_pyg.collection.pairs import Pair
from strl_pyg.collection.work import features_task, init_worker, pair_task
from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.features import LINES, POINTS, PointFeatures
from strl_pyg.frontend.pipeline import thorough_points
from strl_pyg.frontend.store import FeatureStore
from strl_pyg.inference.status import Status

__all__ = ["SceneOptions", "SceneSummary", "run_scene", "check_settings", "pair_task_of",
           "pair_intrinsics", "intrinsics_warning", "PoolRunner"]



@dataclass
class SceneOptions:
    """Settings of :func:`run_scene`.

    Args:
        frontend: The front end's settings (default: ``FrontendConfig()``, the adaptive
            preset).
        methods: The estimator's methods (default: the recommended walk).
        model: A checkpoint path or model for the estimator (default: the shipped model).
        workers: Worker processes (1: this process). (default: 1)
        verified: Statuses whose pose and inlier matches enter the database as verified
            two-view geometries; the others are written as ``DEGENERATE``. (default: ``ok``)
        database: Write the COLMAP database (needs pycolmap). (default: True)
        progress: tqdm progress bars on stderr. (default: True)
    """

    frontend: FrontendConfig = field(default_factory=FrontendConfig)
    methods: Any = None
    model: Any = None
    workers: int = 1
    verified: tuple[str, ...] = STATUS_TO_VERIFY
    database: bool = True
    progress: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) \
                or self.workers < 1:
            raise ValueError(f"Expected workers >= 1 (got {self.workers!r})")


@dataclass
class SceneSummary:
    """What a :func:`run_scene` call did: counts of images and pairs, what it computed (not
    what an earlier, killed run had finished), statuses, outputs and seconds."""

    images: int
    pairs: int
    pairs_computed: int
    features_computed: dict[str, int]
    statuses: dict[str, int]
    outputs: dict[str, str]
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class _Local:
    """The executor of ``workers=1``: runs each task here when it is submitted."""

    def submit(self, fn: Callable, *args: Any) -> Future:
        fut: Future = Future()
        fut.set_result(fn(*args))
        return fut

    def shutdown(self) -> None:
        pass


class PoolRunner:
    """Runs a scene's work in this process (``workers=1``) or a pool of worker processes;
    this process reads the store, builds each task and writes every result.

    The interface :func:`run_scene` drives (:class:`~strl_pyg.collection.distributed.
    CollectiveRunner` is the ``torchrun`` one): ``writer`` (whether this process writes the
    outputs), ``features(tasks)`` and ``pairs(pairs, images, store, cfg)`` (results, on the
    writer, as they complete), ``store(root)`` around each phase, ``shutdown()``."""

    writer = True

    def __init__(self, options: SceneOptions) -> None:
        self.ahead = 2 * options.workers
        if options.workers == 1:
            init_worker(options.methods, options.model, threads=os.cpu_count() or 1)
            self.executor: Any = _Local()
        else:
            self.executor = ProcessPoolExecutor(options.workers, mp_context=get_context("spawn"),
                                                initializer=init_worker,
                                                initargs=(options.methods, options.model, 1))
        self._store: FeatureStore | None = None

    def store(self, root: Path, writing: bool) -> FeatureStore:
        """The store for the next phase (this process keeps one writable store)."""
        if self._store is None:
            self._store = FeatureStore(root)
        return self._store

    def features(self, tasks: list[tuple[CollectionImage, list]]) -> Iterator:
        return _bounded(self.executor, _features_star, tasks, self.ahead)

    def pairs(self, pairs: list[Pair], images: list[CollectionImage], store: FeatureStore,
              cfg: FrontendConfig) -> Iterator:
        return _bounded(self.executor, pair_task, _pair_tasks(pairs, images, store, cfg),
                        self.ahead)

    def shutdown(self) -> None:
        self.executor.shutdown()
        if self._store is not None:
            self._store.close()


def _bounded(executor: Any, fn: Callable, items: Iterable, ahead: int) -> Iterator:
    """``fn(item)`` for each item on the executor, at most ``ahead`` in flight; results as
    they complete."""
    pending: set[Future] = set()
    for item in items:
        pending.add(executor.submit(fn, item))
        if len(pending) >= ahead:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            yield from (f.result() for f in done)
    while pending:
        done, pending = wait(pending, return_when=FIRST_COMPLETED)
        yield from (f.result() for f in done)


def _bar(options: SceneOptions, total: int, desc: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, disable=not options.progress, unit=desc.split()[-1])


def _compute_features(runner: Any, store: FeatureStore, images: list[CollectionImage],
                      needs: dict[int, list[tuple[str, dict]]], options: SceneOptions,
                      counts: dict[str, int]) -> None:
    """Computes ``needs`` (image index -> ``(kind, config fields)``); the writer stores them
    and adds what it stored to ``counts`` (per kind)."""
    if not needs:
        return
    index = {im.name: k for k, im in enumerate(images)}
    with _bar(options if runner.writer else _QUIET, len(needs), "features images") as bar:
        tasks = [(images[k], v) for k, v in sorted(needs.items())]
        for name, size, arrays in runner.features(tasks):
            for kind, _ in needs[index[name]]:
                counts[kind] += 1
            _store_arrays(store, name, size, arrays, needs[index[name]])
            bar.update(1)


def _features_star(args: tuple) -> Any:
    return features_task(*args)


def _store_arrays(store: FeatureStore, name: str, size: tuple[int, int],
                  arrays: dict[str, Any], configs: list[tuple[str, dict]]) -> None:
    from strl_pyg.frontend.features import settings_key

    for kind, fields in configs:
        cfg = FrontendConfig(**fields)
        value = arrays[settings_key(kind, cfg)]
        store.put(kind, name, cfg, value, size)


def _first_needs(store: FeatureStore, images: list[CollectionImage], cfg: FrontendConfig,
                 used: set[int]) -> dict[int, list[tuple[str, dict]]]:
    """The first pass's features (and segments) missing for the images ``used`` by a pair."""
    needs: dict[int, list[tuple[str, dict]]] = {}
    for k in sorted(used):
        im = images[k]
        want = [(POINTS, cfg)] + ([(LINES, cfg)] if cfg.lines else [])
        miss = [(kind, asdict(c)) for kind, c in want if not store.has(kind, im.name, c)]
        if miss:
            needs[k] = miss
    return needs


def pair_intrinsics(p: Pair, images: list[CollectionImage]) -> tuple[Any, Any]:
    """The pair's ``(K0, K1)``: its own where the pairs file gives them, else its images'
    cameras'; ``(None, None)`` where either is unknown (the pair runs without intrinsics)."""
    a, b = images[p.i], images[p.j]
    K0 = p.K0 if p.K0 is not None else (None if a.camera is None else a.camera.K)
    K1 = p.K1 if p.K1 is not None else (None if b.camera is None else b.camera.K)
    return (None, None) if K0 is None or K1 is None else (K0, K1)


def intrinsics_warning(images: list[CollectionImage], pairs: list[Pair],
                       options: SceneOptions) -> str | None:
    """The one-line warning :func:`run_scene` gives where pairs have no intrinsics and the
    database would get none of their geometries: a pose without intrinsics is
    ``unreliable`` (rule ``no_intrinsics``), which ``options.verified`` does not hold by
    default, so COLMAP's mappers would find no verified pair among them; ``None`` otherwise."""
    blind = sum(pair_intrinsics(p, images)[0] is None for p in pairs)
    if not blind or not options.database or Status.UNRELIABLE.value in options.verified:
        return None
    return (f"{blind} of {len(pairs)} pairs have no intrinsics (an image without a camera and "
            f"no K in the pairs file): their poses are 'unreliable' (no_intrinsics), so none "
            f"enters the database as a verified geometry at verified={','.join(options.verified)}"
            f"; give a K or cameras (--K, --cameras), or verify 'unreliable' too")


def pair_task_of(p: Pair, images: list[CollectionImage], store: FeatureStore,
                 cfg: FrontendConfig) -> dict[str, Any]:
    """The task of one pair for :func:`~strl_pyg.collection.work.pair_task`: both images,
    their ``K`` (the pair's own where the pairs file gives one; none where either image has
    no camera) and their stored features."""
    configs = [cfg, thorough_points(cfg)] if cfg.thorough_below > 0 else [cfg]
    a, b = images[p.i], images[p.j]
    K0, K1 = pair_intrinsics(p, images)
    return {"i": p.i, "j": p.j, "image0": a, "image1": b,
            "K0": None if K0 is None else np.asarray(K0, dtype=float),
            "K1": None if K1 is None else np.asarray(K1, dtype=float),
            "arrays0": store.arrays(a.name, configs), "arrays1": store.arrays(b.name, configs),
            "config": asdict(cfg)}


def _pair_tasks(pairs: list[Pair], images: list[CollectionImage], store: FeatureStore,
                cfg: FrontendConfig) -> Iterator[dict[str, Any]]:
    for p in pairs:
        yield pair_task_of(p, images, store, cfg)


def _write_pair(result: dict[str, Any], images: list[CollectionImage], matches_h5: Any,
                jsonl: Any) -> dict:
    a, b = images[result["i"]].name, images[result["j"]].name
    if "error" in result:
        rec = {"image0": a, "image1": b, "error": result["error"]}
    else:
        key = pair_key(a, b)
        if key in matches_h5:
            del matches_h5[key]
        g = matches_h5.create_group(key)
        g.create_dataset("matches", data=np.asarray(result["matches"], np.int64).reshape(-1, 2))
        g.create_dataset("inliers", data=np.asarray(result["inliers"], bool))
        g.attrs["points_key"] = result["points_key"] or ""
        matches_h5.flush()
        rec = {"image0": a, "image1": b, **result["record"]}
    jsonl.write(json.dumps(rec) + "\n")
    jsonl.flush()
    return rec


def run_scene(images: list[CollectionImage], pairs: list[Pair], out_dir: str | os.PathLike,
              options: SceneOptions | None = None, runner: Any = None) -> SceneSummary | None:
    """Features, a recommended pose per pair, a table and a COLMAP database (module
    docstring).

    Args:
        images: The collection (:func:`~strl_pyg.collection.images.read_collection`).
        pairs: Pairs of indices into ``images`` (:mod:`strl_pyg.collection.pairs`).
        out_dir: The output folder (created; a rerun resumes it).
        options: :class:`SceneOptions`.
        runner: Who computes (default: :class:`PoolRunner` of ``options.workers``; the
            ``torchrun`` ranks pass a :class:`~strl_pyg.collection.distributed.
            CollectiveRunner`).

    Returns:
        :class:`SceneSummary` (also written to ``<out_dir>/summary.json``); ``None`` on a
        process that does not write the outputs (``torchrun`` ranks other than 0).

    Raises:
        ValueError: pairs outside the images; an output folder made with other front-end
            or estimator settings (:func:`check_settings`).
    """
    options = options or SceneOptions()
    if not images:
        raise ValueError("Expected at least two images (got none)")
    for p in pairs:
        if not (0 <= p.i < len(images) and 0 <= p.j < len(images)) or p.i == p.j:
            raise ValueError(f"Expected pairs of two of the {len(images)} images (got "
                             f"({p.i}, {p.j}))")
    out = Path(out_dir)
    t0 = time.perf_counter()
    if runner is None:
        out.mkdir(parents=True, exist_ok=True)
        check_settings(out, options)
        runner = PoolRunner(options)
    message = intrinsics_warning(images, pairs, options) if runner.writer else None
    if message:
        warnings.warn(message, UserWarning, stacklevel=2)
    try:
        done, computed, store = _run_phases(runner, images, pairs, out, options)
        if not runner.writer:
            return None
        return _finish(images, pairs, out, options, done, computed, store, t0)
    finally:
        runner.shutdown()


def check_settings(out: Path, options: SceneOptions) -> None:
    """Records the run's front-end and estimator settings in ``<out>/settings.json``, or checks
    that a folder being resumed was made with the same (``ValueError`` naming the first field
    that differs: its features and pairs would mix two settings)."""
    from strl_pyg.frontend.features import settings_key

    cfg = options.frontend
    now = {"frontend": cfg.result_fields(), "points": settings_key(POINTS, cfg),
           "methods": None if options.methods is None else str(options.methods),
           "model": None if options.model is None else str(getattr(options.model, "source",
                                                                       type(options.model)))}
    path = out / "settings.json"
    if path.exists():
        try:
            before = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"Expected the settings of a scene run in JSON at '{path}' (got "
                             f"{err})") from None
        for k in sorted(set(now) | set(before)):
            if json.dumps(now.get(k), sort_keys=True) != json.dumps(before.get(k), sort_keys=True):
                raise ValueError(f"Expected the settings the folder '{out}' was made with to "
                                 f"resume it (got another {k}: {now.get(k)} against "
                                 f"{before.get(k)}); use another --out")
        return
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(now, indent=1, sort_keys=True))
    os.replace(tmp, path)


def _run_phases(runner: Any, images: list[CollectionImage], pairs: list[Pair], out: Path,
                options: SceneOptions) -> tuple[dict, tuple[int, dict], FeatureStore]:
    """The features and the pairs, resumed from what ``out`` holds; on the writer, the
    finished records by names, how many pairs and image features this call computed, and
    the store."""
    import h5py

    cfg = options.frontend
    jsonl_path = out / "pairs.jsonl"
    done = read_done(jsonl_path) if runner.writer else {}
    done_names = runner.agree(set(done)) if hasattr(runner, "agree") else set(done)
    store = runner.store(out / "features", writing=True)
    counts = {POINTS: 0, LINES: 0}
    used = {k for p in pairs for k in (p.i, p.j)}
    needs = _first_needs(store, images, cfg, used) if runner.writer else {}
    if hasattr(runner, "agree"):
        needs = runner.agree(needs)
    _compute_features(runner, store, images, needs, options, counts)
    todo = [p for p in pairs if (images[p.i].name, images[p.j].name) not in done_names]
    computed = 0
    with (h5py.File(out / "matches.h5", "a") if runner.writer else nullcontext()) as mh5, \
            (open(jsonl_path, "a") if runner.writer else nullcontext()) as jsonl, \
            _bar(options if runner.writer else _QUIET, len(pairs), "pairs") as bar:
        bar.update(len(pairs) - len(todo))
        while todo:
            waiting: list[Pair] = []
            needs: dict[int, list[tuple[str, dict]]] = {}
            by_ij = {(p.i, p.j): p for p in todo}
            store = runner.store(out / "features", writing=False)
            for res in runner.pairs(todo, images, store, cfg):
                if "missing" in res:
                    waiting.append(by_ij[(res["i"], res["j"])])
                    for side, kind, fields in res["missing"]:
                        k = res["i"] if side == 0 else res["j"]
                        if (kind, fields) not in needs.setdefault(k, []):
                            needs[k].append((kind, fields))
                    continue
                rec = _write_pair(res, images, mh5, jsonl)
                done[(rec["image0"], rec["image1"])] = rec
                computed += 1
                bar.update(1)
            if hasattr(runner, "agree"):
                waiting, needs = runner.agree((waiting, needs))
            if waiting and not needs:
                raise RuntimeError("Expected the waiting pairs to name missing features (got "
                                   "none)")
            store = runner.store(out / "features", writing=True)
            _compute_features(runner, store, images, needs, options, counts)
            todo = waiting
    return done, (computed, counts), store


_QUIET = SceneOptions(progress=False)


def _finish(images: list[CollectionImage], pairs: list[Pair], out: Path, options: SceneOptions,
            done: dict, computed: tuple[int, dict], store: FeatureStore,
            t0: float) -> SceneSummary:
    """The table, the database and the summary, from the finished records."""
    cfg = options.frontend
    jsonl_path = out / "pairs.jsonl"
    statuses: dict[str, int] = {}
    for rec in done.values():
        s = rec.get("status", "error")
        statuses[s] = statuses.get(s, 0) + 1
    outputs = {"pairs": str(jsonl_path), "matches": str(out / "matches.h5"),
               "features": str(out / "features")}
    outputs["csv"] = str(_write_csv(out / "pairs.csv", images, pairs, done))
    if options.database:
        from strl_pyg.collection.database import write_database

        outputs["database"] = str(write_database(out / "database.db", images, pairs, done,
                                                 store, out / "matches.h5", cfg,
                                                 options.verified))
    summary = SceneSummary(len(images), len(pairs), computed[0], dict(computed[1]), statuses,
                           outputs, time.perf_counter() - t0)
    (out / "summary.json").write_text(json.dumps(summary.to_dict(), indent=1))
    return summary


_CSV_FIELDS = ("image0", "image1", "status", "rule", "method", "configuration", "num_points",
               "num_lines", "num_inliers", "rotation_sigma_deg", "translation_sigma_deg",
               "qw", "qx", "qy", "qz", "tx", "ty", "tz", "error")


def _write_csv(path: Path, images: list[CollectionImage], pairs: list[Pair],
               done: dict[tuple[str, str], dict]) -> Path:
    """``pairs.csv``: one row per pair in the pairs' order (pose as a unit quaternion and a
    unit translation of ``T_0to1``), written to a temporary file and renamed."""
    import csv

    from strl_pyg.geometry.pose import rotation_to_quaternion

    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, _CSV_FIELDS)
        w.writeheader()
        for p in pairs:
            rec = done.get((images[p.i].name, images[p.j].name))
            if rec is None:
                continue
            row = {k: rec.get(k) for k in _CSV_FIELDS if k in rec}
            sigma = rec.get("sigma") or {}
            row["rotation_sigma_deg"] = sigma.get("rotation_deg")
            row["translation_sigma_deg"] = sigma.get("translation_deg")
            if rec.get("T_0to1") is not None:
                T = np.asarray(rec["T_0to1"], dtype=float)
                q = rotation_to_quaternion(T[:3, :3]).double().numpy().reshape(4)
                row.update(zip(("qw", "qx", "qy", "qz"), q.tolist(), strict=True))
                row.update(zip(("tx", "ty", "tz"), T[:3, 3].tolist(), strict=True))
            w.writerow(row)
    os.replace(tmp, path)
    return path


def stored_points(store: FeatureStore, name: str, cfg: FrontendConfig) -> list[tuple[str,
                                                                                   PointFeatures]]:
    """The stored point features of ``name`` for the first pass and the second, in that order
    (what the database's keypoints concatenate)."""
    from strl_pyg.frontend.features import settings_key

    out = []
    for c in ([cfg, thorough_points(cfg)] if cfg.thorough_below > 0 else [cfg]):
        if store.has(POINTS, name, c):
            out.append((settings_key(POINTS, c), store.points(name, c)))
    return out
