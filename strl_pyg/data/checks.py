"""The checks every match set passes (:class:`~strl_pyg.data.PairMatches` and the readers of
other tools' files): arrays, image sizes, intrinsics, images, coordinates inside the image, and
the safe ``.npz`` reading and atomic writing of match files. Each refusal is one line naming
what was expected and what was given."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.utils.images import check_image
from strl_pyg.utils.io import atomic_open

__all__ = ["OUT_OF_IMAGE_TOLERANCE", "MIN_LINE_LENGTH", "as_array", "check_finite", "check_size",
           "check_K", "check_optional_image", "outside_image", "check_in_image", "load_npz",
           "atomic_save_npz"]


#: A coordinate may lie this many pixels outside ``[0, W - 1] x [0, H - 1]`` (detectors and
#: projections of generated scenes place points on the border, sub-pixel refinement nudges
#: them past it); anything further is treated as a bug in the caller's match list.
OUT_OF_IMAGE_TOLERANCE = 4.0


#: Line segments shorter than this (pixels, in either image) have no direction and are
#: rejected.
MIN_LINE_LENGTH = 1e-3


def as_array(value: Any, name: str, dtype=np.float64) -> np.ndarray:
    if hasattr(value, "detach"):  # torch tensor
        value = value.detach().cpu().numpy()
    try:
        arr = np.asarray(value)
    except Exception as err:  # pragma: no cover - numpy accepts nearly everything
        raise TypeError(f"Expected an array for '{name}' (got {type(value).__name__})") from err
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise TypeError(f"Expected a numeric array for '{name}' (got dtype {arr.dtype})")
    return arr.astype(dtype, copy=False) if dtype is not None else arr


def check_finite(arr: np.ndarray, name: str) -> None:
    if not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr)).reshape(len(arr), -1).any(1).sum()) if arr.ndim else 1
        raise ValueError(f"Expected finite values in '{name}' (got NaN or inf in {bad} rows)")


def check_size(value: Any, name: str) -> tuple[int, int]:
    arr = as_array(value, name, dtype=None).reshape(-1)
    if (
        arr.shape != (2,)
        or not np.all(np.isfinite(arr))
        or np.any(arr <= 0)
        or np.any(arr != np.round(arr))
    ):
        raise ValueError(f"Expected '{name}' as two positive integers (H, W) (got {value!r})")
    return int(arr[0]), int(arr[1])


def check_K(value: Any, name: str) -> np.ndarray | None:
    if value is None:
        return None
    K = as_array(value, name)
    if K.shape != (3, 3):
        hint = (": four numbers (fx, fy, cx, cy) make K = [[fx, 0, cx], [0, fy, cy], "
                "[0, 0, 1]]" if K.shape == (4,) else "")
        raise ValueError(f"Expected '{name}' of shape (3, 3) (got {tuple(K.shape)}){hint}")
    check_finite(K, name)
    if not np.allclose(K[2], [0.0, 0.0, 1.0], atol=1e-6):
        raise ValueError(f"Expected the last row of '{name}' to be [0, 0, 1] (got {K[2].tolist()})")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(
            f"Expected positive focal lengths in '{name}' (got fx={K[0, 0]}, fy={K[1, 1]})"
        )
    if abs(np.linalg.det(K)) < 1e-12 or np.linalg.cond(K) > 1e12:
        raise ValueError(f"Expected an invertible '{name}' (got det={np.linalg.det(K):.3g})")
    return K


def check_optional_image(value: Any, name: str) -> np.ndarray | None:
    """``None``, or the image checked by the package's one image check
    (:func:`strl_pyg.utils.images.check_image`, kept as given)."""
    return None if value is None else check_image(value, name)


def outside_image(xy: np.ndarray, h: int, w: int, tol: float) -> np.ndarray:
    """Per ``(x, y)`` row, whether it lies outside an ``h x w`` image (+- ``tol`` px)."""
    return ((xy[:, 0] < -tol) | (xy[:, 0] > w - 1 + tol)
            | (xy[:, 1] < -tol) | (xy[:, 1] > h - 1 + tol))


def check_in_image(coords: np.ndarray, size: tuple[int, int], name: str) -> None:
    if coords.size == 0:
        return
    h, w = size
    xy = coords.reshape(-1, 2)
    tol = OUT_OF_IMAGE_TOLERANCE
    out = outside_image(xy, h, w, tol)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        hint = (f"; they fit a {w}x{h} image: was image_size{name[-1]} given as (W, H)? "
                "Sizes are (H, W)" if not outside_image(xy, w, h, tol).any() else "")
        raise ValueError(
            f"Expected '{name}' inside the {h}x{w} px image (H x W, +-{tol} px) "
            f"(got {int(out.sum())} coordinates outside, first {xy[i].tolist()}){hint}"
        )


def atomic_save_npz(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Writes ``arrays`` to ``path`` via a temporary file in the same folder and a rename, so
    readers never see a half-written file."""
    with atomic_open(path) as f:
        np.savez(f, **arrays)  # type: ignore[arg-type]  # numpy's stub types **kwds as bool


def load_npz(path: str | os.PathLike) -> dict[str, np.ndarray]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected a match file at '{path}' (got no such file)")
    with open(path, "rb") as f:
        head = f.read(6)
    if not head.startswith(b"PK"):  # an .npz is a zip archive; numpy reads anything else
        # as a pickle and would say so
        what = "an empty file" if not head else (
            "a single .npy array" if head.startswith(b"\x93NUMPY") else
            f"a file that is not an .npz archive: it starts with {head!r}")
        raise ValueError(f"Expected a readable .npz match file at '{path}' (got {what})")
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except Exception as err:
        why = str(err).splitlines()[0] if str(err) else type(err).__name__
        if "allow_pickle" in why:  # numpy's wording would suggest unsafe loading
            why = "an object array; pickled data is never read"
        raise ValueError(f"Expected a readable .npz match file at '{path}' (got {why})") from err
