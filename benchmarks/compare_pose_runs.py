"""Two ``bench_pose.py`` outputs side by side (the same matches, e.g. the shipped weights and a
retrained candidate): per set, for the chosen methods, median rotation / translation errors,
AUC@10 and the 1- and 2-sigma coverage of each.

Usage::

    python benchmarks/compare_pose_runs.py OLD.md NEW.md --labels shipped,candidate \\
        --methods regression,geometric,fused,recommended
"""

from __future__ import annotations

import argparse
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
