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
:data:`~strl_pyg.data.checks.OUT_OF_IMAGE_TOLERANCE`) raise, with a hint when the size looks
transposed. GlueStick matches lines regardless of endpoint order; :func:`load_external_matches`
orients each matched line by its endpoints' point matches (``line_endpoints="auto"``) and
drops, with a warning, lines whose order cannot be told.

Modules: this one detects the layout and assembles the result; the per-layout readers are in
:mod:`strl_pyg.data.external.readers`, the shared checks in :mod:`strl_pyg.data.external.checks`
and the hloc ``.h5`` reader in :mod:`strl_pyg.data.external.hloc`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.data.checks import as_array, load_npz
from strl_pyg.data.external.checks import (
    MatchFormatError,
    as_numpy,
    build_matches,
    filter_scores,
    image_size_from,
    unbatch,
)
from strl_pyg.data.external.readers import RANKS, READERS
from strl_pyg.data.matches import PairMatches

__all__ = ["FORMATS", "detect_format", "load_external_matches", "from_lightglue"]

FORMATS = ("strl", "matched", "superglue", "lightglue", "gluestick", "kornia")

_SIZE_ORDER = {"strl": "HW", "matched": "HW", "lightglue": "WH", "gluestick": "WH"}
_KNOWN = (
    "strl (points0, points1), matched (mkpts0, mkpts1), superglue (keypoints0/1 + matches "
    "[N0] + match_confidence), lightglue (keypoints0/1 + matches [M, 2] or matches0 + "
    "matching_scores0), gluestick (keypoints0/1 + matches0 + match_scores0 and/or lines0/1 + "
    "line_matches0), kornia (keypoints0/1 + confidence + batch_indexes), hloc .h5 "
    "(load_hloc_matches)"
)
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


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
            "matches" in keys and np.ndim(as_numpy(data["matches"], "matches", 0)) == 1
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
    image0: Any = None,
    image1: Any = None,
) -> PairMatches:
    """Reads matches of another tool (``.npz`` or a dict of arrays / tensors); see the table
    in :mod:`strl_pyg.data.external.formats` for the layouts.

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
        image0, image1: The images the matches come from (``(H, W)`` or ``(H, W, 3)``), for
            the methods that read pixels (the network's visual branch, ``guided``); they
            give the image sizes too. A file that stores images of its own refuses them.
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
        d = unbatch(data, RANKS[fmt], batch_index)
        kw = READERS[fmt](d, batch_index, line_endpoints)
    for i, img in ((0, image0), (1, image1)):
        if img is None:
            continue
        if kw.get(f"image{i}") is not None:
            raise ValueError(f"Expected image{i} either in {source} or as an argument (got "
                             "both)")
        kw[f"image{i}"] = img
    for i, arg in ((0, image_size0), (1, image_size1)):
        kw[f"image_size{i}"] = image_size_from(
            arg, d.get(f"image_size{i}"), _SIZE_ORDER.get(fmt), i,
            kw.get(f"image{i}") is not None, fmt, source)
    for i, arg in ((0, K0), (1, K1)):
        stored = d.get(f"K{i}")
        if arg is not None and stored is not None and not np.allclose(
                as_array(arg, f"K{i}"), as_array(stored, f"K{i}")):
            raise ValueError(f"Expected K{i} to agree with the one in {source} (got another)")
        kw[f"K{i}"] = arg if arg is not None else stored
    if fmt != "strl":
        kw.setdefault("info", {})["source_format"] = fmt
    return filter_scores(build_matches(kw), min_score, min_line_score)


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
    data = load_npz(path)
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


