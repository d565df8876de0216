"""The network's own pose on real photographs: weights against weights, per scene, on the same
front-end matches, with PoseLib beside them.

Sets: the real_scenes validation scenes' ``(i, i+2)`` pairs for every 4th ``i`` (66 pairs; the
split's validation scenes are never trained on), KITTI 06 ``(i, i+1)`` and ``(i, i+3)``, the
dino's consecutive pairs and DeMoN (``../shared/data``). For each set and model: the median
rotation and translation-direction errors of the regression, its 2-sigma coverage (the
5-dof Mahalanobis distance of the error under its own covariance below the chi-square 95.45 %
quantile, Wilson interval), and the paired ratio of the medians against the first model
(bootstrap interval over pairs). PoseLib's medians are on the same matches.

    python benchmarks/bench_real_scenes.py --models shipped:geometric,runs/real/best_model.pt \\
        --out benchmarks/results_real_scenes/README.md
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_pose as bp  # noqa: E402
import bench_two_view as btv  # noqa: E402
from strl_bench_common import banner  # noqa: E402

VAL_SCENES = ("drone_hall", "fruit", "ethiopian_head", "office_drink")


def load(spec: str):
    from strl_pyg.model.strl_pose import StrLPose

    if spec.startswith("shipped:"):
        return StrLPose.from_pretrained(spec.split(":", 1)[1])
    return StrLPose.load(spec)


def pair_sets(cache: Path) -> dict[str, list]:
    sets: dict[str, list] = {}
    for pid, m, T in btv.real_val_pairs(cache, 2, 4):
        sets.setdefault(pid.split("/")[0], []).append((pid, m, T))
    sets["real validation (pooled)"] = [p for s in VAL_SCENES for p in sets.get(s, [])]
    sets["KITTI 06 (i, i+1)"] = bp.kitti_pairs(1, cache)
    sets["KITTI 06 (i, i+3)"] = bp.kitti_pairs(3, cache)
    sets["dino"] = bp.dino_pairs(cache)
    sets["DeMoN"] = bp.demon_pairs(cache)
    return {k: [p for p in v if p[1] is not None] for k, v in sets.items() if v}


def score(model, pairs, with_poselib: bool) -> dict:
    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.inference import PoseEstimator

    est = PoseEstimator(model, methods=("regression",))
    out = {"rot": [], "trans": [], "hit": [], "pl_rot": [], "pl_trans": []}
    for _, m, T in pairs:
        e = est.estimate(m)
        reg = e.methods["regression"]
        if reg.status != "ok":
            out["rot"].append(np.nan)
            out["trans"].append(np.nan)
            out["hit"].append(False)
        else:
            r, t = bp.errors(reg.T_0to1, T)
            out["rot"].append(r)
            out["trans"].append(t)
            hit = False
            if reg.covariance is not None and np.isfinite(reg.covariance).all():
                err = bp.tangent_error(reg.T_0to1, T)
                hit = float(err @ np.linalg.pinv(reg.covariance) @ err) < bp.CHI2_5[2]
            out["hit"].append(hit)
        if with_poselib:  # its pose on every pair (as Table 3's report scores it), not
            # only where the estimator's support checks would keep it
            pl = estimate_relative_pose(m, "poselib", est.config.threshold_px,
                                        seed=est.config.seed)
            r, t = (bp.errors(pl.T_0to1.matrix().numpy(), T) if pl.success
                    else (np.nan, np.nan))
            out["pl_rot"].append(r)
            out["pl_trans"].append(t)
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", required=True,
                    help="comma-separated weights (shipped:NAME or model.pt); the first is "
                         "the reference of the paired ratios")
    ap.add_argument("--cache", default="outputs/bench_cache")
    ap.add_argument("--out", default=None)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    import torch

    from strl_pyg.metrics.stats import coverage_interval, median_ratio_interval

    torch.set_num_threads(1)
    specs = args.models.split(",")
    sets = pair_sets(Path(args.cache))
    results = {}
    for k, spec in enumerate(specs):
        model = load(spec)
        for name, pairs in tqdm(sets.items(), desc=spec):
            results[(spec, name)] = score(model, pairs, with_poselib=k == 0)
    L = ["# The network's pose on real photographs", "", banner(), "",
         f"Command: `python benchmarks/bench_real_scenes.py {' '.join(argv or sys.argv[1:])}`",
         "", "Median rotation / translation-direction error (deg) of the regression; "
         "2-sigma coverage with its Wilson interval; paired ratio of the medians against "
         f"`{specs[0]}` with a 95 % bootstrap interval (below 1: better), and against "
         "PoseLib's pose on the same matches (rotation / translation; below 1 with the "
         "interval: the network beats PoseLib there). PoseLib is scored on every pair where "
         "it returns a pose (`estimate_relative_pose`, the estimator's threshold and seed), "
         "including the pairs the estimator's support checks would mark `failed`.", "",
         "| set (pairs) | weights | rotation | translation | 2-sigma coverage | rot ratio | "
         "trans ratio | vs PoseLib rot / trans |", "|---|---|---|---|---|---|---|---|"]
    for name, pairs in sets.items():
        ref = results[(specs[0], name)]
        for spec in specs:
            r = results[(spec, name)]
            n = len(r["hit"])
            lo, hi = coverage_interval(int(r["hit"].sum()), n)
            ratios = []
            for key in ("rot", "trans"):
                ok = np.isfinite(r[key]) & np.isfinite(ref[key])
                if spec == specs[0] or ok.sum() < 3:
                    ratios.append("-")
                    continue
                q, a, b = median_ratio_interval(r[key][ok], ref[key][ok])
                ratios.append(f"{q:.2f} [{a:.2f}, {b:.2f}]")
            vs_pl = []
            for key in ("rot", "trans"):
                ok = np.isfinite(r[key]) & np.isfinite(ref["pl_" + key])
                if ok.sum() < 3:
                    vs_pl.append("-")
                    continue
                q, a, b = median_ratio_interval(r[key][ok], ref["pl_" + key][ok])
                vs_pl.append(f"{q:.2f} [{a:.2f}, {b:.2f}]")
            L.append(f"| {name} ({len(pairs)}) | `{spec}` | {np.nanmedian(r['rot']):.2f} | "
                     f"{np.nanmedian(r['trans']):.1f} | {r['hit'].mean():.0%} "
                     f"[{lo:.0%}, {hi:.0%}] | {ratios[0]} | {ratios[1]} | "
                     f"{vs_pl[0]} / {vs_pl[1]} |")
        L.append(f"| {name} ({len(pairs)}) | PoseLib | {np.nanmedian(ref['pl_rot']):.2f} | "
                 f"{np.nanmedian(ref['pl_trans']):.1f} | - | - | - | - |")
    text = "\n".join(L) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    if args.json:
        Path(args.json).write_text(json.dumps(
            {f"{s}|{n}": {k: v.tolist() for k, v in r.items()}
             for (s, n), r in results.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
