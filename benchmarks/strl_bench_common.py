"""Helpers shared by the benchmarks: machine/version banner, a robust timer and the command
line of a resumable ``run`` / ``report`` benchmark."""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from collections.abc import Callable


def banner() -> str:
    import cv2
    import numpy as np
    import torch
    import torch_geometric

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return (
        f"machine: {cpu}, {os.cpu_count()} cores, torch threads {torch.get_num_threads()}\n"
        f"versions: python {platform.python_version()}, torch {torch.__version__}, "
        f"torch_geometric {torch_geometric.__version__}, numpy {np.__version__}, "
        f"opencv {cv2.__version__}"
    )


def time_it(fn: Callable[[], object], repeat: int = 20, warmup: int = 3) -> dict[str, float]:
    """Median / min / mean wall time of ``fn`` in milliseconds."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return {
        "median_ms": statistics.median(times),
        "min_ms": min(times),
        "mean_ms": statistics.fmean(times),
    }


def run_report_parser(doc: str, out: str) -> argparse.ArgumentParser:
    """The command line of a benchmark that measures (``run``, resumable, rows in ``--out``)
    and writes its report (``report``): its docstring's first paragraph as the description."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("what", choices=("run", "report"))
    ap.add_argument("--out", default=out)
    return ap
