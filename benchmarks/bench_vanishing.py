"""The vanishing-point solver (``vp``) where points are too few, beside PoseLib, on the same
matches (issue "Do lines help?", item 4).

    python benchmarks/bench_vanishing.py --out benchmarks/results_vanishing.md

For every pair of the point-poor sets (``point_poor``: generated pairs with <= 30 point and
>= 20 line matches; ``kitti06_kp40`` / ``demon_kp40`` / ``dino_kp40``: the real slices with the
front end limited to 40 keypoints per image) and of the full real sets (where ``vp`` must not
make the recommended pose worse), it scores:

- ``PoseLib``: PoseLib's raw pose (any pose it returns);
- ``vp``: :func:`~strl_pyg.estimation.vanishing.vanishing_point_pose`'s raw pose;
- ``recommended (no vp)`` and ``recommended``: :class:`~strl_pyg.inference.PoseEstimator`'s
  recommended pose (the shipped model, every method) without and with ``vp`` in the order; a
  pose that is not ``"ok"`` counts as no pose.

AUC@20 of max(rotation, translation) error with no pose = 180 deg, [95 % bootstrap interval
over pairs]; medians over the pairs with a pose; the paired AUC difference recommended - PoseLib
with its paired-bootstrap interval.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))

METHODS = ("PoseLib", "vp", "recommended (no vp)", "recommended")


def score_pairs(pairs, model, progress: bool = True) -> dict[str, list]:
    """``method -> [(rot, trans) or None]`` over ``pairs``."""
    import bench_pose as bp

    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.estimation.vanishing import vanishing_point_pose
    from strl_pyg.inference import PoseEstimator
    from strl_pyg.inference.estimator import METHODS as REGISTRY

    without = tuple(m for m in REGISTRY if m != "vp" and REGISTRY[m].available())
    est_without = PoseEstimator(model, methods=without)
    est_with = PoseEstimator(model, methods=(*without, "vp"))
    out = {k: [] for k in METHODS}
    for _, m, T in tqdm(pairs, desc="pairs", disable=not progress, leave=False):
        if m is None or m.num_points < 5:
            for k in METHODS:
                out[k].append(None)
            continue
        res = estimate_relative_pose(m, "poselib")
        out["PoseLib"].append(list(bp.errors(res.T_0to1.matrix().numpy(), T))
                              if res.success else None)
        res = vanishing_point_pose(m) if m.num_lines else None
        out["vp"].append(list(bp.errors(res.T_0to1.matrix().numpy(), T))
                         if res is not None and res.success else None)
        a = est_without.estimate(m)
        b = est_with.estimate(m, known=a.methods)
        for k, e in (("recommended (no vp)", a), ("recommended", b)):
            ok = e.pose.status == "ok"
            out[k].append(list(bp.errors(e.pose.T_0to1, T)) if ok else None)
            if k == "recommended":
                out.setdefault("recommended_method", []).append(e.pose.method if ok else None)
    return out


def _worst(rows: list) -> np.ndarray:
    return np.array([180.0 if r is None else max(r) for r in rows])


def _auc(worst: np.ndarray) -> float:
    import ablation_eval as ae

    return 100 * ae.auc20(worst)


def auc_interval(worst: np.ndarray, resamples: int = 1000, seed: int = 0):
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(worst), (resamples, len(worst)))
    boots = [_auc(worst[i]) for i in idx]
    return _auc(worst), *np.percentile(boots, [2.5, 97.5])


def paired_auc_diff(a: np.ndarray, b: np.ndarray, resamples: int = 1000, seed: int = 0):
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(a), (resamples, len(a)))
    boots = [_auc(a[i]) - _auc(b[i]) for i in idx]
    return _auc(a) - _auc(b), *np.percentile(boots, [2.5, 97.5])


def main(argv: list[str] | None = None) -> int:
    import ablation_eval as ae
    import bench_pose as bp
    from common import banner

    from strl_pyg.frontend import FrontendConfig
    from strl_pyg.model.strl_pose import StrLPose

    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "strl-pyg" / "eval_cache"),
                    help="front-end match cache (shared with benchmarks/ablation.py eval)")
    ap.add_argument("--point-poor", type=int, default=ae.POINT_POOR_PAIRS,
                    help="pairs of the generated point_poor set")
    ap.add_argument("--out", default=None, help="write the markdown table here")
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    few = FrontendConfig(max_keypoints=ae.FEW_KEYPOINTS)
    sets = {"point_poor": ae.point_poor_pairs(cache, args.point_poor),
            "kitti06_kp40": bp.kitti_pairs(1, cache, config=few),
            "demon_kp40": bp.demon_pairs(cache, config=few),
            "dino_kp40": bp.dino_pairs(cache, config=few),
            "kitti06": bp.kitti_pairs(1, cache),
            "demon": bp.demon_pairs(cache),
            "dino": bp.dino_pairs(cache)}
    sets = {k: v for k, v in sets.items() if v}
    model = StrLPose.from_pretrained()
    scores = {}
    for name, pairs in tqdm(sets.items(), desc="sets"):
        scores[name] = score_pairs(pairs, model)
    lines = ["# The vanishing-point solver where points are too few", "", "```", banner(),
             "```", "", "`python benchmarks/bench_vanishing.py` (module docstring). AUC@20 "
             "(%) of max(rotation, translation) error, no pose (or a non-ok recommended "
             "pose) = 180 deg, [95 % bootstrap interval]; median max-error (deg) over the "
             "pairs with a pose, and how many of the pairs have one.", "",
             "| set | pairs | " + " | ".join(METHODS) + " | recommended - PoseLib (AUC) |",
             "|---|---" + "|---" * len(METHODS) + "|---|"]
    for name, sc in scores.items():
        cells = []
        for k in METHODS:
            w = _worst(sc[k])
            a, lo, hi = auc_interval(w)
            have = [max(r) for r in sc[k] if r is not None]
            med = f"{np.median(have):.1f}" if have else "-"
            cells.append(f"{a:.1f} [{lo:.1f}-{hi:.1f}]; med {med} ({len(have)})")
        d, lo, hi = paired_auc_diff(_worst(sc["recommended"]), _worst(sc["PoseLib"]))
        lines.append(f"| {name} | {len(sc['PoseLib'])} | " + " | ".join(cells)
                     + f" | {d:+.1f} [{lo:+.1f}-{hi:+.1f}] |")
    lines += ["", "Which method gave the recommended pose: " + "; ".join(
        f"{name}: " + ", ".join(f"{m} {c}" for m, c in zip(*np.unique(
            [str(x) for x in sc["recommended_method"]], return_counts=True), strict=True))
        for name, sc in scores.items())]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
