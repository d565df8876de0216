"""Process-wide thread pools for work that releases the GIL (OpenCV detectors, PoseLib), and
the number of cores this process may use.

A pool is made once per name (starting threads on every call cost ~3 ms each on a busy 2-core
machine) and forgotten in a child process after ``fork``: the child inherits the pool object
but not its threads, so a task submitted there would wait forever (reproduced with a
``fork``-ed ``multiprocessing`` child, as DataLoader workers are on Linux).
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

__all__ = ["shared_pool", "available_cores"]

_POOLS: dict[str, tuple[ThreadPoolExecutor, int]] = {}  # name -> (pool, its size)
_LOCK = threading.Lock()


def _forget_after_fork() -> None:
    global _LOCK
    _POOLS.clear()
    _LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):  # not on Windows (no fork there)
    os.register_at_fork(after_in_child=_forget_after_fork)


def shared_pool(name: str, size: int) -> ThreadPoolExecutor:
    """The process's pool ``name`` with at least ``size`` threads (made, or replaced by a
    larger one, on demand). Tasks must not wait on other tasks of the same pool."""
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ValueError(f"Expected a pool size as an integer >= 1 (got {size!r})")
    with _LOCK:
        pool, have = _POOLS.get(name, (None, 0))
        if pool is None or have < size:
            # a smaller pool is dropped, not shut down: a caller that got it a moment ago may
            # still submit to it; its threads end when it is garbage-collected
            pool = ThreadPoolExecutor(size, thread_name_prefix=f"strl-{name}")
            _POOLS[name] = (pool, size)
        return pool


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS reports one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)
