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

Besides, ``unrelated`` pairs: a frame of one scene against a frame of another (each its own
K), which must never come back ``ok``.

The report: per variant and gap, AUC@10 of both with the paired interval; right poses refused
(PoseLib within 5 deg, the recommended pose not ``ok``), pooled and in the worst scene;
confident wrong answers (``ok``, off by more than 10 deg and more than 3 sigma: ``sigma`` with
the true K, ``sigma_with_focal`` with perturbed ones); ``ok`` poses with a capped sigma; per
rule (the record's own ``rule`` and ``verdicts``) how many right and wrong poses it refused;
per scene the 2-sigma coverage, the sharpness (median translation sigma of right ``ok``
poses) and the discrimination (ROC-AUC of the sigma separating ``ok`` poses within 10 deg from
those beyond). ethiopian_head is a turntable (two real motions): a pose counts as right there
when it matches either (``TWO_MOTION_SCENES``).

``run --fit`` records every rule's evidence without MULTIPLE refusing (its share threshold at
infinity), for ``benchmarks/studies/fit_rules_loso.py`` to choose the threshold
leave-one-scene-out.

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
#: scenes whose pairs show two real motions (a turntable's room and object): a pose matching
#: either counts as right
TWO_MOTION_SCENES = ("ethiopian_head",)
#: unrelated pairs per scene (its frame against another scene's)
UNRELATED_PER_SCENE = 2
#: pairs per scene and gap (``bench_matches.scene_pairs``): what ``run`` matches and caches,
#: and what :func:`cached_pairs` reads back
PER_GAP = 12
RIGHT_DEG, WRONG_DEG = 5.0, 10.0

def perturbed(m, variant: str):
    if variant == "true":
        return m
    if variant == "dup":  # every point match twice (a matcher run on both orders, say)
        return m.select(point_index=np.tile(np.arange(m.num_points), 2))
    if variant not in VARIANTS:
        raise ValueError(f"Expected a variant among {VARIANTS} (got {variant!r})")
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
        return {**row, "poselib": 180.0, "rec": 180.0, "status": "degenerate",
                "rule": "no_matches", "verdicts": [], "refused": None}
    pl = estimate_relative_pose(m, "poselib", 1.0, seed=0)
    row["poselib"] = max(bp.errors(pl.T_0to1.matrix().numpy(), T)) if pl.success else 180.0
    e = est.estimate(m)
    pose = e.pose
    row.update(status=pose.status.value, method=pose.method, num_inliers=pose.num_inliers,
               rule=pose.rule)
    row["rec"] = max(bp.errors(pose.T_0to1, T)) if pose.status == "ok" else 180.0
    row["sigma"] = None if pose.sigma is None else [pose.sigma["rotation_deg"],
                                                    pose.sigma["translation_deg"]]
    sf = pose.sigma_with_focal
    row["sigma_with_focal"] = None if sf is None else [sf["rotation_deg"],
                                                       sf["translation_deg"]]
    if pose.status == "ok":
        row["rec_rt"] = list(bp.errors(pose.T_0to1, T))
    row["verdicts"] = [{"rule": v.rule, "action": v.action.value, "status": v.status.value,
                        "evidence": _small(v.evidence)} for v in pose.verdicts]
    row["configuration"] = e.configuration
    row["focal"] = (pose.info.get("focal") or {}).get("verdict")
    refused = pose.info.get("unreliable_T_0to1")
    row["refused"] = None if refused is None else max(bp.errors(refused, T))
    second = pose.info.get("second_motion_T_0to1")
    row["second"] = None if second is None else max(bp.errors(second, T))
    return row


def _small(ev: dict) -> dict:
    """A verdict's evidence with its numbers rounded (rows stay small)."""
    out = {}
    for k, v in ev.items():
        if isinstance(v, float):
            out[k] = None if not np.isfinite(v) else round(v, 4)
        elif isinstance(v, (int, bool, str)) or v is None:
            out[k] = v
        elif isinstance(v, dict):
            out[k] = _small(v)
        elif isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) for x in v):
            out[k] = [round(float(x), 4) for x in v]
    return out


def unrelated_pairs(scenes, per_scene: int = UNRELATED_PER_SCENE):
    """``(pair id, path0, path1, K0, K1, None, "unrelated")``: frame ``i`` of each scene
    against a frame of the next scene (cyclically), ``per_scene`` of them, spread over both
    captures."""
    out, found = [], {s: bm.scene_frames(s) for s in scenes}
    found = {s: f for s, f in found.items() if f is not None}
    names = sorted(found)
    for k, a in enumerate(names):
        b = names[(k + 1) % len(names)]
        if a == b:
            continue
        (fa, ia), (fb, ib) = found[a], found[b]
        for j in range(per_scene):
            x, y = ia[(j * len(ia)) // per_scene], ib[(j * len(ib)) // (per_scene + 1)]
            out.append((f"{a}/unrelated-{b}-{j}", fa / x["file"], fb / y["file"],
                        np.array(x["K"], float), np.array(y["K"], float), None, "unrelated"))
    return out


def run(args) -> int:
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT
    from strl_pyg.inference import PoseEstimator

    if args.fit:  # every rule's evidence, MULTIPLE refusing nothing
        from strl_pyg.inference.rules import multiple

        multiple.MULTIPLE_COMPARABLE = float("inf")
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
        for pair in tqdm(pairs + unrelated_pairs(scenes), desc=f"pairs ({args.scenes})"):
            variants = ("unrelated",) if pair[6] == "unrelated" else args.variants
            todo = [v for v in variants if (pair[0], v) not in done]
            if not todo:
                continue
            m = matches_of(pair, Path(args.cache))
            for v in todo:
                if v == "unrelated":
                    row = measure_unrelated(est, m, pair[0])
                else:
                    row = measure(est, None if m is None else perturbed(m, v), pair[5],
                                  pair[0], pair[6], v)
                f.write(json.dumps(row) + "\n")
                f.flush()
    return 0


def measure_unrelated(est, m, pid: str) -> dict:
    row = {"pair": pid, "scene": pid.split("/")[0], "gap": None, "variant": "unrelated"}
    if m is None:
        return {**row, "status": "degenerate", "rule": "no_matches", "num_points": 0}
    pose = est.estimate(m).pose
    return {**row, "status": pose.status.value, "rule": pose.rule,
            "num_points": m.num_points, "num_inliers": pose.num_inliers,
            "sigma": None if pose.sigma is None else [pose.sigma["rotation_deg"],
                                                      pose.sigma["translation_deg"]]}


# ----------------------------------------------------------------------------- report
def rules_of(r: dict) -> list[str]:
    """The rule that refused the pair's pose (the record's own ``rule``); ``[]`` for ``ok``."""
    if r["status"] == "ok":
        return []
    return [r.get("rule") or "unnamed"]


def right_pose(r: dict, err: float | None = None) -> bool:
    """Within :data:`RIGHT_DEG` (of either motion in a two-motion scene)."""
    err = r["rec"] if err is None else err
    if r["scene"] in TWO_MOTION_SCENES and r.get("second") is not None:
        err = min(err, r["second"])
    return err <= RIGHT_DEG


def sigma_for(r: dict) -> list | None:
    """The sigma a row's pose is judged against: ``sigma`` with the true K, the focal-inclusive
    one (where measured) with a perturbed K."""
    if r["variant"] in ("true", "dup") or not r.get("sigma_with_focal"):
        return r.get("sigma")
    return r["sigma_with_focal"]


def confident_wrong(r: dict) -> bool:
    sig = sigma_for(r)
    if r["status"] != "ok" or sig is None:
        return False
    err = r["rec"]
    if r["scene"] in TWO_MOTION_SCENES and r.get("second") is not None:
        err = min(err, r["second"])
    if err <= WRONG_DEG:
        return False
    rot, tr = r["rec_rt"]
    return rot > 3 * sig[0] or tr > 3 * sig[1]


def capped(r: dict) -> bool:
    return r["status"] == "ok" and r.get("sigma") is not None and max(r["sigma"]) >= 179.8


def covered(r: dict) -> bool:
    rot, tr = r["rec_rt"]
    sig = sigma_for(r)
    return rot <= 2 * sig[0] and tr <= 2 * sig[1]


def replay_multiple(rows: list[dict], comparable: float) -> list[dict]:
    """Rows of ``run --fit`` (MULTIPLE refusing nothing) as the shipped rule decides them:
    an ``ok`` pose whose second motion (not repeated structure) has at least ``comparable``
    of its support is refused by ``multiple``; exact, as MULTIPLE runs before every rule that
    could refuse what it leaves (a refused pose meets no later rule)."""
    out = []
    for r in rows:
        share = next((v["evidence"].get("share") for v in r.get("verdicts", [])
                      if v["rule"] == "multiple"
                      and not v["evidence"].get("repeated_structure")), None)
        if r["status"] == "ok" and share is not None and share >= comparable:
            r = {**r, "status": "unreliable", "rule": "multiple", "refused": r["rec"],
                 "rec": 180.0, "sigma": None, "sigma_with_focal": None}
        out.append(r)
    return out


def report(args) -> int:
    from strl_pyg.metrics.stats import auc_difference_interval, coverage_interval, roc_auc

    out = Path(args.out)
    every = [json.loads(x) for x in (out / "rows.jsonl").open()]
    if args.replay_fit:
        from strl_pyg.inference.rules.multiple import MULTIPLE_COMPARABLE

        every = replay_multiple(every, MULTIPLE_COMPARABLE)
    rows = [r for r in every if r["variant"] != "unrelated"]
    unrelated = [r for r in every if r["variant"] == "unrelated"]
    lines = [f"# The recommended pose's status on real photographs ({out.name})", "",
             banner(), "",
             "Generated by `python benchmarks/bench_status.py report "
             f"{'--replay-fit ' if args.replay_fit else ''}--out {out}`. Right: "
             f"within {RIGHT_DEG:g} deg (of either motion on {', '.join(TWO_MOTION_SCENES)}); "
             f"confident wrong: `ok`, off by > {WRONG_DEG:g} deg and > 3 sigma (`sigma` with "
             "the true K, `sigma_with_focal` with a perturbed one). AUC@10 of max(rotation, "
             "translation direction); a pose that is not `ok` counts as 180 deg; intervals: "
             "paired bootstrap over pairs. Right refused: of the pairs where PoseLib called "
             "directly is within 5 deg, those whose recommended pose is not `ok` (worst scene "
             "in brackets).", "",
             "| variant | gap | pairs | AUC@10 recommended | AUC@10 PoseLib | difference [95 %] "
             "| right refused (of PoseLib right) | worst scene | confident wrong | ok, capped "
             "sigma | ok |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
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
            worst = _worst_scene(right)
            cw = sum(confident_wrong(r) for r in rg)
            cap = sum(capped(r) for r in rg)
            ok = sum(r["status"] == "ok" for r in rg)
            pct = f" ({100 * refused / len(right):.1f} %)" if right else ""
            lines.append(f"| {v} | {g} | {len(rg)} | {bm.auc(rec, 10):.1f} | "
                         f"{bm.auc(pl, 10):.1f} | {100 * d:+.1f} [{100 * lo:+.1f}, "
                         f"{100 * hi:+.1f}] | {refused} of {len(right)}{pct} | {worst} | {cw} | "
                         f"{cap} | {ok} |")
    lines += ["", "Per rule: the poses it refused (the record's `rule`), judged by the refused "
                  "pose's own error (kept in `info['unreliable_T_0to1']`; where there is none, "
                  "by PoseLib's on the same matches).", "",
              "| rule | variant | refused right (<= 5 deg) | refused wrong (> 5 deg) |",
              "|---|---|---|---|"]
    for rule in sorted({x for r in rows for x in rules_of(r)}):
        for v in VARIANTS:
            fired = [r for r in rows if r["variant"] == v and rule in rules_of(r)]
            if not fired:
                continue
            err = [r["refused"] if r["refused"] is not None else r["poselib"] for r in fired]
            right = sum(right_pose(r, e) for r, e in zip(fired, err, strict=True))
            lines.append(f"| {rule} | {v} | {right} | {len(err) - right} |")
    lines += ["", "The sigma with the true K, per scene (`ok` poses): 2-sigma coverage (both "
                  "angles within 2 sigma, Wilson interval), sharpness (median translation sigma "
                  "of the right ones) and discrimination (ROC-AUC of max(sigma) separating "
                  f"poses within {WRONG_DEG:g} deg from those beyond; - where a class is "
                  "empty).", "",
              "| scene | ok poses | coverage [95 %] | median translation sigma of right ok "
              "(deg) | ROC-AUC | wrong ok |", "|---|---|---|---|---|---|"]
    true_ok = [r for r in rows if r["variant"] == "true" and r["status"] == "ok"
               and r.get("sigma")]
    for scene in [*sorted({r["scene"] for r in rows}), "all"]:
        ok = [r for r in true_ok if scene == "all" or r["scene"] == scene]
        if not ok:
            continue
        hits = sum(covered(r) for r in ok)
        lo, hi = coverage_interval(hits, len(ok))
        right = [r for r in ok if right_pose(r)]
        sharp = np.median([r["sigma"][1] for r in right]) if right else float("nan")
        wrong = [not right_pose(r, r["rec"]) and r["rec"] > WRONG_DEG for r in ok]
        auc = roc_auc([max(r["sigma"]) for r in ok], wrong) if 0 < sum(wrong) < len(ok) \
            else None
        lines.append(f"| {scene} | {len(ok)} | {100 * hits / len(ok):.0f} % [{100 * lo:.0f}, "
                     f"{100 * hi:.0f}] | {sharp:.1f} | "
                     f"{'-' if auc is None else f'{auc:.3f}'} | {sum(wrong)} |")
    if unrelated:
        ok = [r for r in unrelated if r["status"] == "ok"]
        by = {}
        for r in unrelated:
            by[r["status"]] = by.get(r["status"], 0) + 1
        lines += ["", f"Unrelated pairs (a frame of one scene against another scene's, each "
                      f"its own K): {len(ok)} of {len(unrelated)} `ok`; statuses "
                      f"{dict(sorted(by.items()))}; refused by "
                      f"{dict(sorted(_count(r.get('rule') for r in unrelated).items()))}."]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    plot(rows, out / "auc.png")
    print((out / "report.md").read_text())
    return 0


def _count(items) -> dict:
    out: dict = {}
    for x in items:
        out[str(x)] = out.get(str(x), 0) + 1
    return out


def _worst_scene(right: list[dict]) -> str:
    """The scene with the largest share of right poses refused (``-`` when none is)."""
    worst, share = "-", 0.0
    for scene in sorted({r["scene"] for r in right}):
        rs = [r for r in right if r["scene"] == scene]
        k = sum(r["status"] != "ok" for r in rs)
        if k / len(rs) > share:
            worst, share = f"{scene} {k} of {len(rs)} ({100 * share:.0f} %)", k / len(rs)
            worst = f"{scene} {k} of {len(rs)} ({100 * k / len(rs):.0f} %)"
    return worst


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


def _variants(text: str) -> tuple[str, ...]:
    """``--variants``: comma-separated names of :data:`VARIANTS` (an unknown one would be
    perturbed as a swap: refused in one line instead)."""
    import argparse

    names = tuple(v.strip() for v in text.split(",") if v.strip())
    bad = [v for v in names if v not in VARIANTS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"Expected variants among {','.join(VARIANTS)} (got "
                                         f"{text!r})")
    return names


def main(argv=None) -> int:
    ap = run_report_parser(__doc__, "benchmarks/results_real_scenes/status/val")
    ap.add_argument("--scenes", choices=("val", "train"), default="val")
    ap.add_argument("--per-gap", type=int, default=PER_GAP)
    ap.add_argument("--focal-range", type=float, default=None,
                    help="the estimator's focal_range (default: EstimatorConfig's)")
    ap.add_argument("--cache", default="outputs/bench_status_cache")
    ap.add_argument("--variants", type=_variants, default=VARIANTS,
                    help=f"comma-separated variants to run (default {','.join(VARIANTS)})")
    ap.add_argument("--replay-fit", action="store_true",
                    help="report: rows of run --fit, with MULTIPLE's shipped threshold applied")
    ap.add_argument("--fit", action="store_true",
                    help="record every rule's evidence with MULTIPLE refusing nothing (for "
                         "benchmarks/studies/fit_rules_loso.py)")
    args = ap.parse_args(argv)
    return run(args) if args.what == "run" else report(args)


if __name__ == "__main__":
    raise SystemExit(main())
