"""Middlebury multi-view stereo data sets (Seitz et al., CVPR 2006), e.g. "dino" and "temple".

Layout: ``<name>_par.txt`` (first line: the number of views; then one line per view:
``imgname.png k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 ... r33 t1 t2 t3``, with the projection
``x = K [R t] X``, i.e. ``[R t]`` is **world-to-camera**) beside the PNG images. Slices of a
data set may hold only some of the listed images: pairs are formed from the images that exist.

Relative pose of views ``a`` (image 0) and ``b`` (image 1): ``T_0to1 = [R_b t_b] [R_a t_a]^-1``,
so ``X_b = R X_a + t`` with ``R = R_b R_a^T`` and ``t = t_b - R t_a``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["MiddleburyView", "read_middlebury_parameters", "middlebury_pairs"]


@dataclass(frozen=True)
class MiddleburyView:
    """One calibrated view: image path, intrinsics ``K`` [3, 3] and world-to-camera ``R``
    [3, 3], ``t`` [3]."""

    name: str
    path: Path
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray


def read_middlebury_parameters(path: str | os.PathLike) -> dict[str, MiddleburyView]:
    """Parses a ``*_par.txt`` file; returns ``name -> MiddleburyView`` for every listed view
    (whether its image exists or not). Malformed lines raise ``ValueError`` naming the line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected a Middlebury parameter file at '{path}' (got none)")
    lines = [ln.split() for ln in path.read_text().splitlines() if ln.strip()]
    if not lines:
        raise ValueError(f"Expected a view count and one line per view in '{path}' (got empty)")
    start = 1 if len(lines[0]) == 1 else 0
    views = {}
    for i, parts in enumerate(lines[start:], start=start + 1):
        if len(parts) != 22:
            raise ValueError(f"Expected 'name k11..k33 r11..r33 t1..t3' (22 fields) on line {i} "
                             f"of '{path}' (got {len(parts)} fields)")
        try:
            v = np.array([float(x) for x in parts[1:]], dtype=np.float64)
        except ValueError as err:
            raise ValueError(f"Expected numbers on line {i} of '{path}' (got {err})") from err
        K, R, t = v[:9].reshape(3, 3), v[9:18].reshape(3, 3), v[18:]
        if abs(np.linalg.det(R) - 1.0) > 1e-3 or np.abs(R @ R.T - np.eye(3)).max() > 1e-3:
            raise ValueError(f"Expected a rotation matrix on line {i} of '{path}' "
                             f"(got det {np.linalg.det(R):.4f})")
        views[parts[0]] = MiddleburyView(parts[0], path.parent / parts[0], K, R, t)
    return views


def middlebury_pairs(root: str | os.PathLike, gap: int = 1,
                     parameters: str | None = None) -> list[tuple[MiddleburyView, MiddleburyView,
                                                                  np.ndarray]]:
    """Pairs ``(view_a, view_b, T_0to1 [4, 4])`` of consecutive existing images (sorted by
    name), ``gap`` apart in that order.

    Args:
        root: folder with ``*_par.txt`` and the PNG images.
        gap: step between the two views of a pair (default 1: every consecutive pair).
        parameters: the parameter file's name (default: the only ``*_par.txt`` in ``root``).
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"Expected a Middlebury data folder at '{root}' (got none)")
    if parameters is None:
        found = sorted(root.glob("*_par.txt"))
        if len(found) != 1:
            raise ValueError(f"Expected one '*_par.txt' in '{root}' (got {len(found)})")
        par = found[0]
    else:
        par = root / parameters
    if not isinstance(gap, int) or gap < 1:
        raise ValueError(f"Expected a positive integer gap (got {gap!r})")
    views = read_middlebury_parameters(par)
    present = [v for name, v in sorted(views.items()) if v.path.is_file()]
    pairs = []
    for a, b in zip(present[:-gap], present[gap:], strict=True):
        R = b.R @ a.R.T
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, b.t - R @ a.t
        pairs.append((a, b, T))
    return pairs
