"""What a pose the support check refuses costs: one estimate of random matches (unrelated
images) by PoseLib with the default bootstrap, and the bootstrap resamples of its pose that
the estimate no longer computes (``strl_pyg.inference.methods.classical``), best of 3 after a
warm-up, in one process. Nothing else should run.

    python benchmarks/studies/time_refused_bootstrap.py --points 300
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from strl_bench_common import banner  # noqa: E402


def best_ms(fn, repeat: int = 3) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * min(times)


def main() -> None:
    from strl_pyg.data.matches import PairMatches
    from strl_pyg.estimation.uncertainty import bootstrap_resamples
    from strl_pyg.inference import PoseEstimator

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print(banner())
    rng = np.random.default_rng(args.seed)
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    pts = [rng.uniform([0, 0], [639, 479], size=(args.points, 2)) for _ in range(2)]
    img = [rng.integers(0, 256, size=(480, 640), dtype=np.uint8) for _ in range(2)]
    matches = PairMatches(pts[0], pts[1], K0=K, K1=K, image0=img[0], image1=img[1])
    est = PoseEstimator(methods=("poselib",))
    rec = est.estimate(matches).methods["poselib"]
    print(f"poselib: {rec.status}, {rec.info.get('bootstrap', 'bootstrapped')}")
    estimate = best_ms(lambda: est.estimate(matches))
    pose = rec.raw.pose
    n = PoseEstimator().config.bootstrap
    skipped = best_ms(lambda: bootstrap_resamples(matches, pose, "poselib", n, 1.0, 0))
    print(f"{args.points} random matches: the estimate {estimate:.0f} ms; the {n} bootstrap "
          f"resamples it skips {skipped:.0f} ms (estimate with them: ~{estimate + skipped:.0f} "
          f"ms, {(estimate + skipped) / estimate:.1f}x)")


if __name__ == "__main__":
    main()
