"""Is PoseLib's inlier threshold a lever on real photographs?

PoseLib on the default front end's matches (deduplicated) of the real_scenes pairs that
``bench_status.py`` matched and cached (``--cache``), at several thresholds (px, Sampson);
AUC@10 of max(rotation, translation direction) per split. A threshold would be chosen on the
training scenes and checked on the validation scenes::

    python benchmarks/studies/study_poselib_threshold.py --cache outputs/bench_status_cache \\
        --out benchmarks/studies/results_poselib_threshold.md
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_pose as bp  # noqa: E402
import bench_status as bs  # noqa: E402
from strl_bench_common import banner  # noqa: E402

THRESHOLDS = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", default="outputs/bench_status_cache")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.metrics.two_view import pose_auc

    cache = Path(args.cache)
    lines = ["# PoseLib's threshold on real photographs "
             "(`benchmarks/studies/study_poselib_threshold.py`)", "", banner(), "",
             "| split | pairs | " + " | ".join(f"{t:g} px" for t in THRESHOLDS) + " |",
             "|---|---|" + "---|" * len(THRESHOLDS)]
    for split in ("train", "val"):
        errs = {t: [] for t in THRESHOLDS}
        for pair, m in tqdm(list(bs.cached_pairs(split, cache)), desc=split):
            for t in THRESHOLDS:
                res = estimate_relative_pose(m, "poselib", t, seed=0)
                errs[t].append(max(bp.errors(res.T_0to1.matrix().numpy(), pair[5]))
                               if res.success else 180.0)
        n = len(errs[THRESHOLDS[0]])
        aucs = [100 * float(pose_auc(np.asarray(errs[t]), [10])[0]) for t in THRESHOLDS]
        lines.append(f"| {split} | {n} | " + " | ".join(f"{a:.1f}" for a in aucs) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
