"""Validation shared by the match-file readers of :mod:`strl_pyg.data.external.formats` and
:mod:`strl_pyg.data.external.hloc`: batch removal, index arrays, scores, image sizes, and
building / score-filtering the resulting :class:`~strl_pyg.data.PairMatches`.

Every check raises :class:`MatchFormatError` (a ``ValueError``) with a one-line
``Expected ... (got ...)`` message naming the key; the layouts themselves are documented in
:mod:`strl_pyg.data.external.formats`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from strl_pyg.data.checks import as_array, check_size
from strl_pyg.data.matches import PairMatches

__all__ = [
    "MatchFormatError",
    "as_numpy",
    "unbatch",
    "index_per_node",
    "index_pairs",
    "as_indices",
    "scores_at",
    "keypoints",
    "image_size_from",
    "build_matches",
    "filter_scores",
]


class MatchFormatError(ValueError):
    """A match file or dict whose layout is unknown, ambiguous or inconsistent."""


def as_numpy(value: Any, name: str, batch_index: int | None) -> np.ndarray:
    """``value`` (array, tensor, or a batch as a list of them, as LightGlue) -> numpy."""
    if isinstance(value, (list, tuple)) and value and all(hasattr(v, "shape") for v in value):
        value = value[_pick(len(value), name, batch_index)]  # a batch as a list (LightGlue)
    return as_array(value, name, dtype=None)


def _pick(batch: int, name: str, batch_index: int | None) -> int:
    if batch_index is None:
        if batch != 1:
            raise MatchFormatError(
                f"Expected one image pair in '{name}' (got a batch of {batch}): "
                "pass batch_index=")
        return 0
    if not 0 <= batch_index < batch:
        raise MatchFormatError(
            f"Expected batch_index in [0, {batch}) for '{name}' (got {batch_index})")
    return batch_index


def unbatch(data: Mapping, ranks: dict[str, int], batch_index: int | None) -> dict:
    """The keys of ``ranks`` present in ``data`` as numpy, with a leading batch dimension
    (one rank more than ``ranks`` says) removed: size 1 dropped, else ``batch_index`` taken."""
    out, batched = {}, False
    for key, rank in ranks.items():
        if key not in data or data[key] is None:
            continue
        value = data[key]
        batched |= isinstance(value, (list, tuple)) and bool(value) and hasattr(value[0], "shape")
        arr = as_numpy(value, key, batch_index)
        if arr.ndim == rank + 1:
            arr, batched = arr[_pick(arr.shape[0], key, batch_index)], True
        elif arr.ndim != rank and arr.size > 0:
            raise MatchFormatError(
                f"Expected '{key}' with {rank} dimensions (got shape {tuple(arr.shape)})")
        out[key] = arr
    if batch_index is not None and not batched and "batch_indexes" not in out:
        raise MatchFormatError(f"Expected a batched input for batch_index={batch_index} "
                               "(got arrays of a single pair)")
    return out


def index_per_node(m0: np.ndarray, n0: int, n1: int, name: str):
    """``m0 [N0]`` (index into image 1, -1 = none) -> (idx0, idx1)."""
    m0 = as_indices(m0, name).reshape(-1)
    if len(m0) != n0:
        raise MatchFormatError(f"Expected '{name}' of length {n0} (got {len(m0)})")
    bad = (m0 < -1) | (m0 >= n1)
    if bad.any():
        raise MatchFormatError(
            f"Expected '{name}' values in [-1, {n1}) (got {int(m0[bad][0])})")
    idx0 = np.flatnonzero(m0 >= 0)
    warn_one_to_many(m0[idx0], 1, name)
    return idx0, m0[idx0]


def index_pairs(pairs: np.ndarray, n0: int, n1: int, name: str):
    """``pairs [M, 2]`` (index into image 0, index into image 1) -> (idx0, idx1)."""
    pairs = as_indices(pairs, name)
    if pairs.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if pairs.ndim != 2 or pairs.shape[1] != 2:
        raise MatchFormatError(f"Expected '{name}' of shape [M, 2] (got {tuple(pairs.shape)})")
    for col, n in ((0, n0), (1, n1)):
        bad = (pairs[:, col] < 0) | (pairs[:, col] >= n)
        if bad.any():
            raise MatchFormatError(
                f"Expected '{name}[:, {col}]' in [0, {n}) (got {int(pairs[bad][0, col])})")
    warn_one_to_many(pairs[:, 0], 0, name)
    warn_one_to_many(pairs[:, 1], 1, name)
    return pairs[:, 0], pairs[:, 1]


def warn_one_to_many(idx: np.ndarray, image: int, name: str) -> None:
    """Warns (``UserWarning``, one line) when matches in ``name`` reuse keypoints of
    ``image``: a matcher's index arrays are one-to-one, so a repeat is usually a bug in how
    they were built (every match pointing at keypoint 0)."""
    if len(idx) == 0:
        return
    uniq = len(np.unique(idx))
    if uniq < len(idx):
        warnings.warn(f"Expected one-to-one matches in '{name}' (got {len(idx)} matches onto "
                      f"{uniq} distinct keypoints of image {image}): each correspondence "
                      "counts once in the estimate", UserWarning, stacklevel=4)


def as_indices(arr: np.ndarray, name: str) -> np.ndarray:
    """Integer-valued ``arr`` (any dtype) -> int64; non-integers raise."""
    arr = as_array(arr, name)
    if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
        raise MatchFormatError(f"Expected integer indices in '{name}' (got non-integers)")
    return arr.astype(np.int64)


def scores_at(d: dict, key: str, n: int, idx: np.ndarray | None):
    """``d[key]`` of length ``n`` at ``idx`` (all with ``None``); ``None`` when absent."""
    if key not in d:
        return None
    s = as_array(d[key], key).reshape(-1)
    if len(s) != n:
        raise MatchFormatError(f"Expected '{key}' of length {n} (got {len(s)})")
    return s if idx is None else s[idx]


def keypoints(d: dict, i: int) -> np.ndarray:
    """``d["keypoints{i}"]`` as ``[N, 2]``."""
    kp = as_array(d[f"keypoints{i}"], f"keypoints{i}")
    if kp.size == 0:
        return np.zeros((0, 2))
    if kp.ndim != 2 or kp.shape[1] != 2:
        raise MatchFormatError(f"Expected 'keypoints{i}' of shape [N, 2] (got {kp.shape})")
    return kp


def image_size_from(arg, stored, order, i, has_image, fmt, source) -> tuple[int, int] | None:
    """``(H, W)`` of image ``i``: the argument ``arg`` (``(H, W)``) and/or the size stored in
    the input in ``order`` (``"HW"`` or ``"WH"``; ``None``: the format stores none), which
    must agree; an error when neither is known and there is no image."""
    name = f"image_size{i}"
    given = None if arg is None else check_size(arg, name)
    if stored is None or order is None:
        if given is None and not has_image:
            raise ValueError(f"Expected {name}=(H, W) for {fmt} matches (got none in {source})")
        return given
    a, b = check_size(stored, f"{name} stored as {order}")
    from_file = (a, b) if order == "HW" else (b, a)
    if given is not None and given != from_file:
        raise ValueError(
            f"Expected {name}={given} (H, W) to agree with the {fmt} input's stored "
            f"({order[0]}, {order[1]}) = ({a}, {b}) (got {from_file} as (H, W))")
    return from_file


def build_matches(kw: dict) -> PairMatches:
    """``PairMatches(**kw)`` (points outside the image get its hint when the size looks
    transposed)."""
    return PairMatches(**kw)


def filter_scores(pm: PairMatches, min_score, min_line_score) -> PairMatches:
    """Keeps the point (line) matches scored ``>= min_score`` (``min_line_score``); an error
    when a threshold is given and the matches have no such scores."""
    keep_p = keep_l = None
    if min_score is not None:
        if pm.point_scores is None:
            raise ValueError(f"Expected point scores to apply min_score={min_score} (got none)")
        keep_p = np.flatnonzero(pm.point_scores >= min_score)
    if min_line_score is not None:
        if pm.line_scores is None:
            raise ValueError(
                f"Expected line scores to apply min_line_score={min_line_score} (got none)")
        keep_l = np.flatnonzero(pm.line_scores >= min_line_score)
    return pm if keep_p is None and keep_l is None else pm.select(keep_p, keep_l)
