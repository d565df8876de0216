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
import statistics
import sys
from pathlib import Path


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


def paired_ratios(old: dict, new: dict, methods: list[str]) -> list[tuple]:
    """``(set, method, rotation (ratio, low, high), translation (...), n)``: new / old over
    the pairs of a set both runs solved (``status`` ok), matched by the pair's name."""
    import numpy as np

    from strl_pyg.metrics.stats import median_ratio_interval

    rows = []
    for name, records in new.items():
        by_pair = {r["pair"]: r for r in old.get(name, [])}
        for m in methods:
            got = [(r["methods"][m], by_pair[r["pair"]]["methods"][m]) for r in records
                   if r["pair"] in by_pair and m in r["methods"]
                   and m in by_pair[r["pair"]]["methods"]]
            got = [(x, y) for x, y in got if x.get("status") == "ok" == y.get("status")]
            if len(got) < 2:
                continue
            ratios = [median_ratio_interval(np.array([x[k] for x, _ in got]),
                                            np.array([y[k] for _, y in got]))
                      for k in ("rot", "trans")]
            rows.append((name, m, *ratios, len(got)))
    return rows


def pooled_generated(pairs: dict, method: str) -> tuple[int, float, float] | None:
    """``(pairs, mean, median)`` of the method's translation error over every generated set
    (``generated/*``); the pairs it did not solve are left out (their count is ``pairs``'s
    complement)."""
    errors = [r["methods"][method]["trans"] for name, records in pairs.items()
              if name.startswith("generated/") for r in records
              if r["methods"].get(method, {}).get("status") == "ok"]
    if not errors:
        return None
    return len(errors), statistics.fmean(errors), statistics.median(errors)


def _print_paired(old_json: Path, new_json: Path, labels: tuple[str, str],
                  methods: list[str]) -> None:
    try:
        old, new = (json.loads(p.read_text())["pairs"] for p in (old_json, new_json))
    except (OSError, ValueError, KeyError) as err:
        print(f"error: expected two bench_pose.py per-pair files (got {err})", file=sys.stderr)
        return
    la, lb = labels
    print(f"\nPaired median ratios {lb} / {la} (below 1: {lb} better; 95 % bootstrap over the "
          f"pairs both solved):\n")
    print("| set | method | rotation | translation | n |\n|---|---|---|---|---|")
    for name, m, rot, trans, n in paired_ratios(old, new, methods):
        print(f"| {name} | {m} | {rot[0]:.2f} [{rot[1]:.2f}, {rot[2]:.2f}] | "
              f"{trans[0]:.2f} [{trans[1]:.2f}, {trans[2]:.2f}] | {n} |")
    print("\nTranslation error over the generated sets together (deg):\n")
    print(f"| method | {la}: pairs, mean / median | {lb}: pairs, mean / median |\n|---|---|---|")
    for m in methods:
        cells = [pooled_generated(p, m) for p in (old, new)]
        if any(cells):
            print(f"| {m} | " + " | ".join("-" if c is None else f"{c[0]}, {c[1]:.1f} / "
                                           f"{c[2]:.1f}" for c in cells) + " |")


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
    if old_json.is_file() and new_json.is_file():
        _print_paired(old_json, new_json, (la, lb), args.methods.split(","))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
