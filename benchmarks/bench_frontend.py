"""Benchmark of the image front end: time per stage and match quality.

Generated pairs (exact ground truth): point inlier ratio (Sampson < 2 px under the true pose),
line precision (both endpoints within 4 px of their plane-homography transfer) and line recall
(fraction of ground-truth lines with a correct match on them). Real slices: KITTI 06 pairs and
the DeMoN MVS sequence, fraction of points / lines (both endpoints) with Sampson error < 2 px
under the ground-truth pose. Baselines measured in the same run: ORB instead of SIFT, and the
line matcher without its descriptor (geometry only, ``line_min_score=-1``).

    .venv/bin/python benchmarks/bench_frontend.py --pairs 6
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time
from pathlib import Path

import cv2
import numpy as np

from strl_pyg.frontend import FrontendConfig, match_images
from strl_pyg.geometry import epipolar_residuals
from strl_pyg.synthetic import SceneConfig, evaluate_matches, generate_pair

STAGES = ("points_detect", "points_match", "geometry", "lines_detect", "lines_match", "total")


def _machine() -> str:
    import torch

    return (f"{platform.platform()} | {platform.processor() or platform.machine()} | "
            f"{os.cpu_count()} cpus | python {platform.python_version()} | numpy "
            f"{np.__version__} | opencv {cv2.__version__} | torch {torch.__version__} | "
            f"cv2 threads {cv2.getNumThreads()}")


def _kitti(root: Path, a: int, b: int):
    calib = {}
    for line in (root / "sequences/06/calib.txt").read_text().splitlines():
        if ":" in line:
            key, vals = line.split(":", 1)
            calib[key.strip()] = np.array(vals.split(), dtype=np.float64)
    K = calib["P0"].reshape(3, 4)[:, :3]
    poses = np.loadtxt(root / "poses/06.txt").reshape(-1, 3, 4)
    T = [np.vstack([poses[i], [0, 0, 0, 1]]) for i in (a, b)]  # camera-to-world
    imgs = [cv2.imread(str(root / f"sequences/06/image_0/{i:06d}.png"), cv2.IMREAD_GRAYSCALE)
            for i in (a, b)]
    return imgs, K, np.linalg.inv(T[1]) @ T[0]


def _demon(seq: Path, a: int, b: int):
    K = np.loadtxt(seq / "cam.txt").reshape(3, 3)
    P = np.loadtxt(seq / "poses.txt").reshape(-1, 3, 4)
    T = [np.vstack([P[i], [0, 0, 0, 1]]) for i in (a, b)]  # world-to-camera
    imgs = [cv2.imread(str(seq / f"{i:04d}.jpg"), cv2.IMREAD_GRAYSCALE) for i in (a, b)]
    return imgs, K, T[1] @ np.linalg.inv(T[0])


def _fmt(x: float) -> str:
    return "nan" if x != x else f"{x:.3f}"


def bench_synthetic(args, cfgs: dict[str, FrontendConfig]) -> None:
    print("\n## Generated pairs")
    print(f"{args.pairs} seeds per scene kind; default SceneConfig (noise 0, no outliers)\n")
    for size in ((192, 640), (480, 640)):
        print(f"### image size {size[0]}x{size[1]}\n")
        print("| kind | front end | points | lines | point inlier | line precision | "
              "line recall | gen ms | " + " | ".join(f"{s} ms" for s in STAGES) + " |")
        print("|---" * (8 + len(STAGES)) + "|")
        for kind in args.kinds:
            pairs, gen = [], []
            for seed in range(args.pairs):
                t = time.perf_counter()
                pairs.append(generate_pair(seed, SceneConfig(kind=kind, image_size=size)))
                gen.append(1e3 * (time.perf_counter() - t))
            for name, cfg in cfgs.items():
                rows, times = [], []
                for p in pairs:
                    m = match_images(p.image0, p.image1, p.K, p.K, cfg)
                    rows.append(evaluate_matches(p, m))
                    times.append([m.info["timings_ms"][s] for s in STAGES])
                mean = {k: float(np.nanmean([r.get(k, np.nan) for r in rows])) for k in rows[0]}
                med_t = np.median(np.asarray(times), axis=0)
                print(f"| {kind} | {name} | {mean['num_points']:.0f} | {mean['num_lines']:.0f} | "
                      f"{_fmt(mean['point_inlier_ratio'])} | {_fmt(mean['line_precision'])} | "
                      f"{_fmt(mean['line_recall'])} | {np.median(gen):.0f} | "
                      + " | ".join(f"{v:.0f}" for v in med_t) + " |")
        print()


def bench_real(args, cfgs: dict[str, FrontendConfig]) -> None:
    data = Path(args.data)
    cases = []
    kitti = data / "kitti_odometry"
    if (kitti / "sequences/06").is_dir():
        for a, b in ((0, 1), (10, 11), (20, 21), (30, 31), (40, 41), (0, 2), (20, 22)):
            cases.append((f"KITTI 06 {a}-{b}", *_kitti(kitti, a, b)))
    demon = data / "demon_deepsfm/test/mvs_test_00000"
    if demon.is_dir():
        cases.append(("DeMoN mvs_test_00000 0-1", *_demon(demon, 0, 1)))
    if not cases:
        print(f"\n(no real data under {data})")
        return
    print("\n## Real slices (fraction with Sampson error < 2 px under the ground-truth pose)\n")
    print("| pair | size | front end | points | point < 2px | median px | lines | "
          "lines < 2px (both endpoints) | median px | total ms |")
    print("|---" * 10 + "|")
    for name, (im0, im1), K, T in cases:
        for fe, cfg in cfgs.items():
            m = match_images(im0, im1, K, K, cfg)
            pe, le = epipolar_residuals(m, T)
            print(f"| {name} | {im0.shape[0]}x{im0.shape[1]} | {fe} | {m.num_points} | "
                  f"{_fmt(float(np.mean(pe < 2)))} | {np.median(pe):.2f} | {m.num_lines} | "
                  f"{_fmt(float(np.mean(le < 2)) if len(le) else float('nan'))} | "
                  f"{np.median(le) if len(le) else float('nan'):.2f} | "
                  f"{m.info['timings_ms']['total']:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pairs", type=int, default=6, help="seeds per scene kind")
    parser.add_argument("--kinds", nargs="+", default=["street", "indoor", "boxes"])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[1].parent
                                              / "shared" / "data"))
    parser.add_argument("--no-baselines", action="store_true")
    args = parser.parse_args()
    print(f"# Front-end benchmark\n\nmachine: {_machine()}")
    default = FrontendConfig()
    cfgs = {"sift+lsd (default)": default}
    if not args.no_baselines:
        cfgs["orb+lsd"] = FrontendConfig(detector="orb")
        cfgs["sift+lsd, no line descriptor"] = dataclasses.replace(default, line_min_score=-1.0)
    bench_synthetic(args, cfgs)
    bench_real(args, cfgs)


if __name__ == "__main__":
    main()
