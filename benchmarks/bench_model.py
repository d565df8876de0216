"""Speed, memory and achieved FLOP rate of StrLPose: dense path vs explicit edges.

Every measurement runs in a fresh subprocess. Peak memory is the process's resident high-water
mark (``VmHWM``, reset through ``/proc/self/clear_refs`` after building the model and the
inputs) minus the resident size at that point: the memory the passes themselves add.
The FLOP count is analytic (multiply-adds of every linear layer and of the attention products,
times 2; norms, activations, softmax and gathers are not counted) and is compared with a
square fp32 ``torch.mm`` measured in the same run.

``torch.compile`` rows: the same dense forward through ``torch.compile(model)`` (inductor),
against eager rows measured in the same run; the first call (tracing and compilation) is timed
apart, and each compiled row reports the graph breaks ``torch._dynamo.explain`` counts.

Usage::

    python benchmarks/bench_model.py                  # default config, 384 points + 192 lines
    python benchmarks/bench_model.py --batches 1 16 --explicit-batches 1 4 --repeats 5
    python benchmarks/bench_model.py --rows compile --compile-batches 1 16   # compiled vs eager
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

import numpy as np
import torch
import torch_geometric
from torch_geometric.loader import DataLoader

from strl_pyg.data import PairMatches, build_pair_graph
from strl_pyg.model import StrLPoseConfig
from strl_pyg.model.strl_pose import StrLPose


def make_batch(batch: int, points: int, lines: int, complete: str, seed: int = 0):
    rng = np.random.default_rng(seed)
    H, W = 120, 160  # only the sampled pixels enter the model
    graphs = []
    for _ in range(batch):
        def xy(n):
            return rng.uniform([0, 0], [W - 1, H - 1], (n, 2))
        img = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
        m = PairMatches(xy(points), xy(points), xy(2 * lines).reshape(-1, 2, 2),
                        xy(2 * lines).reshape(-1, 2, 2), image0=img, image1=img)
        graphs.append(build_pair_graph(m, complete_edges=complete))
    return next(iter(DataLoader(graphs, batch_size=batch)))


def model_flops(cfg: StrLPoseConfig, batch: int, points: int, lines: int) -> float:
    """Forward FLOPs (2 x multiply-adds) of the model on ``batch`` pairs, by layer shapes."""
    C, r, L, CL = cfg.hidden, cfg.mlp_ratio, cfg.layers, cfg.line_channels
    n = points + (2 * lines if cfg.use_lines else 0)  # nodes per pair
    macs = n * (4 * C // 2 + C // 2 * C + C * C)  # SCE
    if cfg.visual == "pixel":
        macs += n * (2 * cfg.patch_features * C + C * C)  # PE
    attn = n * 4 * C * C + 2 * n * n * C + n * (2 * C * r * C + r * C * C)  # proj, QK/AV, MLP
    n_attn = 1 + (2 if cfg.visual_graph else 0)
    macs += L * n_attn * attn
    if cfg.line_mp:
        e = 2 * lines
        macs += 2 * lines * (8 * CL + CL * CL)  # LSE
        macs += L * e * ((2 * C + CL) * r * C + r * C * C)
    macs *= batch
    d_in = (2 if cfg.visual else 1) * C
    macs += batch * (2 * d_in * C + C * C + 14 * C)  # fusion heads, once per pair
    return 2.0 * macs


def matmul_gflops(size: int = 2048, repeats: int = 8) -> float:
    """Best-of-``repeats`` fp32 ``torch.mm`` rate (the machine is shared: best-of is the
    least disturbed estimate of what it can do)."""
    a, b = torch.randn(size, size), torch.randn(size, size)
    a @ b
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t)
    return 2 * size**3 / best / 1e9


def child(args) -> dict:
    torch.manual_seed(0)
    cfg = StrLPoseConfig()
    model = StrLPose(cfg)
    data = make_batch(args.batch, args.points, args.lines, args.complete)
    breaks = None
    fn = model
    if args.compile:
        model.eval()
        with torch.inference_mode():
            breaks = torch._dynamo.explain(model)(data).graph_break_count
        torch._dynamo.reset()
        fn = torch.compile(model)
    base = _reset_peak_rss()
    times = []

    def step():
        if args.mode == "forward":
            model.eval()
            with torch.inference_mode():
                if args.bf16:
                    with torch.autocast("cpu", dtype=torch.bfloat16):
                        fn(data)
                else:
                    fn(data)
        else:
            model.train()
            model.zero_grad(set_to_none=True)
            out = fn(data)
            (out.quaternion.sum() + out.translation.sum() + out.log_var.sum()).backward()

    t0 = time.perf_counter()
    step()  # warm-up (and compilation)
    first_s = time.perf_counter() - t0
    step()
    for _ in range(args.repeats):
        t = time.perf_counter()
        step()
        times.append(time.perf_counter() - t)
    peak_kib = _status_kib("VmHWM") - base
    best, med = min(times), statistics.median(times)
    flops = model_flops(cfg, args.batch, args.points, args.lines)
    return {"best_ms": 1e3 * best / args.batch, "median_ms": 1e3 * med / args.batch,
            "peak_mib": peak_kib / 1024, "gflops": flops / best / 1e9,
            "matmul_gflops": matmul_gflops(), "first_s": first_s, "graph_breaks": breaks}


def run_child(batch, complete, mode, bf16, args, compile=False) -> dict:
    cmd = [sys.executable, __file__, "--child", "--batch", str(batch), "--complete", complete,
           "--mode", mode, "--points", str(args.points), "--lines", str(args.lines),
           "--repeats", str(args.repeats), "--threads", str(args.threads)]
    if bf16:
        cmd.append("--bf16")
    if compile:
        cmd.append("--compile")
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=int, default=384)
    p.add_argument("--lines", type=int, default=192)
    p.add_argument("--batches", type=int, nargs="+", default=[1, 16])
    p.add_argument("--explicit-batches", type=int, nargs="*", default=[1, 4],
                   help="explicit edges hold B*N^2 edges per relation: ~1.2 GB per gathered "
                        "[E, 128] tensor at B=4, ~4.8 GB at B=16")
    p.add_argument("--explicit-train-batches", type=int, nargs="*", default=[1],
                   help="fwd+bwd on explicit edges keeps ~3 gathered [E, 128] tensors per "
                        "attention layer for backward: ~11 GB for the default model at B=1")
    p.add_argument("--compile-batches", type=int, nargs="*", default=[1, 16],
                   help="batches of the torch.compile rows (each next to an eager row)")
    p.add_argument("--rows", choices=("all", "compile"), default="all",
                   help="'compile': only the eager and compiled forward rows")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--threads", type=int, default=torch.get_num_threads())
    # internal: one measurement
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--batch", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("--complete", default="implicit", help=argparse.SUPPRESS)
    p.add_argument("--mode", default="forward", help=argparse.SUPPRESS)
    p.add_argument("--bf16", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--compile", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    if args.child:
        print(json.dumps(child(args)))
        return

    cfg = StrLPoseConfig()
    n = args.points + 2 * args.lines
    print(f"machine: {platform.machine()} {_cpu_name()}, {os.cpu_count()} cores, "
          f"{args.threads} torch threads")
    print(f"versions: python {platform.python_version()}, torch {torch.__version__}, "
          f"torch_geometric {torch_geometric.__version__}; torch.compile backend inductor, "
          f"C++ compiler {_cxx()}")
    print(f"sizes: {args.points} points + {args.lines} lines = {n} nodes per pair; config "
          f"hidden={cfg.hidden} layers={cfg.layers} heads={cfg.heads} (full model: lines, "
          f"line MP, pixel visual graph, weighted fusion); repeats={args.repeats}")
    print(f"fp32 torch.mm 2048^3 at start: {matmul_gflops():.1f} GFLOP/s (best of 8); each row "
          "also measures it in its own process, right after its passes\n")
    print("| path | batch | pass | ms / pair best (median) | peak MiB | model GFLOP/s | "
          "matmul GFLOP/s | % of matmul |")
    print("|---|---|---|---|---|---|---|---|")
    dense = {}
    rows = []
    if args.rows == "all":
        rows += [("dense", b, "forward", False) for b in args.batches]
        rows += [("dense", b, "fwd+bwd", False) for b in args.batches]
        rows += [("dense bf16 autocast", max(args.batches), "forward", True)]
        rows += [("explicit", b, "forward", False) for b in args.explicit_batches]
        rows += [("explicit", b, "fwd+bwd", False) for b in args.explicit_train_batches]
    for b in args.compile_batches:
        if args.rows == "compile" or b not in args.batches:
            rows.append(("dense", b, "forward", False))
        rows.append(("dense compiled", b, "forward", False))
    results = {}
    for name, b, mode, bf16 in rows:
        complete = "explicit" if name == "explicit" else "implicit"
        r = run_child(b, complete, "forward" if mode == "forward" else "train", bf16, args,
                      compile=name == "dense compiled")
        results[(name, b, mode)] = r
        if name == "dense":
            dense[(b, mode)] = r
        mm = r["matmul_gflops"]
        rate = f"{r['gflops']:.1f}" if mode == "forward" else "-"
        pct = f"{100 * r['gflops'] / mm:.0f}%" if mode == "forward" else "-"
        print(f"| {name} | {b} | {mode} | {r['best_ms']:.1f} ({r['median_ms']:.1f}) | "
              f"{r['peak_mib']:.0f} | {rate} | {mm:.0f} | {pct} |", flush=True)
    print()
    for (name, b, mode), r in results.items():
        if name == "dense compiled":
            e = results[("dense", b, mode)]
            print(f"compiled / eager, batch {b}, {mode}: {r['best_ms'] / e['best_ms']:.2f}x best "
                  f"({r['median_ms'] / e['median_ms']:.2f}x median) time per pair; first "
                  f"compiled call {r['first_s']:.1f} s (eager {e['first_s']:.1f} s); "
                  f"{r['graph_breaks']} graph break(s)")
    for (name, b, mode), r in results.items():
        if name != "explicit":
            continue
        for db in args.batches:
            if (db, mode) in dense:
                ratio = r["best_ms"] / dense[(db, mode)]["best_ms"]
                print(f"explicit(batch {b}) / dense(batch {db}), {mode}, best time per pair: "
                      f"{ratio:.1f}x")


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def _reset_peak_rss() -> int:
    """Resets the resident high-water mark (Linux) and returns the current resident KiB."""
    gc.collect()
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:  # not Linux: the peak then includes building the inputs
        pass
    return _status_kib("VmRSS")


def _cxx() -> str:
    import shutil

    for cc in ("g++", "c++", "clang++"):
        path = shutil.which(cc)
        if path:
            return path
    return "none (inductor cannot compile C++ kernels here)"


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


if __name__ == "__main__":
    main()
