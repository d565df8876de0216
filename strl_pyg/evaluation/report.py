"""The evaluation report: per-pair errors (:class:`PairResult`), their tables per subset and
method (:class:`EvalReport`), KITTI-style trajectories, markdown, JSON and the saved files.

Errors are the rotation angle and the translation-direction angle in degrees (DeMoN's, sign not
folded); the table's statistics (mean / median errors, AUC@5/10/20 of ``max(rotation,
translation)`` with failures counting as infinite) come from
:func:`strl_pyg.metrics.stats.pose_error_stats`, the same function as the training log's.

KITTI (pairs carrying frame indices): per sequence the relative poses are chained into a
trajectory with the ground-truth scale of each pair (the two-view protocol for
unit-translation predictions) and scored with :func:`~strl_pyg.metrics.kitti_odometry_errors`
(t_rel in %, r_rel in deg / 100 m). Where no 100 m segment fits (the shared slice of sequence
06, frames 0-50, covers 59.9 m) ``t_rel``/``r_rel`` are ``NaN`` and the per-pair RMSE of the
rotation (deg) and of the scaled translation (m) is reported instead, with the drift on short
10-50 m segments as a non-standard extra.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.geometry import Pose
from strl_pyg.metrics import integrate_relative_poses, kitti_odometry_errors, kitti_odometry_summary
from strl_pyg.metrics.stats import AUC_THRESHOLDS, pose_error_stats
from strl_pyg.metrics.two_view import relative_pose_error
from strl_pyg.utils.io import atomic_open

__all__ = ["SHORT_SEGMENT_LENGTHS", "PairResult", "pair_result", "EvalReport"]

#: Non-standard short segments (metres) for slices too short for KITTI's 100-800 m.
SHORT_SEGMENT_LENGTHS = (10.0, 20.0, 30.0, 40.0, 50.0)


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
    """:func:`~strl_pyg.metrics.stats.pose_error_stats` of ``rows`` and their median time (ms)."""
    s = pose_error_stats([r.rot_err for r in rows], [r.trans_err for r in rows],
                         [r.success for r in rows], AUC_THRESHOLDS)
    return {**s, "time_ms": float(np.median([r.time_ms for r in rows]))}


def _fmt(v: float, digits: int = 2) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else (
        f"{v:.{digits}f}")


@dataclass
class EvalReport:
    """Per-pair results of :func:`~strl_pyg.evaluation.run.evaluate_pairs` and their tables.

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
        """Writes ``results.md``, ``results.json`` and the trajectory PNGs to ``out_dir``; each
        text file is rendered first and written atomically (never half-written)."""
        out = Path(out_dir)
        texts = {out / "results.md": self.to_markdown(),
                 out / "results.json": json.dumps(self.to_dict(), indent=1, default=float)}
        for path, text in texts.items():
            with atomic_open(path, "w") as f:
                f.write(text)
        return [*texts, *self.plot_trajectories(out)]


def pair_result(pair: Any, method: str, pose: Pose, time_ms: float,
                success: bool) -> PairResult:
    """Scores one estimate of ``pair`` (an :class:`~strl_pyg.evaluation.pairs.EvalPair`; errors in
    degrees, NaN on failure)."""
    T = pose.matrix().detach().cpu().double().numpy()
    if success:
        r, t = relative_pose_error(Pose.from_matrix(T), Pose.from_matrix(pair.T_0to1))
        r, t = float(r), float(t)
    else:
        r, t = float("nan"), float("nan")
    return PairResult(pair.pair_id, pair.subset, method, r, t, time_ms, success, T)
