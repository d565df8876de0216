"""The recommended pose's sigma on the real slices: coverage of the true error and the largest
sigmas (issue "First contact, round 4": a sigma that means what it says).

Per pair of KITTI 06 (i, i+1), every consecutive Middlebury dino pair and the DeMoN pairs,
front-end matches of the package being measured (``--cache`` per version: the front end of
0.4 drops repeated matches), ``PoseEstimator(methods="poselib")`` (the recommended pose on
these sets), bootstrap 8 with the shipped calibration. Reported per set: pairs with an ``ok``
pose, the 1- and 2-sigma coverage of the 5-dof tangent error (chi-square, 5 dof, with 95 %
Wilson intervals), the median and the largest sigma (rotation / translation, deg), and how
many sigmas were capped at 180 deg. Run it from the checkout to measure (``before``: an
earlier commit's worktree with this file copied into its ``benchmarks/``)::

    python benchmarks/studies/bench_sigma_coverage.py --cache outputs/sigma_cache --label after
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", required=True, help="front-end match cache of this version")
    ap.add_argument("--label", required=True)
    ap.add_argument("--out", default=None, help="JSON of the figures")
    args = ap.parse_args(argv)
    import bench_pose as bp
    from strl_bench_common import banner

    from strl_pyg.inference import PoseEstimator
    from strl_pyg.metrics.stats import coverage_interval

    print(banner())
    cache = Path(args.cache)
    sets = {"kitti06": bp.kitti_pairs(1, cache), "dino": bp.dino_pairs(cache),
            "demon": bp.demon_pairs(cache)}
    est = PoseEstimator(methods="poselib")
    out = {}
    for name, pairs in sets.items():
        d2, sig, capped, n_ok = [], [], 0, 0
        for _, m, T in pairs:
            if m is None:
                continue
            r = est.estimate(m).pose
            if r.status != "ok" or r.covariance is None:
                continue
            n_ok += 1
            e = bp.tangent_error(r.T_0to1, T)
            cov = np.asarray(r.covariance, dtype=np.float64)
            d2.append(float(e @ np.linalg.pinv(cov) @ e))
            sig.append((r.sigma["rotation_deg"], r.sigma["translation_deg"]))
            capped += bool(r.info.get("sigma_capped"))
        d2, sig = np.asarray(d2), np.asarray(sig).reshape(-1, 2)
        row = {"pairs": len(pairs), "ok": n_ok, "capped": capped}
        for k, q in bp.CHI2_5.items():
            inside = int((d2 <= q).sum())
            lo, hi = coverage_interval(inside, len(d2)) if len(d2) else (np.nan, np.nan)
            row[f"cover{k}"] = [round(inside / max(len(d2), 1), 3), round(lo, 3), round(hi, 3)]
        row["sigma_median"] = np.median(sig, axis=0).round(3).tolist() if len(sig) else None
        row["sigma_max"] = sig.max(axis=0).round(3).tolist() if len(sig) else None
        out[name] = row
        print(f"{args.label} {name}: {row}")
    if args.out:
        Path(args.out).write_text(json.dumps({"label": args.label, "sets": out}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
