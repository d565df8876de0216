"""Two ``bench_pose.py`` outputs side by side (the same matches, e.g. the shipped weights and a
retrained candidate): per set, for the chosen methods, median rotation / translation errors,
AUC@10 and the 1- and 2-sigma coverage of each. Where both runs wrote their per-pair file
(``OUT.json`` beside ``OUT.md``): the paired median ratios new / old per set and method, with
95 % bootstrap intervals over the pairs both solved, and each run's translation error pooled
over the generated sets (mean and median, per method).

Usage::

    python benchmarks/compare_pose_runs.py OLD.md NEW.md --labels shipped,candidate \\
        --methods regression,geometric,fused,recommended
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def read_tables(path: Path) -> dict[tuple[str, str], list[str]]:
    """``(set, method) -> cells`` of a ``bench_pose.py`` markdown file."""
    out, current = {}, None
    for line in path.read_text().splitlines():
        if line.startswith("### "):
            current = line[4:].rsplit(" (", 1)[0].strip()
        elif current and line.startswith("| ") and not line.startswith(("| method", "|---")):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            out[(current, cells[0])] = cells[1:]
    return out


def load_pairs(path: Path) -> dict[str, list[dict]]:
    """The per-pair records of a ``bench_pose.py`` JSON file (``{"pairs": {set: [{"pair":
    name, "methods": {method: {...}}}]}}``), or a one-line ``ValueError``."""
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise ValueError(f"Expected a bench_pose.py per-pair file at '{path}' "
                         f"(got {err})") from None
    pairs = data.get("pairs") if isinstance(data, dict) else None
    if not isinstance(pairs, dict) or not all(
            isinstance(v, list) and all(isinstance(r, dict) and isinstance(r.get("pair"), str)
                                        and isinstance(r.get("methods"), dict) for r in v)
            for v in pairs.values()):
        raise ValueError(f"Expected a bench_pose.py per-pair file at '{path}': an object "
                         f"with 'pairs' {{set: [{{'pair', 'methods'}}, ...]}} (got another "
                         f"layout)")
    return pairs


def _both_solved(old: dict, new: dict, names: list[str], method: str) -> tuple:
    """``(old, new)`` rotation and translation errors ``[n, 2]`` of ``method`` on the pairs
    of the sets ``names`` both runs solved, matched by the pair's name
    (``bench_pose.paired_errors``: a translation without a direction counts as 180 deg)."""
    import bench_pose as bp

    rows = []
    for name in names:
        by_pair = {r["pair"]: r["methods"].get(method) for r in old.get(name, [])}
        rows += [{"methods": {"old": by_pair[r["pair"]], "new": r["methods"].get(method)}}
                 for r in new.get(name, []) if r["pair"] in by_pair]
    return bp.paired_errors(rows, "old", "new")


def paired_ratios(old: dict, new: dict, methods: list[str]) -> list[tuple]:
    """``(set, method, rotation (ratio, low, high), translation (...), n)``: new / old over
    the pairs of a set both runs solved (:func:`_both_solved`); sets in one file only, and
    methods with fewer than 2 such pairs, are left out."""
    from strl_pyg.metrics.stats import median_ratio_interval

    rows = []
    for name in (n for n in new if n in old):
        for m in methods:
            a, b = _both_solved(old, new, [name], m)
            if len(a) < 2:
                continue
            rows.append((name, m, median_ratio_interval(b[:, 0], a[:, 0]),
                         median_ratio_interval(b[:, 1], a[:, 1]), len(a)))
    return rows


def pooled_generated(old: dict, new: dict, method: str) -> tuple | None:
    """``(pairs, (mean, median) of old, (mean, median) of new)`` of the method's translation
    error over every generated set (``generated/*``), on the pairs both runs solved; None
    without such pairs."""
    a, b = _both_solved(old, new, [n for n in new if n.startswith("generated/")], method)
    if not len(a):
        return None
    return len(a), *((float(np.mean(t)), float(np.median(t))) for t in (a[:, 1], b[:, 1]))


def _print_paired(old_json: Path, new_json: Path, labels: tuple[str, str],
                  methods: list[str]) -> None:
    old, new = load_pairs(old_json), load_pairs(new_json)
    la, lb = labels
    print(f"\nPaired median ratios {lb} / {la} (below 1: {lb} better; 95 % bootstrap over the "
          f"pairs both solved):\n")
    print("| set | method | rotation | translation | n |\n|---|---|---|---|---|")
    for name, m, rot, trans, n in paired_ratios(old, new, methods):
        print(f"| {name} | {m} | {rot[0]:.2f} [{rot[1]:.2f}, {rot[2]:.2f}] | "
              f"{trans[0]:.2f} [{trans[1]:.2f}, {trans[2]:.2f}] | {n} |")
    print("\nTranslation error over the generated sets together, on the pairs both solved "
          "(deg):\n")
    print(f"| method | pairs | {la}: mean / median | {lb}: mean / median |\n|---|---|---|---|")
    for m in methods:
        got = pooled_generated(old, new, m)
        if got:
            print(f"| {m} | {got[0]} | {got[1][0]:.1f} / {got[1][1]:.1f} | "
                  f"{got[2][0]:.1f} / {got[2][1]:.1f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--labels", default="old,new")
    ap.add_argument("--methods", default="regression,geometric,fused,recommended")
    args = ap.parse_args(argv)
    a, b = read_tables(args.old), read_tables(args.new)
    la, lb = args.labels.split(",")
    sets = list(dict.fromkeys(s for s, _ in a))
    print(f"| set | method | {la}: rot / trans med (deg) | AUC@10 | 1-sigma | 2-sigma | "
          f"{lb}: rot / trans med (deg) | AUC@10 | 1-sigma | 2-sigma |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in sets:
        for m in args.methods.split(","):
            if (s, m) in a and (s, m) in b:
                x, y = a[(s, m)], b[(s, m)]
                print(f"| {s} | {m} | {x[0]} / {x[1]} | {x[3]} | {x[6]} | {x[7]} | "
                      f"{y[0]} / {y[1]} | {y[3]} | {y[6]} | {y[7]} |")
    old_json, new_json = args.old.with_suffix(".json"), args.new.with_suffix(".json")
    missing = [str(p) for p in (old_json, new_json) if not p.is_file()]
    if len(missing) == 1:
        print(f"\n(no paired ratios: no per-pair file '{missing[0]}' beside its table)")
    elif not missing:
        try:
            _print_paired(old_json, new_json, (la, lb), args.methods.split(","))
        except ValueError as err:
            print(f"error: {err}", file=sys.stderr)
            return 1
        except (KeyError, TypeError) as err:  # a solved record without its errors
            print(f"error: Expected 'rot' and 'trans' numbers in every solved record of "
                  f"'{old_json}' and '{new_json}' (got {type(err).__name__}: {err})",
                  file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
