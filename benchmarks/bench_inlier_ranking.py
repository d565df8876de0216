"""What ranks the matches best, and what does a ranking buy PoseLib?

The pairs and matches of ``bench_status.py`` (real_scenes validation scenes, gaps 1-16, the
default front end, the same cache). Per pair, each match is labelled by the stored pose
(Sampson < 2 px: a true inlier) and ranked by:

* ``ratio``: the front end's score (1 - Lowe's ratio);
* ``consensus``: a neighbourhood-consensus score in the spirit of GMS: the share of a match's
  ``k`` nearest matches in image 0 that are also among its ``k`` nearest in image 1
  (``k`` = 12);
* ``net:<weights>``: the geometric head's inlier probability on every match (no resampling).

Besides PROSAC, PoseLib on the best-ranked 50 / 70 / 85 % of the matches only
(``top<percent>:<ranking>``, for the two rankings without a network).

Scored: the median per-pair ROC-AUC of each ranking, and the AUC@10 of max(rotation,
translation direction) of PoseLib called directly (all matches, LO-RANSAC), PoseLib's
PROSAC on the matches ordered by each ranking (``progressive_sampling``), and the ceiling
(PoseLib on the true inliers only), with paired intervals against PoseLib. Turntable scenes
(ethiopian_head): the static background's matches follow a second motion and are labelled
outliers by the object-centred poses; they stay in, as they do for every method.

    python benchmarks/bench_inlier_ranking.py run --models shipped:geometric \\
        --out benchmarks/results_real_scenes/inlier_ranking
    python benchmarks/bench_inlier_ranking.py report \
        --out benchmarks/results_real_scenes/inlier_ranking
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_matches as bm  # noqa: E402
import bench_pose as bp  # noqa: E402
import bench_status as bs  # noqa: E402
from strl_bench_common import banner, run_report_parser  # noqa: E402

K_NEIGHBOURS = 12
#: shares of the best-ranked matches that PoseLib is run on (``top<percent>:<ranking>``)
SUBSETS = (0.5, 0.7, 0.85)


def roc_auc(score: np.ndarray, label: np.ndarray) -> float:
    from strl_pyg.metrics.stats import roc_auc as auc

    return auc(score, label)


def consensus(p0: np.ndarray, p1: np.ndarray, k: int = K_NEIGHBOURS) -> np.ndarray:
    """Share of each match's ``k`` nearest matches in image 0 that are among its ``k``
    nearest in image 1."""
    n = len(p0)
    if n <= 1:
        return np.zeros(n)
    k = min(k, n - 1)

    def knn(p):
        d = ((p[:, None, :] - p[None, :, :]) ** 2).sum(-1)
        np.fill_diagonal(d, np.inf)
        return np.argpartition(d, k - 1, axis=1)[:, :k]

    a, b = knn(p0), knn(p1)
    return np.array([len(np.intersect1d(a[i], b[i], assume_unique=True)) / k
                     for i in range(n)])


def poselib_err(m, T, order=None, subset=None) -> float:
    """PoseLib on the matches (``subset``: those rows only; ``order``: PROSAC on the rows in
    this order), max error in degrees, 180 where it fails."""
    import poselib


    x0, x1, thr = (np.ascontiguousarray(v) if isinstance(v, np.ndarray) else v
                   for v in _normalised(m))
    if subset is not None:
        x0, x1 = x0[subset], x1[subset]
    if order is not None:
        x0, x1 = x0[order], x1[order]
    if len(x0) < 5:
        return 180.0
    cam = {"model": "PINHOLE", "width": 2, "height": 2, "params": [1.0, 1.0, 0.0, 0.0]}
    opt = {"max_epipolar_error": float(thr), "success_prob": 0.9999, "max_iterations": 10000,
           "min_iterations": 100, "seed": 0, "progressive_sampling": order is not None}
    pose, info = poselib.estimate_relative_pose(np.ascontiguousarray(x0),
                                                np.ascontiguousarray(x1), cam, cam, opt, {})
    t = np.asarray(pose.t)
    if np.linalg.norm(t) < 1e-12 or sum(info.get("inliers", [])) < 5:
        return 180.0
    T_est = np.eye(4)
    T_est[:3, :3], T_est[:3, 3] = np.asarray(pose.R), t / np.linalg.norm(t)
    return float(max(bp.errors(T_est, T)))


def _normalised(m):
    from strl_pyg.estimation.classical import _normalised as norm

    return norm(m, 1.0)


def network_scores(model, m) -> np.ndarray:
    import torch

    from strl_pyg.inference.network import network_pose

    out = network_pose(model, m, resample=None)
    w = torch.sigmoid(out.geometric.point_logits.double().cpu()).numpy().reshape(-1)
    if len(w) != m.num_points:
        raise ValueError(f"Expected one weight per point match ({m.num_points}; got {len(w)})")
    return w


def run(args) -> int:
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT

    models = {}
    for spec in filter(None, args.models.split(",")):
        import bench_real_scenes as brs

        models[f"net:{spec}"] = brs.load(spec)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows_path = out / "rows.jsonl"
    done = set()
    if rows_path.is_file():
        done = {(r["pair"], r["what"]) for r in map(json.loads, rows_path.open())}
    pairs = bm.scene_pairs(REAL_SCENES_SPLIT[args.scenes], per_gap=args.per_gap)
    print(banner())
    with rows_path.open("a") as f:
        for pair in tqdm(pairs, desc="pairs"):
            pid, T, gap = pair[0], pair[5], pair[6]
            whats = ["base", "subsets", *models]
            if all((pid, w) in done for w in whats):
                continue
            m = bs.matches_of(pair, Path(args.cache))
            if m is None or m.num_points < 8:
                continue
            label = bm.sampson_px(m.points0, m.points1, m.K0, m.K1, T) < bm.TRUE_PX
            head = {"pair": pid, "scene": pid.split("/")[0], "gap": gap,
                    "n": int(m.num_points), "true": int(label.sum())}
            if (pid, "base") not in done:
                ranks = {"ratio": np.asarray(m.point_scores, float),
                         "consensus": consensus(m.points0, m.points1)}
                row = {**head, "what": "base", "poselib": poselib_err(m, T),
                       "ceiling": poselib_err(m, T, subset=np.flatnonzero(label))}
                for name, s in ranks.items():
                    row[f"roc:{name}"] = roc_auc(s, label)
                    row[f"prosac:{name}"] = poselib_err(m, T, order=np.argsort(-s,
                                                                               kind="stable"))
                f.write(json.dumps(row) + "\n")
            if (pid, "subsets") not in done:  # PoseLib on the best-ranked share only
                row = {**head, "what": "subsets"}
                for name, sc in (("ratio", np.asarray(m.point_scores, float)),
                                 ("consensus", consensus(m.points0, m.points1))):
                    order = np.argsort(-sc, kind="stable")
                    for frac in SUBSETS:
                        keep = order[:max(8, int(round(frac * len(order))))]
                        row[f"top{int(100 * frac)}:{name}"] = poselib_err(m, T, subset=keep)
                f.write(json.dumps(row) + "\n")
            for name, model in models.items():
                if (pid, name) in done:
                    continue
                s = network_scores(model, m)
                f.write(json.dumps({**head, "what": name, f"roc:{name}": roc_auc(s, label),
                                    f"prosac:{name}": poselib_err(
                                        m, T, order=np.argsort(-s, kind="stable"))}) + "\n")
            f.flush()
    return 0


def report(args) -> int:
    from strl_pyg.metrics.stats import auc_difference_interval

    out = Path(args.out)
    rows = [json.loads(x) for x in (out / "rows.jsonl").open()]
    merged: dict[str, dict] = {}
    for r in rows:
        merged.setdefault(r["pair"], {}).update(r)
    pairs = list(merged.values())
    rankers = sorted({k[4:] for r in pairs for k in r if k.startswith("roc:")})
    groups = [(f"gap {g}", [r for r in pairs if r["gap"] == g]) for g in bm.GAPS]
    groups += [("gaps 2-8", [r for r in pairs if r["gap"] in (2, 4, 8)]), ("all", pairs)]
    lines = ["# Ranking matches on real photographs", "", banner(), "",
             f"Generated by `python benchmarks/bench_inlier_ranking.py report --out {out}`. "
             "ROC-AUC: per pair, of the ranking against the true inliers (Sampson < 2 px "
             "under the stored pose); AUC@10 of max(rotation, translation direction); PROSAC: "
             "PoseLib's progressive sampling on the matches ordered by the ranking; "
             "differences against PoseLib called directly, paired bootstrap over pairs.", "",
             "| pairs | ranking | median ROC-AUC |", "|---|---|---|"]
    for label, rs in groups:
        for k in rankers:
            v = [r[f"roc:{k}"] for r in rs if np.isfinite(r.get(f"roc:{k}", np.nan))]
            if v:
                lines.append(f"| {label} ({len(rs)}) | {k} | {np.median(v):.3f} |")
    lines += ["", "| pairs | method | AUC@10 | vs PoseLib [95 %] |", "|---|---|---|---|"]
    for label, rs in groups:
        rs = [r for r in rs if all(f"prosac:{k}" in r for k in rankers)]
        if not rs:
            continue
        base = np.array([r["poselib"] for r in rs])
        lines.append(f"| {label} ({len(rs)}) | PoseLib called directly | "
                     f"{bm.auc(base, 10):.1f} | |")
        tops = sorted({k for r in rs for k in r if k.startswith("top")})
        for key in ["ceiling", *[f"prosac:{k}" for k in rankers], *tops]:
            if not all(key in r for r in rs):
                continue
            e = np.array([r[key] for r in rs])
            d, lo, hi = auc_difference_interval(e, base, 10.0)
            name = "PoseLib on the true inliers (ceiling)" if key == "ceiling" else key
            lines.append(f"| {label} ({len(rs)}) | {name} | {bm.auc(e, 10):.1f} | "
                         f"{100 * d:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] |")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    plot(pairs, rankers, out / "gaps.png")
    print((out / "report.md").read_text())
    return 0


def plot(pairs, rankers, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gs = [g for g in bm.GAPS if any(r["gap"] == g for r in pairs)]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for k in rankers:
        ax[0].plot(gs, [np.nanmedian([r.get(f"roc:{k}", np.nan) for r in pairs
                                      if r["gap"] == g]) for g in gs], "o-", label=k)
    for key, name in [("poselib", "PoseLib called directly"), ("ceiling", "true inliers"),
                      *[(f"prosac:{k}", f"PROSAC by {k}") for k in rankers]]:
        ax[1].plot(gs, [bm.auc([r[key] for r in pairs if r["gap"] == g and key in r], 10)
                        for g in gs], "o-", label=name)
    ax[0].set_ylabel("median per-pair ROC-AUC")
    ax[1].set_ylabel("AUC@10 (%)")
    ax[0].set_title("Ranking the matches, real_scenes validation")
    ax[1].set_title("PoseLib with each ranking")
    for a in ax:
        a.set_xscale("log", base=2)
        a.set_xlabel("frame gap g")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = run_report_parser(__doc__, "benchmarks/results_real_scenes/inlier_ranking")
    ap.add_argument("--models", default="shipped:geometric")
    ap.add_argument("--scenes", choices=("val", "train"), default="val")
    ap.add_argument("--per-gap", type=int, default=12)
    ap.add_argument("--cache", default="outputs/bench_status_cache")
    args = ap.parse_args(argv)
    return run(args) if args.what == "run" else report(args)


if __name__ == "__main__":
    raise SystemExit(main())
