"""How much work ``strl-pose predict`` does per pair, counted rather than timed: calls of
``normalize_points``, ``Pose.from_matrix``, ``match_images``, ``PairMatches.deduplicated`` and
``intrinsics_problems`` on the pairs of ``bench_predict.py`` (KITTI 06, DeMoN, dino, the
generated point-poor pair), for ``--methods recommended`` and ``all``, the shipped weights.

Counts do not depend on the machine or its load; they were the targets of issue 'One record
per method, one pass per pair' (a default predict called ``normalize_points`` 14 times).
Calls made in the bootstrap's worker threads are counted too (the wrappers are module
attributes, not a profiler)::

    python benchmarks/studies/count_predict_calls.py \\
        --out benchmarks/studies/results_predict_calls.md
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # bench_predict, strl_bench_common


def _install_counters(counts: collections.Counter) -> None:
    """Wraps the counted functions where their callers look them up."""
    import strl_pyg.data.matches as matches_mod
    import strl_pyg.estimation.classical as classical
    import strl_pyg.frontend as frontend
    import strl_pyg.inference.estimator as estimator
    from strl_pyg.geometry.pose import Pose

    def counted(name, fn):
        def wrapper(*a, **k):
            counts[name] += 1
            return fn(*a, **k)
        return wrapper

    # normalize_points: the one normalisation (classical) and the network's graph (data.build)
    import strl_pyg.data.build as build
    for mod in (classical, build):
        mod.normalize_points = counted("normalize_points", mod.normalize_points)
    frontend.match_images = counted("match_images", frontend.match_images)
    estimator.intrinsics_problems = counted("intrinsics_problems",
                                            estimator.intrinsics_problems)
    real_dedup = matches_mod.PairMatches.deduplicated
    matches_mod.PairMatches.deduplicated = counted("deduplicated", real_dedup)
    real_from = Pose.from_matrix.__func__
    Pose.from_matrix = classmethod(counted("Pose.from_matrix", real_from))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--out", default=None, help="also write the table to this Markdown file")
    args = ap.parse_args()
    from bench_predict import _pairs, _point_poor_pair
    from strl_bench_common import banner

    from strl_pyg.frontend import FrontendConfig
    from strl_pyg.inference.recommended import estimate_methods

    counts: collections.Counter = collections.Counter()
    _install_counters(counts)
    tmp = tempfile.TemporaryDirectory()
    pairs = _pairs(Path(args.data)) + [_point_poor_pair(Path(tmp.name))]
    names = ("normalize_points", "Pose.from_matrix", "match_images", "deduplicated",
             "intrinsics_problems")
    lines = ["| pair | --methods | pose from; ran | " + " | ".join(f"`{n}`" for n in names)
             + " |", "|---|---|---|" + "---|" * len(names)]
    for label, paths, K in pairs:
        img0, img1 = (cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in paths)
        for methods in ("recommended", "all"):
            counts.clear()
            est = estimate_methods(None, img0, img1, K, K, FrontendConfig(), methods)
            lines.append(f"| {label} | {methods} | {est.pose.method}; "
                         f"{', '.join(est.methods)} | "
                         + " | ".join(str(counts[n]) for n in names) + " |")
    text = "\n".join(["# Calls per `strl-pose predict` "
                      "(`benchmarks/studies/count_predict_calls.py`)",
                      "", "    python benchmarks/studies/count_predict_calls.py --out "
                      "benchmarks/studies/results_predict_calls.md", "", banner(), "", *lines, ""])
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
