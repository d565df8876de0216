"""Diagnostic (not a fit): are the recommended poses whose sigma reached the 180-deg cap
right or wrong, and does the flipped-line-endpoint warning fire on real front-end matches?

On the Middlebury dino's consecutive pairs and KITTI 06 (i, i+3) (front-end matches,
``--cache`` as :mod:`bench_pose`; skipped where the data is absent), the shipped weights'
recommended pose per pair: status, method, rotation / translation error and sigma (deg),
whether a block is capped (``info["sigma_capped"]``), and whether
:func:`strl_pyg.inference.checks.flipped_lines` warns. Prints one line per pair and a summary
per set (what ``docs/uncertainty.md`` quotes for the dino).

    python benchmarks/studies/diag_capped_sigma.py --cache outputs/bench_pose_cache
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/

import bench_pose as bp  # noqa: E402
from strl_bench_common import banner  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", default="outputs/bench_pose_cache")
    ap.add_argument("--usable-deg", type=float, default=15.0,
                    help="a capped pose within this in rotation and translation counts usable")
    args = ap.parse_args(argv)
    print(banner())
    from strl_pyg.inference.checks import flipped_lines
    from strl_pyg.inference.estimator import PoseEstimator

    cache, est = Path(args.cache), PoseEstimator()
    for name, pairs in (("dino", bp.dino_pairs(cache)), ("KITTI 06 (i, i+3)",
                                                         bp.kitti_pairs(3, cache))):
        ok = capped = usable = flipped = 0
        for key, m, T in pairs:
            if m is None:
                continue
            flipped += bool(flipped_lines(m))
            r = est.estimate(m, methods="recommended").pose
            if r.status != "ok":
                print(f"{key} {r.status}")
                continue
            ok += 1
            er, et = bp.errors(r.T_0to1, T)
            cap = bool(r.info.get("sigma_capped"))
            capped += cap
            usable += cap and er <= args.usable_deg and et <= args.usable_deg
            print(f"{key} ok {r.method} err {er:.2f} / {et:.2f} sigma "
                  f"{r.sigma['rotation_deg']:.2f} / {r.sigma['translation_deg']:.2f}"
                  f"{' capped' if cap else ''}")
        print(f"{name}: {len(pairs)} pairs, {ok} ok, {capped} capped, {usable} of them within "
              f"{args.usable_deg:g} deg in both; flipped-lines warning on {flipped}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
