"""Trajectory and drift plots written as PNG files.

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas directly, so the
global ``pyplot`` state and backend are never touched (safe in tests, workers and headless
machines). Files are written atomically: a temporary file in the target folder, then a rename.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from strl_pyg.geometry import Pose, as_tensor
from strl_pyg.metrics import KittiSegmentErrors, kitti_odometry_summary
from strl_pyg.utils.io import atomic_open

__all__ = ["save_figure", "plot_trajectory_topview", "plot_segment_errors", "plot_match_importance"]

_AXES = {"x": 0, "y": 1, "z": 2}


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Saves ``fig`` as PNG at ``path`` via a temporary file and ``os.replace``."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"Expected a .png path (got '{path}')")
    FigureCanvasAgg(fig)
    with atomic_open(path) as f:
        fig.savefig(f, format="png", dpi=dpi)
    return path


def _positions(x: Any, name: str) -> np.ndarray:
    if isinstance(x, Pose):
        p = x.t.detach().cpu().double().numpy()
    else:
        a = as_tensor(x, name).detach().cpu().double().numpy()
        if a.ndim == 2 and a.shape[1] == 12:
            a = a.reshape(-1, 3, 4)
        p = a[:, :3, 3] if a.ndim == 3 and a.shape[1:] in ((3, 4), (4, 4)) else a
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(
            f"Expected '{name}' as camera-to-world poses (Pose [N], [N, 4, 4], [N, 3, 4], "
            f"[N, 12]) or positions [N, 3] (got shape {tuple(p.shape)})"
        )
    return p


def plot_trajectory_topview(
    path: str | os.PathLike,
    gt: Any,
    estimates: Mapping[str, Any] | None = None,
    axes: tuple[str, str] = ("x", "z"),
    title: str | None = None,
) -> Path:
    """Top view of camera trajectories: ground truth against any number of estimates.

    Args:
        path: output ``.png`` file.
        gt: **camera-to-world** poses (:class:`~strl_pyg.geometry.Pose` ``[N]``,
            ``[N, 4, 4]``, ``[N, 3, 4]``, KITTI rows ``[N, 12]``) or positions ``[N, 3]``.
        estimates: ``{label: poses or positions}`` in the same frame as ``gt`` (align them
            first, e.g. with :func:`~strl_pyg.metrics.absolute_trajectory_error`).
        axes: the two world axes to draw (default ``("x", "z")``, KITTI's ground plane).
        title: optional figure title.

    Returns:
        the written path.
    """
    if len(axes) != 2 or any(a not in _AXES for a in axes):
        raise ValueError(f"Expected two axes from 'x', 'y', 'z' (got {axes!r})")
    i, j = _AXES[axes[0]], _AXES[axes[1]]
    fig = Figure(figsize=(6, 6))
    ax = fig.add_subplot(1, 1, 1)
    G = _positions(gt, "gt")
    ax.plot(G[:, i], G[:, j], "k-", lw=2, label="ground truth")
    ax.plot(G[:1, i], G[:1, j], "ko", ms=6, label="start")
    for label, est in (estimates or {}).items():
        P = _positions(est, f"estimates[{label!r}]")
        ax.plot(P[:, i], P[:, j], "-", lw=1.5, label=str(label))
    ax.set_xlabel(f"{axes[0]} [m]")
    ax.set_ylabel(f"{axes[1]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return save_figure(fig, path)


def plot_segment_errors(
    path: str | os.PathLike,
    errors: Mapping[str, KittiSegmentErrors | dict],
    title: str | None = None,
) -> Path:
    """KITTI drift against segment length: translation (%) and rotation (deg / 100 m).

    Args:
        path: output ``.png`` file.
        errors: ``{label: KittiSegmentErrors}`` (from
            :func:`~strl_pyg.metrics.kitti_odometry_errors`) or ``{label: summary}`` (the dict of
            :func:`~strl_pyg.metrics.kitti_odometry_summary`), one curve per label.
        title: optional figure title.

    Returns:
        the written path.
    """
    if not errors:
        raise ValueError("Expected at least one set of segment errors to plot (got none)")
    fig = Figure(figsize=(10, 4))
    ax_t, ax_r = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for label, e in errors.items():
        summary = e if isinstance(e, dict) else kitti_odometry_summary(e)
        if "per_length" not in summary:
            raise ValueError(
                f"Expected KittiSegmentErrors or a kitti_odometry_summary dict for {label!r} "
                f"(got keys {sorted(summary)})"
            )
        lengths = sorted(summary["per_length"])
        t = [summary["per_length"][L][0] for L in lengths]
        r = [summary["per_length"][L][1] for L in lengths]
        ax_t.plot(lengths, t, "o-", label=str(label))
        ax_r.plot(lengths, r, "o-", label=str(label))
    ax_t.set_xlabel("segment length [m]")
    ax_t.set_ylabel("translation error [%]")
    ax_r.set_xlabel("segment length [m]")
    ax_r.set_ylabel("rotation error [deg / 100 m]")
    for ax in (ax_t, ax_r):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best")
        ax.set_ylim(bottom=0)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_match_importance(path: str | os.PathLike, matches: Any, points: Any, lines: Any = None,
                          title: str | None = None) -> Path:
    """The two images side by side with each point match (dots) and line segment (lines) of
    ``matches`` coloured by its importance (``points`` ``[Np]``, ``lines`` ``[Nl]``, in
    ``[0, 1]``; e.g. a :class:`~strl_pyg.explain.PoseExplanation`'s), the most important
    drawn on top, a colour bar as the legend; written to ``path`` (PNG)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1)
    lines = np.zeros(0) if lines is None else np.asarray(lines, dtype=np.float64).reshape(-1)
    if not matches.has_images:
        raise ValueError("Expected matches with both images to draw the importance on (got "
                         "none)")
    if len(points) != matches.num_points or len(lines) not in (0, matches.num_lines):
        raise ValueError(f"Expected one importance per point match ({matches.num_points}) and "
                         f"per line ({matches.num_lines}) (got {len(points)} and {len(lines)})")
    fig = Figure(figsize=(12, 5.2))
    axes = fig.subplots(1, 2)
    cmap, order = "viridis", np.argsort(points, kind="stable")
    scatter = None
    for k, ax in enumerate(axes):
        image = matches.image0 if k == 0 else matches.image1
        ax.imshow(image, cmap="gray" if np.ndim(image) == 2 else None)
        xy = (matches.points0 if k == 0 else matches.points1)[order]
        scatter = ax.scatter(xy[:, 0], xy[:, 1], c=points[order], cmap=cmap, vmin=0, vmax=1,
                             s=12, edgecolors="none")
        segs = matches.lines0 if k == 0 else matches.lines1
        for i in np.argsort(lines, kind="stable"):
            ax.plot(segs[i, :, 0], segs[i, :, 1], color=scatter.cmap(float(lines[i])),
                    linewidth=2)
        ax.set_title(f"image {k}: {matches.num_points} points, {len(lines)} lines")
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
    fig.colorbar(scatter, ax=list(axes), label="importance to the network's pose (1 = most)")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)
