"""Cost and front-end quality of the broad generated distribution.

Measures, single-threaded (as in the cache's worker processes):

* render time (``generate_pair``) and front-end time (``match_images``) per pair, per image
  size (one pair per scene kind and size, mixed motions);
* front-end point / line match counts and the point inlier ratio (Sampson error < 2 px under the
  ground-truth pose) per scene kind and per motion, on ``--seeds`` seeds per kind drawn from
  ``mixed_small`` at 240x320;
* that the cached front-end path runs in worker processes.

    .venv/bin/python benchmarks/studies/bench_synthetic_distribution.py \
        --out benchmarks/studies/synthetic_distribution.md
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import defaultdict

import cv2
import numpy as np

from strl_pyg.datasets import SyntheticPairs
from strl_pyg.frontend import match_images
from strl_pyg.geometry import epipolar_residuals
from strl_pyg.synthetic import SCENE_KINDS, generate_pair, scene_distribution
from strl_pyg.synthetic.distributions import DEFAULT_SIZES


def _run(seed, cfg):
    t = time.perf_counter()
    pair = generate_pair(seed, cfg)
    t_render = time.perf_counter() - t
    t = time.perf_counter()
    try:
        m = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K)
    except ValueError:  # NoMatchesError: featureless pair
        return pair, None, t_render, time.perf_counter() - t
    return pair, m, t_render, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10, help="seeds per kind")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    lines = ["# Generated training distribution: cost and front-end quality", ""]
    lines += ["Single-threaded (`cv2.setNumThreads(1)`, as in the cache workers), on the shared "
              "2-core dev machine (other jobs were running: times are upper bounds).", ""]

    # ---- cost per image size
    lines += ["## Time per pair by image size", "",
              "One pair per scene kind (street, indoor, boxes, object) and size, motions and "
              "intrinsics from the `mixed` preset; mean over the four kinds.", "",
              "| size (H x W) | render s/pair | front end s/pair | total s/pair |",
              "|---|---|---|---|"]
    for size in DEFAULT_SIZES:
        rt, ft = [], []
        for i, kind in enumerate(SCENE_KINDS):
            cfg = scene_distribution("mixed", kinds=(kind,), sizes=(size,)).config(500 + i)
            _, _, a, b = _run(500 + i, cfg)
            rt.append(a)
            ft.append(b)
        lines.append(f"| {size[0]} x {size[1]} | {np.mean(rt):.2f} | {np.mean(ft):.2f} | "
                     f"{np.mean(rt) + np.mean(ft):.2f} |")
        print(lines[-1], flush=True)

    # ---- front-end quality per kind and motion
    by_kind, by_motion = defaultdict(list), defaultdict(list)
    for kind in SCENE_KINDS:
        d = scene_distribution("mixed_small", kinds=(kind,), sizes=((240, 320),))
        for s in range(args.seeds):
            seed = 1000 + s
            cfg = d.config(seed)
            pair, m, _, _ = _run(seed, cfg)
            if m is None:
                row = (0, 0, np.nan, pair.matches.num_points)
            else:
                pe, _ = epipolar_residuals(m, pair.T_0to1)
                row = (m.num_points, m.num_lines, float((pe < 2.0).mean()) if len(pe) else np.nan,
                       pair.matches.num_points)
            by_kind[kind].append(row)
            by_motion[cfg.motion].append(row)
        print(kind, np.nanmean(np.array(by_kind[kind], float), 0), flush=True)
    lines += ["", f"## Front-end matches at 240 x 320 ({args.seeds} seeds per kind, `mixed_small`)",
              "", "Default `FrontendConfig` (SIFT + LSD). Inlier: Sampson error < 2 px under the "
              "ground-truth pose. Medians over pairs, the inlier ratio pooled as the mean of the "
              "per-pair ratios.", ""]
    for title, table in (("kind", by_kind), ("motion", by_motion)):
        lines += [f"| {title} | pairs | points (median) | lines (median) | point inlier ratio "
                  "(mean) | min ratio | GT points (median) |", "|---|---|---|---|---|---|---|"]
        for key, rows in table.items():
            a = np.array(rows, float)
            lines.append(f"| {key} | {len(a)} | {np.median(a[:, 0]):.0f} | {np.median(a[:, 1]):.0f}"
                         f" | {np.nanmean(a[:, 2]):.2f} | {np.nanmin(a[:, 2]):.2f} | "
                         f"{np.median(a[:, 3]):.0f} |")
        lines.append("")

    # ---- the cached front-end path in worker processes
    with tempfile.TemporaryDirectory() as tmp:
        ds = SyntheticPairs(4, seed=3000, scene_config=scene_distribution("mixed_small"),
                            matches="frontend", cache_dir=tmp)
        t = time.perf_counter()
        report = ds.build_cache(num_workers=2, progress=False)
        lines += ["## Cache build in worker processes", "",
                  f"`SyntheticPairs(4, scene_config=scene_distribution('mixed_small'), "
                  f"matches='frontend').build_cache(num_workers=2)`: {report.computed} computed, "
                  f"{len(ds.failed_pairs())} failed, {time.perf_counter() - t:.1f} s (including "
                  f"spawning the workers); sizes in the cache: "
                  f"{sorted({tuple(ds[i]['image_size0'][0].tolist()) for i in range(len(ds))})}.",
                  ""]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
