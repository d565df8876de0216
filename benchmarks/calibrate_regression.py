"""Calibrates the network's own uncertainty on real photographs and writes a shippable
checkpoint: the regression's covariance scale fitted on the real_scenes validation scenes'
``(i, i+2)`` pairs so that its 2-sigma region holds 95.45 % of them (the 5-dof Mahalanobis
distance of the error under the covariance, chi-square quantile), with the coverage that scale
gives on each scene when it is fitted on the other three (leave one scene out: the honest
figure), and the classical methods' scales of the shipped weights (they do not read the
network).

    python benchmarks/calibrate_regression.py --model runs/real/best_model.pt \\
        --out strl_pyg/weights/strl_pose_real.pt --training-data "..."

Your own posed photographs (any format of ``strl_pyg.datasets.read_posed_folder``: real_scenes,
COLMAP, NeRF, LLFF), scenes the model was not trained on::

    python benchmarks/calibrate_regression.py --model runs/mine/best_model.pt \\
        --data-root my_scenes --scenes hall,garden --out runs/mine/calibrated.pt
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_pose as bp  # noqa: E402
import bench_two_view as btv  # noqa: E402
from strl_bench_common import banner  # noqa: E402

QUANTILE = 0.9545  # the 2-sigma region's share under a calibrated covariance


def posed_pairs(root: Path, scenes: list[str], cache: Path, gap: int = 2, stride: int = 4):
    """``(scene/i-j, matches, T_0to1)`` of the pairs ``(i, i + gap)`` for every ``stride``-th
    ``i`` of each scene folder (the front end's matches, cached)."""
    from strl_pyg.datasets.camera_files import read_posed_folder
    from strl_pyg.frontend import NoMatchesError, match_images

    out = []
    for scene in scenes:
        images = read_posed_folder(root / scene)
        for i in range(0, len(images) - gap, stride):
            a, b = images[i], images[i + gap]
            T = np.linalg.inv(b.T_c2w) @ a.T_c2w
            try:
                m = bp._cached(cache, f"posed_{scene}_{i}_{i + gap}", lambda a=a, b=b:
                               match_images(bp._read(a.path), bp._read(b.path), K0=a.K,
                                            K1=b.K))
            except NoMatchesError:
                continue
            out.append((f"{scene}/{i}-{i + gap}", m, T))
    return out


def mahalanobis(model, pairs, own: bool = False) -> tuple[np.ndarray, list[str]]:
    """The regression's squared 5-dof Mahalanobis error of every pair (uncalibrated: scale 1)
    and each pair's scene; ``own``: the network's own covariance (its log-variances alone,
    without the swap and data checks the estimator adds)."""
    from strl_pyg.inference import PoseEstimator

    model.metadata = {**model.metadata, "calibration": {
        **(model.metadata.get("calibration") or {}), "regression": 1.0}}
    est = PoseEstimator(model, methods=("regression", "poselib"), swap_check=not own,
                        data_check=not own)
    d2, scenes = [], []
    for pid, m, T in pairs:
        reg = est.estimate(m).methods["regression"]
        if reg.status != "ok" or reg.covariance is None:
            d2.append(np.inf)
        else:
            e = bp.tangent_error(reg.T_0to1, T)
            d2.append(float(e @ np.linalg.pinv(reg.covariance) @ e))
        scenes.append(pid.split("/")[0])
    return np.asarray(d2), scenes


def fit(d2: np.ndarray) -> float:
    return float(max(np.quantile(d2, QUANTILE) / bp.CHI2_5[2], 1e-6))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", required=True, help="model.pt to calibrate")
    ap.add_argument("--out", default=None, help="write the calibrated checkpoint here")
    ap.add_argument("--training-data", default=None, help="metadata: what it was trained on")
    ap.add_argument("--cache", default="outputs/bench_cache")
    ap.add_argument("--data-root", default=None,
                    help="a folder of posed scene folders (default: the real_scenes "
                         "validation scenes' (i, i+2) pairs)")
    ap.add_argument("--scenes", default=None,
                    help="with --data-root: the scene folders to calibrate on, comma-separated "
                         "(scenes the model was not trained on)")
    ap.add_argument("--own", action="store_true",
                    help="the network's own covariance (no swap / data check); no --out")
    ap.add_argument("--report", default=None,
                    help="also write the printed figures to this markdown file (appended, "
                         "with the command)")
    args = ap.parse_args(argv)
    if args.own and args.out:
        ap.error("--own measures the network's own covariance; the estimator's is calibrated")
    import torch

    from strl_pyg.metrics.stats import coverage_interval
    from strl_pyg.model.strl_pose import StrLPose

    torch.set_num_threads(1)
    model = StrLPose.load(args.model)
    if args.data_root:
        if not args.scenes:
            ap.error("--data-root needs --scenes (the held-out scenes to calibrate on)")
        pairs = posed_pairs(Path(args.data_root), [s.strip() for s in args.scenes.split(",")
                                                   if s.strip()], Path(args.cache))
    else:
        pairs = btv.real_val_pairs(Path(args.cache), 2, 4)
    if not pairs:
        print("error: expected matched pairs to calibrate on (got none)", file=sys.stderr)
        return 2
    d2, scenes = mahalanobis(model, pairs, own=args.own)
    scale = fit(d2)
    what = "the network's own covariance" if args.own else "the estimator's covariance"
    lines = [banner(), "", "Command: `python benchmarks/calibrate_regression.py "
             f"{shlex.join(sys.argv[1:] if argv is None else argv)}`", "",
             f"regression scale (pooled, {len(d2)} pairs, {what}): {scale:.4g}", "",
             "| scene | pairs | 2-sigma coverage, scale fitted on the other scenes | "
             "coverage at the pooled scale |", "|---|---|---|---|"]
    for s in dict.fromkeys(scenes):
        own = np.array([x == s for x in scenes])
        other = fit(d2[~own])
        hit = int((d2[own] / other < bp.CHI2_5[2]).sum())
        lo, hi = coverage_interval(hit, int(own.sum()))
        pooled = float((d2[own] / scale < bp.CHI2_5[2]).mean())
        lines.append(f"| {s} | {int(own.sum())} | {hit / own.sum():.0%} [{lo:.0%}, {hi:.0%}] "
                     f"(scale {other:.3g}) | {pooled:.0%} |")
    print("\n".join(lines))
    if args.report:
        with open(args.report, "a") as f:
            f.write(f"## `{Path(args.model).name}`, {what}\n\n" + "\n".join(lines) + "\n\n")
    if args.out:
        _, shipped = StrLPose.pretrained_header("geometric")
        calibration = {k: v for k, v in shipped["calibration"].items()
                       if k in ("poselib", "opencv")}
        calibration["regression"] = scale
        model.metadata = {**{k: v for k, v in model.metadata.items()
                             if k not in ("calibration", "recommended_order")},
                          "calibration": calibration,
                          "recommended_order": ["poselib", "opencv", "regression"],
                          **({"training_data": args.training_data}
                             if args.training_data else {})}
        model.save(args.out)
        print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
