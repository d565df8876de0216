"""Which pairs of a collection to match.

- :func:`exhaustive_pairs`: every pair ``(i, j)``, ``i < j``;
- :func:`sequential_pairs`: each image with its next ``window`` images (video, capture order);
- :func:`read_pairs_file`: hloc's pairs file (``name0 name1`` per line) or SuperGlue's
  ``pairs_with_gt`` (``name0 name1 rot0 rot1 K0[9] K1[9] T_0to1[16]``), whose ``K`` per pair
  replaces the images' cameras for that pair (EXIF rotations other than 0 are refused: rotate
  the files instead).

A pair is :class:`Pair`: the two image indices and, from SuperGlue's format, the two ``K``.
Pairs are kept once (``(i, j)`` and ``(j, i)`` are the same pair; the first listed stays).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Pair", "exhaustive_pairs", "sequential_pairs", "read_pairs_file", "parse_pairs"]


@dataclass(frozen=True)
class Pair:
    """Images ``i`` and ``j`` of a collection; ``K0``/``K1`` ``[3, 3]`` where the pairs file
    gives a ``K`` per pair (else ``None``: the images' cameras)."""

    i: int
    j: int
    K0: tuple | None = None
    K1: tuple | None = None


def exhaustive_pairs(n: int) -> list[Pair]:
    """Every pair of ``n`` images, ``(i, j)`` with ``i < j``, row by row."""
    return [Pair(i, j) for i in range(n) for j in range(i + 1, n)]


def sequential_pairs(n: int, window: int) -> list[Pair]:
    """Each of ``n`` images with its next ``window`` images (``window >= 1``)."""
    if isinstance(window, bool) or not isinstance(window, int) or window < 1:
        raise ValueError(f"Expected a sequential window >= 1 (got {window!r})")
    return [Pair(i, j) for i in range(n) for j in range(i + 1, min(n, i + window + 1))]


def _K(values: list[str], where: str) -> tuple:
    K = np.array([float(v) for v in values]).reshape(3, 3)
    if not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"Expected a K with positive focal lengths in {where} (got "
                         f"{K.tolist()})")
    return tuple(map(tuple, K.tolist()))


def read_pairs_file(path: str | os.PathLike, names: list[str]) -> list[Pair]:
    """The pairs of an hloc or SuperGlue pairs file over the image ``names`` (module
    docstring); blank lines and ``#`` comments skipped. One-line ``ValueError`` for a name
    not among ``names``, a line of neither format, or a non-zero EXIF rotation."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected a pairs file at '{path}' (got no such file)")
    return parse_pairs(path.read_text().splitlines(), names, f"'{path}'")


def parse_pairs(lines: list[str], names: list[str], where: str = "the pairs") -> list[Pair]:
    """:func:`read_pairs_file` on lines already read."""
    index = {n: k for k, n in enumerate(names)}
    base = {}
    for k, n in enumerate(names):
        base.setdefault(Path(n).name, k)
    out, seen = [], set()
    for n, line in enumerate(lines, 1):
        f = line.split()
        if not f or f[0].startswith("#"):
            continue
        at = f"{where} line {n}"
        if len(f) not in (2, 38):
            raise ValueError(f"Expected 'name0 name1' (hloc) or 'name0 name1 rot0 rot1 K0[9] "
                             f"K1[9] T[16]' (SuperGlue) on {at} (got {len(f)} fields)")
        ij = []
        for name in f[:2]:
            k = index.get(name, base.get(Path(name).name))
            if k is None:
                raise ValueError(f"Expected an image of the collection on {at} (got "
                                 f"{name!r}, not among its {len(names)} images)")
            ij.append(k)
        i, j = ij
        if i == j:
            raise ValueError(f"Expected two different images on {at} (got {f[0]!r} twice)")
        K0 = K1 = None
        if len(f) == 38:
            try:
                if int(f[2]) != 0 or int(f[3]) != 0:
                    raise ValueError(f"Expected EXIF rotations 0 on {at} (got {f[2]}, {f[3]}): "
                                     "rotate the image files instead")
                K0, K1 = _K(f[4:13], at), _K(f[13:22], at)
            except ValueError as err:
                if "Expected" in str(err):
                    raise
                raise ValueError(f"Expected numbers after the names on {at} (got {err})") \
                    from None
        key = (min(i, j), max(i, j))
        if key in seen:
            continue
        seen.add(key)
        out.append(Pair(i, j, K0, K1))
    if not out:
        raise ValueError(f"Expected at least one pair in {where} (got none)")
    return out
