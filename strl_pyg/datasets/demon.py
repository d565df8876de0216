"""DeMoN benchmark data (MVS, SUN3D, RGB-D, Scenes11) in its two published layouts.

**DeepSfM folders** (what DeepSfM's preparation writes)::

    root/<split>/<split>.txt                 sequence names, one a line (optional)
    root/<split>/<sequence>/cam.txt           3x3 intrinsics (pixels)
    root/<split>/<sequence>/poses.txt         one row-major 3x4 world-to-camera per frame
    root/<split>/<sequence>/0000.jpg, ...     images (0000.npy: depth, unused here)

**Original DeMoN HDF5** (e.g. ``mvs_test.h5``)::

    /<group>/frames/t0/v<N>/image     int8 bytes of a webp image
    /<group>/frames/t0/v<N>/camera    float64 [17]: fx, fy, skew, cx, cy, R (9, column-major), t
    /<group>/frames/t0/v<N>/depth     (unused here)

with ``x = K (R X + t)`` (world-to-camera); groups whose name starts with ``.`` are reserved.
The subset comes from the name prefix of a sequence folder or ``.h5`` file.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.datasets.base import ImageSource, PairDataset, PairRecord, check_on_missing
from strl_pyg.datasets.files import read_number_rows, report_missing, rows_to_matrices
from strl_pyg.geometry import relative_pose_from_w2c

__all__ = [
    "DEMON_SUBSETS",
    "DeMoNFolder",
    "DeMoNHDF5",
    "demon_subset",
    "pair_indices",
    "read_demon_camera",
]

#: Name prefixes of the DeMoN data and the subset names used for evaluation.
DEMON_SUBSETS = {"mvs": "MVS", "sun3d": "SUN3D", "rgbd": "RGB-D", "scenes11": "Scenes11"}
PAIR_MODES = ("reference", "consecutive", "all")
_IMAGE_EXT = (".jpg", ".jpeg", ".png", ".webp")


def demon_subset(name: str) -> str:
    """Subset of a sequence or file name: ``"sun3d_train_0.1m_to_0.2m_00000"`` -> ``"SUN3D"``
    (an unknown prefix is returned as is)."""
    prefix = Path(name).name.split("_")[0].lower()
    return DEMON_SUBSETS.get(prefix, prefix)


def _check_subsets(subsets: Sequence[str] | None) -> set[str] | None:
    if subsets is None:
        return None
    subsets = [subsets] if isinstance(subsets, str) else list(subsets)
    bad = [s for s in subsets if s not in DEMON_SUBSETS.values()]
    if bad:
        raise ValueError(f"Expected subsets among {list(DEMON_SUBSETS.values())} (got {bad})")
    return set(subsets)


def pair_indices(num_views: int, mode: str = "reference") -> list[tuple[int, int]]:
    """View pairs of one sequence: ``"reference"`` ``(0, j)``, ``"consecutive"``
    ``(j, j + 1)`` or ``"all"`` ordered pairs ``(i, j)``, ``i != j``."""
    if mode == "reference":
        return [(0, j) for j in range(1, num_views)]
    if mode == "consecutive":
        return [(j, j + 1) for j in range(num_views - 1)]
    if mode == "all":
        return [(i, j) for i in range(num_views) for j in range(num_views) if i != j]
    raise ValueError(f"Expected pairs in {PAIR_MODES} (got {mode!r})")


def read_demon_camera(values: Any, name: str = "camera") -> tuple[np.ndarray, np.ndarray]:
    """DeMoN camera vector ``[17]`` -> ``(K [3, 3], T_c_w [4, 4])`` (world-to-camera)."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.shape != (17,) or not np.isfinite(v).all():
        raise ValueError(
            f"Expected 17 finite camera values (fx, fy, skew, cx, cy, R column-major, t) in "
            f"'{name}' (got shape {v.shape})"
        )
    fx, fy, skew, cx, cy = v[:5]
    K = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = v[5:14].reshape(3, 3, order="F")
    T[:3, 3] = v[14:17]
    return K, T


class _DeMoNPairs(PairDataset):
    """What both DeMoN layouts share: the options, checked before anything is read, and the
    dataset built from the records that a subclass's :meth:`_index` reads from its source."""

    _KIND = "demon"

    def __init__(
        self,
        source: Any,
        *,
        cache_dir: str | os.PathLike,
        subsets: Sequence[str] | None = None,
        pairs: str = "reference",
        image_size: tuple[int, int] | None = (192, 256),
        on_missing: str = "error",
        transform: Callable | None = None,
        **kwargs: Any,
    ) -> None:
        check_on_missing(on_missing)
        pair_indices(2, pairs)  # validates the mode
        records, root = self._index(source, _check_subsets(subsets), pairs, on_missing)
        if root is not None:
            kwargs["root"] = root
        super().__init__(
            records, cache_dir=cache_dir, image_size=image_size, transform=transform,
            kind=self._KIND, **kwargs,
        )

    def _index(self, source: Any, keep: set[str] | None, pairs: str,
               on_missing: str) -> tuple[list[PairRecord], Path | None]:
        """``(records, data folder or None)`` of ``source``, subsets ``keep`` only."""
        raise NotImplementedError


class DeMoNFolder(_DeMoNPairs):
    """DeMoN pairs in the DeepSfM folder layout, as pair graphs.

    The sequences are those listed in ``<split>/<split>.txt`` when it exists, else every
    folder of ``<split>/``. Listed sequences that are absent raise an error naming them, or
    are skipped with a warning when ``on_missing="skip"`` (their names are kept in
    :attr:`missing_sequences`).

    Args:
        root: Folder holding ``train/`` and/or ``test/``.
        cache_dir: Root of the match cache.
        split: ``"test"`` (default) or ``"train"`` (any sub-folder name works).
        subsets: Keep only these of ``MVS``, ``SUN3D``, ``RGB-D``, ``Scenes11``.
        pairs: ``"reference"`` (default), ``"consecutive"`` or ``"all"``
            (:func:`pair_indices`); the benchmark's test sequences have two views.
        image_size: ``(H, W)`` for matching (default: ``(192, 256)``, as the paper).
        on_missing: ``"error"`` (default) or ``"skip"`` listed sequences that are absent.
        transform: Applied to each graph on access, e.g. ``FixedSizeResample()``.
        **kwargs: ``frontend_config``, ``patch_size``, ``keep_images``, ``grayscale``,
            ``limit`` of :class:`PairDataset`.
    """

    _KIND = "demon_folder"

    def __init__(self, root: str | os.PathLike, *, split: str = "test", **kwargs: Any) -> None:
        self.split = split
        super().__init__(root, **kwargs)

    def _index(self, root, keep, pairs, on_missing):
        root = Path(root)
        split_dir = root / self.split
        if not split_dir.is_dir():
            raise FileNotFoundError(f"Expected a DeMoN split folder at '{split_dir}' (got none)")
        list_file = split_dir / f"{self.split}.txt"
        if list_file.is_file():
            names = [s.strip() for s in list_file.read_text().splitlines() if s.strip()]
        else:
            names = sorted(p.name for p in split_dir.iterdir() if p.is_dir())
        if keep is not None:
            names = [n for n in names if demon_subset(n) in keep]
        missing = [n for n in names if not (split_dir / n).is_dir()]
        report_missing(missing, f"Expected the {len(names)} sequences listed in '{list_file}' "
                       f"under '{split_dir}' (got {len(missing)} absent, e.g. {missing[:3]})",
                       on_missing)
        #: Listed sequences with no folder (skipped).
        self.missing_sequences = missing
        self.sequences = [n for n in names if n not in set(missing)]
        records = []
        for name in self.sequences:
            records.extend(self._sequence_records(split_dir / name, pairs))
        return records, root

    @staticmethod
    def _sequence_records(seq_dir: Path, mode: str) -> list[PairRecord]:
        K = read_number_rows(seq_dir / "cam.txt", 3, "a 3x3 intrinsics matrix", "'cam.txt'")
        if K.shape != (3, 3):
            raise ValueError(
                f"Expected a 3x3 intrinsics matrix in '{seq_dir / 'cam.txt'}' (got {K.shape})"
            )
        poses = read_number_rows(seq_dir / "poses.txt", 12,
                                 "rows of 12 numbers (3x4 world-to-camera)", "'poses.txt'")
        images = sorted(p for p in seq_dir.iterdir() if p.suffix.lower() in _IMAGE_EXT)
        if len(images) < 2:
            raise FileNotFoundError(
                f"Expected at least two images in '{seq_dir}' (got {len(images)})"
            )
        if len(poses) != len(images):
            raise ValueError(
                f"Expected one pose per image in '{seq_dir / 'poses.txt'}' "
                f"(got {len(poses)} poses for {len(images)} images)"
            )
        W = rows_to_matrices(poses)
        subset = demon_subset(seq_dir.name)
        records = []
        for i, j in pair_indices(len(images), mode):
            records.append(
                PairRecord(
                    pair_id=f"demon/{seq_dir.parent.name}/{seq_dir.name}/{i}-{j}",
                    subset=subset,
                    source0=ImageSource(str(images[i])),
                    source1=ImageSource(str(images[j])),
                    K0=K,
                    K1=K,
                    T_0to1=relative_pose_from_w2c(W[i], W[j]).numpy(),
                )
            )
        return records


class DeMoNHDF5(_DeMoNPairs):
    """DeMoN pairs read from the original HDF5 files, as pair graphs.

    Args:
        files: One ``.h5`` file or several (e.g. ``mvs_test.h5``, ``sun3d_test.h5``); the
            subset of each comes from its name prefix.
        cache_dir: Root of the match cache.
        subsets: Keep only the files of these subsets.
        pairs: ``"reference"`` (default), ``"consecutive"`` or ``"all"``.
        image_size: ``(H, W)`` for matching (default: ``(192, 256)``).
        on_missing: ``"error"`` (default) or ``"skip"`` absent files.
        transform: Applied to each graph on access.
        **kwargs: as :class:`PairDataset`.
    """

    _KIND = "demon_h5"

    def __init__(self, files: str | os.PathLike | Sequence[str | os.PathLike],
                 **kwargs: Any) -> None:
        super().__init__(files, **kwargs)

    def _index(self, files, keep, pairs, on_missing):
        import h5py

        files = [files] if isinstance(files, (str, os.PathLike)) else list(files)
        files = [Path(f) for f in files]
        if keep is not None:
            files = [f for f in files if demon_subset(f.stem) in keep]
        missing = [str(f) for f in files if not f.is_file()]
        report_missing(missing, f"Expected DeMoN HDF5 files {missing} (got {len(missing)} absent)",
                       on_missing)
        self.missing_files = missing
        self.files = [f for f in files if f.is_file()]
        records = []
        for path in self.files:
            try:
                with h5py.File(path, "r") as f:
                    records.extend(self._file_records(path, f, pairs))
            except OSError as err:
                raise ValueError(f"Expected a readable HDF5 file at '{path}' (got {err})") from err
        return records, None

    @staticmethod
    def _file_records(path: Path, f: Any, mode: str) -> list[PairRecord]:
        subset = demon_subset(path.stem)
        records = []
        for group in sorted(g for g in f.keys() if not g.startswith(".")):
            t0 = f.get(f"{group}/frames/t0")
            if t0 is None:
                raise KeyError(
                    f"Expected '{group}/frames/t0' in '{path}' (got keys {list(f[group])})"
                )
            views = sorted(int(v[1:]) for v in t0.keys() if v[:1] == "v" and v[1:].isdigit())
            if views != list(range(len(views))) or len(views) < 2:
                raise ValueError(
                    f"Expected views v0..vN (N >= 1) in '{path}:{group}/frames/t0' (got {views})"
                )
            cams = []
            for v in views:
                key = f"{group}/frames/t0/v{v}"
                if "camera" not in t0[f"v{v}"] or "image" not in t0[f"v{v}"]:
                    raise KeyError(f"Expected 'image' and 'camera' in '{path}:{key}'")
                cams.append(read_demon_camera(t0[f"v{v}/camera"][()], f"{path}:{key}/camera"))
            for i, j in pair_indices(len(views), mode):
                records.append(
                    PairRecord(
                        pair_id=f"demon_h5/{path.stem}/{group}/{i}-{j}",
                        subset=subset,
                        source0=ImageSource(str(path), f"{group}/frames/t0/v{i}"),
                        source1=ImageSource(str(path), f"{group}/frames/t0/v{j}"),
                        K0=cams[i][0],
                        K1=cams[j][0],
                        T_0to1=relative_pose_from_w2c(cams[i][1], cams[j][1]).numpy(),
                    )
                )
        return records
