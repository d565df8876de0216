"""Does the recommended pose's status keep its promise on real photographs?

Pairs ``(i, i+g)`` of the real_scenes scenes (``--scenes val``: the 4 validation scenes;
``train``: the 11 training scenes, where rules are fitted), ``g`` in {1, 2, 4, 8, 16}, true
rotation <= 60 deg (the pairs of ``bench_matches.py``), matched once by the default front end
(cached under ``--cache``), each also with perturbed intrinsics: both focal lengths x0.5 or
x2 (``f/2``, ``2f``), ``cx`` / ``cy`` swapped (``swap``) and every point match given twice
(``dup``). On each: PoseLib called directly
on the matches (``estimate_relative_pose(m, "poselib", 1.0)``) and the recommended pose of
``PoseEstimator()`` (its default order, bootstrap and checks). Errors are max(rotation,
translation direction) in degrees; a pose that is not ``ok`` counts as 180.

The report: per variant and gap, AUC@10 of both with the paired interval; right poses refused
(PoseLib within 5 deg, the recommended pose not ``ok``); confident wrong answers (``ok``, off
by more than 10 deg and more than 3 sigma); and per rule (read from the reasons the refusals
give) how many right and wrong poses it refused; the 2-sigma coverage per scene.

    python benchmarks/bench_status.py run --scenes val \\
        --out benchmarks/results_real_scenes/status/val
    python benchmarks/bench_status.py report --out benchmarks/results_real_scenes/status/val
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_matches as bm  # noqa: E402
import bench_pose as bp  # noqa: E402
from strl_bench_common import banner, run_report_parser  # noqa: E402

VARIANTS = ("true", "f/2", "2f", "swap", "dup")
#: pairs per scene and gap (``bench_matches.scene_pairs``): what ``run`` matches and caches,
#: and what :func:`cached_pairs` reads back
PER_GAP = 12
RIGHT_DEG, WRONG_DEG = 5.0, 10.0

#: A refusal's reason -> the rule that gave it (first match wins).
RULES = (("focal lengths do not fit", "focal"), ("resamples found", "bootstrap"),
         ("behind a camera", "cheirality"), ("support band", "support"),
         ("stands in for no solver", "learned support"),
         ("principal point", "intrinsics"), ("looks normalised", "intrinsics"),
         ("focal length (fx=", "intrinsics"), ("different sizes", "intrinsics"),
         ("pure rotation", "configuration"), ("plane", "configuration"),
         ("too few", "too few matches"), ("two motions", "multiple"),
         ("a watermark", "watermark"))


def rule_of(reason: str) -> str:
    for key, rule in RULES:
        if key in reason:
            return rule
    return "other"


def perturbed(m, variant: str):
    if variant == "true":
        return m
    if variant == "dup":  # every point match twice (a matcher run on both orders, say)
        return m.select(point_index=np.tile(np.arange(m.num_points), 2))
    K0, K1 = (np.asarray(K, float).copy() for K in (m.K0, m.K1))
    for K in (K0, K1):
        if variant in ("f/2", "2f"):
            K[0, 0] *= 0.5 if variant == "f/2" else 2.0
            K[1, 1] *= 0.5 if variant == "f/2" else 2.0
        else:
            K[0, 2], K[1, 2] = K[1, 2], K[0, 2]
    return replace(m, K0=K0, K1=K1)


def matches_of(pair, cache: Path):
    from strl_pyg.frontend import FrontendConfig, NoMatchesError, match_images

    pid, a, b, K0, K1, T, g = pair
    try:
        return bp._cached(cache, "status_" + pid.replace("/", "_"), lambda: match_images(
            bm.read_gray(a), bm.read_gray(b), K0=K0, K1=K1,
            config=FrontendConfig(lines=False)), FrontendConfig(lines=False))
    except NoMatchesError:
        return None


def cached_pairs(split: str, cache: Path, per_gap: int = PER_GAP):
    """``(pair, matches)`` of the ``split`` scenes' pairs (``bench_matches.scene_pairs``)
    whose matches this benchmark already matched and cached under ``cache``, deduplicated:
    for studies that reuse them without matching anything."""
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT

    for pair in bm.scene_pairs(REAL_SCENES_SPLIT[split], per_gap=per_gap):
        if not any(cache.rglob("status_" + pair[0].replace("/", "_") + "*")):
            continue
        m = matches_of(pair, cache)
        if m is not None:
            yield pair, m.deduplicated().matches


def measure(est, m, T, pid: str, gap, variant: str) -> dict:
    from strl_pyg.estimation.classical import estimate_relative_pose

    row = {"pair": pid, "scene": pid.split("/")[0], "gap": gap, "variant": variant}
    if m is None:
        return {**row, "poselib": 180.0, "rec": 180.0, "status": "degenerate", "rules": [],
                "refused": None}
    pl = estimate_relative_pose(m, "poselib", 1.0, seed=0)
    row["poselib"] = max(bp.errors(pl.T_0to1.matrix().numpy(), T)) if pl.success else 180.0
    e = est.estimate(m)
    pose = e.pose
    row.update(status=pose.status, method=pose.method, num_inliers=pose.num_inliers)
    row["rec"] = max(bp.errors(pose.T_0to1, T)) if pose.status == "ok" else 180.0
    row["sigma"] = None if pose.sigma is None else [pose.sigma["rotation_deg"],
                                                    pose.sigma["translation_deg"]]
    if pose.status == "ok":
        row["rec_rt"] = list(bp.errors(pose.T_0to1, T))
    reasons = list(pose.info.get("unreliable", [])) if pose.status != "ok" else []
    if pose.status != "ok" and not reasons:
        reasons = list(pose.warnings)
    row["rules"] = sorted({rule_of(r) for r in reasons})
    row["reasons"] = [r[:160] for r in reasons]
    row["configuration"] = e.configuration
    row["focal"] = (pose.info.get("focal") or {}).get("verdict")
    refused = pose.info.get("unreliable_T_0to1")
    row["refused"] = None if refused is None else max(bp.errors(refused, T))
    return row


def run(args) -> int:
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT
    from strl_pyg.inference import PoseEstimator

    scenes = REAL_SCENES_SPLIT[args.scenes]
    pairs = bm.scene_pairs(scenes, per_gap=args.per_gap)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows_path = out / "rows.jsonl"
    done = set()
    if rows_path.is_file():
        done = {(r["pair"], r["variant"]) for r in map(json.loads, rows_path.open())}
    print(banner())
    est = PoseEstimator(**({} if args.focal_range is None else {"focal_range": args.focal_range}))
    with rows_path.open("a") as f:
        for pair in tqdm(pairs, desc=f"pairs ({args.scenes})"):
            todo = [v for v in VARIANTS if (pair[0], v) not in done]
            if not todo:
                continue
            m = matches_of(pair, Path(args.cache))
            for v in todo:
                row = measure(est, None if m is None else perturbed(m, v), pair[5], pair[0],
                              pair[6], v)
                f.write(json.dumps(row) + "\n")
                f.flush()
    return 0


# ----------------------------------------------------------------------------- report
def rules_of(r: dict) -> list[str]:
    """The rules that refused the pair's pose; a pair with no pose at all (``failed``,
    ``degenerate``: every method failed, e.g. its bootstrap found other poses) is "no pose"."""
    if r["status"] in ("failed", "degenerate"):
        return [f"no pose ({r['status']})"]
    if r.get("reasons"):  # named again from the stored reasons (rules added since the run)
        return sorted({rule_of(x) for x in r["reasons"]})
    return r["rules"]


def confident_wrong(r: dict) -> bool:
    if r["status"] != "ok" or r["rec"] <= WRONG_DEG or r.get("sigma") is None:
        return False
    rot, tr = r["rec_rt"]
    return rot > 3 * r["sigma"][0] or tr > 3 * r["sigma"][1]


def covered(r: dict) -> bool:
    rot, tr = r["rec_rt"]
    return rot <= 2 * r["sigma"][0] and tr <= 2 * r["sigma"][1]


def report(args) -> int:
    from strl_pyg.metrics.stats import auc_difference_interval, coverage_interval

    out = Path(args.out)
    rows = [json.loads(x) for x in (out / "rows.jsonl").open()]
    lines = [f"# The recommended pose's status on real photographs ({out.name})", "",
             banner(), "",
             f"Generated by `python benchmarks/bench_status.py report --out {out}`. Right: "
             f"within {RIGHT_DEG:g} deg; confident wrong: `ok`, off by > {WRONG_DEG:g} deg and "
             "> 3 sigma. AUC@10 of max(rotation, translation direction); a pose that is not "
             "`ok` counts as 180 deg; intervals: paired bootstrap over pairs.", "",
             "| variant | gap | pairs | AUC@10 recommended | AUC@10 PoseLib | difference [95 %] "
             "| right refused (of PoseLib right) | confident wrong | ok |",
             "|---|---|---|---|---|---|---|---|---|"]
    for v in VARIANTS:
        rv = [r for r in rows if r["variant"] == v]
        for g in [*bm.GAPS, "all"]:
            rg = [r for r in rv if g == "all" or r["gap"] == g]
            if not rg:
                continue
            rec = np.array([r["rec"] for r in rg])
            pl = np.array([r["poselib"] for r in rg])
            d, lo, hi = auc_difference_interval(rec, pl, 10.0)
            right = [r for r in rg if r["poselib"] <= RIGHT_DEG]
            refused = sum(r["status"] != "ok" for r in right)
            cw = sum(confident_wrong(r) for r in rg)
            ok = sum(r["status"] == "ok" for r in rg)
            lines.append(f"| {v} | {g} | {len(rg)} | {bm.auc(rec, 10):.1f} | "
                         f"{bm.auc(pl, 10):.1f} | {100 * d:+.1f} [{100 * lo:+.1f}, "
                         f"{100 * hi:+.1f}] | {refused} of {len(right)} | {cw} | {ok} |")
    lines += ["", "Per rule: the poses it refused (a refusal may name several rules), judged "
                  "by the refused pose's own error (kept in `info['unreliable_T_0to1']`; where "
                  "there is none, by PoseLib's on the same matches).", "",
              "| rule | variant | refused right (<= 5 deg) | refused wrong (> 5 deg) |",
              "|---|---|---|---|"]
    rules = sorted({x for r in rows for x in rules_of(r)})
    for rule in rules:
        for v in VARIANTS:
            fired = [r for r in rows if r["variant"] == v and rule in rules_of(r)]
            if not fired:
                continue
            err = [r["refused"] if r["refused"] is not None else r["poselib"] for r in fired]
            right = sum(e <= RIGHT_DEG for e in err)
            lines.append(f"| {rule} | {v} | {right} | {len(err) - right} |")
    lines += ["", "2-sigma coverage of the recommended pose's sigma (true intrinsics, `ok` "
                  "poses; both rotation and translation direction within 2 sigma), Wilson "
                  "interval:", "", "| scene | ok poses | coverage [95 %] |", "|---|---|---|"]
    for scene in sorted({r["scene"] for r in rows}):
        ok = [r for r in rows if r["scene"] == scene and r["variant"] == "true"
              and r["status"] == "ok" and r.get("sigma")]
        if ok:
            hits = sum(covered(r) for r in ok)
            c = hits / len(ok)
            lo, hi = coverage_interval(hits, len(ok))
            lines.append(f"| {scene} | {len(ok)} | {100 * c:.0f} % [{100 * lo:.0f}, "
                         f"{100 * hi:.0f}] |")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    plot(rows, out / "auc.png")
    print((out / "report.md").read_text())
    return 0


def plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, len(VARIANTS), figsize=(14, 3.6), sharey=True)
    for a, v in zip(ax, VARIANTS, strict=True):
        gs = [g for g in bm.GAPS if any(r["gap"] == g and r["variant"] == v for r in rows)]
        for key, label in (("rec", "recommended"), ("poselib", "PoseLib called directly")):
            a.plot(gs, [bm.auc([r[key] for r in rows if r["gap"] == g and r["variant"] == v],
                               10) for g in gs], "o-", label=label)
        a.set_xscale("log", base=2)
        a.set_title(f"input: {v}" if v == "dup" else f"intrinsics: {v}")
        a.set_xlabel("frame gap g")
        a.grid(alpha=0.3)
    ax[0].set_ylabel("AUC@10 (%), not ok = 180 deg")
    ax[0].legend(fontsize=8)
    fig.suptitle("Recommended pose vs PoseLib on the same matches, real_scenes")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = run_report_parser(__doc__, "benchmarks/results_real_scenes/status/val")
    ap.add_argument("--scenes", choices=("val", "train"), default="val")
    ap.add_argument("--per-gap", type=int, default=PER_GAP)
    ap.add_argument("--focal-range", type=float, default=None,
                    help="the estimator's focal_range (default: EstimatorConfig's)")
    ap.add_argument("--cache", default="outputs/bench_status_cache")
    args = ap.parse_args(argv)
    return run(args) if args.what == "run" else report(args)


if __name__ == "__main__":
    raise SystemExit(main())
