"""What the MULTIPLE rule's moving branch costs the estimator: ``PoseEstimator().estimate`` on
the default front end's matches of KITTI 06 ``(i, i+1)`` (every 6th ``i``), with the branch on
and off (``MULTIPLE_MOVING_MIN_INLIERS`` set out of reach: the share rule alone, as before
it), interleaved in one process, median of ``--repeat`` runs per pair; plus how often the
branch solves a second motion the share rule would not have. Run it on a quiet machine::

    python benchmarks/studies/time_multiple_motions.py --repeat 7
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_matches as bm  # noqa: E402
from strl_bench_common import banner  # noqa: E402


def main(argv=None) -> int:
    import cv2
    import torch

    from strl_pyg.estimation import classical
    from strl_pyg.frontend import FrontendConfig, match_images
    from strl_pyg.inference import PoseEstimator, evidence

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    pairs = [p for p in bm.slice_pairs() if p[-1] == "KITTI 06 +1"]
    if not pairs:
        print("KITTI 06 not found under ../shared/data: nothing to time")
        return 0
    calls = []
    solve = classical.estimate_relative_pose

    def counted(m, *a, **k):
        calls.append(m.num_points)
        return solve(m, *a, **k)

    classical.estimate_relative_pose = counted  # the rule's own solve, imported at call time
    est = PoseEstimator()
    on = evidence.MULTIPLE_MOVING_MIN_INLIERS
    print(banner())
    rows, extra = [], 0
    for pid, a, b, K0, K1, _, _ in pairs:
        m = match_images(cv2.imread(str(a), cv2.IMREAD_GRAYSCALE),
                         cv2.imread(str(b), cv2.IMREAD_GRAYSCALE), K0=K0, K1=K1,
                         config=FrontendConfig(lines=False))
        times = {"on": [], "off": []}
        counts = {}
        for _ in range(args.repeat):
            for mode in ("off", "on"):
                evidence.MULTIPLE_MOVING_MIN_INLIERS = on if mode == "on" else 10 ** 9
                n = len(calls)
                t0 = time.perf_counter()
                est.estimate(m)
                times[mode].append(time.perf_counter() - t0)
                counts[mode] = len(calls) - n
        evidence.MULTIPLE_MOVING_MIN_INLIERS = on
        extra += counts["on"] > counts["off"]
        rows.append((pid, m.num_points,
                     *(1e3 * statistics.median(times[k]) for k in ("off", "on"))))
    lines = ["| pair | matches | share rule only (ms) | with the moving branch (ms) | ratio |",
             "|---|---|---|---|---|"]
    lines += [f"| {pid} | {n} | {off:.1f} | {on_:.1f} | {on_ / off:.2f} |"
              for pid, n, off, on_ in rows]
    tot_off, tot_on = sum(r[2] for r in rows), sum(r[3] for r in rows)
    lines.append(f"| all ({len(rows)}) | | {tot_off:.0f} | {tot_on:.0f} | "
                 f"{tot_on / tot_off:.2f} |")
    print("\n".join(lines))
    print(f"\nthe moving branch solved a second motion the share rule would not have on "
          f"{extra} of {len(rows)} pairs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
