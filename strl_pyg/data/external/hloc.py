"""hloc's features and matches ``.h5`` files -> :class:`~strl_pyg.data.PairMatches`.

Needs h5py (``pip install h5py``, or the ``hdf5`` extra). Layout written by hloc's
``extract_features`` / ``match_features`` / ``match_dense``:

* features file: one group per image name (a name with ``/`` is a nested group) holding
  ``keypoints [N, 2]`` (pixels, centre of the top-left pixel at ``(0, 0)``), ``image_size``
  ``[2]`` as **(W, H)**, and ``scores``, ``descriptors`` (not read);
* matches file: one group per pair holding ``matches0 [N0]`` (index into the second image's
  keypoints, -1 = none) and ``matching_scores0 [N0]``. The pair's group is named
  ``names_to_pair(name0, name1)`` = ``name0/name1`` with every ``/`` inside a name replaced by
  ``-`` (current hloc), or ``name0_name1`` (hloc before 2022); the pair may be stored in either
  order, and a reversed pair is turned back. The old ``_`` names can collide (``a_b`` + ``c``
  and ``a`` + ``b_c``); the current ones cannot.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.data.external.checks import (
    build_matches,
    filter_scores,
    image_size_from,
    index_per_node,
)
from strl_pyg.data.matches import PairMatches

__all__ = ["load_hloc_matches", "hloc_pair_names"]


def _h5py():
    try:
        import h5py
    except ImportError as err:
        raise ImportError(
            "Expected h5py to read hloc .h5 files (got it not installed): pip install h5py "
            "(or pip install 'strl-pyg[hdf5]')"
        ) from err
    return h5py


def _open(h5py, path: str | os.PathLike, what: str):
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected an hloc {what} file at '{path}' (got no such file)")
    try:
        return h5py.File(path, "r")
    except OSError as err:
        raise ValueError(f"Expected a readable HDF5 {what} file at '{path}' (got {err})") from err


def hloc_pair_names(name0: str, name1: str) -> list[tuple[str, bool]]:
    """Group names under which hloc may store the pair, each with whether it is reversed."""
    a, b = name0.replace("/", "-"), name1.replace("/", "-")
    return [(f"{a}/{b}", False), (f"{b}/{a}", True), (f"{a}_{b}", False), (f"{b}_{a}", True)]


def _group_names(h5py, f) -> list[str]:
    names: list[str] = []
    f.visititems(lambda n, obj: names.append(n) if isinstance(obj, h5py.Dataset) else None)
    return sorted({n.rsplit("/", 1)[0] for n in names if "/" in n})


def load_hloc_matches(
    features: str | os.PathLike,
    matches: str | os.PathLike,
    name0: str,
    name1: str,
    *,
    features1: str | os.PathLike | None = None,
    image_size0: Any = None,
    image_size1: Any = None,
    K0: Any = None,
    K1: Any = None,
    min_score: float | None = None,
) -> PairMatches:
    """Reads the matches of images ``name0`` and ``name1`` (as hloc names them, relative to
    its image folder).

    Args:
        features: hloc features ``.h5`` (of both images, or of image 0 with ``features1``).
        matches: hloc matches ``.h5``.
        image_size0, image_size1: ``(H, W)``; optional when the features hold ``image_size``
            (stored (W, H), converted), and must agree with it when given.
        min_score: Keep matches with ``matching_scores0 >= min_score``.
    """
    h5py = _h5py()
    kps, sizes = [], []
    for path, name in ((features, name0), (features1 or features, name1)):
        with _open(h5py, path, "features") as f:
            grp = f.get(name)
            if not isinstance(grp, h5py.Group) or "keypoints" not in grp:
                known = _group_names(h5py, f)
                raise ValueError(
                    f"Expected image '{name}' with 'keypoints' in hloc features '{path}' "
                    f"(got {len(known)} images, e.g. {known[:3]})")
            kp = np.asarray(grp["keypoints"][()], dtype=np.float64).reshape(-1, 2)
            kps.append(kp)
            sizes.append(grp["image_size"][()] if "image_size" in grp else None)
    with _open(h5py, matches, "matches") as f:
        tried = hloc_pair_names(name0, name1)
        found = [(p, r) for p, r in tried if isinstance(f.get(p), h5py.Group)
                 and "matches0" in f[p]]
        if not found:
            raise ValueError(
                f"Expected the pair ({name0!r}, {name1!r}) in hloc matches '{matches}' under "
                f"one of {[p for p, _ in tried]} (got none; {len(_group_names(h5py, f))} pairs)")
        pair, reverse = found[0]
        m = np.asarray(f[pair]["matches0"][()])
        s = np.asarray(f[pair]["matching_scores0"][()]) if "matching_scores0" in f[pair] else None
    n_a, n_b = (len(kps[1]), len(kps[0])) if reverse else (len(kps[0]), len(kps[1]))
    i_a, i_b = index_per_node(m, n_a, n_b, f"{pair}/matches0")
    scores = None
    if s is not None:
        s = s.astype(np.float64).reshape(-1)
        if len(s) != n_a:
            raise ValueError(f"Expected '{pair}/matching_scores0' of length {n_a} (got {len(s)})")
        scores = s[i_a]
    i0, i1 = (i_b, i_a) if reverse else (i_a, i_b)
    source = f"'{features}'"
    kw = dict(points0=kps[0][i0], points1=kps[1][i1], point_scores=scores, K0=K0, K1=K1,
              info={"source_format": "hloc", "hloc_pair": pair, "hloc_reversed": reverse})
    for i, arg in ((0, image_size0), (1, image_size1)):
        kw[f"image_size{i}"] = image_size_from(arg, sizes[i], "WH", i, False, "hloc", source)
    return filter_scores(build_matches(kw), min_score, None)
