"""Diagnostic (not a fit): ``vp``'s raw AUC@20 on the real point-poor slices for several line
weights ``VP_LINE_SIGMA_PX``, with and without PoseLib's pose as a second start.

    python benchmarks/studies/diag_line_weight.py --cache <eval cache>

The package's constant is fitted on generated calibration pairs only
(``bench_vanishing.py --fit``); this script shows how that choice transfers to real images
(KITTI 06 and the dino at 40 keypoints per image). Figures in ``results_vanishing.md``'s notes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/

SIGMAS = (None, 3.0, 1.0, 0.3, 0.1, 0.03)


def main(argv: list[str] | None = None) -> int:
    import ablation_eval as ae
    import bench_pose as bp
    import bench_vanishing as bv
    from strl_bench_common import banner

    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.estimation.vanishing import vanishing_directions, vanishing_point_pose
    from strl_pyg.frontend import FrontendConfig

    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "strl-pyg" / "eval_cache"))
    args = ap.parse_args(argv)
    cache, few = Path(args.cache), FrontendConfig.preset("legacy", max_keypoints=ae.FEW_KEYPOINTS)
    print(banner())
    for name, pairs in (("kitti06_kp40", bp.kitti_pairs(1, cache, config=few)),
                        ("dino_kp40", bp.dino_pairs(cache, config=few))):
        pre = []
        for _, m, T in pairs:
            if m is None or m.num_points < 5 or not m.num_lines:
                pre.append(None)
                continue
            r = estimate_relative_pose(m, "poselib")
            pre.append((m, np.asarray(T, float), vanishing_directions(m),
                        [r.T_0to1] if r.success else None))
        for sigma in SIGMAS:
            for label, with_start in (("PoseLib as a second start", True), ("vp only", False)):
                if sigma is None and with_start:
                    continue  # starts need the joint refinement
                worst = []
                for p in pre:
                    if p is None:
                        worst.append(180.0)
                        continue
                    m, T, d, st = p
                    res = vanishing_point_pose(m, directions=d, line_sigma_px=sigma,
                                               starts=st if with_start else None)
                    worst.append(max(bp.errors(res.T_0to1.matrix().numpy(), T))
                                 if res.success else 180.0)
                a, lo, hi = bv.auc_interval(np.array(worst))
                print(f"{name} sigma {sigma} ({label}): AUC@20 {a:.1f} [{lo:.1f}-{hi:.1f}]",
                      flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
