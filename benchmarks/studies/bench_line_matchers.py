"""Does a line matcher that needs no fundamental matrix widen the regime where lines help?
(issue "Do lines help?", item 3).

    python benchmarks/studies/bench_line_matchers.py \\
        --out benchmarks/studies/results_line_matchers.md

The front end's line matcher (``epipolar``) needs a fundamental matrix fitted on >= 8 point
matches; below that a pair has no line matches at all. ``descriptor``
(:func:`~strl_pyg.frontend.lines.match_lines_by_descriptor`: band descriptors, mutual nearest
neighbours, ratio test) needs none; ``descriptor+guide`` adds the point matches' displacement
as a loose position prior where there are >= 3 of them. All three run on the same detected
segments (LSD on the cached grey images) and the same point matches of each pair.

Sets (the ablation's evaluation cache, ``$STRL_ABLATION_ROOT/eval_cache``, is reused where it
holds the pair):

- ``few_points``: the generated point-poor candidates (seeds of ``point_poor`` and of its
  calibration split) whose front end found fewer than 8 point matches, the regime the
  epipolar matcher cannot reach;
- ``point_poor``: the ablation's 100 point-poor pairs (8-30 point matches, an F from few
  points);
- ``kitti06_kp20`` / ``dino_kp20``: the real slices with the front end limited to 20 keypoints
  per image (a few point matches).

Per matcher: line matches per pair, the fraction of them consistent with the ground-truth
epipolar geometry (the epipolar lines of one segment's endpoints cut the other's supporting
line over at least half of the shorter of that cut and the other segment; segments within
10 deg of their epipolar lines cannot be judged and are left out; beside it, in brackets,
the same check of the same segments each paired with another's match, its chance level), and
the pose of the vanishing-point solver
(``vp``, >= 5 point matches) from those lines and the same points, beside PoseLib on the
points: AUC@20 of max(rotation, translation) error with no pose = 180 deg, [95 % bootstrap
interval over pairs].
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/

MATCHERS = ("epipolar", "descriptor", "descriptor+guide")
FEW_POINT_SEEDS = ((2_100_000, 1500), (2_300_000, 1500))


def _root() -> Path:
    return Path(os.environ.get("STRL_ABLATION_ROOT",
                               Path.home() / ".cache" / "strl-pyg" / "ablation"))


def consistent(l0: np.ndarray, l1: np.ndarray, F: np.ndarray,
               min_overlap: float = 0.5) -> np.ndarray:
    """Per line match: 1 consistent with ``F``, 0 not, -1 cannot be judged (a segment within
    10 deg of its epipolar lines). The epipolar lines of segment 0's endpoints cut segment 1's
    supporting line in a band; consistent when the band and segment 1 overlap over at least
    ``min_overlap`` of the shorter of the two (so a fragment of either matches the whole edge,
    as the epipolar matcher's own overlap test)."""
    out = np.full(len(l0), -1)
    for i in range(len(l0)):
        D1 = l1[i, 1] - l1[i, 0]
        len1 = np.linalg.norm(D1)
        e = np.concatenate([l0[i], np.ones((2, 1))], axis=1) @ F.T  # epipolar lines in image 1
        den = e[:, :2] @ D1
        sin = np.abs(den) / (np.linalg.norm(e[:, :2], axis=1) * len1)
        if not (sin > np.sin(np.deg2rad(10.0))).all():
            continue
        s = -(e @ np.append(l1[i, 0], 1.0)) / den
        common = max(min(max(s), 1.0) - max(min(s), 0.0), 0.0)
        shorter = min(abs(s[1] - s[0]), 1.0)
        out[i] = int(shorter > 0 and common / shorter >= min_overlap)
    return out


def _errors(T_est, T_gt) -> tuple[float, float]:
    from ablation_eval import _errors as err  # the ablation's error definition

    return err(T_est, T_gt)


def few_point_pairs(cache: Path, limit: int | None = None):
    """The cached generated candidates with fewer than 8 point matches (rendered again for
    their ground truth)."""
    from bench_pose import match_cache

    from strl_pyg.data.matches import PairMatches
    from strl_pyg.synthetic import generate_pair
    from strl_pyg.synthetic.distributions import eval_distribution

    dist = eval_distribution("low_texture", kinds=("street", "indoor", "boxes"))
    store = match_cache(cache, scene=dist)  # ablation_eval.point_poor_pairs' candidates
    out = []
    for seed0, n in FEW_POINT_SEEDS:
        for seed in range(seed0, seed0 + n):
            path = store.path(f"pp_{seed}")
            if not path.is_file():
                continue
            m = PairMatches.load(path)
            if m.num_points >= 8:
                continue
            p = generate_pair(seed, dist.config(seed))
            out.append((f"few_points/{seed}", m, np.asarray(p.T_0to1, dtype=np.float64)))
            if limit and len(out) >= limit:
                return out
    return out


def line_sets(matches, cfg):
    """``matcher -> (lines0, lines1)`` on the same detected segments of ``matches``' images."""
    from strl_pyg.frontend.lines import detect_lines, match_lines_by_descriptor

    g0, g1 = np.asarray(matches.image0), np.asarray(matches.image1)
    s0, s1 = detect_lines(g0, cfg), detect_lines(g1, cfg)
    p0, p1 = np.asarray(matches.points0), np.asarray(matches.points1)
    has = matches.lines0 is not None and len(matches.lines0) > 0
    out = {"epipolar": (np.asarray(matches.lines0), np.asarray(matches.lines1)) if has
           else (np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))}
    out["descriptor"] = match_lines_by_descriptor(s0, s1, g0, g1, cfg)[:2]
    out["descriptor+guide"] = match_lines_by_descriptor(s0, s1, g0, g1, cfg,
                                                        guide=(p0, p1))[:2]
    return out


def score(pairs, progress=True) -> dict:
    from dataclasses import replace

    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.estimation.vanishing import VP_MIN_POINTS, vanishing_point_pose
    from strl_pyg.frontend import FrontendConfig
    from strl_pyg.geometry.epipolar import fundamental_from_pose

    cfg = FrontendConfig()
    res = {"PoseLib": [], **{f"vp ({k})": [] for k in MATCHERS},
           **{f"lines ({k})": [] for k in MATCHERS}, **{f"right ({k})": [] for k in MATCHERS},
           **{f"chance ({k})": [] for k in MATCHERS},
           "points": []}
    for _, m, T in tqdm(pairs, disable=not progress, desc="pairs"):
        K0, K1 = np.asarray(m.K0, dtype=np.float64), np.asarray(m.K1, dtype=np.float64)
        F = fundamental_from_pose(T, K0, K1)
        res["points"].append(m.num_points)
        pl = None
        if m.num_points >= 5:
            r = estimate_relative_pose(replace(m, lines0=None, lines1=None, line_scores=None),
                                       "poselib", 1.0, seed=0)
            pl = _errors(r.pose.matrix().numpy(), T) if r.success else None
        res["PoseLib"].append(pl)
        for name, (l0, l1) in line_sets(m, cfg).items():
            c = consistent(l0, l1, F) if len(l0) else np.zeros(0)
            res[f"lines ({name})"].append(len(l0))
            judged = c >= 0
            res[f"right ({name})"].append((int((c == 1).sum()), int(judged.sum())))
            # the chance level of that check: the same segments, paired at random
            # (a derangement: every segment paired with another's match, none with its own)
            c = consistent(l0, np.roll(l1, 1, axis=0), F) if len(l0) > 1 else np.zeros(0)
            res[f"chance ({name})"].append((int((c == 1).sum()), int((c >= 0).sum())))
            pose = None
            if m.num_points >= VP_MIN_POINTS and len(l0) >= 4:
                mm = replace(m, lines0=l0, lines1=l1, line_scores=None)
                r = vanishing_point_pose(mm, 1.0, seed=0)
                pose = _errors(r.pose.matrix().numpy(), T) if r.success else None
            res[f"vp ({name})"].append(pose)
    return res


def _auc(poses, seed=0):
    from ablation_eval import auc20

    worst = np.array([180.0 if p is None else max(p) for p in poses])
    rng = np.random.default_rng(seed)
    boots = [auc20(worst[rng.integers(0, len(worst), len(worst))]) for _ in range(1000)]
    return auc20(worst), np.percentile(boots, 2.5), np.percentile(boots, 97.5)


def _paired_diff(a, b, seed=0):
    """AUC@20(a) - AUC@20(b) on the same pairs and its paired-bootstrap 95 % interval."""
    from ablation_eval import auc20

    wa = np.array([180.0 if p is None else max(p) for p in a])
    wb = np.array([180.0 if p is None else max(p) for p in b])
    rng = np.random.default_rng(seed)
    boots = []
    for _ in range(1000):
        i = rng.integers(0, len(wa), len(wa))
        boots.append(auc20(wa[i]) - auc20(wb[i]))
    return auc20(wa) - auc20(wb), np.percentile(boots, 2.5), np.percentile(boots, 97.5)


def table(name: str, res: dict) -> list[str]:
    n = len(res["points"])
    out = [f"## {name} ({n} pairs; point matches per pair: median "
           f"{np.median(res['points']):.0f}, range {min(res['points'])}-{max(res['points'])})",
           "", "| method | line matches / pair (median) | consistent with the true geometry "
           "(random pairing) | pairs with a pose | AUC@20 [95 %] | - PoseLib (paired) [95 %] | "
           "- vp on epipolar lines (paired) [95 %] |", "|---|---|---|---|---|---|---|"]
    a = _auc(res["PoseLib"])
    got = sum(p is not None for p in res["PoseLib"])
    out.append(f"| PoseLib (points only) | - | - | {got} | {100 * a[0]:.1f} "
               f"[{100 * a[1]:.1f}, {100 * a[2]:.1f}] | - | - |")
    for k in MATCHERS:
        right = np.array(res[f"right ({k})"]).reshape(-1, 2)
        frac = right[:, 0].sum() / max(right[:, 1].sum(), 1)
        chance = np.array(res[f"chance ({k})"]).reshape(-1, 2)
        chance = chance[:, 0].sum() / max(chance[:, 1].sum(), 1)
        a = _auc(res[f"vp ({k})"])
        got = sum(p is not None for p in res[f"vp ({k})"])
        out.append(f"| vp, {k} lines | {np.median(res[f'lines ({k})']):.0f} | "
                   f"{100 * frac:.0f} % of {right[:, 1].sum()} judged "
                   f"({100 * chance:.0f} %) | {got} | "
                   f"{100 * a[0]:.1f} [{100 * a[1]:.1f}, {100 * a[2]:.1f}] | "
                   "{:+.1f} [{:+.1f}, {:+.1f}] | ".format(
                       *(100 * np.array(_paired_diff(res[f"vp ({k})"], res["PoseLib"]))))
                   + ("-" if k == "epipolar" else "{:+.1f} [{:+.1f}, {:+.1f}]".format(
                       *(100 * np.array(_paired_diff(res[f"vp ({k})"],
                                                     res["vp (epipolar)"])))))
                   + " |")
    return out + [""]


def main(argv=None) -> int:
    import bench_pose as bp
    from ablation_eval import POINT_POOR_PAIRS, point_poor_pairs

    from strl_pyg.frontend import FrontendConfig

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--quick", action="store_true", help="a few pairs per set (a smoke run)")
    args = ap.parse_args(argv)
    cache = _root() / "eval_cache"
    n = 3 if args.quick else None
    few = FrontendConfig.preset("legacy", max_keypoints=20)
    sets = {
        "few_points": few_point_pairs(cache, n),
        "point_poor": point_poor_pairs(cache, 3 if args.quick else POINT_POOR_PAIRS),
        "kitti06_kp20": bp.kitti_pairs(1, cache, config=few)[:n],
        "dino_kp20": bp.dino_pairs(cache, config=few)[:n],
    }
    import cv2
    import torch
    from strl_bench_common import banner

    lines = ["# Line matchers with and without a fundamental matrix "
             "(`benchmarks/studies/bench_line_matchers.py`)", "",
             "    python benchmarks/studies/bench_line_matchers.py --out "
             "benchmarks/studies/results_line_matchers.md", "", "```", banner(), "```", "",
             f"python {platform.python_version()}, torch {torch.__version__}, "
             f"opencv {cv2.__version__}; {time.strftime('%Y-%m-%d %H:%M')}; no timings", ""]
    for name, pairs in sets.items():
        if not pairs:
            lines += [f"## {name}: no pairs (data or cache absent)", ""]
            continue
        lines += table(name, score(pairs))
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
