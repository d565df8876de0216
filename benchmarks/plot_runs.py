"""Validation curves of several training runs on one figure (from each run's ``log.csv``):
the regression head's mean rotation and translation-direction errors, and the geometric
head's median ones where the runs have it.

Usage::

    python benchmarks/plot_runs.py RUN_A RUN_B --labels "rot weight 3,rot weight 1" \\
        --title "Phase 3 from phase 2's weights" --out benchmarks/figures/training_phase3.png
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

PANELS = (
    ("rot_err_deg", "regression: mean rotation error"),
    ("trans_err_deg", "regression: mean translation-direction error"),
    ("geo_rot_err_med", "geometric head: median rotation error"),
    ("geo_trans_err_med", "geometric head: median translation-direction error"),
)


def read_validation(run: Path) -> dict[str, list[tuple[int, float]]]:
    """``key -> [(step, value)]`` of a run's validation rows."""
    path = run / "log.csv"
    if not path.is_file():
        raise SystemExit(f"error: expected a training log at '{path}' (got no such file)")
    out: dict[str, list[tuple[int, float]]] = defaultdict(list)
    with open(path) as f:
        for row in csv.DictReader(f):
            if row["split"] == "val":
                out[row["key"]].append((int(row["step"]), float(row["value"])))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--labels", help="comma-separated, one per run (default: folder names)")
    ap.add_argument("--title", default="Validation curves")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    labels = args.labels.split(",") if args.labels else [r.name for r in args.runs]
    if len(labels) != len(args.runs):
        raise SystemExit(f"error: expected one label per run ({len(args.runs)}), got {len(labels)}")
    logs = [read_validation(r) for r in args.runs]
    panels = [p for p in PANELS if any(p[0] in log for log in logs)]

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = 2 if len(panels) > 2 else len(panels)
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 3.6 * rows), squeeze=False)
    flat = axes.ravel()
    for ax in flat[len(panels):]:
        ax.set_visible(False)
    for ax, (key, title) in zip(flat, panels, strict=False):
        for log, label in zip(logs, labels, strict=True):
            if key in log:
                steps, values = zip(*sorted(log[key]), strict=True)
                ax.plot(steps, values, marker="o", ms=3, label=label)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("training step")
        ax.set_ylabel("degrees")
        ax.grid(alpha=0.3)
    flat[0].legend(fontsize=8)
    fig.suptitle(args.title)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
