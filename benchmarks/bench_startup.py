"""Start-up time of the command line and of ``import strl_pyg``, in fresh subprocesses.

    python benchmarks/bench_startup.py [--repeat 7]

Each figure is the median wall time of ``--repeat`` fresh interpreters (the first, cold run
is dropped as a warm-up): ``strl-pose --help``, an argument error (``strl-pose bench --repeat
x``), ``import strl_pyg``, and for comparison ``import torch`` and the first touch of
``strl_pyg.StrLPose`` (which loads torch and PyG). Also checks that ``--help`` leaves torch
unimported.

Measured (AMD EPYC, 2 shared CPU cores, load average ~5.7 from other jobs, Python 3.11.7,
torch 2.13.0+cpu, 7 runs): ``strl-pose --help`` 0.17 s median (console script 0.16 s), an
argument error 0.18 s, ``import strl_pyg`` 0.04 s; ``import torch`` alone 1.6 s and ``from
strl_pyg import StrLPose`` 3.8 s for reference. Before the torch-free parser and the lazy
package imports (commit 93ac487, same machine, 6 runs): ``--help`` 3.4-4.1 s, ``import
strl_pyg`` 3.7-4.1 s (torch, PyG and kornia at import time).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

CASES = {
    "strl-pose --help": ["-m", "strl_pyg.cli.commands", "--help"],
    "strl-pose bench --repeat x (argument error)": ["-m", "strl_pyg.cli.commands", "bench",
                                                    "--repeat",
                                                    "x"],
    "import strl_pyg": ["-c", "import strl_pyg"],
    "import torch (reference)": ["-c", "import torch"],
    "from strl_pyg import StrLPose (loads torch, PyG)": ["-c", "from strl_pyg import StrLPose"],
}


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")),
                       cpu)
    except OSError:
        pass
    out = subprocess.run([sys.executable, "-c", "import torch, numpy; "
                          "print(torch.__version__, numpy.__version__)"],
                         capture_output=True, text=True).stdout.split()
    versions = f"torch {out[0]}, numpy {out[1]}" if len(out) == 2 else "torch not importable"
    return (f"machine: {cpu}, {os.cpu_count()} cores, load average "
            f"{os.getloadavg()[0]:.1f}\nversions: python {platform.python_version()}, {versions}")


def wall_times(args: list[str], repeat: int) -> list[float]:
    times = []
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, *args], capture_output=True, check=False)
        times.append(time.perf_counter() - t0)
    return times[1:]  # the first run warms the file cache


def torch_after_help() -> bool:
    code = ("import sys, contextlib, io\nfrom strl_pyg.cli.commands import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        main(['--help'])\n    except SystemExit:\n        pass\n"
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    return out.stdout.strip() == "True"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    print(machine())
    entry = shutil.which("strl-pose") or str(Path(sys.executable).with_name("strl-pose"))
    print(f"console script: {entry}; torch imported by --help: {torch_after_help()}\n")
    print(f"| command ({args.repeat} fresh processes) | median s | min s | max s |")
    print("|---|---|---|---|")
    for name, case in CASES.items():
        t = wall_times(case, args.repeat)
        print(f"| {name} | {statistics.median(t):.2f} | {min(t):.2f} | {max(t):.2f} |")
    if Path(entry).exists():
        t = wall_times_script(entry, args.repeat)
        print(f"| {entry} --help (console script) | {statistics.median(t):.2f} | "
              f"{min(t):.2f} | {max(t):.2f} |")
    return 0


def wall_times_script(entry: str, repeat: int) -> list[float]:
    times = []
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        subprocess.run([entry, "--help"], capture_output=True, check=False)
        times.append(time.perf_counter() - t0)
    return times[1:]


if __name__ == "__main__":
    sys.exit(main())
