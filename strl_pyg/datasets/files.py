"""What the dataset readers share about their on-disk layouts: numeric text files (intrinsics,
pose rows), 3x4 pose rows as ``[N, 4, 4]`` matrices, and parts of a dataset that are absent
(``on_missing``: an error, or a warning and skip).

Warnings here are attributed to the first caller outside :mod:`strl_pyg.datasets` (the
line that built the dataset), however deep the reader that found the problem.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

import numpy as np

__all__ = ["read_number_rows", "rows_to_matrices", "report_missing", "warn_caller"]

_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def read_number_rows(path: str | os.PathLike, cols: int, what: str, file_desc: str) -> np.ndarray:
    """Whitespace-separated numbers of a text file as float64 ``[N, cols]``, ``N >= 1``, all
    finite.

    Args:
        path: The file.
        cols: Numbers per row.
        what: What the rows hold, for errors (e.g. ``"rows of 12 numbers"``).
        file_desc: The file, for the error when it is absent (e.g. ``"a KITTI pose file"``).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected {file_desc} at '{path}' (got no such file)")
    try:
        arr = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as err:
        raise ValueError(f"Expected {what} in '{path}' (got {err})") from err
    if arr.shape[1] != cols or len(arr) == 0:
        raise ValueError(f"Expected {what} in '{path}' (got shape {arr.shape})")
    if not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).all(1))[0]) + 1
        raise ValueError(f"Expected {what} in '{path}' (got a NaN or inf on row {bad})")
    return arr


def rows_to_matrices(rows: np.ndarray) -> np.ndarray:
    """Row-major 3x4 matrices ``[N, 12]`` -> ``[N, 4, 4]`` with the last row ``0 0 0 1``."""
    T = np.tile(np.eye(4), (len(rows), 1, 1))
    T[:, :3, :] = np.asarray(rows, dtype=np.float64).reshape(-1, 3, 4)
    return T


def report_missing(missing: list, message: str, on_missing: str) -> None:
    """Nothing when ``missing`` is empty; else ``FileNotFoundError(message)`` (with how to go
    on without them) for ``on_missing="error"``, or a warning that they are skipped."""
    if not missing:
        return
    if on_missing == "error":
        raise FileNotFoundError(message + "; pass on_missing='skip' to use the others")
    warn_caller(message + ": skipped")


def warn_caller(message: str) -> None:
    """``UserWarning(message)`` attributed to the first frame outside this package folder."""
    level, frame = 1, sys._getframe(0)
    while frame is not None and _in_package(frame.f_code.co_filename):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, UserWarning, stacklevel=level)


def _in_package(filename: str) -> bool:
    return os.path.dirname(os.path.abspath(filename)) == _PACKAGE_DIR
