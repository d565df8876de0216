"""Training logs: the CSV (and optional TensorBoard) logger and the validation curves."""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["TrainLogger", "plot_history"]


class TrainLogger:
    """Appends ``step, split, key, value`` rows to ``<out_dir>/log.csv`` (rank 0 only);
    on resume, rows past the resumed step are dropped."""

    def __init__(self, out_dir: Path, enabled: bool, tensorboard: bool, resume_step: int):
        self.enabled = enabled
        self.csv_path = out_dir / "log.csv"
        self.tb = None
        if not enabled:
            return
        if resume_step > 0 and self.csv_path.exists():  # drop rows past the resumed step
            with open(self.csv_path) as f:
                rows = [r for r in csv.DictReader(f) if int(r["step"]) <= resume_step]
            with open(self.csv_path, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["step", "split", "key", "value"])
                w.writerows([[r["step"], r["split"], r["key"], r["value"]] for r in rows])
        elif not self.csv_path.exists() or resume_step == 0:
            with open(self.csv_path, "w", newline="") as f:
                csv.writer(f).writerow(["step", "split", "key", "value"])
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.tb = SummaryWriter(str(out_dir / "tb"), purge_step=resume_step or None)
            except ImportError:
                self.tb = None

    def log(self, step: int, split: str, values: dict[str, float]) -> None:
        if not self.enabled:
            return
        with open(self.csv_path, "a", newline="") as f:
            w = csv.writer(f)
            for k, v in values.items():
                w.writerow([step, split, k, f"{float(v):.6g}"])
        if self.tb is not None:
            for k, v in values.items():
                self.tb.add_scalar(f"{split}/{k}", float(v), step)

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()


def plot_history(history: list[dict[str, Any]], path: str | os.PathLike,
                 marks: Sequence[tuple[int, str]] = ()) -> Path:
    """Validation error curves (model against the trivial mean-pose predictor) as a PNG;
    ``marks`` draws labelled vertical lines, e.g. where a run was continued with new settings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from strl_pyg.viz.plots import save_figure

    steps = [h["step"] for h in history]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, key, title in zip(axes, ("rot_err_deg", "trans_err_deg", "auc10"),
                              ("rotation error (deg)", "translation-direction error (deg)",
                               "pose AUC@10"), strict=True):
        ax.plot(steps, [h[key] for h in history], "o-", label="Str-L Pose")
        ax.plot(steps, [h["trivial_" + key] for h in history], "--", label="mean pose")
        for step, label in marks:
            ax.axvline(step, color="grey", lw=0.8, ls=":")
            ax.text(step, ax.get_ylim()[1], f" {label}", va="top", fontsize=7, color="grey")
        ax.set_xlabel("step")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        if not math.isnan(history[-1][key]):
            ax.legend()
    fig.tight_layout()
    return save_figure(fig, path)
