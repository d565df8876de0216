"""Evaluation of a Str-L Pose checkpoint against the classical baselines and the fused pose,
on the same matches, with the paper's tables.

Per pair (:class:`EvalPair`: matches, ground-truth ``T_0to1``, subset, id) every method in
:data:`METHODS` estimates ``T_0to1`` (``X1 = R X0 + t``):

* ``"strl"``: the network, on the graph of :func:`~strl_pyg.data.build_pair_graph` built from
  the matches (patches greyscale when the model's ``patch_features`` is 1, grey replicated to
  RGB when it is 3), resampled to ``(384, 192)`` points/lines with
  :class:`~strl_pyg.data.transforms.FixedSizeResample` seeded by ``seed + pair index`` (so a
  pair's graph does not depend on the order or the other pairs), or not resampled with
  ``resample=None``;
* ``"opencv"``, ``"poselib"``: :func:`~strl_pyg.baselines.estimate_relative_pose`;
* ``"fused_opencv"``, ``"fused_poselib"``: :func:`~strl_pyg.pose_fusion.fuse_poses` of the
  network with that baseline.

Errors are the rotation angle and the translation-direction angle in degrees (DeMoN's, sign not
folded); AUC@5/10/20 of ``max(rotation, translation)``, failures counting as infinite.

KITTI (pairs carrying frame indices): per sequence the relative poses are chained into a
trajectory with the ground-truth scale of each pair (the two-view protocol for
unit-translation predictions) and scored with :func:`~strl_pyg.metrics.kitti_odometry_errors`
(t_rel in %, r_rel in deg / 100 m). Where no 100 m segment fits (the shared slice of sequence
06, frames 0-50, covers 59.9 m) ``t_rel``/``r_rel`` are ``NaN`` and the per-pair RMSE of the
rotation (deg) and of the scaled translation (m) is reported instead, with the drift on short
10-50 m segments as a non-standard extra.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from strl_pyg.baselines import MIN_POINTS, estimate_relative_pose
from strl_pyg.data.matches import PairMatches
from strl_pyg.geometry import Pose
from strl_pyg.inference import forward_pose, prepare_graph, prepare_matches
from strl_pyg.metrics import (
    integrate_relative_poses,
    kitti_odometry_errors,
    kitti_odometry_summary,
    pose_auc,
    relative_pose_error,
)
from strl_pyg.pose_fusion import fuse_poses
from strl_pyg.synthetic.config import LINE_SCENE_KINDS, SCENE_KINDS

__all__ = [
    "METHODS",
    "AUC_THRESHOLDS",
    "SHORT_SEGMENT_LENGTHS",
    "EvalPair",
    "PairResult",
    "pair_result",
    "EvalReport",
    "available_methods",
    "prepare_matches",
    "predict_pose",
    "evaluate_pairs",
    "synthetic_eval_pairs",
    "demon_eval_pairs",
    "kitti_eval_pairs",
]

METHODS = ("strl", "opencv", "poselib", "fused_opencv", "fused_poselib")
AUC_THRESHOLDS = (5.0, 10.0, 20.0)
#: Non-standard short segments (metres) for slices too short for KITTI's 100-800 m.
SHORT_SEGMENT_LENGTHS = (10.0, 20.0, 30.0, 40.0, 50.0)


def _have_poselib() -> bool:
    try:
        import poselib  # noqa: F401
    except ImportError:
        return False
    return True


def available_methods() -> tuple[str, ...]:
    """:data:`METHODS` without the PoseLib ones when PoseLib is not importable."""
    return METHODS if _have_poselib() else tuple(m for m in METHODS if "poselib" not in m)


# ----------------------------------------------------------------------------- data
@dataclass
class EvalPair:
    """One pair to evaluate.

    Args:
        matches: :class:`~strl_pyg.data.PairMatches` with ``K0``, ``K1`` (pixels).
        T_0to1: ground truth ``[4, 4]``, camera 0 to camera 1.
        subset: name to group results by (e.g. ``"MVS"``, ``"KITTI/06"``).
        pair_id: unique id.
        frames: ``(i, j)`` frame indices within the subset's sequence, for trajectories.
    """

    matches: PairMatches
    T_0to1: np.ndarray
    subset: str
    pair_id: str
    frames: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.matches, PairMatches):
            raise TypeError(f"Expected a PairMatches (got {type(self.matches).__name__})")
        if not self.matches.has_intrinsics:
            raise ValueError(f"Expected intrinsics in the matches of '{self.pair_id}' (got none)")
        T = np.asarray(self.T_0to1, dtype=np.float64)
        if T.shape == (3, 4):
            T = np.vstack([T, [0.0, 0.0, 0.0, 1.0]])
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise ValueError(f"Expected a finite T_0to1 of shape (4, 4) (got {T.shape})")
        self.T_0to1 = T


def synthetic_eval_pairs(
    num_pairs: int,
    seed: int = 2_000_000,
    kinds: Sequence[str] = LINE_SCENE_KINDS,
    matches: str = "ground_truth",
    scene: dict[str, Any] | None = None,
    frontend_config: Any = None,
    progress: bool = False,
) -> list[EvalPair]:
    """Held-out generated pairs (training uses seeds below 2,000,000): pair ``i`` is kind
    ``kinds[i % len(kinds)]`` from seed ``seed + i``.

    Args:
        matches: ``"ground_truth"`` (the generator's matches, after ``scene``'s noise and
            outliers) or ``"frontend"`` (:func:`~strl_pyg.frontend.match_images` on the
            rendered images).
        scene: other :class:`~strl_pyg.synthetic.SceneConfig` fields, e.g.
            ``{"noise_px": 1.0, "outlier_fraction": 0.3}``.
    """
    from strl_pyg.synthetic import SceneConfig, generate_pair

    if matches not in ("ground_truth", "frontend"):
        raise ValueError(f"Expected matches in ('ground_truth', 'frontend') (got {matches!r})")
    if not isinstance(num_pairs, int) or num_pairs < 1:
        raise ValueError(f"Expected a positive integer num_pairs (got {num_pairs!r})")
    if not kinds:
        raise ValueError("Expected at least one scene kind (got none)")
    out = []
    for i in tqdm(range(num_pairs), desc="generate", disable=not progress, leave=False):
        kind = kinds[i % len(kinds)]
        pair = generate_pair(seed + i, SceneConfig(**{**(scene or {}), "kind": kind}))
        m = pair.matches
        if matches == "frontend":
            from strl_pyg.frontend import match_images

            m = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                             config=frontend_config)
            m = replace(m, K0=pair.K, K1=pair.K)
        out.append(EvalPair(m, pair.T_0to1, f"synthetic/{kind}", f"synthetic/{kind}/{seed + i}"))
    return out


def _dataset_pairs(ds: Any, num_workers: int, progress: bool,
                   frames: bool = False) -> list[EvalPair]:
    ds.build_cache(num_workers=num_workers, progress=progress)
    out = []
    for i in range(len(ds)):
        rec = ds.record(i)
        fr = None
        if frames:
            a, b = rec.pair_id.rsplit("/", 1)[-1].split("-")
            fr = (int(a), int(b))
        out.append(EvalPair(ds.load_matches(i), rec.T_0to1, rec.subset, rec.pair_id, fr))
    return out


def demon_eval_pairs(root: str | os.PathLike, cache_dir: str | os.PathLike, split: str = "test",
                     limit: int | None = None, num_workers: int = 0, progress: bool = False,
                     **kwargs: Any) -> list[EvalPair]:
    """DeMoN pairs of a DeepSfM folder root (front-end matches, cached in ``cache_dir``);
    ``kwargs`` go to :class:`~strl_pyg.data.datasets.DeMoNFolder`."""
    from strl_pyg.data.datasets import DeMoNFolder

    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"Expected a DeMoN DeepSfM folder at '{root}' (got none)")
    ds = DeMoNFolder(root, cache_dir=cache_dir, split=split, limit=limit, **kwargs)
    return _dataset_pairs(ds, num_workers, progress)


def kitti_eval_pairs(root: str | os.PathLike, cache_dir: str | os.PathLike,
                     sequences: Sequence[str] = ("09", "10"), frame_gap: int = 1,
                     limit: int | None = None, num_workers: int = 0, progress: bool = False,
                     **kwargs: Any) -> list[EvalPair]:
    """KITTI odometry pairs ``(i, i + frame_gap)`` (front-end matches, cached in
    ``cache_dir``) with their frame indices; ``kwargs`` go to
    :class:`~strl_pyg.data.datasets.KITTIOdometry`."""
    from strl_pyg.data.datasets import KITTIOdometry

    root = Path(root)
    if not (root / "sequences").is_dir():
        raise FileNotFoundError(f"Expected a KITTI odometry root with 'sequences/' at '{root}' "
                                "(got none)")
    ds = KITTIOdometry(root, cache_dir=cache_dir, sequences=list(sequences),
                       frame_gap=frame_gap, limit=limit, **kwargs)
    return _dataset_pairs(ds, num_workers, progress, frames=True)


# ----------------------------------------------------------------------------- model
def predict_pose(model: torch.nn.Module, matches: PairMatches,
                 resample: tuple[int, int] | None = (384, 192), seed: int = 0,
                 device: str | torch.device = "cpu") -> Any:
    """The model's ``PoseOutput`` (one pair) on the graph of ``matches`` (module docstring):
    :func:`strl_pyg.inference.prepare_graph` then :func:`strl_pyg.inference.forward_pose`
    (``no_grad``, eval mode, the graph cast to the model's dtype); ``resample="model"``
    takes the counts the checkpoint stores."""
    return forward_pose(model, prepare_graph(matches, model, seed, resample), device)


# ----------------------------------------------------------------------------- report
@dataclass
class PairResult:
    """One method on one pair: errors in degrees (``NaN`` translation on failure)."""

    pair_id: str
    subset: str
    method: str
    rot_err: float
    trans_err: float
    time_ms: float
    success: bool
    T_0to1: np.ndarray = field(repr=False)  # the estimate [4, 4]

    @property
    def max_err(self) -> float:
        if not self.success or not math.isfinite(self.trans_err):
            return math.inf
        return max(self.rot_err, self.trans_err)


def _stats(rows: list[PairResult]) -> dict[str, float]:
    rot = np.array([r.rot_err if r.success else np.nan for r in rows])
    tr = np.array([r.trans_err if r.success else np.nan for r in rows])
    auc = pose_auc(np.array([r.max_err for r in rows]), AUC_THRESHOLDS)

    def agg(fn, a):
        return float(fn(a)) if np.isfinite(a).any() else float("nan")

    return {
        "n": len(rows),
        "failures": sum(not r.success for r in rows),
        "rot_mean": agg(np.nanmean, rot),
        "rot_median": agg(np.nanmedian, rot),
        "trans_mean": agg(np.nanmean, tr),
        "trans_median": agg(np.nanmedian, tr),
        **{f"auc{int(t)}": a for t, a in zip(AUC_THRESHOLDS, auc, strict=True)},
        "time_ms": float(np.median([r.time_ms for r in rows])),
    }


def _fmt(v: float, digits: int = 2) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else (
        f"{v:.{digits}f}")


@dataclass
class EvalReport:
    """Per-pair results of :func:`evaluate_pairs` and their tables.

    Attributes:
        results: one :class:`PairResult` per (pair, method).
        methods: methods in table order.
        pairs: the ground truth of each pair: ``{pair_id: (subset, T_0to1, frames)}``.
        meta: free-form description (checkpoint, dataset, options).
    """

    results: list[PairResult]
    methods: tuple[str, ...]
    pairs: dict[str, tuple[str, np.ndarray, tuple[int, int] | None]]
    meta: dict[str, Any] = field(default_factory=dict)

    def subsets(self) -> list[str]:
        return list(dict.fromkeys(s for s, _, _ in self.pairs.values()))

    def summary(self) -> dict[str, dict[str, dict[str, float]]]:
        """``{subset or "all": {method: stats}}`` with mean/median rotation and translation
        errors (deg), AUC@5/10/20 (as fractions), failure count and median time (ms)."""
        out = {}
        groups = [(s, s) for s in self.subsets()]
        if len(groups) > 1:
            groups.append(("all", None))
        for name, subset in groups:
            out[name] = {}
            for m in self.methods:
                rows = [r for r in self.results
                        if r.method == m and (subset is None or r.subset == subset)]
                if rows:
                    out[name][m] = _stats(rows)
        return out

    # -- trajectories
    def _chains(self) -> dict[str, list[str]]:
        """Per subset, the longest run of pairs with consecutive frames, in frame order."""
        chains = {}
        for subset in self.subsets():
            ids = [(fr, pid) for pid, (s, _, fr) in self.pairs.items()
                   if s == subset and fr is not None]
            ids.sort()
            best, run = [], []
            for fr, pid in ids:
                if run and self.pairs[run[-1]][2][1] != fr[0]:
                    run = []
                run.append(pid)
                if len(run) > len(best):
                    best = list(run)
            if best:
                chains[subset] = best
        return chains

    def trajectories(self) -> dict[str, dict[str, Pose]]:
        """``{subset: {"ground truth" | method: camera-to-world Pose [M + 1]}}`` of each
        subset's longest chain of consecutive pairs, scaled per pair by the ground truth."""
        lookup = {(r.pair_id, r.method): r for r in self.results}
        out = {}
        for subset, ids in self._chains().items():
            gt = Pose.from_matrix(np.stack([self.pairs[i][1] for i in ids]))
            scales = gt.t.norm(dim=-1)
            trajs = {"ground truth": integrate_relative_poses(gt)}
            for m in self.methods:
                rows = [lookup.get((i, m)) for i in ids]
                if any(r is None or not r.success for r in rows):
                    continue  # a failed pair breaks the chain
                est = Pose.from_matrix(np.stack([r.T_0to1 for r in rows]))
                trajs[m] = integrate_relative_poses(est, scales=scales)
            out[subset] = trajs
        return out

    def kitti_summary(self) -> dict[str, dict[str, dict[str, float]]]:
        """``{subset: {method: {t_rel, r_rel, num_segments, t_rel_short, r_rel_short,
        rmse_rot_deg, rmse_trans_m, length_m}}}`` (module docstring)."""
        out = {}
        lookup = {(r.pair_id, r.method): r for r in self.results}
        chains = self._chains()
        for subset, trajs in self.trajectories().items():
            gt = trajs["ground truth"]
            steps = gt.t[1:] - gt.t[:-1]
            length = float(steps.norm(dim=-1).sum())
            out[subset] = {}
            for m, est in trajs.items():
                if m == "ground truth":
                    continue
                full = kitti_odometry_summary(kitti_odometry_errors(gt, est))
                short = kitti_odometry_summary(
                    kitti_odometry_errors(gt, est, lengths=SHORT_SEGMENT_LENGTHS, step=1))
                rows = [lookup[(i, m)] for i in chains[subset]]
                T_gt = Pose.from_matrix(np.stack([self.pairs[i][1] for i in chains[subset]]))
                T_est = Pose.from_matrix(np.stack([r.T_0to1 for r in rows]))
                t_est = T_est.t / T_est.t.norm(dim=-1, keepdim=True) * T_gt.t.norm(
                    dim=-1, keepdim=True)
                rot = np.array([r.rot_err for r in rows])
                out[subset][m] = {
                    "t_rel": full["t_err_pct"],
                    "r_rel": full["r_err_deg_per_100m"],
                    "num_segments": full["num_segments"],
                    "t_rel_short": short["t_err_pct"],
                    "r_rel_short": short["r_err_deg_per_100m"],
                    "num_short_segments": short["num_segments"],
                    "rmse_rot_deg": float(np.sqrt(np.mean(rot**2))),
                    "rmse_trans_m": float((t_est - T_gt.t).norm(dim=-1).pow(2).mean().sqrt()),
                    "length_m": length,
                    "num_pairs": len(rows),
                }
        return out

    def plot_trajectories(self, out_dir: str | os.PathLike) -> list[Path]:
        """One top-view PNG per subset with a chain (``trajectory_<subset>.png``)."""
        from strl_pyg.viz.plots import plot_trajectory_topview

        paths = []
        for subset, trajs in self.trajectories().items():
            gt = trajs.pop("ground truth")
            name = "trajectory_" + "".join(c if c.isalnum() else "_" for c in subset) + ".png"
            paths.append(plot_trajectory_topview(
                Path(out_dir) / name, gt, trajs,
                title=f"{subset}: relative poses chained with GT scale"))
        return paths

    # -- output
    def to_markdown(self) -> str:
        """The tables as markdown: one row per subset and method, then KITTI drift."""
        lines = []
        if self.meta:
            lines += [", ".join(f"{k}: {v}" for k, v in self.meta.items()), ""]
        head = ("| subset | method | pairs | fail | rot mean | rot med | trans mean | trans med "
                "| AUC@5 | AUC@10 | AUC@20 | time ms |")
        lines += ["Errors in degrees; AUC of max(rot, trans) in %; time: median per pair.", "",
                  head, "|" + "---|" * 12]
        for subset, per in self.summary().items():
            for m, s in per.items():
                lines.append(
                    f"| {subset} | {m} | {s['n']} | {s['failures']} | {_fmt(s['rot_mean'])} | "
                    f"{_fmt(s['rot_median'])} | {_fmt(s['trans_mean'])} | "
                    f"{_fmt(s['trans_median'])} | {_fmt(100 * s['auc5'], 1)} | "
                    f"{_fmt(100 * s['auc10'], 1)} | {_fmt(100 * s['auc20'], 1)} | "
                    f"{_fmt(s['time_ms'], 1)} |")
        kitti = self.kitti_summary()
        if kitti:
            lines += ["", "Trajectories (relative poses chained, GT scale per pair). t_rel (%) and "
                      "r_rel (deg/100 m) on KITTI's 100-800 m segments ('-': none fits); "
                      "short: the same on 10-50 m segments (non-standard); RMSE per pair.", "",
                      "| sequence | method | pairs | length m | t_rel % | r_rel deg/100m | "
                      "t_rel short % | r_rel short deg/100m | RMSE rot deg | RMSE trans m |",
                      "|" + "---|" * 10]
            for subset, per in kitti.items():
                for m, s in per.items():
                    lines.append(
                        f"| {subset} | {m} | {s['num_pairs']} | {s['length_m']:.1f} | "
                        f"{_fmt(s['t_rel'])} | {_fmt(s['r_rel'])} | {_fmt(s['t_rel_short'])} | "
                        f"{_fmt(s['r_rel_short'])} | {_fmt(s['rmse_rot_deg'], 3)} | "
                        f"{_fmt(s['rmse_trans_m'], 3)} |")
        return "\n".join(lines) + "\n"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: meta, summary, KITTI summary and the per-pair errors."""
        def clean(v: Any) -> Any:
            if isinstance(v, dict):
                return {str(k): clean(x) for k, x in v.items()}
            if isinstance(v, float) and not math.isfinite(v):
                return None
            return v

        return clean({
            "meta": self.meta,
            "methods": list(self.methods),
            "summary": self.summary(),
            "kitti": self.kitti_summary(),
            "pairs": [{"pair_id": r.pair_id, "subset": r.subset, "method": r.method,
                       "rot_err": r.rot_err, "trans_err": r.trans_err, "time_ms": r.time_ms,
                       "success": r.success} for r in self.results],
        })

    def save(self, out_dir: str | os.PathLike) -> list[Path]:
        """Writes ``results.md``, ``results.json`` and the trajectory PNGs to ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        md = out / "results.md"
        md.write_text(self.to_markdown())
        js = out / "results.json"
        js.write_text(json.dumps(self.to_dict(), indent=1, default=float))
        return [md, js, *self.plot_trajectories(out)]


# ----------------------------------------------------------------------------- evaluation
def pair_result(pair: EvalPair, method: str, pose: Pose, time_ms: float,
                success: bool) -> PairResult:
    """Scores one estimate of ``pair`` (errors in degrees, NaN on failure)."""
    T = pose.matrix().detach().cpu().double().numpy()
    if success:
        r, t = relative_pose_error(Pose.from_matrix(T), Pose.from_matrix(pair.T_0to1))
        r, t = float(r), float(t)
    else:
        r, t = float("nan"), float("nan")
    return PairResult(pair.pair_id, pair.subset, method, r, t, time_ms, success, T)


def evaluate_pairs(
    model: torch.nn.Module | None,
    pairs: Iterable[EvalPair],
    methods: Sequence[str] | None = None,
    resample: tuple[int, int] | None = (384, 192),
    seed: int = 0,
    threshold_px: float = 1.0,
    device: str | torch.device = "cpu",
    progress: bool = True,
    meta: dict[str, Any] | None = None,
) -> EvalReport:
    """Runs every method on every pair (module docstring).

    Args:
        model: a :class:`~strl_pyg.model.StrLPose` (``None``: classical methods only).
        pairs: :class:`EvalPair` s.
        methods: subset of :data:`METHODS` (default: :func:`available_methods`, without the
            model's methods when ``model`` is ``None``).
        resample: ``(points, lines)`` for the network's graph, or ``None``.
        seed: resampling seed of pair ``i`` is ``seed + i``; also the RANSAC seed.
        threshold_px: inlier threshold of the classical estimators, pixels.

    Returns:
        :class:`EvalReport`.
    """
    if methods is None:
        methods = available_methods()
        if model is None:
            methods = tuple(m for m in methods if m in ("opencv", "poselib"))
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(f"Expected methods from {METHODS} (got {list(methods)})")
    needs_model = any(m == "strl" or m.startswith("fused") for m in methods)
    if needs_model and model is None:
        raise ValueError(f"Expected a model for methods {list(methods)} (got None)")
    if resample is not None and (len(resample) != 2 or min(resample) < 0):
        raise ValueError(f"Expected resample as (points, lines) >= 0 or None (got {resample!r})")
    if model is not None:
        model = model.to(device).eval()
    classical = [m for m in ("opencv", "poselib")
                 if m in methods or f"fused_{m}" in methods]
    results: list[PairResult] = []
    truth: dict[str, tuple[str, np.ndarray, tuple[int, int] | None]] = {}
    for i, pair in enumerate(tqdm(list(pairs), desc="evaluate", disable=not progress)):
        if not isinstance(pair, EvalPair):
            raise TypeError(f"Expected EvalPair items (got {type(pair).__name__})")
        if pair.pair_id in truth:
            raise ValueError(f"Expected unique pair ids (got '{pair.pair_id}' twice)")
        truth[pair.pair_id] = (pair.subset, pair.T_0to1, pair.frames)
        out = None
        if needs_model:
            start = time.perf_counter()
            out = predict_pose(model, pair.matches, resample, seed + i, device)
            net_ms = (time.perf_counter() - start) * 1e3
            out.quaternion, out.translation, out.log_var = (
                x.detach().cpu().double() for x in (out.quaternion, out.translation, out.log_var))
            if "strl" in methods:
                results.append(pair_result(pair, "strl", out.pose[0], net_ms, True))
        est = {}
        for c in classical:
            if pair.matches.num_points < MIN_POINTS:
                from strl_pyg.baselines import BaselineResult

                est[c] = BaselineResult(Pose.identity(), np.zeros(pair.matches.num_points, bool),
                                        0.0, c, False)
            else:
                est[c] = estimate_relative_pose(pair.matches, c, threshold_px, seed=seed)
            if c in methods:
                results.append(pair_result(pair, c, est[c].pose, est[c].time_ms, est[c].success))
            if f"fused_{c}" in methods:
                start = time.perf_counter()
                fused = fuse_poses(out, None, est[c], pair.matches)
                ms = (time.perf_counter() - start) * 1e3 + net_ms + est[c].time_ms
                results.append(pair_result(pair, f"fused_{c}", fused.pose, ms, True))
    order = tuple(m for m in METHODS if m in methods)
    return EvalReport(results, order, truth, dict(meta or {}))


# ----------------------------------------------------------------------------- command line
def build_parser(prog: str | None = None) -> argparse.ArgumentParser:
    """The flags of ``examples/evaluate.py`` and ``strl-pose evaluate``."""
    p = argparse.ArgumentParser(prog=prog, description=(
        "Evaluates a Str-L Pose checkpoint against the classical baselines and the fused pose."),
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    from strl_pyg.checkpoints import default_checkpoint

    p.add_argument("--checkpoint", default=str(default_checkpoint()),
                   help="StrLPose checkpoint (StrLPose.save); default: the shipped weights")
    p.add_argument("--dataset", choices=("synthetic", "demon", "kitti"), default="synthetic")
    p.add_argument("--data-root", help="DeMoN DeepSfM root or KITTI odometry root")
    p.add_argument("--sequences", nargs="+", default=["09", "10"], help="KITTI test sequences")
    p.add_argument("--frame-gap", type=int, default=1, help="KITTI pair (i, i + gap)")
    p.add_argument("--split", default="test", help="DeMoN split folder")
    p.add_argument("--limit", type=int, default=None, help="real data: first N pairs only")
    p.add_argument("--cache-dir", default="outputs/match_cache", help="front-end match cache")
    p.add_argument("--workers", type=int, default=1, help="front-end matching processes")
    p.add_argument("--num-pairs", type=int, default=30, help="synthetic: number of pairs")
    p.add_argument("--seed", type=int, default=2_000_000, help="synthetic: first held-out seed")
    p.add_argument("--kinds", nargs="+", default=list(LINE_SCENE_KINDS), choices=SCENE_KINDS)
    p.add_argument("--matches", choices=("ground_truth", "frontend"), default="ground_truth",
                   help="synthetic: generator matches or front-end matches")
    p.add_argument("--noise-px", type=float, default=0.0, help="synthetic match noise")
    p.add_argument("--outlier-fraction", type=float, default=0.0, help="synthetic outliers")
    p.add_argument("--methods", nargs="+", choices=METHODS, default=None,
                   help="default: all available (PoseLib ones only if importable)")
    p.add_argument("--no-resample", action="store_true",
                   help="feed all matches instead of resampling to 384 points / 192 lines")
    p.add_argument("--resample-seed", type=int, default=0)
    p.add_argument("--threshold-px", type=float, default=1.0, help="classical inlier threshold")
    p.add_argument("--device", default="cpu")
    p.add_argument("--out", default=None, help="output folder (results.md, .json, PNGs)")
    p.add_argument("--no-progress", action="store_true")
    return p


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """Runs an evaluation from command-line flags; returns an exit code."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    ckpt = Path(args.checkpoint)
    if not ckpt.is_file():
        parser.error(f"Expected a checkpoint file at '{ckpt}' (got none)")
    if args.dataset != "synthetic":
        if not args.data_root:
            parser.error(f"Expected --data-root for --dataset {args.dataset} (got none)")
        if not Path(args.data_root).is_dir():
            parser.error(f"Expected a data folder at '{args.data_root}' (got none)")
    if args.methods is not None:
        missing = sorted(set(args.methods) - set(available_methods()))
        if missing:
            parser.error(f"Expected available methods (got {missing}: is PoseLib installed?)")

    from strl_pyg.model import StrLPose

    model = StrLPose.load(ckpt, map_location=args.device)
    progress = not args.no_progress
    try:
        if args.dataset == "synthetic":
            pairs = synthetic_eval_pairs(
                args.num_pairs, args.seed, args.kinds, args.matches,
                scene={"noise_px": args.noise_px, "outlier_fraction": args.outlier_fraction},
                progress=progress)
        elif args.dataset == "demon":
            pairs = demon_eval_pairs(args.data_root, args.cache_dir, split=args.split,
                                     limit=args.limit, num_workers=args.workers,
                                     progress=progress, on_missing="skip")
        else:
            pairs = kitti_eval_pairs(args.data_root, args.cache_dir, args.sequences,
                                     args.frame_gap, limit=args.limit, num_workers=args.workers,
                                     progress=progress, on_missing="skip")
    except (FileNotFoundError, ValueError) as err:
        parser.error(str(err))
    if not pairs:
        parser.error(f"Expected pairs to evaluate in {args.dataset} (got none)")
    meta = {"checkpoint": str(ckpt), "dataset": args.dataset, "pairs": len(pairs),
            "resample": "none" if args.no_resample else f"384/192 seed {args.resample_seed}"}
    if args.dataset == "synthetic":
        meta.update(matches=args.matches, noise_px=args.noise_px,
                    outliers=args.outlier_fraction, seed=args.seed)
    report = evaluate_pairs(
        model, pairs, args.methods, None if args.no_resample else (384, 192),
        seed=args.resample_seed, threshold_px=args.threshold_px, device=args.device,
        progress=progress, meta=meta)
    print(report.to_markdown())
    if args.out:
        for path in report.save(args.out):
            print(f"wrote {path}")
    return 0
