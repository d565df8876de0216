"""Training logs: the CSV (and, when installed, TensorBoard) logger, reading the CSV back, and
the curves (validation against the mean-pose predictor, with the training loss beside)."""

from __future__ import annotations

import csv
import math
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["TrainLogger", "read_log", "plot_history"]


class TrainLogger:
    """Appends ``step, split, key, value`` rows to ``<out_dir>/log.csv`` (rank 0 only);
    on resume, rows past the resumed step are dropped. With ``tensorboard``, also writes
    ``<out_dir>/tb`` when TensorBoard is installed, and warns once when it is not;
    :attr:`tensorboard` says whether it is written."""

    def __init__(self, out_dir: Path, enabled: bool, tensorboard: bool, resume_step: int):
        self.enabled = enabled
        self.csv_path = out_dir / "log.csv"
        self.tb = None
        #: Whether TensorBoard events are written (asked for, installed, rank 0).
        self.tensorboard = False
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
            except ImportError as err:
                warnings.warn(f"TensorBoard is not installed ({err}): logging to "
                              f"'{self.csv_path}' only (pip install tensorboard, or pass "
                              "--no-tensorboard to silence this)", UserWarning, stacklevel=3)
            else:
                self.tb = SummaryWriter(str(out_dir / "tb"), purge_step=resume_step or None)
                self.tensorboard = True

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


def read_log(path: str | os.PathLike) -> dict[str, dict[str, tuple[list[int], list[float]]]]:
    """``log.csv`` of :class:`TrainLogger` as ``{split: {key: (steps, values)}}``."""
    out: dict[str, dict[str, tuple[list[int], list[float]]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            steps, values = out.setdefault(row["split"], {}).setdefault(row["key"], ([], []))
            steps.append(int(row["step"]))
            values.append(float(row["value"]))
    return out


def _running_mean(values: list[float]) -> list[float]:
    """Trailing mean over ``max(1, n // 20)`` values (at most 50): the per-step training
    values are single batches and noisy."""
    window = max(1, min(50, len(values) // 20))
    out, total = [], 0.0
    for i, v in enumerate(values):
        total += v
        if i >= window:
            total -= values[i - window]
        out.append(total / min(i + 1, window))
    return out


def _train_pose_loss(train: dict[str, tuple[list[int], list[float]]]):
    """The training rows' pose loss (``loss`` less ``geo_loss`` when the geometric head
    trains): the quantity the validation ``loss`` measures."""
    if "loss" not in train:
        return None
    steps, loss = train["loss"]
    if "geo_loss" in train and train["geo_loss"][0] == steps:
        loss = [a - b for a, b in zip(loss, train["geo_loss"][1], strict=True)]
    return steps, loss


def plot_history(history: list[dict[str, Any]], path: str | os.PathLike,
                 marks: Sequence[tuple[int, str]] = (),
                 log: str | os.PathLike | None = None) -> Path:
    """Validation error curves (model against the trivial mean-pose predictor) as a PNG;
    with ``log`` (a ``log.csv`` of :class:`TrainLogger`), also the running mean of the
    training errors on the same panels and a panel of the pose loss, training beside
    validation. ``marks`` draws labelled vertical lines, e.g. where a run was continued with
    new settings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from strl_pyg.viz.plots import save_figure

    train = read_log(log).get("train", {}) if log is not None and Path(log).is_file() else {}
    pose_loss = _train_pose_loss(train)
    steps = [h["step"] for h in history]
    panels = [("rot_err_deg", "rotation error (deg)"),
              ("trans_err_deg", "translation-direction error (deg)"), ("auc10", "pose AUC@10")]
    if pose_loss is not None:
        panels.append(("loss", "pose loss"))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.4 * len(panels), 3.6))
    for ax, (key, title) in zip(axes, panels, strict=True):
        if key == "loss":
            ax.plot(pose_loss[0], pose_loss[1], color="C2", alpha=0.25, lw=0.6)
            ax.plot(pose_loss[0], _running_mean(pose_loss[1]), color="C2",
                    label="train (running mean)")
            if history and all("loss" in h for h in history):
                ax.plot(steps, [h["loss"] for h in history], "o-", color="C0",
                        label="validation")
        else:
            if key in train:
                ax.plot(train[key][0], _running_mean(train[key][1]), color="C2", alpha=0.8,
                        lw=0.9, label="train (running mean)")
            ax.plot(steps, [h[key] for h in history], "o-", color="C0", label="Str-L Pose")
            trivial = [h.get("trivial_" + key, math.nan) for h in history]
            if any(math.isfinite(v) for v in trivial):  # markers: one validation is a point
                ax.plot(steps, trivial, "s--", ms=4, color="C1", label="mean pose")
        for step, label in marks:
            ax.axvline(step, color="grey", lw=0.8, ls=":")
            ax.text(step, ax.get_ylim()[1], f" {label}", va="top", fontsize=7, color="grey")
        ax.set_xlabel("step")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        if key == "loss" or (history and not math.isnan(history[-1][key])):
            ax.legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)
