"""How much match noise a pure rotation takes before it stops being called ``rotation_only``.

Generated pure rotations (400 points at depths 4-12 in front of a 640x480 camera, f = 500,
a 6 deg rotation about a random axis, no translation), Gaussian noise of ``sigma`` px on every
coordinate of both images; the recommended pose of ``PoseEstimator(methods=("poselib",))``.
The classifier compares the rotation's inliers (2-D transfer error) with the essential
matrix's (1-D Sampson error) at one threshold, so at a noise near that threshold a rotation
counts fewer inliers than an essential matrix with any translation::

    python benchmarks/studies/study_rotation_noise.py --real outputs/bench_status_cache \\
        --out benchmarks/studies/results_rotation_noise.md

``--real CACHE`` also counts, on the real_scenes pairs whose matches ``bench_status.py`` cached
there, how many a looser rule would call rotations (the rotation's inliers counted at 1.25 px,
the square root of the chi-square ratio of two to one degree of freedom at 95 %), and in how
many of those PoseLib's pose is within 5 deg: the right poses the looser rule would refuse.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from strl_bench_common import banner  # noqa: E402

K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
SIZE = (480, 640)


def pure_rotation(seed: int, sigma: float, n: int = 400):
    import cv2

    from strl_pyg.data import PairMatches

    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    R = cv2.Rodrigues(axis / np.linalg.norm(axis) * np.radians(6.0))[0]
    d = rng.uniform(4.0, 12.0, size=n)
    X = np.c_[rng.uniform(-0.6, 0.6, size=(n, 2)), np.ones(n)] * d[:, None]

    def project(P):
        p = P @ K.T
        return p[:, :2] / p[:, 2:] + rng.normal(scale=sigma, size=(len(P), 2))

    x0, x1 = project(X), project(X @ R.T)
    keep = (x0 > 0).all(1) & (x0 < [639, 479]).all(1) & (x1 > 0).all(1) & \
        (x1 < [639, 479]).all(1)
    return PairMatches(x0[keep], x1[keep], K0=K, K1=K, image_size0=SIZE, image_size1=SIZE)


def real_pairs_table(cache: Path) -> list[str]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import bench_pose as bp
    import bench_status as bs

    from strl_pyg.estimation import two_view as tv
    from strl_pyg.estimation.classical import estimate_relative_pose, normalised_matches

    rows = []
    for split in ("val", "train"):
        for pair, m in bs.cached_pairs(split, cache):
            x0, x1, f = (a.numpy() if hasattr(a, "numpy") else a for a in normalised_matches(m))
            g = tv.classify_two_view(x0, x1, f, 1.0, 0, m.points0, m.points1)
            loose = int(tv.rotation_only(x0, x1, f, 1.25)[1].sum())
            pl = estimate_relative_pose(m, "poselib", 1.0, seed=0)
            err = max(bp.errors(pl.T_0to1.matrix().numpy(), pair[5])) if pl.success else 180
            rows.append((g.inliers_R / max(g.inliers_E, g.inliers_H, 1),
                         loose / max(g.inliers_E, g.inliers_H, 1), err))
    out = ["", f"Real pairs (matches cached by `bench_status.py`): {len(rows)}.", "",
           "| rotation's share of the top model's inliers >= | pairs called rotations, 1 px "
           "(PoseLib within 5 deg) | pairs called rotations, 1.25 px (PoseLib within 5 deg) |",
           "|---|---|---|"]
    for c in (0.6, 0.7, 0.8, 0.9):
        a = [e for r, _, e in rows if r >= c]
        b = [e for _, r, e in rows if r >= c]
        out.append(f"| {c:g} | {len(a)} ({sum(e <= 5 for e in a)}) | {len(b)} "
                   f"({sum(e <= 5 for e in b)}) |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--out", default=None)
    ap.add_argument("--real", default=None, metavar="CACHE",
                    help="also the real pairs whose matches bench_status.py cached here")
    args = ap.parse_args()
    from strl_pyg.inference import PoseEstimator

    est = PoseEstimator(methods=("poselib",))
    lines = ["# A pure rotation under match noise (`benchmarks/studies/study_rotation_noise.py`)",
             "", banner(), "", __doc__.split("\n\n")[1].replace("\n", " ").replace("::", "."), "",
             f"{args.seeds} pairs per noise level.", "",
             "| noise sigma (px) | rotation_only | ok | of them translation sigma >= 90 deg | "
             "unreliable | other |", "|---|---|---|---|---|---|"]
    for sigma in (0.3, 0.5, 0.7, 1.0):
        counts, wide = Counter(), 0
        for seed in range(args.seeds):
            pose = est.estimate(pure_rotation(seed, sigma)).pose
            counts[pose.status] += 1
            if pose.status == "ok" and (pose.sigma or {}).get("translation_deg", 0) >= 90:
                wide += 1
        other = args.seeds - counts["rotation_only"] - counts["ok"] - counts["unreliable"]
        lines.append(f"| {sigma:g} | {counts['rotation_only']} | {counts['ok']} | {wide} | "
                     f"{counts['unreliable']} | {other} |")
    if args.real:
        lines += real_pairs_table(Path(args.real))
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
