"""Learned vs classical vs fused relative pose on held-out generated pairs.

Pairs: seeds from 2,000,000 (training uses lower seeds), kinds street/indoor/boxes in turn,
the generator's matches with 1 px noise and 30 % outliers (or front-end matches with
``--matches frontend``). Every method runs on the same matches; ratios are against OpenCV
measured in the same run. Also reports how well the classical covariance predicts the actual
error (median Mahalanobis distance of the truth; 4.35 for a calibrated 5-D Gaussian).

    python benchmarks/studies/bench_fusion.py --pairs 60 [--checkpoint PATH] [--inflation 1 4 16]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/
from strl_bench_common import banner  # noqa: E402

from strl_pyg.estimation.classical import estimate_relative_pose  # noqa: E402
from strl_pyg.estimation.pose_fusion import classical_covariance, fuse_poses, pose_to_tangent
from strl_pyg.evaluation import EvalReport, PairResult, pair_result, synthetic_eval_pairs
from strl_pyg.evaluation.run import predict_pose
from strl_pyg.geometry import (
    Pose,  # noqa: E402
    tangent_basis,
)
from strl_pyg.model.strl_pose import StrLPose  # noqa: E402

DEFAULT_CKPT = Path(__file__).resolve().parents[2] / "strl_pyg" / "weights" / (
    "strl_pose_synthetic.pt")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", default=str(DEFAULT_CKPT))
    p.add_argument("--pairs", type=int, default=60)
    p.add_argument("--seed", type=int, default=2_000_000)
    p.add_argument("--matches", choices=("ground_truth", "frontend"), default="ground_truth")
    p.add_argument("--noise-px", type=float, default=1.0)
    p.add_argument("--outlier-fraction", type=float, default=0.3)
    p.add_argument("--inflation", type=float, nargs="+", default=[1.0, 16.0])
    args = p.parse_args()
    if not Path(args.checkpoint).is_file():
        sys.exit(f"Expected a checkpoint at '{args.checkpoint}' (got none)")
    model = StrLPose.load(args.checkpoint)
    pairs = synthetic_eval_pairs(
        args.pairs, args.seed, matches=args.matches,
        scene={"noise_px": args.noise_px, "outlier_fraction": args.outlier_fraction})
    results: list[PairResult] = []
    methods = ["strl", "opencv"] + [f"fused x{f:g}" for f in args.inflation]
    mahal, truth = [], {}
    for i, pair in enumerate(pairs):
        truth[pair.pair_id] = (pair.subset, pair.T_0to1, None)
        out = predict_pose(model, pair.matches, (384, 192), seed=i)
        out.quaternion, out.translation, out.log_var = (
            x.detach().double() for x in (out.quaternion, out.translation, out.log_var))
        results.append(pair_result(pair, "strl", out.pose[0], 0.0, True))
        c = estimate_relative_pose(pair.matches, "opencv", seed=0)
        results.append(pair_result(pair, "opencv", c.pose, c.time_ms, c.success))
        for f in args.inflation:
            fused = fuse_poses(out, None, c, pair.matches, inflation=f)
            results.append(pair_result(pair, f"fused x{f:g}", fused.pose, 0.0, True))
        if c.success and c.num_inliers >= 6:
            info, _, _ = classical_covariance(c.pose, pair.matches, c.inliers)
            gt = Pose.from_matrix(pair.T_0to1)
            x = pose_to_tangent(gt, c.pose.R, c.pose.t, tangent_basis(c.pose.t))
            mahal.append(float(x @ info @ x))
    rep = EvalReport(results, tuple(methods), truth)
    print(banner())
    print(f"checkpoint: {args.checkpoint} ({model!r})")
    print(f"pairs: {len(pairs)} from seed {args.seed}, matches {args.matches}, noise "
          f"{args.noise_px} px, outliers {args.outlier_fraction}; points per pair "
          f"median {int(np.median([q.matches.num_points for q in pairs]))}\n")
    summ = rep.summary()

    print("| subset | method | rot mean | rot med | trans mean | trans med | AUC@5 | AUC@10 "
          "| AUC@20 | rot med / opencv | trans med / opencv |")
    print("|" + "---|" * 11)
    for subset, per in summ.items():
        ref = per["opencv"]
        for m, s in per.items():
            print(f"| {subset} | {m} | {s['rot_mean']:.3f} | {s['rot_median']:.3f} | "
                  f"{s['trans_mean']:.2f} | {s['trans_median']:.2f} | {100 * s['auc5']:.1f} | "
                  f"{100 * s['auc10']:.1f} | {100 * s['auc20']:.1f} | "
                  f"{s['rot_median'] / ref['rot_median']:.2f} | "
                  f"{s['trans_median'] / ref['trans_median']:.2f} |")

    print(f"\nclassical covariance calibration: median Mahalanobis distance of the truth "
          f"{np.median(mahal):.1f} (calibrated: 4.35), 90th percentile "
          f"{np.percentile(mahal, 90):.1f} over {len(mahal)} pairs")


if __name__ == "__main__":
    main()
