"""How much match noise a pure rotation takes before it stops being called ``rotation_only``.

Generated pure rotations (400 points at depths 4-12 in front of a 640x480 camera, f = 500,
a 6 deg rotation about a random axis, no translation), Gaussian noise of ``sigma`` px on every
coordinate of both images; the recommended pose of ``PoseEstimator(methods=("poselib",))``.
The classifier compares the rotation's inliers (2-D transfer error) with the essential
matrix's (1-D Sampson error) at one threshold, so at a noise near that threshold a rotation
counts fewer inliers than an essential matrix with any translation::

    python benchmarks/studies/study_rotation_noise.py --out benchmarks/studies/results_rotation_noise.md
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    from strl_pyg.inference import PoseEstimator

    est = PoseEstimator(methods=("poselib",))
    lines = ["# A pure rotation under match noise (`benchmarks/studies/study_rotation_noise.py`)",
             "", banner(), "", __doc__.split("\n\n")[1].replace("\n", " "), "",
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
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
