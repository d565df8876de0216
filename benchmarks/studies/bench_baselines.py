"""Accuracy and time of the classical baselines on generated matches with outliers.

Each pair: random 3D points in front of two pinhole cameras (640x480, f ~ 500 px) with a
random relative pose (rotation ~5-10 deg, translation mostly sideways), projected, Gaussian
pixel noise added, then a fraction of the matches in image 1 replaced by uniform random
pixels (outliers). Both baselines see the same match lists.

    python benchmarks/studies/bench_baselines.py --pairs 50 --points 500 --noise 0.5
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/
from strl_bench_common import banner  # noqa: E402

from strl_pyg.data.matches import PairMatches  # noqa: E402
from strl_pyg.estimation.classical import estimate_relative_pose  # noqa: E402
from strl_pyg.geometry import Pose, quaternion_to_rotation  # noqa: E402
from strl_pyg.metrics.two_view import pose_auc, relative_pose_error  # noqa: E402

H, W = 480, 640


def make_pair(rng, n, noise_px, outlier_ratio):
    K0 = np.array([[520.0, 0, 320], [0, 520, 240], [0, 0, 1]])
    K1 = np.array([[500.0, 0, 315], [0, 502, 238], [0, 0, 1]])
    R = quaternion_to_rotation(np.array([1.0, *rng.normal(0, 0.06, 3)])).numpy()
    t = np.array([1.0, 0.0, 0.3]) + rng.normal(0, 0.3, 3)
    t *= 0.6 / np.linalg.norm(t)
    m = 0
    p0s, p1s = [], []
    while m < n:
        X0 = np.column_stack([rng.uniform(-8, 8, 4 * n), rng.uniform(-6, 6, 4 * n),
                              rng.uniform(4, 25, 4 * n)])
        X1 = X0 @ R.T + t
        p0 = X0 @ K0.T
        p1 = X1 @ K1.T
        ok = (p0[:, 2] > 0) & (p1[:, 2] > 0)
        p0, p1 = p0[:, :2] / p0[:, 2:], p1[:, :2] / p1[:, 2:]
        lim = np.array([W - 1, H - 1])
        ok &= ((p0 >= 0) & (p0 <= lim) & (p1 >= 0) & (p1 <= lim)).all(1)
        p0s.append(p0[ok])
        p1s.append(p1[ok])
        m += int(ok.sum())
    p0, p1 = np.concatenate(p0s)[:n], np.concatenate(p1s)[:n]
    p0 = np.clip(p0 + rng.normal(0, noise_px, p0.shape), 0, [W - 1, H - 1])
    p1 = np.clip(p1 + rng.normal(0, noise_px, p1.shape), 0, [W - 1, H - 1])
    k = int(round(outlier_ratio * n))
    p1[:k] = rng.uniform([0, 0], [W - 1, H - 1], (k, 2))
    return PairMatches(p0, p1, image_size0=(H, W), image_size1=(H, W), K0=K0, K1=K1), Pose(R, t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=50, help="pairs per outlier ratio")
    ap.add_argument("--points", type=int, default=500, help="matches per pair")
    ap.add_argument("--noise", type=float, default=0.5, help="pixel noise sigma")
    ap.add_argument("--outliers", type=float, nargs="+", default=[0.0, 0.3, 0.6])
    ap.add_argument("--threshold", type=float, default=1.0, help="inlier threshold, px")
    ap.add_argument("--methods", nargs="+", default=["opencv", "poselib"])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    import poselib

    print(banner())
    print(f"poselib {getattr(poselib, '__version__', '2.x')}")
    print(f"input: {args.pairs} pairs per outlier ratio, {args.points} matches per pair, "
          f"image {W}x{H}, noise sigma {args.noise} px, threshold {args.threshold} px, "
          f"seed {args.seed}")
    print()
    header = ("| outliers | method | median rot err (deg) | median t err (deg) | "
              "AUC@5/10/20 (%) | failures | median time (ms) | time vs opencv |")
    print(header)
    print("|" + "---|" * 8)
    for ratio in args.outliers:
        rng = np.random.default_rng(args.seed)
        pairs = [make_pair(rng, args.points, args.noise, ratio) for _ in range(args.pairs)]
        times = {}
        for method in args.methods:
            er, et, tm, fail = [], [], [], 0
            for m, gt in pairs:
                res = estimate_relative_pose(m, method=method, threshold_px=args.threshold)
                r, t = relative_pose_error(res.pose, gt, fold_sign=False)
                fail += not res.success
                er.append(float(r))
                et.append(float(t) if res.success else math.inf)
                tm.append(res.time_ms)
            times[method] = statistics.median(tm)
            auc = pose_auc(np.maximum(er, et))
            ratio_t = times[method] / times["opencv"] if "opencv" in times else float("nan")
            print(f"| {ratio:.0%} | {method} | {statistics.median(er):.3f} | "
                  f"{statistics.median(et):.3f} | "
                  + "/".join(f"{100 * a:.1f}" for a in auc)
                  + f" | {fail} | {times[method]:.2f} | {ratio_t:.2f}x |")


if __name__ == "__main__":
    main()
