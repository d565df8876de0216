"""Which rules may refuse a pose, and MULTIPLE's share threshold, leave-one-scene-out.

Reads the rows of ``bench_status.py run --fit`` (every rule's evidence recorded, MULTIPLE
refusing nothing) on the real_scenes training scenes. For each rule that can refuse, and each
scene held out, the rule's form is decided on the other scenes: it may refuse only where, there,
it refuses more wrong poses (> 5 deg) than right ones (<= 5 deg), pooled and in most of the
scenes where it fires; MULTIPLE's threshold (the second motion's support as a share of the
pose's) is, among those on a grid that may refuse, the one that refuses the most wrong poses
net of right ones (a tie: the larger), counting only the poses the other rules leave ``ok``
(what MULTIPLE changes). The held-out scene is then scored with that choice: the right and
wrong poses it refuses there. The shipped choice is the one made on all
training scenes. The validation scenes are not read here (``bench_status.py`` scores them
once, with the shipped rules).

    python benchmarks/bench_status.py run --scenes train --fit \\
        --variants true,f/2,2f,swap --out outputs/status_fit/train
    python benchmarks/studies/fit_rules_loso.py outputs/status_fit/train/rows.jsonl \\
        --out benchmarks/studies/results_rules_loso.md
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench_status import RIGHT_DEG, TWO_MOTION_SCENES  # noqa: E402
from strl_bench_common import banner  # noqa: E402

#: MULTIPLE's candidate thresholds (second motion's inliers / the pose's; from 0.4, the share
#: the second motion needs to be found at all: below it only a still background is one);
#: inf: never refuses
GRID = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.25, 1.5, float("inf"))


def pose_error(r: dict) -> float | None:
    """The error of the pose the rules judged (the ``ok`` pose, or the refused one); ``None``
    where no pose was computed. On a two-motion scene, the nearer of the two motions."""
    err = r["rec"] if r["status"] == "ok" else r.get("refused")
    if err is None:
        return None
    if r["scene"] in TWO_MOTION_SCENES and r.get("second") is not None:
        err = min(err, r["second"])
    return err


def multiple_share(r: dict) -> float | None:
    """The second motion's share of the pose's support, where MULTIPLE found one that is not
    repeated structure (``None`` elsewhere)."""
    for v in r.get("verdicts", []):
        if v["rule"] == "multiple" and not v["evidence"].get("repeated_structure"):
            return v["evidence"].get("share")
    return None


def refusals(rows: list[dict], rule: str, c: float | None = None) -> dict:
    """Per scene ``[right, wrong]`` refused by ``rule`` (MULTIPLE at threshold ``c``)."""
    out: dict = {}
    for r in rows:
        err = pose_error(r)
        if err is None:
            continue
        if rule == "multiple":  # what it changes: poses the other rules leave ok
            share = multiple_share(r)
            fired = share is not None and share >= c and r["status"] == "ok"
        else:
            fired = r["status"] != "ok" and r.get("rule") == rule
        if fired:
            out.setdefault(r["scene"], [0, 0])[0 if err <= RIGHT_DEG else 1] += 1
    return out


def may_refuse(per_scene: dict) -> bool:
    """More wrong than right pooled, and in most of the scenes where it fires."""
    if not per_scene:
        return False
    right = sum(v[0] for v in per_scene.values())
    wrong = sum(v[1] for v in per_scene.values())
    most = sum(v[1] > v[0] for v in per_scene.values()) > len(per_scene) / 2
    return wrong > right and most


def choose_threshold(rows: list[dict]) -> float:
    """Among the thresholds at which MULTIPLE may refuse (:func:`may_refuse`), the one whose
    refusals gain most: wrong poses refused minus right ones; a tie goes to the larger
    threshold (fewer refusals). ``inf`` where none may refuse."""
    best, gain = float("inf"), 0
    for c in GRID:
        per = refusals(rows, "multiple", c)
        if not may_refuse(per):
            continue
        g = sum(v[1] - v[0] for v in per.values())
        if g > gain or (g == gain and c > best):
            best, gain = c, g
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rows", help="rows.jsonl of bench_status.py run --fit")
    ap.add_argument("--out", default="benchmarks/studies/results_rules_loso.md")
    args = ap.parse_args(argv)
    rows = [json.loads(x) for x in Path(args.rows).open()]
    rows = [r for r in rows if r["variant"] != "unrelated"]
    scenes = sorted({r["scene"] for r in rows})
    refusing = sorted({r["rule"] for r in rows if r["status"] == "unreliable" and r.get("rule")})
    lines = ["# Which rules may refuse, leave-one-scene-out (real_scenes training scenes)", "",
             banner(), "",
             f"Generated by `python benchmarks/studies/fit_rules_loso.py {args.rows}` from "
             f"{len(rows)} rows (variants {sorted({r['variant'] for r in rows})}) of "
             f"{len(scenes)} training scenes. Right: within {RIGHT_DEG:g} deg (of either motion "
             f"on {', '.join(TWO_MOTION_SCENES)}). A rule may refuse where, on the other "
             "scenes, it refuses more wrong poses than right ones, pooled and in most scenes "
             "where it fires; each row scores the held-out scene with the choice made without "
             "it.", ""]
    # MULTIPLE: its threshold
    lines += ["## MULTIPLE's share threshold", "",
              "| held-out scene | threshold chosen on the others | refused there: right | "
              "wrong |", "|---|---|---|---|"]
    tot = np.zeros(2, int)
    for s in scenes:
        c = choose_threshold([r for r in rows if r["scene"] != s])
        got = refusals([r for r in rows if r["scene"] == s], "multiple", c).get(s, [0, 0])
        tot += got
        lines.append(f"| {s} | {c:g} | {got[0]} | {got[1]} |")
    c_all = choose_threshold(rows)
    lines += [f"| **pooled** | | **{tot[0]}** | **{tot[1]}** |", "",
              f"Chosen on all training scenes: **{c_all:g}**.", "",
              "Refusals per threshold on all training scenes (right / wrong, pooled; scenes "
              "where it refuses more wrong than right, of those where it fires):", "",
              "| threshold | right | wrong | scenes |", "|---|---|---|---|"]
    for c in GRID:
        per = refusals(rows, "multiple", c)
        right = sum(v[0] for v in per.values())
        wrong = sum(v[1] for v in per.values())
        good = sum(v[1] > v[0] for v in per.values())
        lines.append(f"| {c:g} | {right} | {wrong} | {good} of {len(per)} |")
    # the other refusing rules: refuse or not
    lines += ["", "## The other rules that refuse (as they stand)", "",
              "| rule | held-out scenes where the others say it may refuse | refused on "
              "held-out scenes: right | wrong | all scenes: may refuse |", "|---|---|---|---|---|"]
    for rule in [x for x in refusing if x != "multiple"]:
        yes, tot = 0, np.zeros(2, int)
        for s in scenes:
            if may_refuse({k: v for k, v in refusals(rows, rule).items() if k != s}):
                yes += 1
                tot += refusals([r for r in rows if r["scene"] == s], rule).get(s, [0, 0])
        allv = may_refuse(refusals(rows, rule))
        lines.append(f"| {rule} | {yes} of {len(scenes)} | {tot[0]} | {tot[1]} | "
                     f"{'yes' if allv else 'no'} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
