"""Which matches can vote on the cheirality rule? A match whose two rays are nearly parallel
(a distant point) triangulates in front or behind by noise. For PoseLib's pose on the
real_scenes training scenes (the pairs and cached matches of ``bench_status.py``, true and
perturbed intrinsics), the rule "fewer than 90 % of the band's matches in front of both
cameras" with only the matches whose rays are at least ``theta`` apart voting: how many right
(<= 5 deg) and wrong (> 5 deg) poses it refuses, per ``theta``.

    python benchmarks/studies/study_cheirality_parallax.py --scenes train \
        --out benchmarks/studies/results_cheirality_parallax.md
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_matches as bm  # noqa: E402
import bench_pose as bp  # noqa: E402
import bench_status as bs  # noqa: E402
from strl_bench_common import banner  # noqa: E402

THETAS = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0)
VARIANTS = ("true", "f/2", "2f", "swap")


def votes(m, T, threshold_px=1.0):
    """Per band match: (in front of both cameras, ray angle in degrees)."""
    from strl_pyg.estimation.classical import normalised_matches
    from strl_pyg.geometry import pose_sampson
    from strl_pyg.geometry.essential import triangulated_depths

    R = torch.as_tensor(T[:3, :3])
    t = torch.as_tensor(T[:3, 3])
    x0, x1, focal = normalised_matches(m)
    near = pose_sampson(R, t, x0, x1).abs() < 2.0 * threshold_px / focal
    z0, z1 = triangulated_depths(R[None], t[None], x0[None], x1[None])
    front = (z0[0] > 0) & (z1[0] > 0)
    h0 = torch.cat([x0, torch.ones_like(x0[:, :1])], -1) @ R.T
    h1 = torch.cat([x1, torch.ones_like(x1[:, :1])], -1)
    cos = (h0 * h1).sum(-1) / (h0.norm(dim=-1) * h1.norm(dim=-1))
    angle = torch.rad2deg(torch.arccos(cos.clamp(-1, 1)))
    return front[near].numpy(), angle[near].numpy()


def main() -> int:
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT
    from strl_pyg.estimation.classical import estimate_relative_pose

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", choices=("train", "val"), default="train")
    ap.add_argument("--cache", default="outputs/bench_status_cache")
    ap.add_argument("--out", default="benchmarks/studies/results_cheirality_parallax.md")
    args = ap.parse_args()
    counts = {(v, th): [0, 0, 0, 0] for v in VARIANTS for th in THETAS}  # rr, rw, n_r, n_w
    for pair in tqdm(bm.scene_pairs(REAL_SCENES_SPLIT[args.scenes], per_gap=12), desc="pairs"):
        m0 = bs.matches_of(pair, Path(args.cache))
        if m0 is None:
            continue
        for v in VARIANTS:
            m = bs.perturbed(m0, v)
            pl = estimate_relative_pose(m, "poselib", 1.0, seed=0)
            if not pl.success:
                continue
            T = pl.T_0to1.matrix().double().numpy()
            right = max(bp.errors(T, pair[5])) <= bs.RIGHT_DEG
            front, angle = votes(m, T)
            for th in THETAS:
                vote = angle >= th
                refused = vote.sum() >= 12 and front[vote].mean() < 0.9
                c = counts[(v, th)]
                c[0 if right else 1] += int(refused)
                c[2 if right else 3] += 1
    lines = ["# Cheirality votes by ray angle", "", banner(), "",
             f"`python benchmarks/studies/study_cheirality_parallax.py --scenes {args.scenes}`: "
             "PoseLib's pose on every pair, the cheirality rule (< 90 % of the voting band "
             "matches in front of both cameras, at least 12 voting) with only matches whose "
             "rays are at least theta apart voting.", "",
             "| variant | theta (deg) | right refused | wrong refused |", "|---|---|---|---|"]
    for v in VARIANTS:
        for th in THETAS:
            rr, rw, nr, nw = counts[(v, th)]
            lines.append(f"| {v} | {th:g} | {rr} of {nr} | {rw} of {nw} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
