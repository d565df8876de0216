"""Evaluation sets and scoring of the ablation study (``benchmarks/ablation.py eval|report``).

Every run's regression head and PoseLib are scored on the same front-end matches of each set,
computed once and cached under ``<root>/eval_cache``:

- ``point_poor``: held-out generated pairs (seeds from 2,100,000, the ``low_texture``
  evaluation distribution without the object kind) whose default front end finds at most 30
  point matches and at least 20 line matches; the first :data:`POINT_POOR_PAIRS` that do.
- the generated evaluation sets of ``bench_pose.py`` (``driving``, ``indoor``, ``object``,
  ``wide``, ``low_texture``, ``outliers50``; :data:`GENERATED_PAIRS` each, seeds from
  2,000,000).
- the real slices: KITTI 06 consecutive frames, the DeMoN pairs, the Middlebury dino; and
  their point-poor variants (``*_kp40``): the front end limited to 40 keypoints per image, so
  the lines are matched with the fundamental matrix those few points give (never with one of
  points that were then removed).

A pose that a method does not give counts as 180 deg in the AUCs and is left out of the
medians (the number of such pairs is reported).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

POINT_POOR_PAIRS = 100
POINT_POOR_SEED = 2_100_000
POINT_POOR_MAX_CANDIDATES = 1500
GENERATED_PAIRS = 50
GENERATED_SETS = ("driving", "indoor", "object", "wide", "low_texture", "outliers50")
REAL_SETS = ("kitti06", "demon", "dino")
FEW_KEYPOINTS = 40


def point_poor_distribution():
    """The distribution the ``point_poor`` candidates are drawn from (low texture; street,
    indoor and boxes scenes)."""
    from strl_pyg.synthetic.distributions import eval_distribution

    return eval_distribution("low_texture", kinds=("street", "indoor", "boxes"))


def point_poor_pairs(cache: Path, n: int = POINT_POOR_PAIRS, seed0: int = POINT_POOR_SEED
                     ) -> list[tuple[str, Any, np.ndarray]]:
    """The ``point_poor`` set (see the module docstring); another ``seed0`` gives another
    split selected the same way (``bench_vanishing.py --fit``'s calibration split)."""
    from bench_pose import _cached, match_cache

    from strl_pyg.data.matches import PairMatches
    from strl_pyg.frontend import NoMatchesError, match_images
    from strl_pyg.synthetic import generate_pair

    def wanted(m) -> bool:
        lines = 0 if m.lines0 is None else len(m.lines0)
        return m.num_points <= 30 and lines >= 20

    dist = point_poor_distribution()
    store = match_cache(cache, scene=dist)
    out = []
    for seed in range(seed0, seed0 + POINT_POOR_MAX_CANDIDATES):
        if len(out) == n:
            break
        path = store.path(f"pp_{seed}")
        # a candidate matched before and not wanted is not rendered again (most are not:
        # about 1 in 12 is point-poor); the wanted ones are, for their ground-truth pose
        if path.is_file() and not wanted(PairMatches.load(path)):
            continue
        p = generate_pair(seed, dist.config(seed))
        try:
            m = _cached(cache, f"pp_{seed}", lambda p=p: match_images(
                p.image0, p.image1, K0=p.K, K1=p.K), scene=dist)
        except (NoMatchesError, RuntimeError):
            continue
        if wanted(m):
            out.append((f"point_poor/{seed}", m, np.asarray(p.T_0to1, dtype=np.float64)))
    return out


def all_sets(cache: Path, quick: bool = False) -> dict[str, list]:
    """Every evaluation set: name -> [(pair id, PairMatches or None, T_0to1)]."""
    import bench_pose as bp

    from strl_pyg.frontend import FrontendConfig

    n_gen = 4 if quick else GENERATED_PAIRS
    sets = {"point_poor": point_poor_pairs(cache, 4 if quick else POINT_POOR_PAIRS)}
    for name in GENERATED_SETS:
        sets[name] = bp.generated_pairs(name, n_gen, cache)
    few = FrontendConfig.preset("legacy", max_keypoints=FEW_KEYPOINTS)
    for suffix, cfg in (("", None), (f"_kp{FEW_KEYPOINTS}", few)):
        sets[f"kitti06{suffix}"] = bp.kitti_pairs(1, cache, config=cfg)
        sets[f"demon{suffix}"] = bp.demon_pairs(cache, config=cfg)
        sets[f"dino{suffix}"] = bp.dino_pairs(cache, config=cfg)
    if quick:
        sets = {k: v[:4] for k, v in sets.items()}
    return {k: v for k, v in sets.items() if v}


def _errors(T_est: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    """Rotation and translation-direction errors (deg), to 1e-4 deg (the results files are
    committed: the digits beyond say nothing)."""
    import bench_pose as bp

    return tuple(round(float(e), 4) for e in bp.errors(T_est, T_gt))


def poselib_errors(sets: dict[str, list]) -> dict[str, list]:
    """PoseLib on every pair: ``[rot, trans]`` in degrees or ``None`` where it gives no pose."""
    from strl_pyg.estimation.classical import estimate_relative_pose

    out = {}
    for name, pairs in sets.items():
        rows = []
        for _, m, T in pairs:
            if m is None or m.num_points < 5:
                rows.append(None)
                continue
            res = estimate_relative_pose(m, method="poselib")
            rows.append(list(_errors(res.T_0to1.matrix().numpy(), T)) if res.success else None)
        out[name] = rows
    return out


def model_errors(model: Any, sets: dict[str, list]) -> dict[str, list]:
    """The regression head on every pair (``None`` where the pair has no matches)."""
    import torch

    from strl_pyg.inference.network import forward_pose, prepare_graph

    out = {}
    with torch.inference_mode():
        for name, pairs in sets.items():
            rows = []
            for _, m, T in pairs:
                if m is None or (m.num_points == 0 and m.num_lines == 0):
                    rows.append(None)
                    continue
                o = forward_pose(model, prepare_graph(m, model, seed=0))
                T_est = o.T_0to1[0].double().numpy()
                rows.append(list(_errors(T_est, T)))
            out[name] = rows
    return out


def save_json(path: Path, obj: Any) -> None:
    from strl_pyg.utils.io import atomic_open

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "w") as f:
        json.dump(obj, f)


def check_or_save_sets(path: Path, ids: dict[str, list[str]]) -> None:
    """Writes the sets' pair ids, or checks them against the ones already written: runs scored
    in another session must have been scored on the same pairs (else one error line)."""
    if path.exists():
        old = json.loads(path.read_text())
        if old != ids:
            diff = [k for k in sorted(set(old) | set(ids)) if old.get(k) != ids.get(k)]
            raise SystemExit(f"error: the evaluation sets differ from the ones the committed "
                             f"results were scored on ({path}): sets {diff}; delete the results "
                             f"folder to start the study over")
        return
    save_json(path, ids)


# ----------------------------------------------------------------------------- report
def _rows(errs: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rotation, translation, worst) per pair; NaN / inf where there is no pose."""
    r = np.array([np.nan if e is None else e[0] for e in errs], dtype=float)
    t = np.array([np.nan if e is None else e[1] for e in errs], dtype=float)
    worst = np.where(np.isfinite(r) & np.isfinite(t), np.fmax(r, t), np.inf)
    return r, t, worst


def median_interval(x: np.ndarray, resamples: int = 2000, seed: int = 0) -> tuple[float, ...]:
    """Median of the finite values and its 95 % percentile-bootstrap interval over pairs."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return (np.nan, np.nan, np.nan)
    idx = np.random.default_rng(seed).integers(0, x.size, size=(resamples, x.size))
    lo, hi = np.quantile(np.median(x[idx], axis=1), [0.025, 0.975])
    return float(np.median(x)), float(lo), float(hi)


def auc20(worst: np.ndarray) -> float:
    from strl_pyg.metrics.two_view import pose_auc

    return float(pose_auc(worst, (20.0,))[0])


def seeded_paired_ratio(a: list[list], b: list[list], which: int
                        ) -> tuple[float, float, float, int]:
    """:func:`paired_ratio` for two rows of several seeds each (``a[s]``: seed ``s``'s
    per-pair errors): the mean of the seeds' medians, a / b, on the pairs where every run of
    both gave a pose, with the bootstrap interval over pairs and seeds
    (:func:`strl_pyg.metrics.seeded_median_ratio_interval`), and the number of such pairs."""
    from strl_pyg.metrics.stats import seeded_median_ratio_interval

    runs = list(a) + list(b)
    if len({len(r) for r in runs}) != 1:
        raise ValueError(f"Expected every run scored on the same pairs (got "
                         f"{sorted({len(r) for r in runs})} pairs)")
    keep = [i for i in range(len(runs[0])) if all(r[i] is not None for r in runs)]
    if not keep:
        return (np.nan, np.nan, np.nan, 0)
    x = np.array([[e[i][which] for i in keep] for e in a])
    y = np.array([[e[i][which] for i in keep] for e in b])
    return (*seeded_median_ratio_interval(x, y), len(keep))


def paired_ratio(a: list, b: list, which: int) -> tuple[float, float, float, int]:
    """median(a) / median(b) of rotation (0) or translation (1) errors on the pairs where
    both gave a pose, with its paired-bootstrap interval, and the number of such pairs."""
    from strl_pyg.metrics.stats import median_ratio_interval

    keep = [i for i, (x, y) in enumerate(zip(a, b, strict=True))
            if x is not None and y is not None]
    if not keep:
        return (np.nan, np.nan, np.nan, 0)
    x = np.array([a[i][which] for i in keep])
    y = np.array([b[i][which] for i in keep])
    return (*median_ratio_interval(x, y), len(keep))
