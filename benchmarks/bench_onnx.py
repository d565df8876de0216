"""Latency of the exported ONNX graph (onnxruntime, CPU) beside PyTorch, in the same run.

    python benchmarks/bench_onnx.py --out benchmarks/results_onnx.md

On generated pairs through :func:`~strl_pyg.inference.network.prepare_graph` at the shipped
model's resampled size (768 nodes), one thread each:

- ``PyTorch forward_pose``: the package's batch-1 forward (a shallow copy of the graph,
  dtype/device casts, input gathering and validation, then the model) on the graph;
- ``PyTorch tensors``: :class:`~strl_pyg.inference.export.DensePoseModule` on the gathered
  tensors (what the export contains: no per-call host work);
- ``onnxruntime``: the exported graph on the same tensors.

Median of ``--repeat`` calls per pair after a warm-up, and the largest output difference of
onnxruntime from PyTorch. Time it on a quiet machine.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _median_ms(fn, repeat: int) -> float:
    from strl_bench_common import time_it

    return time_it(fn, repeat, warmup=1)["median_ms"]


def main(argv: list[str] | None = None) -> int:
    import onnxruntime as ort
    from strl_bench_common import banner

    from strl_pyg.inference.export import INPUT_NAMES, DensePoseModule, export_onnx, onnx_inputs
    from strl_pyg.inference.network import forward_pose, prepare_graph
    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.synthetic import generate_pair

    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    model = StrLPose.from_pretrained().eval()
    graphs = [prepare_graph(generate_pair(s).matches, model) for s in range(args.pairs)]
    with tempfile.TemporaryDirectory() as tmp:
        path = export_onnx(model, Path(tmp) / "m.onnx", example=graphs[0])
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.inter_op_num_threads = 1
        sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    dense = DensePoseModule(model)
    rows = []
    for g in tqdm(graphs, desc="pairs"):
        x = onnx_inputs(model, g)
        feed = {n: t.numpy() for n, t in zip(INPUT_NAMES, x, strict=True)}
        with torch.inference_mode():
            a = _median_ms(lambda g=g: forward_pose(model, g), args.repeat)
            b = _median_ms(lambda x=x: dense(*x), args.repeat)
            ref = dense(*x)
        c = _median_ms(lambda feed=feed: sess.run(None, feed), args.repeat)
        diff = max(float(np.abs(o - r.numpy()).max())
                   for o, r in zip(sess.run(None, feed), ref, strict=True))
        rows.append((a, b, c, diff))
    r = np.array(rows)
    med = np.median(r[:, :3], axis=0)
    lines = ["# ONNX export: onnxruntime beside PyTorch", "", "```", banner(),
             f"onnxruntime {ort.__version__}", "```", "",
             f"`python benchmarks/bench_onnx.py` ({args.pairs} generated pairs, {args.repeat} "
             "calls each, 1 thread; medians over the pairs of the per-pair medians).", "",
             "| path | ms per pair | ratio to PyTorch forward_pose |", "|---|---|---|",
             f"| PyTorch forward_pose (batch 1) | {med[0]:.1f} | 1.00 |",
             f"| PyTorch on the gathered tensors | {med[1]:.1f} | {med[1] / med[0]:.2f} |",
             f"| onnxruntime | {med[2]:.1f} | {med[2] / med[0]:.2f} |", "",
             f"Largest output difference onnxruntime - PyTorch: {r[:, 3].max():.1e}."]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
