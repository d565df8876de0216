"""KITTI odometry in its official layout.

::

    root/sequences/NN/image_0/000000.png   (image_1, image_2, image_3 likewise)
    root/sequences/NN/calib.txt            "P0: 12 values" lines (row-major 3x4)
    root/poses/NN.txt                      one row-major 3x4 camera-to-world pose per frame

Pairs are frames ``(i, i + k)`` of one sequence where both images exist. Poses are those of the
left grey camera (``image_0``); for another camera ``c`` the pose is conjugated by its
rectified offset ``K_c^{-1} P_c[:, 3]`` from camera 0.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.datasets.base import ImageSource, PairDataset, PairRecord, check_on_missing
from strl_pyg.datasets.files import (
    read_number_rows,
    report_missing,
    rows_to_matrices,
    warn_caller,
)
from strl_pyg.geometry import relative_pose_from_c2w

__all__ = [
    "KITTI_SPLITS",
    "KITTIOdometry",
    "read_kitti_calib",
    "read_kitti_poses",
]

#: The standard odometry split (sequences with ground truth): 00-08 train, 09-10 test.
KITTI_SPLITS = {
    "train": tuple(f"{i:02d}" for i in range(9)),
    "test": ("09", "10"),
    "all": tuple(f"{i:02d}" for i in range(11)),
}

_CAMERAS = ("image_0", "image_1", "image_2", "image_3")


def read_kitti_calib(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Parses ``KEY: v1 v2 ...`` lines into ``{KEY: float64 array}`` (3x4 for 12 values).

    Any set of keys is accepted (a full file has ``P0..P3`` and ``Tr``); malformed lines
    raise an error naming the file and line.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected a KITTI calibration file at '{path}' (got no such file)")
    out = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        try:
            if not sep:
                raise ValueError("no ':'")
            arr = np.array([float(v) for v in values.split()], dtype=np.float64)
        except ValueError as err:
            raise ValueError(
                f"Expected 'KEY: numbers' in '{path}' line {n} (got {line[:60]!r}: {err})"
            ) from err
        out[key.strip()] = arr.reshape(3, 4) if arr.size == 12 else arr
    return out


def read_kitti_poses(path: str | os.PathLike) -> np.ndarray:
    """Reads a pose file: ``[N, 4, 4]`` camera-to-world matrices (rows are 3x4 row-major)."""
    return rows_to_matrices(read_number_rows(path, 12, "rows of 12 numbers", "a KITTI pose file"))


class KITTIOdometry(PairDataset):
    """KITTI odometry pairs ``(i, i + frame_gap)`` as pair graphs.

    Indexes the images that exist: a sequence with only some frames on disk gives the pairs
    among those (a ``UserWarning`` says how many frames are missing; :attr:`frames` has the
    counts). Absent sequence folders raise an error listing them, or are skipped with a
    warning when ``on_missing="skip"``.

    Args:
        root: Folder holding ``sequences/`` and ``poses/``.
        cache_dir: Root of the match cache.
        split: ``"train"`` (00-08), ``"test"`` (09-10) or ``"all"``; ignored when
            ``sequences`` is given.
        sequences: Explicit sequence names, e.g. ``["06"]``.
        frame_gap: ``k`` of the pairs ``(i, i + k)`` (default: ``1``).
        camera: ``"image_0"`` (default, left grey) .. ``"image_3"``.
        image_size: ``(H, W)`` for matching (default: ``(128, 416)``, as the paper).
        on_missing: ``"error"`` (default) or ``"skip"`` absent sequences.
        transform: Applied to each graph on access, e.g. ``FixedSizeResample()``.
        **kwargs: ``frontend_config``, ``patch_size``, ``keep_images``, ``grayscale``,
            ``limit`` of :class:`PairDataset`.
    """

    def __init__(
        self,
        root: str | os.PathLike,
        *,
        cache_dir: str | os.PathLike,
        split: str = "train",
        sequences: Sequence[str] | None = None,
        frame_gap: int = 1,
        camera: str = "image_0",
        image_size: tuple[int, int] | None = (128, 416),
        on_missing: str = "error",
        transform: Callable | None = None,
        **kwargs: Any,
    ) -> None:
        root = Path(root)
        check_on_missing(on_missing)
        if sequences is None:
            if split not in KITTI_SPLITS:
                raise ValueError(f"Expected split in {tuple(KITTI_SPLITS)} (got {split!r})")
            sequences = KITTI_SPLITS[split]
        if isinstance(sequences, str):
            sequences = [sequences]
        if not isinstance(frame_gap, int) or frame_gap < 1:
            raise ValueError(f"Expected an integer frame_gap >= 1 (got {frame_gap!r})")
        if camera not in _CAMERAS:
            raise ValueError(f"Expected camera in {_CAMERAS} (got {camera!r})")
        self.frame_gap = frame_gap
        self.camera = camera
        #: Per sequence: ``(frames with images, frames with poses)``.
        self.frames: dict[str, tuple[int, int]] = {}
        seq_dir = root / "sequences"
        missing = [s for s in sequences if not (seq_dir / s / camera).is_dir()]
        report_missing(missing, f"Expected KITTI sequences {missing} with a '{camera}' folder "
                       f"under '{seq_dir}' (got {len(missing)} of {len(sequences)} absent)",
                       on_missing)
        self.sequences = [s for s in sequences if s not in missing]
        self.missing_sequences = missing
        records = []
        for seq in self.sequences:
            records.extend(self._sequence_records(root, seq))
        super().__init__(
            records, cache_dir=cache_dir, image_size=image_size, transform=transform,
            kind=f"kitti/{camera}", root=root, **kwargs,
        )

    def _sequence_records(self, root: Path, seq: str) -> list[PairRecord]:
        seq_dir = root / "sequences" / seq
        calib_path = seq_dir / "calib.txt"
        calib = read_kitti_calib(calib_path)
        cam = f"P{self.camera[-1]}"
        if cam not in calib or calib[cam].shape != (3, 4):
            raise KeyError(
                f"Expected a 3x4 '{cam}:' row in '{calib_path}' (got keys {sorted(calib)})"
            )
        P = calib[cam]
        K = P[:, :3].copy()
        # Rectified cameras share the rotation; camera c sits at offset K^-1 P[:, 3] from
        # camera 0 (whose poses the files hold): X_c = X_0 + offset.
        E = np.eye(4)
        E[:3, 3] = np.linalg.solve(K, P[:, 3])
        E_inv = np.linalg.inv(E)
        poses = read_kitti_poses(root / "poses" / f"{seq}.txt")
        frames = {}
        for p in (seq_dir / self.camera).glob("*.png"):
            if p.stem.isdigit():
                frames[int(p.stem)] = p
        beyond = [f for f in frames if f >= len(poses)]
        if beyond:
            raise ValueError(
                f"Expected a pose for every image of sequence {seq} in "
                f"'{root / 'poses' / f'{seq}.txt'}' (got {len(poses)} poses, images up "
                f"to frame {max(beyond)})"
            )
        self.frames[seq] = (len(frames), len(poses))
        if len(frames) < len(poses):
            warn_caller(
                f"KITTI {seq}: images for {len(frames)} of {len(poses)} posed frames in "
                f"'{seq_dir / self.camera}'; pairs use only existing frames"
            )
        records = []
        k = self.frame_gap
        for i in sorted(frames):
            j = i + k
            if j not in frames:
                continue
            T = relative_pose_from_c2w(poses[i], poses[j]).numpy()
            T = E @ T @ E_inv
            records.append(
                PairRecord(
                    pair_id=f"kitti/{seq}/{self.camera}/{i:06d}-{j:06d}",
                    subset=f"KITTI/{seq}",
                    source0=ImageSource(str(frames[i])),
                    source1=ImageSource(str(frames[j])),
                    K0=K,
                    K1=K,
                    T_0to1=T,
                )
            )
        return records
