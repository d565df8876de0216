"""The validated container of one image pair's matched points and line segments.

Coordinates are **pixels** with OpenCV's convention: the centre of the top-left pixel is
``(0, 0)``, ``x`` grows to the right and ``y`` downwards. Image sizes are ``(H, W)``.
"""

from __future__ import annotations

import copy
import json
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from strl_pyg.data.checks import (
    MIN_LINE_LENGTH,
    as_array,
    atomic_save_npz,
    check_finite,
    check_in_image,
    check_K,
    check_optional_image,
    check_size,
    load_npz,
)

__all__ = [
    "PairMatches",
    "MatchFileKeyError",
    "LINE_ENDPOINTS",
    "ENDPOINTS_CORRESPONDING",
    "ENDPOINTS_AS_DETECTED",
    "DUPLICATE_TOLERANCE_PX",
    "first_unique_rows",
    "Deduplicated",
]

#: Two matches closer than this (pixels, in every coordinate of both images) are one
#: correspondence: :meth:`PairMatches.deduplicated`.
DUPLICATE_TOLERANCE_PX = 1e-3

#: ``PairMatches.info`` key saying whether the lines' endpoints correspond, and its values:
#: ``"corresponding"`` (endpoint ``k`` matches endpoint ``k``: the front end's epipolar
#: matcher clips both segments to their common part) or ``"as detected"`` (the descriptor
#: matcher: the segments match as lines, their endpoints are where the detector ended them).
#: Absent means corresponding (external match lists, generated scenes).
LINE_ENDPOINTS = "line_endpoints"
ENDPOINTS_CORRESPONDING = "corresponding"
ENDPOINTS_AS_DETECTED = "as detected"



_NPZ_ARRAYS = (
    "points0",
    "points1",
    "lines0",
    "lines1",
    "point_scores",
    "line_scores",
    "image_size0",
    "image_size1",
    "K0",
    "K1",
    "image0",
    "image1",
)


class MatchFileKeyError(ValueError, KeyError):
    """A match file without the arrays it needs: a ``ValueError`` (one-line "Expected ...
    (got ...)" message, like every input error of the package) that is also a ``KeyError``
    for code written against earlier versions."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""

@dataclass
class PairMatches:
    """Matched points and line segments between image 0 (reference) and image 1 (target).

    Validated on construction; every violation raises ``ValueError``/``TypeError`` with an
    ``Expected ... (got ...)`` message.

    Args:
        points0, points1: Matched points, ``[Np, 2]`` pixels; row ``i`` of both is one match.
        lines0, lines1: Matched segments, ``[Nl, 2, 2]`` pixels (``[Nl, 4]`` or ``[Nl, 1, 4]``
            rows ``(x1, y1, x2, y2)``, as OpenCV's LSD gives them, are read as that); endpoint
            ``k`` of line ``i`` in
            image 0 matches endpoint ``k`` of line ``i`` in image 1, unless
            ``info["line_endpoints"] == "as detected"`` (:data:`ENDPOINTS_AS_DETECTED`: the front
            end's descriptor matcher, whose segments match as lines but whose endpoints do not
            correspond; :attr:`line_endpoints_correspond` is then ``False``).
        image_size0, image_size1: ``(H, W)``; taken from the images when omitted.
        point_scores, line_scores: Optional confidences ``[Np]``, ``[Nl]``.
        K0, K1: Optional intrinsics ``[3, 3]`` (pixels), last row ``[0, 0, 1]``.
        image0, image1: Optional images ``(H, W)`` or ``(H, W, 3)``, uint8 or float in [0, 1].
        info: Free-form metadata (e.g. timings per stage), saved as JSON.

    Zero lines is valid (a points-only pair); zero points with some lines is valid too
    (a lines-only pair: every node is a line endpoint). No match at all is an error.
    """

    points0: Any
    points1: Any
    lines0: Any = None
    lines1: Any = None
    image_size0: Any = None
    image_size1: Any = None
    point_scores: Any = None
    line_scores: Any = None
    K0: Any = None
    K1: Any = None
    image0: Any = None
    image1: Any = None
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.image0 = check_optional_image(self.image0, "image0")
        self.image1 = check_optional_image(self.image1, "image1")
        for i in (0, 1):
            size_name, img = f"image_size{i}", getattr(self, f"image{i}")
            size = getattr(self, size_name)
            if size is None:
                if img is None:
                    raise ValueError(
                        f"Expected '{size_name}' (H, W) or 'image{i}' to be given (got neither)"
                    )
                size = img.shape[:2]
            size = check_size(size, size_name)
            if img is not None and tuple(img.shape[:2]) != size:
                raise ValueError(
                    f"Expected 'image{i}' of size {size} (H, W) (got {tuple(img.shape[:2])})"
                )
            setattr(self, size_name, size)

        self.points0 = self._coords(self.points0, "points0", (2,))
        self.points1 = self._coords(self.points1, "points1", (2,))
        self.lines0 = self._coords(self.lines0, "lines0", (2, 2))
        self.lines1 = self._coords(self.lines1, "lines1", (2, 2))
        if len(self.points0) != len(self.points1):
            raise ValueError(
                "Expected as many points in image 0 as in image 1 "
                f"(got {len(self.points0)} and {len(self.points1)})"
            )
        if len(self.lines0) != len(self.lines1):
            raise ValueError(
                "Expected as many lines in image 0 as in image 1 "
                f"(got {len(self.lines0)} and {len(self.lines1)})"
            )
        if len(self.points0) == 0 and len(self.lines0) == 0:
            raise ValueError("Expected at least one point or line match (got none)")
        for name in ("lines0", "lines1"):
            lines = getattr(self, name)
            length = np.linalg.norm(lines[:, 1] - lines[:, 0], axis=-1)
            short = length < MIN_LINE_LENGTH
            if short.any():
                raise ValueError(
                    f"Expected line segments of length >= {MIN_LINE_LENGTH} px in '{name}' "
                    f"(got {int(short.sum())} zero-length lines, first index "
                    f"{int(np.flatnonzero(short)[0])})"
                )
        check_in_image(self.points0, self.image_size0, "points0")
        check_in_image(self.points1, self.image_size1, "points1")
        check_in_image(self.lines0, self.image_size0, "lines0")
        check_in_image(self.lines1, self.image_size1, "lines1")
        self.point_scores = self._scores(self.point_scores, "point_scores", len(self.points0))
        self.line_scores = self._scores(self.line_scores, "line_scores", len(self.lines0))
        self.K0 = check_K(self.K0, "K0")
        self.K1 = check_K(self.K1, "K1")
        if (self.K0 is None) != (self.K1 is None):
            raise ValueError("Expected both K0 and K1 or neither (got only one)")
        if not isinstance(self.info, dict):
            raise TypeError(f"Expected 'info' to be a dict (got {type(self.info).__name__})")

    @staticmethod
    def _coords(value: Any, name: str, tail: tuple[int, ...]) -> np.ndarray:
        if value is None:
            return np.zeros((0, *tail), dtype=np.float64)
        arr = as_array(value, name)
        if arr.size == 0:
            return np.zeros((0, *tail), dtype=np.float64)
        if tail == (2, 2) and arr.shape[1:] in ((4,), (1, 4)):
            arr = arr.reshape(-1, 2, 2)  # (x1, y1, x2, y2) rows, as OpenCV's LSD gives them
        if arr.ndim != 1 + len(tail) or arr.shape[1:] != tail:
            want = "[N, " + ", ".join(map(str, tail)) + "]"
            raise ValueError(f"Expected '{name}' of shape {want} (got {tuple(arr.shape)})")
        check_finite(arr, name)
        return np.ascontiguousarray(arr)

    @staticmethod
    def _scores(value: Any, name: str, n: int) -> np.ndarray | None:
        if value is None:
            return None
        arr = as_array(value, name).reshape(-1)
        if len(arr) != n:
            raise ValueError(f"Expected '{name}' of length {n} (got {len(arr)})")
        check_finite(arr, name)
        return arr

    @property
    def num_points(self) -> int:
        return len(self.points0)

    @property
    def num_lines(self) -> int:
        return len(self.lines0)

    @property
    def line_endpoints_correspond(self) -> bool:
        """Whether endpoint ``k`` of each line in image 0 matches endpoint ``k`` in image 1
        (``False`` only when ``info["line_endpoints"]`` is :data:`ENDPOINTS_AS_DETECTED`)."""
        return self.info.get(LINE_ENDPOINTS) != ENDPOINTS_AS_DETECTED

    @property
    def has_intrinsics(self) -> bool:
        return self.K0 is not None

    @property
    def has_images(self) -> bool:
        return self.image0 is not None and self.image1 is not None

    def __repr__(self) -> str:
        parts = [f"points={self.num_points}", f"lines={self.num_lines}"]
        parts.append(f"size0={self.image_size0}, size1={self.image_size1}")
        parts.append(f"K={'yes' if self.has_intrinsics else 'no'}")
        parts.append(f"images={'yes' if self.has_images else 'no'}")
        return f"PairMatches({', '.join(parts)})"

    def select(self, point_index: Any = None, line_index: Any = None) -> PairMatches:
        """Returns a copy keeping the points and lines at the given indices (repeats allowed).
        Point row indices stored in ``info`` (the front end's ``"fundamental_inliers"``) are
        re-indexed to the kept rows."""
        kwargs = {f.name: getattr(self, f.name) for f in fields(self)}
        kwargs.update(self._selected(point_index, line_index))
        return PairMatches(**kwargs)

    def _selected(self, point_index: Any, line_index: Any) -> dict[str, Any]:
        pi = slice(None) if point_index is None else np.asarray(point_index, dtype=np.int64)
        li = slice(None) if line_index is None else np.asarray(line_index, dtype=np.int64)
        return dict(
            points0=self.points0[pi],
            points1=self.points1[pi],
            lines0=self.lines0[li],
            lines1=self.lines1[li],
            point_scores=None if self.point_scores is None else self.point_scores[pi],
            line_scores=None if self.line_scores is None else self.line_scores[li],
            info=_reindexed_info(self.info, pi, self.num_points),
        )

    def _derived(self, point_index: Any = None, line_index: Any = None,
                 **changes: Any) -> PairMatches:
        """:meth:`select` and / or fields replaced, without checking again what these
        validated matches already passed: for the package's own derivations whose result is
        valid by construction (rows of these matches, at least one of them; images converted
        from these). Checked input goes through the constructor."""
        unknown = sorted(set(changes) - {f.name for f in fields(self)})
        if unknown:
            raise TypeError(f"Expected PairMatches fields (got {unknown})")
        out = copy.copy(self)
        if point_index is not None or line_index is not None:
            changes = {**self._selected(point_index, line_index), **changes}
        for name, value in changes.items():
            setattr(out, name, value)
        if out.num_points == 0 and out.num_lines == 0:
            raise ValueError("Expected at least one point or line match (got none)")
        return out

    def swapped(self) -> PairMatches:
        """The same pair seen from image 1: every ``0`` field exchanged with its ``1`` field
        (row order kept). ``info`` entries that hold image-ordered geometry (the front end's
        fundamental matrix and its inliers) are left out; the rest is copied."""
        info = {k: v for k, v in self.info.items()
                if k not in ("fundamental", *POINT_ROW_KEYS)}
        return PairMatches(
            self.points1, self.points0, self.lines1, self.lines0, self.image_size1,
            self.image_size0, self.point_scores, self.line_scores, self.K1, self.K0,
            self.image1, self.image0, info)

    @classmethod
    def from_normalized(cls, x0: Any, x1: Any, K0: Any, K1: Any, image_size0: Any,
                        image_size1: Any, lines0: Any = None, lines1: Any = None,
                        **kwargs: Any) -> PairMatches:
        """Matches from normalised camera coordinates (``x = K^-1 [u, v, 1]``, as kornia's
        and OpenCV's essential-matrix functions take them): ``x0``, ``x1`` ``[Np, 2]``,
        ``lines0``, ``lines1`` ``[Nl, 2, 2]``, converted to pixels with ``K0`` / ``K1``
        (required: they define the conversion); ``image_size0/1`` ``(H, W)`` as the pixel
        frame the checks use. Other arguments as the constructor."""
        K0, K1 = check_K(K0, "K0"), check_K(K1, "K1")
        if K0 is None or K1 is None:
            raise ValueError("Expected K0 and K1 to convert normalised coordinates to pixels "
                             "(got None)")

        def to_px(x: Any, K: np.ndarray, name: str, tail: tuple[int, ...]) -> np.ndarray:
            arr = cls._coords(x, name, tail)
            flat = arr.reshape(-1, 2)
            return (flat @ K[:2, :2].T + K[:2, 2]).reshape(arr.shape)

        return cls(to_px(x0, K0, "x0", (2,)), to_px(x1, K1, "x1", (2,)),
                   to_px(lines0, K0, "lines0", (2, 2)), to_px(lines1, K1, "lines1", (2, 2)),
                   image_size0=image_size0, image_size1=image_size1, K0=K0, K1=K1, **kwargs)

    def deduplicated(self, tol_px: float = DUPLICATE_TOLERANCE_PX) -> Deduplicated:
        """The matches with each correspondence once, one-line notes of what was found, and
        for every input point row the row of its correspondence in the result
        (:class:`Deduplicated`).

        Repeated rows (both images' coordinates within ``tol_px``) are kept once, the first
        occurrence with its score: a match listed ``k`` times is one observation, so it must
        not count ``k`` times towards a minimum count, the support of a pose or the spread of
        a bootstrap. Rows that share one side with another match but not the other
        (one-to-many, many-to-one) are kept and counted in a note: only
        :attr:`num_distinct_points` of them can constrain a pose. Returns ``self`` when
        nothing was repeated."""
        notes = []
        pi, inverse = first_unique_rows(np.concatenate([self.points0, self.points1], axis=1),
                                        tol_px, return_inverse=True)
        li = first_unique_rows(np.concatenate([self.lines0, self.lines1], axis=1), tol_px)
        dp, dl = self.num_points - len(pi), self.num_lines - len(li)
        if dp or dl:
            what = [f"{d} repeated {kind} matches" for d, kind in ((dp, "point"), (dl, "line"))
                    if d]
            notes.append(f"{' and '.join(what)} removed (a repeated match is one "
                         f"correspondence): {len(pi)} point and {len(li)} line matches remain")
        out = self if not (dp or dl) else self.select(pi, li)
        shared = [(int(len(out.points0) - _distinct(out.points0, tol_px)), 0),
                  (int(len(out.points1) - _distinct(out.points1, tol_px)), 1)]
        for extra, side in shared:
            # a few reused keypoints are usual (SIFT keeps one keypoint per orientation at a
            # location); a note when they change what the pair can determine
            if extra and (extra > 0.1 * out.num_points or out.num_distinct_points < 8):
                notes.append(f"{extra} point matches reuse a point of image {side} that another "
                             f"match already uses (one-to-many): {out.num_distinct_points} "
                             "distinct correspondences")
        return Deduplicated(out, notes, inverse)

    @property
    def num_distinct_points(self) -> int:
        """Point matches that can constrain a pose: the smaller of the numbers of distinct
        points in image 0 and in image 1 (equal to :attr:`num_points` without repeats)."""
        return min(_distinct(self.points0), _distinct(self.points1))

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | os.PathLike) -> Path:
        """Saves to ``.npz`` atomically (temporary file, then rename).

        Keys: ``points0``, ``points1`` ``[Np, 2]``; ``lines0``, ``lines1`` ``[Nl, 2, 2]``;
        ``image_size0``, ``image_size1`` ``[2]`` (H, W); optional ``point_scores``,
        ``line_scores``, ``K0``, ``K1``, ``image0``, ``image1``; ``info_json`` (a JSON string).
        """
        path = Path(path)
        arrays = {k: getattr(self, k) for k in _NPZ_ARRAYS if getattr(self, k) is not None}
        arrays["image_size0"] = np.asarray(self.image_size0, dtype=np.int64)
        arrays["image_size1"] = np.asarray(self.image_size1, dtype=np.int64)
        arrays["info_json"] = np.asarray(json.dumps(self.info, default=float))
        atomic_save_npz(path, arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> PairMatches:
        """Loads a file written by :meth:`save`; missing or corrupt files raise clearly."""
        data = load_npz(path)
        missing = [k for k in ("points0", "points1", "image_size0", "image_size1") if k not in data]
        if missing:
            raise MatchFileKeyError(
                f"Expected keys {missing} in match file '{path}' (got {sorted(data)})")
        kwargs = {k: data[k] for k in _NPZ_ARRAYS if k in data}
        info = json.loads(str(data["info_json"])) if "info_json" in data else {}
        return cls(**kwargs, info=info)


#: ``info`` entries that hold point row indices (re-indexed by :meth:`PairMatches.select`).
POINT_ROW_KEYS = ("fundamental_inliers",)


def _reindexed_info(info: dict, point_index: Any, num_points: int) -> dict:
    """A copy of ``info`` whose point row lists follow ``select(point_index)``; a list that
    does not index the ``num_points`` rows is dropped rather than carried over wrong."""
    out = dict(info)
    if isinstance(point_index, slice):
        return out
    for key in POINT_ROW_KEYS:
        if key not in out:
            continue
        rows = np.asarray(out[key], dtype=np.int64).reshape(-1)
        if rows.size and (rows.min() < 0 or rows.max() >= num_points):
            del out[key]
            continue
        kept = np.zeros(num_points, dtype=bool)
        kept[rows] = True
        out[key] = np.flatnonzero(kept[point_index]).tolist()
    return out


def first_unique_rows(rows: np.ndarray, tol: float = DUPLICATE_TOLERANCE_PX,
                      return_inverse: bool = False):
    """Sorted indices of the first occurrence of each distinct row of ``rows`` ``[N, ...]``
    (rows are one when every value rounds to the same multiple of ``tol``: equal on a grid of
    step ``tol``, so two values closer than ``tol`` across a cell boundary stay apart); with
    ``return_inverse``, also for every row the position of its distinct row among those
    indices."""
    if len(rows) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return (empty, empty) if return_inverse else empty
    keys = np.round(np.asarray(rows).reshape(len(rows), -1) / tol).astype(np.int64)
    _, first, inv = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    if not return_inverse:
        return first[order]
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inv.reshape(-1)]


class Deduplicated(NamedTuple):
    """:meth:`PairMatches.deduplicated`: the ``matches`` with each correspondence once, the
    ``notes`` (one line each), and ``point_inverse`` ``[Np_input]``: the row in ``matches`` of
    every input point row."""

    matches: PairMatches
    notes: list[str]
    point_inverse: np.ndarray


def _distinct(points: np.ndarray, tol_px: float = DUPLICATE_TOLERANCE_PX) -> int:
    if len(points) == 0:
        return 0
    return len(np.unique(np.round(points / tol_px).astype(np.int64), axis=0))


