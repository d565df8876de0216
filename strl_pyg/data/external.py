"""Match files and dicts written by other tools, read into a validated :class:`PairMatches`.

Every layout has one documented reader; ``format="auto"`` picks it from the keys and refuses
input that fits none or several. Image sizes passed as arguments are always ``(H, W)``; sizes
stored in a file are converted from the tool's own order (column "size"). Coordinates are
pixels, centre of the top-left pixel at ``(0, 0)`` (the convention of all tools below).

=============  ==============================================================  ============
format         keys -> meaning                                                 size in file
=============  ==============================================================  ============
``strl``       :meth:`PairMatches.save`: ``points0/1 [M, 2]``, ``lines0/1        ``(H, W)``
               [L, 2, 2]``, ``point_scores``, ``line_scores``, ``K0/1``, images
``matched``    ``mkpts0/1 [M, 2]`` (row i matches row i), ``mconf`` or           ``(H, W)``
               ``mscores [M]``; ``mlines0/1 [L, 2, 2]``, ``mline_scores [L]``
``superglue``  ``match_pairs.py`` output: ``keypoints0 [N0, 2]``, ``keypoints1     none
               [N1, 2]``, ``matches [N0]`` (index into keypoints1, -1 = none),
               ``match_confidence [N0]``; or the model's ``matches0``,
               ``matching_scores0 [N0]``
``lightglue``  ``keypoints0/1`` + ``matches [M, 2]`` (index pairs) with            ``(W, H)``
               ``scores [M]``, and/or ``matches0 [N0]`` (-1 = none) with
               ``matching_scores0 [N0]``; ``image_size0/1`` as the extractor's
               ``image_size``. Use :func:`from_lightglue` on its three dicts.
``gluestick``  ``keypoints0/1``, ``matches0 [N0]``, ``match_scores0 [N0]``;       ``(W, H)``
               ``lines0/1 [L, 2, 2]``, ``line_matches0 [L0]`` (-1 = none),
               ``line_match_scores0 [L0]``, optional ``lines_junc_idx0/1 [L, 2]``
``kornia``     ``LoFTR`` / ``LocalFeatureMatcher``: ``keypoints0/1 [M, 2]``        none
               already matched, ``confidence [M]``, ``batch_indexes [M]``
``hloc``       two ``.h5`` files, read by :func:`load_hloc_matches`: features     ``(W, H)``
               group per image name (``keypoints [N, 2]``, ``image_size``,
               ``scores``), matches group per pair (``matches0 [N0]``, -1 = none,
               ``matching_scores0 [N0]``)
=============  ==============================================================  ============

SuperGlue's ``match_pairs.py`` resizes images first (default ``--resize 640 480``): its
keypoints are in the resized image, so pass that size and a scaled K, or run ``--resize -1``.
A leading batch dimension (PyTorch outputs, LightGlue's lists) is removed only where a key
has one rank more than its layout says: size 1 is dropped, a larger batch needs
``batch_index``. Points outside the image (beyond
:data:`~strl_pyg.data.matches.OUT_OF_IMAGE_TOLERANCE`) raise, with a hint when the size looks
transposed. GlueStick matches lines regardless of endpoint order; :func:`load_external_matches`
orients each matched line by its endpoints' point matches (``line_endpoints="auto"``) and
drops, with a warning, lines whose order cannot be told.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.data.matches import PairMatches, _as_array, _check_size, _load_npz

__all__ = [
    "FORMATS",
    "MatchFormatError",
    "detect_format",
    "load_external_matches",
    "from_lightglue",
]

FORMATS = ("strl", "matched", "superglue", "lightglue", "gluestick", "kornia")

#: Rank of each key read by a layout (one more means a batch dimension).
_RANKS: dict[str, dict[str, int]] = {
    "matched": dict(mkpts0=2, mkpts1=2, mconf=1, mscores=1, mlines0=3, mlines1=3,
                    mline_scores=1, image_size0=1, image_size1=1),
    "superglue": dict(keypoints0=2, keypoints1=2, matches=1, match_confidence=1, matches0=1,
                      matching_scores0=1),
    "lightglue": dict(keypoints0=2, keypoints1=2, matches=2, scores=1, matches0=1,
                      matching_scores0=1, image_size0=1, image_size1=1),
    "gluestick": dict(keypoints0=2, keypoints1=2, matches0=1, match_scores0=1, lines0=3,
                      lines1=3, line_matches0=1, line_match_scores0=1, lines_junc_idx0=2,
                      lines_junc_idx1=2, image_size0=1, image_size1=1),
    "kornia": dict(keypoints0=2, keypoints1=2, confidence=1, batch_indexes=1),
}
for _ranks in _RANKS.values():
    _ranks.update(K0=2, K1=2)
_SIZE_ORDER = {"strl": "HW", "matched": "HW", "lightglue": "WH", "gluestick": "WH"}
_KNOWN = (
    "strl (points0, points1), matched (mkpts0, mkpts1), superglue (keypoints0/1 + matches "
    "[N0] + match_confidence), lightglue (keypoints0/1 + matches [M, 2] or matches0 + "
    "matching_scores0), gluestick (keypoints0/1 + matches0 + match_scores0 and/or lines0/1 + "
    "line_matches0), kornia (keypoints0/1 + confidence + batch_indexes), hloc .h5 "
    "(load_hloc_matches)"
)
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


class MatchFormatError(ValueError):
    """A match file or dict whose layout is unknown, ambiguous or inconsistent."""


def _numpy(value: Any, name: str, batch_index: int | None) -> np.ndarray:
    if isinstance(value, (list, tuple)) and value and all(hasattr(v, "shape") for v in value):
        value = value[_pick(len(value), name, batch_index)]  # a batch as a list (LightGlue)
    return _as_array(value, name, dtype=None)


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


def _unbatch(data: Mapping, ranks: dict[str, int], batch_index: int | None) -> dict:
    out, batched = {}, False
    for key, rank in ranks.items():
        if key not in data or data[key] is None:
            continue
        value = data[key]
        batched |= isinstance(value, (list, tuple)) and bool(value) and hasattr(value[0], "shape")
        arr = _numpy(value, key, batch_index)
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


def detect_format(data: Mapping) -> str:
    """Returns the name in :data:`FORMATS` whose keys ``data`` has; raises
    :class:`MatchFormatError` when none or several fit."""
    keys = set(data)
    found = []
    if {"points0", "points1"} <= keys:
        found.append("strl")
    if {"mkpts0", "mkpts1"} <= keys:
        found.append("matched")
    if {"keypoints0", "keypoints1"} <= keys:
        if keys & {"lines0", "line_matches0", "match_scores0"}:
            found.append("gluestick")
        elif "match_confidence" in keys or (
            "matches" in keys and np.ndim(_numpy(data["matches"], "matches", 0)) == 1
        ):
            found.append("superglue")
        elif keys & {"matches", "matches0", "matching_scores0"}:
            found.append("lightglue")
        elif keys & {"confidence", "batch_indexes"}:
            found.append("kornia")
        else:
            raise MatchFormatError(
                "Expected match indices with keypoints0/keypoints1 (got none): if row i of "
                "keypoints0 matches row i of keypoints1, pass format='kornia'")
    if len(found) != 1:
        what = "several layouts " + ", ".join(found) if found else f"keys {sorted(keys)}"
        raise MatchFormatError(
            f"Expected exactly one known layout, {_KNOWN}, or format= (got {what})")
    return found[0]


def load_external_matches(
    path_or_dict: str | os.PathLike | Mapping[str, Any],
    image_size0: Any = None,
    image_size1: Any = None,
    K0: Any = None,
    K1: Any = None,
    min_score: float | None = None,
    *,
    min_line_score: float | None = None,
    format: str = "auto",
    batch_index: int | None = None,
    line_endpoints: str = "auto",
) -> PairMatches:
    """Reads matches of another tool (``.npz`` or a dict of arrays / tensors); see the table
    in :mod:`strl_pyg.data.external` for the layouts.

    Args:
        path_or_dict: An ``.npz`` file (read without pickle) or a mapping of arrays.
        image_size0, image_size1: ``(H, W)`` of each image; needed when the file holds none,
            and must agree with the file's (converted) size when it does.
        K0, K1: Optional intrinsics ``[3, 3]``.
        min_score, min_line_score: Keep point (line) matches whose score is ``>=`` this; an
            error when the input has no such scores.
        format: ``"auto"`` (refuses ambiguous input) or one of :data:`FORMATS`.
        batch_index: Which pair of a batched input to read (required for batches > 1).
        line_endpoints: GlueStick only: ``"auto"`` orients matched lines by their endpoints'
            point matches and drops lines it cannot orient; ``"as_stored"`` trusts the file.
    """
    source, data = _read_source(path_or_dict)
    fmt = detect_format(data) if format == "auto" else format
    if fmt not in FORMATS:
        raise ValueError(f"Expected format 'auto' or one of {FORMATS} (got {format!r})")
    if line_endpoints not in ("auto", "as_stored"):
        raise ValueError(f"Expected line_endpoints 'auto' or 'as_stored' (got {line_endpoints!r})")
    if fmt == "strl":
        if batch_index is not None:
            raise MatchFormatError(f"Expected no batch_index for strl matches (got {batch_index})")
        d = {k: data[k] for k in ("points0", "points1", "lines0", "lines1", "point_scores",
                                  "line_scores", "image0", "image1", "image_size0",
                                  "image_size1", "K0", "K1") if k in data}
        info = _info(data.get("info_json"))
        kw = dict(points0=d["points0"], points1=d["points1"], lines0=d.get("lines0"),
                  lines1=d.get("lines1"), point_scores=d.get("point_scores"),
                  line_scores=d.get("line_scores"), image0=d.get("image0"),
                  image1=d.get("image1"), info=info)
    else:
        d = _unbatch(data, _RANKS[fmt], batch_index)
        kw = _READERS[fmt](d, batch_index, line_endpoints)
    for i, arg in ((0, image_size0), (1, image_size1)):
        kw[f"image_size{i}"] = _size(arg, d.get(f"image_size{i}"), _SIZE_ORDER.get(fmt), i,
                                     kw.get(f"image{i}") is not None, fmt, source)
    for i, arg in ((0, K0), (1, K1)):
        stored = d.get(f"K{i}")
        if arg is not None and stored is not None and not np.allclose(
                _as_array(arg, f"K{i}"), _as_array(stored, f"K{i}")):
            raise ValueError(f"Expected K{i} to agree with the one in {source} (got another)")
        kw[f"K{i}"] = arg if arg is not None else stored
    if fmt != "strl":
        kw.setdefault("info", {})["source_format"] = fmt
    return _filter(_build(kw), min_score, min_line_score)


def _read_source(path_or_dict) -> tuple[str, Mapping]:
    if isinstance(path_or_dict, Mapping):
        return "the given dict", path_or_dict
    if not isinstance(path_or_dict, (str, os.PathLike)):
        raise TypeError(
            f"Expected a path or a dict of arrays (got {type(path_or_dict).__name__})")
    path = Path(path_or_dict)
    if path.is_file():
        with open(path, "rb") as f:
            if f.read(8) == _HDF5_MAGIC:
                raise MatchFormatError(
                    f"Expected an .npz match file at '{path}' (got an HDF5 file): read hloc "
                    "features/matches .h5 with load_hloc_matches(features, matches, name0, name1)")
    data = _load_npz(path)
    if not data:
        raise MatchFormatError(f"Expected one known layout, {_KNOWN} (got an empty '{path}')")
    return f"'{path}'", data


def _info(value) -> dict:
    if value is None:
        return {}
    try:
        info = json.loads(str(np.asarray(value)))
    except ValueError as err:
        raise ValueError(f"Expected 'info_json' to hold a JSON object (got {err})") from err
    if not isinstance(info, dict):
        raise ValueError(f"Expected 'info_json' to hold a JSON object (got {type(info).__name__})")
    return info


def _size(arg, stored, order, i, has_image, fmt, source) -> tuple[int, int] | None:
    name = f"image_size{i}"
    given = None if arg is None else _check_size(arg, name)
    if stored is None or order is None:
        if given is None and not has_image:
            raise ValueError(f"Expected {name}=(H, W) for {fmt} matches (got none in {source})")
        return given
    a, b = _check_size(stored, f"{name} stored as {order}")
    from_file = (a, b) if order == "HW" else (b, a)
    if given is not None and given != from_file:
        raise ValueError(
            f"Expected {name}={given} (H, W) to agree with the {fmt} input's stored "
            f"({order[0]}, {order[1]}) = ({a}, {b}) (got {from_file} as (H, W))")
    return from_file


def _index_per_node(m0: np.ndarray, n0: int, n1: int, name: str):
    """``m0 [N0]`` (index into image 1, -1 = none) -> (idx0, idx1)."""
    m0 = _indices(m0, name).reshape(-1)
    if len(m0) != n0:
        raise MatchFormatError(f"Expected '{name}' of length {n0} (got {len(m0)})")
    bad = (m0 < -1) | (m0 >= n1)
    if bad.any():
        raise MatchFormatError(
            f"Expected '{name}' values in [-1, {n1}) (got {int(m0[bad][0])})")
    idx0 = np.flatnonzero(m0 >= 0)
    return idx0, m0[idx0]


def _index_pairs(pairs: np.ndarray, n0: int, n1: int, name: str):
    pairs = _indices(pairs, name)
    if pairs.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if pairs.ndim != 2 or pairs.shape[1] != 2:
        raise MatchFormatError(f"Expected '{name}' of shape [M, 2] (got {tuple(pairs.shape)})")
    for col, n in ((0, n0), (1, n1)):
        bad = (pairs[:, col] < 0) | (pairs[:, col] >= n)
        if bad.any():
            raise MatchFormatError(
                f"Expected '{name}[:, {col}]' in [0, {n}) (got {int(pairs[bad][0, col])})")
    return pairs[:, 0], pairs[:, 1]


def _indices(arr: np.ndarray, name: str) -> np.ndarray:
    arr = _as_array(arr, name)
    if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
        raise MatchFormatError(f"Expected integer indices in '{name}' (got non-integers)")
    return arr.astype(np.int64)


def _scores_at(d: dict, key: str, n: int, idx: np.ndarray | None):
    if key not in d:
        return None
    s = _as_array(d[key], key).reshape(-1)
    if len(s) != n:
        raise MatchFormatError(f"Expected '{key}' of length {n} (got {len(s)})")
    return s if idx is None else s[idx]


def _kp(d: dict, i: int) -> np.ndarray:
    kp = _as_array(d[f"keypoints{i}"], f"keypoints{i}")
    if kp.size == 0:
        return np.zeros((0, 2))
    if kp.ndim != 2 or kp.shape[1] != 2:
        raise MatchFormatError(f"Expected 'keypoints{i}' of shape [N, 2] (got {kp.shape})")
    return kp


def _read_matched(d, batch_index, line_endpoints) -> dict:
    scores = d.get("mconf", d.get("mscores"))
    return dict(points0=d["mkpts0"], points1=d["mkpts1"], lines0=d.get("mlines0"),
                lines1=d.get("mlines1"), point_scores=scores, line_scores=d.get("mline_scores"))


def _read_superglue(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = _kp(d, 0), _kp(d, 1)
    key, skey = ("matches", "match_confidence") if "matches" in d else ("matches0",
                                                                        "matching_scores0")
    if key not in d:
        raise MatchFormatError("Expected 'matches' or 'matches0' [N0] in superglue matches")
    i0, i1 = _index_per_node(d[key], len(kp0), len(kp1), key)
    return dict(points0=kp0[i0], points1=kp1[i1],
                point_scores=_scores_at(d, skey, len(kp0), i0))


def _read_lightglue(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = _kp(d, 0), _kp(d, 1)
    per_node = per_pair = None
    if "matches0" in d:
        per_node = _index_per_node(d["matches0"], len(kp0), len(kp1), "matches0")
    if "matches" in d:
        per_pair = _index_pairs(d["matches"], len(kp0), len(kp1), "matches")
    if per_node is None and per_pair is None:
        raise MatchFormatError("Expected 'matches' [M, 2] or 'matches0' [N0] in lightglue matches")
    if per_node is not None and per_pair is not None:
        order = np.argsort(per_pair[0], kind="stable")
        if not (np.array_equal(per_pair[0][order], per_node[0])
                and np.array_equal(per_pair[1][order], per_node[1])):
            raise MatchFormatError("Expected 'matches' and 'matches0' to hold the same matches "
                                   "(got different ones)")
    if per_node is not None:
        i0, i1 = per_node
        scores = _scores_at(d, "matching_scores0", len(kp0), i0)
    else:
        i0, i1 = per_pair
        scores = _scores_at(d, "scores", len(i0), None)
        if scores is None:
            scores = _scores_at(d, "matching_scores0", len(kp0), i0)
    return dict(points0=kp0[i0], points1=kp1[i1], point_scores=scores)


def _read_kornia(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = _kp(d, 0), _kp(d, 1)
    if len(kp0) != len(kp1):
        raise MatchFormatError("Expected keypoints0 and keypoints1 of equal length (matched "
                               f"rows) in kornia matches (got {len(kp0)} and {len(kp1)})")
    rows = slice(None)
    if "batch_indexes" in d:
        b = _indices(d["batch_indexes"], "batch_indexes").reshape(-1)
        if len(b) != len(kp0):
            raise MatchFormatError(f"Expected 'batch_indexes' of length {len(kp0)} (got {len(b)})")
        present = np.unique(b)
        if batch_index is None and len(present) > 1:
            raise MatchFormatError(
                f"Expected matches of one image pair (got batch indexes {present.tolist()}): "
                "pass batch_index=")
        rows = b == (present[0] if batch_index is None else batch_index)
    scores = _scores_at(d, "confidence", len(kp0), None)
    return dict(points0=kp0[rows], points1=kp1[rows],
                point_scores=None if scores is None else scores[rows])


def _read_gluestick(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = _kp(d, 0), _kp(d, 1)
    info: dict = {}
    m0 = np.full(len(kp0), -1, np.int64)
    out = dict(points0=np.zeros((0, 2)), points1=np.zeros((0, 2)), info=info)
    if "matches0" in d:
        i0, i1 = _index_per_node(d["matches0"], len(kp0), len(kp1), "matches0")
        m0[i0] = i1
        out.update(points0=kp0[i0], points1=kp1[i1],
                   point_scores=_scores_at(d, "match_scores0", len(kp0), i0))
    if "line_matches0" not in d:
        return out
    lines = [_lines(d, i) for i in (0, 1)]
    j0, j1 = _index_per_node(d["line_matches0"], len(lines[0]), len(lines[1]), "line_matches0")
    l0, l1 = lines[0][j0], lines[1][j1].copy()
    scores = _scores_at(d, "line_match_scores0", len(lines[0]), j0)
    if line_endpoints == "auto" and len(j0):
        junc = [_junctions(d, i, lines[i], (kp0, kp1)[i]) for i in (0, 1)]
        a, b = junc[0][j0], junc[1][j1]
        hit = lambda p, q: (p >= 0) & (m0[np.maximum(p, 0)] == q) & (q >= 0)  # noqa: E731
        same = hit(a[:, 0], b[:, 0]).astype(int) + hit(a[:, 1], b[:, 1])
        swap = hit(a[:, 0], b[:, 1]).astype(int) + hit(a[:, 1], b[:, 0])
        l1[swap > same] = l1[swap > same][:, ::-1]
        keep = same != swap
        if not keep.all():
            warnings.warn(f"Dropped {int((~keep).sum())} of {len(keep)} GlueStick line matches "
                          "whose endpoint order no point match tells; line_endpoints='as_stored' "
                          "keeps them in the file's order",
                          stacklevel=3)
        info.update(lines_flipped=int((swap > same).sum()), lines_unoriented=int((~keep).sum()))
        l0, l1, j0 = l0[keep], l1[keep], j0[keep]
        scores = None if scores is None else scores[keep]
    out.update(lines0=l0, lines1=l1, line_scores=scores)
    return out


def _lines(d: dict, i: int) -> np.ndarray:
    lines = _as_array(d.get(f"lines{i}", np.zeros((0, 2, 2))), f"lines{i}")
    if lines.size == 0:
        return np.zeros((0, 2, 2))
    if lines.shape[1:] != (2, 2) or lines.ndim != 3:
        raise MatchFormatError(f"Expected 'lines{i}' of shape [L, 2, 2] (got {lines.shape})")
    return lines


def _junctions(d: dict, i: int, lines: np.ndarray, kp: np.ndarray) -> np.ndarray:
    """Index of the keypoint at each line endpoint ``[L, 2]`` (-1 where none)."""
    key = f"lines_junc_idx{i}"
    if key in d:
        idx = _indices(d[key], key).reshape(-1, 2)
        if len(idx) != len(lines) or (len(idx) and (idx.min() < 0 or idx.max() >= len(kp))):
            raise MatchFormatError(f"Expected '{key}' [{len(lines)}, 2] in [0, {len(kp)})")
        return idx
    if len(kp) == 0:
        return np.full((len(lines), 2), -1, np.int64)
    ends = lines.reshape(-1, 2)
    nearest = np.empty(len(ends), np.int64)
    for s in range(0, len(ends), 256):  # chunks keep memory at 256 x N distances
        dist = np.linalg.norm(ends[s:s + 256, None] - kp[None], axis=-1)
        near = dist.argmin(1)
        near[dist[np.arange(len(near)), near] > 0.5] = -1  # endpoint is no keypoint
        nearest[s:s + 256] = near
    return nearest.reshape(-1, 2)


_READERS = {"matched": _read_matched, "superglue": _read_superglue,
            "lightglue": _read_lightglue, "gluestick": _read_gluestick, "kornia": _read_kornia}


def _build(kw: dict) -> PairMatches:
    try:
        return PairMatches(**kw)
    except ValueError as err:
        if "inside the" not in str(err):
            raise
        for i in (0, 1):
            size = kw.get(f"image_size{i}")
            try:
                xy = np.concatenate([_as_array(kw[k], k).reshape(-1, 2)
                                     for k in (f"points{i}", f"lines{i}") if kw.get(k) is not None])
            except (ValueError, TypeError):
                continue
            if size is not None and len(xy) and not _fits(xy, size) and _fits(xy, size[::-1]):
                raise ValueError(f"{err}: they fit a {size[0]}x{size[1]} image; was image_size{i} "
                                 "given as (W, H)? Sizes are (H, W)") from err
        raise


def _fits(xy: np.ndarray, size) -> bool:
    from strl_pyg.data.matches import OUT_OF_IMAGE_TOLERANCE as tol

    h, w = size
    return bool(np.all((xy >= -tol) & (xy <= np.array([w - 1, h - 1]) + tol)))


def _filter(pm: PairMatches, min_score, min_line_score) -> PairMatches:
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


def from_lightglue(feats0: Mapping, feats1: Mapping, matches01: Mapping, **kwargs) -> PairMatches:
    """LightGlue's ``extractor.extract`` outputs and ``matcher(...)`` output (batched or after
    ``rbd``) -> :class:`PairMatches`; image sizes come from ``feats['image_size']`` (W, H).
    ``kwargs`` go to :func:`load_external_matches`."""
    data = {k: v for k, v in matches01.items()
            if k in ("matches", "scores", "matches0", "matching_scores0")}
    for i, feats in ((0, feats0), (1, feats1)):
        data[f"keypoints{i}"] = feats["keypoints"]
        if "image_size" in feats:
            data[f"image_size{i}"] = feats["image_size"]
    return load_external_matches(data, format="lightglue", **kwargs)


