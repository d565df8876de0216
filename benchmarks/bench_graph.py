"""Pair-graph construction speed and memory.

    python benchmarks/bench_graph.py [--repeat 200]

Builds graphs of 384 points and 192 lines from two 192x640 images (patch 1 and 7) and reports
the median time per graph, and the bytes of edge tensors in a batch of 16 graphs with implicit
(default) and explicit complete edges.
"""

from __future__ import annotations

import argparse

import numpy as np
from strl_bench_common import banner, time_it
from torch_geometric.loader import DataLoader

from strl_pyg.data import PairMatches, build_pair_graph, materialize_complete_edges


def make_matches(num_points: int, num_lines: int, h: int, w: int, seed: int = 0) -> PairMatches:
    rng = np.random.default_rng(seed)

    def pts(n):
        return rng.uniform([0, 0], [w - 1, h - 1], (n, 2))

    img = lambda: rng.integers(0, 256, (h, w), dtype=np.uint8)  # noqa: E731
    return PairMatches(
        pts(num_points),
        pts(num_points),
        pts(2 * num_lines).reshape(-1, 2, 2),
        pts(2 * num_lines).reshape(-1, 2, 2),
        image0=img(),
        image1=img(),
    )


def edge_bytes(data) -> int:
    return sum(
        v.numel() * v.element_size()
        for et in data.edge_types
        for v in data[et].values()
        if hasattr(v, "numel")
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--repeat", type=int, default=200)
    ap.add_argument("--points", type=int, default=384)
    ap.add_argument("--lines", type=int, default=192)
    ap.add_argument("--height", type=int, default=192)
    ap.add_argument("--width", type=int, default=640)
    args = ap.parse_args()
    print(banner())
    print(f"input: {args.points} points, {args.lines} lines, {args.height}x{args.width} images")
    m = make_matches(args.points, args.lines, args.height, args.width)
    print("\n| patch | median ms/graph | min ms | graphs/s |")
    print("|---|---|---|---|")
    for p in (1, 7):
        t = time_it(lambda p=p: build_pair_graph(m, patch_size=p), repeat=args.repeat)
        print(
            f"| {p}x{p} | {t['median_ms']:.3f} | {t['min_ms']:.3f} | {1e3 / t['median_ms']:.0f} |"
        )
    graphs = [
        build_pair_graph(make_matches(args.points, args.lines, args.height, args.width, s))
        for s in range(16)
    ]
    batch = next(iter(DataLoader(graphs, batch_size=16)))
    implicit = edge_bytes(batch)
    explicit = edge_bytes(materialize_complete_edges(batch))
    print("\n| batch of 16 | edge-tensor bytes |")
    print("|---|---|")
    print(f"| implicit complete edges (default) | {implicit:,} ({implicit / 2**20:.3f} MiB) |")
    print(f"| explicit complete edges | {explicit:,} ({explicit / 2**20:.1f} MiB) |")
    print(f"| ratio | {explicit / implicit:.0f}x |")


if __name__ == "__main__":
    main()
