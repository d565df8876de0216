"""An on-disk, resumable, parallel cache of per-pair matches.

Layout: ``<root>/<fingerprint-hash>/`` holds ``fingerprint.json`` (what produced the entries:
front-end configuration, image size, ...) and, per pair, either ``<key>.npz`` (a
:class:`~strl_pyg.data.PairMatches` written by its atomic ``save``) or ``<key>.failed`` (a
small JSON marker: the pair gave no matches; resume does not retry it). A changed
fingerprint gives a new folder, so stale entries are never reused.

Every file is written to a temporary file in the same folder and renamed, so an interrupted
build (Ctrl-C, a killed process, a full disk) leaves finished entries and nothing half-written;
the next :meth:`MatchCache.build` skips what exists and loads, and redoes the rest.
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import multiprocessing as mp
import os
import re
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.data.matches import PairMatches
from strl_pyg.utils.io import atomic_open

__all__ = [
    "CACHE_FORMAT_VERSION",
    "CacheBuildReport",
    "MatchCache",
    "PairFailedError",
    "cache_key",
    "fingerprint_hash",
]

#: Bumped when the meaning of cache entries changes; part of every fingerprint.
#: 2 (0.4.0): the front end drops repeated point matches (one SIFT keypoint matched once per
#: orientation); entries of version 1 may hold them and are not read.
CACHE_FORMAT_VERSION = 2

#: Temporary files older than this (seconds) are leftovers of killed builds and are removed.
_STALE_TMP_S = 3600.0

_STATUSES = ("done", "failed", "missing", "corrupt")


class PairFailedError(ValueError):
    """Raised when loading a pair that the cache records as failed (no matches)."""


def cache_key(pair_id: str) -> str:
    """A file-name-safe key of a pair id: readable prefix plus 8 hex digits of its SHA-1, so
    ids that differ only in characters replaced by ``_`` still get distinct keys."""
    if not isinstance(pair_id, str) or not pair_id:
        raise ValueError(f"Expected a non-empty string pair id (got {pair_id!r})")
    safe = re.sub(r"[^A-Za-z0-9.-]+", "_", pair_id).strip("._")[:120]
    return f"{safe}-{hashlib.sha1(pair_id.encode()).hexdigest()[:8]}"


def fingerprint_hash(fingerprint: dict[str, Any]) -> str:
    """12 hex digits of the SHA-1 of the canonical JSON of ``fingerprint``."""
    text = json.dumps({"format": CACHE_FORMAT_VERSION, **fingerprint}, sort_keys=True, default=repr)
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def _atomic_write_text(path: Path, text: str) -> None:
    with atomic_open(path, "w") as f:
        f.write(text)


@dataclass
class CacheBuildReport:
    """What one :meth:`MatchCache.build` call did (counts of pairs)."""

    total: int
    already_done: int = 0
    already_failed: int = 0
    corrupt_redone: int = 0
    computed: int = 0
    failed: int = 0
    remaining: int = 0
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        """True when every pair has an entry (matches or a failure marker)."""
        return self.remaining == 0

    def __str__(self) -> str:
        return (
            f"{self.total} pairs: {self.already_done} cached, {self.already_failed} known "
            f"failures, {self.computed} matched now, {self.failed} new failures, "
            f"{self.corrupt_redone} corrupt entries redone, {self.remaining} remaining "
            f"({self.seconds:.1f} s)"
        )


def _worker_init() -> None:
    # One process per core: keep each single-threaded.
    try:
        import cv2

        cv2.setNumThreads(1)
    except Exception:  # pragma: no cover - cv2 is a core dependency
        pass
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _run_job(
    fn: Callable[[Any], PairMatches],
    payload: Any,
    key: str,
    npz_path: str,
    failed_path: str,
    skip_errors: tuple[type[BaseException], ...],
) -> tuple[str, str]:
    """Computes one entry and writes it atomically; returns ``(key, "done"|"failed")``."""
    try:
        matches = fn(payload)
    except skip_errors as err:
        marker = {"key": key, "error": type(err).__name__, "message": str(err)}
        _atomic_write_text(Path(failed_path), json.dumps(marker))
        return key, "failed"
    if not isinstance(matches, PairMatches):
        raise TypeError(
            f"Expected the match function to return a PairMatches for '{key}' "
            f"(got {type(matches).__name__})"
        )
    matches.save(npz_path)
    if os.path.exists(failed_path):  # a stale marker from an older attempt
        os.unlink(failed_path)
    return key, "done"


class MatchCache:
    """A folder of per-pair match files for one fingerprint.

    Args:
        root: Cache root; entries go to ``root/<fingerprint_hash(fingerprint)>/``.
        fingerprint: JSON-serialisable description of everything that determines the
            entries (front-end configuration, image size, colour mode, dataset kind).
    """

    def __init__(self, root: str | os.PathLike, fingerprint: dict[str, Any]) -> None:
        if not isinstance(fingerprint, dict):
            raise TypeError(f"Expected a dict fingerprint (got {type(fingerprint).__name__})")
        self.root = Path(root)
        self.fingerprint = fingerprint
        self.dir = self.root / fingerprint_hash(fingerprint)

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}('{self.dir}')"

    def path(self, key: str) -> Path:
        """The ``.npz`` entry of ``key``."""
        return self.dir / f"{key}.npz"

    def failed_path(self, key: str) -> Path:
        """The failure marker of ``key``."""
        return self.dir / f"{key}.failed"

    def status(self, key: str, verify: bool = True) -> str:
        """``"done"``, ``"failed"``, ``"missing"`` or ``"corrupt"`` (with ``verify``, an entry
        counts as done only if it loads as a valid :class:`PairMatches`)."""
        path = self.path(key)
        if path.is_file():
            if not verify:
                return "done"
            try:
                PairMatches.load(path)
            except Exception:
                return "corrupt"
            return "done"
        if self.failed_path(key).is_file():
            return "failed"
        return "missing"

    def is_failed(self, key: str) -> bool:
        return not self.path(key).is_file() and self.failed_path(key).is_file()

    def load(self, key: str) -> PairMatches:
        """Loads the entry of ``key``.

        Raises:
            PairFailedError: the pair is recorded as giving no matches.
            FileNotFoundError: no entry yet (names the file; build the cache first).
            ValueError / KeyError: a corrupt entry (names the file).
        """
        path = self.path(key)
        if not path.is_file():
            failed = self.failed_path(key)
            if failed.is_file():
                raise PairFailedError(
                    f"Expected matches for pair '{key}' (got a failure marker at '{failed}')"
                )
            raise FileNotFoundError(
                f"Expected a cached match file at '{path}' (got no such file): "
                "build the cache first (dataset.build_cache())"
            )
        return PairMatches.load(path)

    def counts(self, keys: Sequence[str]) -> dict[str, tuple[int, int]]:
        """``key -> (point matches, line matches)`` of the cached entries among ``keys``
        (failed and missing ones are left out), read from the match arrays alone (not the
        images an entry may keep) and remembered in ``counts.json`` in the cache folder, so a
        filter by match count reads each entry once."""
        index_path = self.dir / "counts.json"
        known: dict[str, list[int]] = {}
        if index_path.is_file():
            try:
                known = json.loads(index_path.read_text())
            except (OSError, ValueError):
                known = {}  # a damaged index is rebuilt from the entries
        out, added = {}, False
        for key in keys:
            path = self.path(key)
            if not path.is_file():
                continue
            stamp = path.stat().st_mtime_ns
            row = known.get(key)
            if not (isinstance(row, list) and len(row) == 3 and row[2] == stamp):
                try:
                    with np.load(path, allow_pickle=False) as npz:
                        row = [len(npz["points0"]), len(npz["lines0"]) if "lines0" in npz.files
                               else 0, stamp]
                except Exception as err:
                    raise ValueError(f"Expected a readable match file at '{path}' (got "
                                     f"{type(err).__name__}: {err})") from err
                known[key], added = row, True
            out[key] = (int(row[0]), int(row[1]))
        if added:
            _atomic_write_text(index_path, json.dumps(known))
        return out

    def _prepare_dir(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        meta = self.dir / "fingerprint.json"
        if not meta.is_file():
            text = json.dumps(
                {"format": CACHE_FORMAT_VERSION, **self.fingerprint},
                sort_keys=True, indent=1, default=repr,
            )
            _atomic_write_text(meta, text)
        now = time.time()
        for tmp in self.dir.glob(".*.tmp"):
            try:
                if now - tmp.stat().st_mtime > _STALE_TMP_S:
                    tmp.unlink()
            except FileNotFoundError:  # removed by a concurrent writer's rename
                pass

    def build(
        self,
        keys: Sequence[str],
        payloads: Sequence[Any],
        fn: Callable[[Any], PairMatches],
        *,
        num_workers: int = 0,
        skip_errors: tuple[type[BaseException], ...] = (),
        max_pairs: int | None = None,
        verify: bool = True,
        progress: bool = True,
        mp_context: str | None = "spawn",
        desc: str = "matching pairs",
    ) -> CacheBuildReport:
        """Computes every missing entry once, ``fn(payload)`` per pair.

        Args:
            keys: Cache keys (:func:`cache_key`), one per pair, unique.
            payloads: What ``fn`` needs for each pair (picklable when ``num_workers > 0``).
            fn: ``payload -> PairMatches``; a picklable top-level function (or a
                ``functools.partial`` of one) when ``num_workers > 0``.
            num_workers: Worker processes; ``0`` (default) runs in this process.
            skip_errors: Exceptions of ``fn`` that mean "this pair has no matches": recorded
                as a ``.failed`` marker and not retried. Any other exception stops the build
                (finished entries stay; a rerun resumes).
            max_pairs: Stop after this many newly finished pairs (default: no limit); for
                chunked builds and for testing resumption.
            verify: Load existing entries and redo corrupt ones (default: ``True``); with
                ``False`` an existing file counts as done.
            progress: Show a tqdm progress bar.
            mp_context: Start method of the worker processes (default: ``"spawn"``, safe
                with threaded libraries; ``"fork"`` starts faster).

        Returns:
            A :class:`CacheBuildReport`.
        """
        keys = list(keys)
        if len(keys) != len(payloads):
            raise ValueError(
                f"Expected one payload per key (got {len(keys)} keys, {len(payloads)} payloads)"
            )
        if len(set(keys)) != len(keys):
            raise ValueError(f"Expected unique keys (got {len(keys) - len(set(keys))} duplicates)")
        if not isinstance(num_workers, int) or num_workers < 0:
            raise ValueError(f"Expected num_workers >= 0 (got {num_workers!r})")
        if max_pairs is not None and max_pairs < 0:
            raise ValueError(f"Expected max_pairs >= 0 or None (got {max_pairs})")
        start = time.perf_counter()
        self._prepare_dir()
        report = CacheBuildReport(total=len(keys))
        pending = []
        for i, key in enumerate(keys):
            status = self.status(key, verify=verify)
            if status == "done":
                report.already_done += 1
            elif status == "failed":
                report.already_failed += 1
            else:
                if status == "corrupt":
                    report.corrupt_redone += 1
                    warnings.warn(
                        f"Corrupt cache entry '{self.path(key)}' will be recomputed", stacklevel=2
                    )
                pending.append(i)
        limit = len(pending) if max_pairs is None else min(max_pairs, len(pending))

        from tqdm.auto import tqdm

        bar = tqdm(total=limit, desc=desc, disable=not progress, unit="pair")

        def account(status: str) -> None:
            if status == "done":
                report.computed += 1
            else:
                report.failed += 1
            bar.update(1)
            bar.set_postfix(failed=report.failed, refresh=False)

        def job_args(i: int) -> tuple:
            key = keys[i]
            return (fn, payloads[i], key, str(self.path(key)), str(self.failed_path(key)),
                    tuple(skip_errors))

        try:
            if num_workers == 0:
                for i in pending[:limit]:
                    account(_run_job(*job_args(i))[1])
            else:
                self._build_parallel(pending[:limit], job_args, account, num_workers, mp_context)
        finally:
            bar.close()
            report.remaining = len(pending) - report.computed - report.failed
            report.seconds = time.perf_counter() - start
        return report

    @staticmethod
    def _build_parallel(todo, job_args, account, num_workers, mp_context) -> None:
        ctx = mp.get_context(mp_context)
        # Bounded submission: an interrupt leaves only a few pairs in flight.
        with cf.ProcessPoolExecutor(num_workers, mp_context=ctx, initializer=_worker_init) as ex:
            queue = iter(todo)
            running: set[cf.Future] = set()
            try:
                while True:
                    while len(running) < 2 * num_workers:
                        i = next(queue, None)
                        if i is None:
                            break
                        running.add(ex.submit(_run_job, *job_args(i)))
                    if not running:
                        break
                    done, running = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                    for fut in done:
                        account(fut.result()[1])
            except BaseException:
                for fut in running:
                    fut.cancel()
                ex.shutdown(wait=True, cancel_futures=True)
                raise
