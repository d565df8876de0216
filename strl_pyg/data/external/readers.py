"""One reader per match layout of :mod:`strl_pyg.data.external.formats` (whose docstring has
the table
of layouts): each takes the un-batched arrays of one pair and returns the keyword arguments of
a :class:`~strl_pyg.data.PairMatches` (points, lines, scores, info; sizes and intrinsics are
added by :func:`~strl_pyg.data.external.formats.load_external_matches`).

Readers: ``matched`` (row i matches row i), ``superglue`` and ``lightglue`` (index arrays into
keypoints), ``kornia`` (matched rows with batch indexes) and ``gluestick`` (points and lines;
matched lines are oriented by their endpoints' point matches).
"""

from __future__ import annotations

import warnings

import numpy as np

from strl_pyg.data.checks import as_array
from strl_pyg.data.external.checks import (
    MatchFormatError,
    as_indices,
    index_pairs,
    index_per_node,
    keypoints,
    scores_at,
)

__all__ = ["RANKS", "READERS"]

#: Rank of each key read by a layout (one more means a batch dimension).
RANKS: dict[str, dict[str, int]] = {
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
for _ranks in RANKS.values():
    _ranks.update(K0=2, K1=2)


def _read_matched(d, batch_index, line_endpoints) -> dict:
    scores = d.get("mconf", d.get("mscores"))
    return dict(points0=d["mkpts0"], points1=d["mkpts1"], lines0=d.get("mlines0"),
                lines1=d.get("mlines1"), point_scores=scores, line_scores=d.get("mline_scores"))


def _read_superglue(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = keypoints(d, 0), keypoints(d, 1)
    key, skey = ("matches", "match_confidence") if "matches" in d else ("matches0",
                                                                        "matching_scores0")
    if key not in d:
        raise MatchFormatError("Expected 'matches' or 'matches0' [N0] in superglue matches")
    i0, i1 = index_per_node(d[key], len(kp0), len(kp1), key)
    return dict(points0=kp0[i0], points1=kp1[i1],
                point_scores=scores_at(d, skey, len(kp0), i0))


def _read_lightglue(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = keypoints(d, 0), keypoints(d, 1)
    per_node = per_pair = None
    if "matches0" in d:
        per_node = index_per_node(d["matches0"], len(kp0), len(kp1), "matches0")
    if "matches" in d:
        per_pair = index_pairs(d["matches"], len(kp0), len(kp1), "matches")
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
        scores = scores_at(d, "matching_scores0", len(kp0), i0)
    else:
        assert per_pair is not None  # one of the two was read (checked above)
        i0, i1 = per_pair
        scores = scores_at(d, "scores", len(i0), None)
        if scores is None:
            scores = scores_at(d, "matching_scores0", len(kp0), i0)
    return dict(points0=kp0[i0], points1=kp1[i1], point_scores=scores)


def _read_kornia(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = keypoints(d, 0), keypoints(d, 1)
    if len(kp0) != len(kp1):
        raise MatchFormatError("Expected keypoints0 and keypoints1 of equal length (matched "
                               f"rows) in kornia matches (got {len(kp0)} and {len(kp1)})")
    rows = slice(None)
    if "batch_indexes" in d:
        b = as_indices(d["batch_indexes"], "batch_indexes").reshape(-1)
        if len(b) != len(kp0):
            raise MatchFormatError(f"Expected 'batch_indexes' of length {len(kp0)} (got {len(b)})")
        present = np.unique(b)
        if batch_index is None and len(present) > 1:
            raise MatchFormatError(
                f"Expected matches of one image pair (got batch indexes {present.tolist()}): "
                "pass batch_index=")
        rows = b == (present[0] if batch_index is None else batch_index)
    scores = scores_at(d, "confidence", len(kp0), None)
    return dict(points0=kp0[rows], points1=kp1[rows],
                point_scores=None if scores is None else scores[rows])


def _read_gluestick(d, batch_index, line_endpoints) -> dict:
    kp0, kp1 = keypoints(d, 0), keypoints(d, 1)
    info: dict = {}
    m0 = np.full(len(kp0), -1, np.int64)
    out = dict(points0=np.zeros((0, 2)), points1=np.zeros((0, 2)), info=info)
    if "matches0" in d:
        i0, i1 = index_per_node(d["matches0"], len(kp0), len(kp1), "matches0")
        m0[i0] = i1
        out.update(points0=kp0[i0], points1=kp1[i1],
                   point_scores=scores_at(d, "match_scores0", len(kp0), i0))
    if "line_matches0" not in d:
        return out
    lines = [_lines(d, i) for i in (0, 1)]
    j0, j1 = index_per_node(d["line_matches0"], len(lines[0]), len(lines[1]), "line_matches0")
    l0, l1 = lines[0][j0], lines[1][j1].copy()
    scores = scores_at(d, "line_match_scores0", len(lines[0]), j0)
    if line_endpoints == "auto" and len(j0):
        junc = [_junctions(d, i, lines[i], (kp0, kp1)[i]) for i in (0, 1)]
        a, b = junc[0][j0], junc[1][j1]
        hit = lambda p, q: (p >= 0) & (m0[np.maximum(p, 0)] == q) & (q >= 0)  # noqa: E731
        same = hit(a[:, 0], b[:, 0]).astype(int) + hit(a[:, 1], b[:, 1])
        swap = hit(a[:, 0], b[:, 1]).astype(int) + hit(a[:, 1], b[:, 0])
        l1[swap > same] = l1[swap > same][:, ::-1]
        keep = same != swap
        if not keep.all():
            # stacklevel 3: the caller of load_external_matches
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
    lines = as_array(d.get(f"lines{i}", np.zeros((0, 2, 2))), f"lines{i}")
    if lines.size == 0:
        return np.zeros((0, 2, 2))
    if lines.shape[1:] != (2, 2) or lines.ndim != 3:
        raise MatchFormatError(f"Expected 'lines{i}' of shape [L, 2, 2] (got {lines.shape})")
    return lines


def _junctions(d: dict, i: int, lines: np.ndarray, kp: np.ndarray) -> np.ndarray:
    """Index of the keypoint at each line endpoint ``[L, 2]`` (-1 where none)."""
    key = f"lines_junc_idx{i}"
    if key in d:
        idx = as_indices(d[key], key).reshape(-1, 2)
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


#: Reader of each layout but ``strl``: ``(arrays, batch_index, line_endpoints) -> kwargs``.
READERS = {"matched": _read_matched, "superglue": _read_superglue,
           "lightglue": _read_lightglue, "gluestick": _read_gluestick, "kornia": _read_kornia}
