"""Posed photographs: image folders with known cameras, in the formats people have, and the
pairs of them that overlap.

Every reader (:mod:`strl_pyg.datasets.camera_files`) returns a list of :class:`PosedImage` in one
convention: ``K`` ``[3, 3]`` in
pixels of the image file, OpenCV pixel centres (the top-left pixel's centre is ``(0, 0)``) and
``T_c2w`` ``[4, 4]`` camera-to-world with OpenCV camera axes (x right, y down, z forward). The
relative pose of a pair is then ``T_0to1 = inv(T_c2w[1]) @ T_c2w[0]`` (``X1 = R X0 + t``).

Formats and their conventions:

* **real_scenes** (``cameras.json``, the layout of ``shared/data/real_scenes``): already in the
  convention above.
* **COLMAP** (``cameras.txt`` / ``images.txt`` or ``cameras.bin`` / ``images.bin``): images
  store world-to-camera ``(qw, qx, qy, qz, tx, ty, tz)`` in OpenCV axes, inverted here; COLMAP
  puts the top-left pixel's *corner* at ``(0, 0)``, so the principal point is shifted by
  -0.5 px. Lens distortion is kept in :attr:`PosedImage.distortion` (undistort the images,
  e.g. with ``colmap image_undistorter``, before using them as pinhole views).
* **NeRF / instant-ngp** ``transforms.json``: camera-to-world in OpenGL axes (x right, y up,
  z back), converted by ``T @ diag(1, -1, -1, 1)``; the focal length from ``fl_x`` / ``fl_y``
  or ``camera_angle_x``; ``cx`` / ``cy`` in the corner convention (shifted by -0.5 px),
  the image centre when absent.
* **LLFF** ``poses_bounds.npy``: ``[N, 17]`` rows, a 3x5 ``[R | t | hwf]`` camera-to-world
  with rotation columns (down, right, back) reordered to (right, down, forward), then two
  depth bounds; ``hwf`` is the full-size height, width and focal length, scaled to the image
  files found, principal point at the centre.

Pairs are chosen by view overlap (:func:`select_pairs`): capture-order gaps, a relative
rotation range, the angle between the optical axes and, where the model has them, the share
of 3D points both images see (COLMAP), as glue-factory samples MegaDepth by overlap.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.datasets.base import ImageSource, PairDataset, PairRecord
from strl_pyg.datasets.camera_files import (
    PosedImage,
    check_pinhole,
    posed_format,
    read_posed_folder,
)

__all__ = ["PosedPairOptions", "REAL_SCENES_SPLIT", "select_pairs", "PosedImagePairs"]

REAL_SCENES_SPLIT = {
    "val": ("drone_hall", "fruit", "ethiopian_head", "office_drink"),
    "train": ("beer_can", "bird_figurine", "blowtorch", "cup", "mary_rose_tankard",
              "mold_gold_cape", "office_chair", "robot_table", "rooftop", "stitch_toy",
              "study_room"),
}

# -- pairs -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class PosedPairOptions:
    """How :func:`select_pairs` chooses pairs of a scene.

    Args:
        gaps: Capture-order gaps ``k`` of the candidate pairs ``(i, i + k)``.
        stride: Take every ``stride``-th first image ``i``.
        min_rotation_deg, max_rotation_deg: Range of the relative rotation angle.
        max_axis_angle_deg: Largest angle between the two optical axes (views that face
            apart share little).
        min_covisible: Smallest share of co-visible 3D points: the points both images see
            over the points of the image that sees fewer (COLMAP models with point tracks;
            ignored where the images carry no point ids).
        min_baseline: Smallest baseline over the median baseline of the gap-1 pairs of the
            scene (units differ per reconstruction; 0: any).
    """

    gaps: tuple[int, ...] = (1, 2, 3)
    stride: int = 1
    min_rotation_deg: float = 0.0
    max_rotation_deg: float = 60.0
    max_axis_angle_deg: float = 70.0
    min_covisible: float = 0.1
    min_baseline: float = 0.0

    def __post_init__(self) -> None:
        if not self.gaps or any(not isinstance(g, int) or g < 1 for g in self.gaps):
            raise ValueError(f"Expected gaps as positive integers (got {self.gaps!r})")
        if not isinstance(self.stride, int) or self.stride < 1:
            raise ValueError(f"Expected a positive integer stride (got {self.stride!r})")
        if not 0 <= self.min_rotation_deg <= self.max_rotation_deg <= 180:
            raise ValueError(f"Expected 0 <= min_rotation_deg <= max_rotation_deg <= 180 (got "
                             f"{self.min_rotation_deg}, {self.max_rotation_deg})")


def _rotation_deg(R: np.ndarray) -> float:
    from strl_pyg.geometry.pose import rotation_angle_deg

    return float(rotation_angle_deg(np.asarray(R, dtype=np.float64)))


def select_pairs(images: Sequence[PosedImage], options: PosedPairOptions | None = None
                 ) -> list[tuple[int, int]]:
    """Pairs ``(i, j)`` of ``images`` (capture order) that overlap by ``options``."""
    o = options or PosedPairOptions()
    n = len(images)
    centres = np.array([im.T_c2w[:3, 3] for im in images]) if n else np.zeros((0, 3))
    step = np.linalg.norm(np.diff(centres, axis=0), axis=1) if n > 1 else np.zeros(0)
    unit = float(np.median(step)) if len(step) else 0.0
    out = []
    for i in range(0, n, o.stride):
        for k in o.gaps:
            j = i + k
            if j >= n:
                continue
            a, b = images[i], images[j]
            R = b.T_c2w[:3, :3].T @ a.T_c2w[:3, :3]
            rot = _rotation_deg(R)
            if not o.min_rotation_deg <= rot <= o.max_rotation_deg:
                continue
            axis = float(np.degrees(np.arccos(np.clip(a.T_c2w[:3, 2] @ b.T_c2w[:3, 2], -1, 1))))
            if axis > o.max_axis_angle_deg:
                continue
            if o.min_baseline > 0 and unit > 0 and \
                    np.linalg.norm(centres[j] - centres[i]) < o.min_baseline * unit:
                continue
            if a.points is not None and b.points is not None and o.min_covisible > 0:
                union = min(len(a.points), len(b.points))
                if union == 0 or len(a.points & b.points) / union < o.min_covisible:
                    continue
            out.append((i, j))
    return out


class PosedImagePairs(PairDataset):
    """Pair graphs of posed photographs: scene folders in any format of
    :func:`read_posed_folder`, pairs by :func:`select_pairs`, front-end matches cached once.

    Args:
        scenes: Scene folders (or ``(name, images)`` tuples of already read scenes).
        cache_dir: Root of the match cache.
        pairs: A :class:`PosedPairOptions` (default: gaps 1-3, every image).
        image_size: ``(H, W)`` to resize to before matching (``None``: keep the files' size,
            as stored in ``real_scenes``).
        **kwargs: ``frontend_config``, ``patch_size``, ``keep_images``, ``grayscale``,
            ``limit``, ``transform``, ``min_points``, ``min_lines`` of :class:`PairDataset`.

    Items carry ``subset`` = the scene's name, ``pair_id`` = ``"scene/i-j"``.
    """

    def __init__(
        self,
        scenes: Sequence[str | os.PathLike | tuple[str, Sequence[PosedImage]]],
        *,
        cache_dir: str | os.PathLike,
        pairs: PosedPairOptions | None = None,
        image_size: tuple[int, int] | None = None,
        transform: Callable | None = None,
        **kwargs: Any,
    ) -> None:
        self.pair_options = pairs or PosedPairOptions()
        records = []
        self.scene_names = []
        #: scene name -> (images, pairs kept by the pair options)
        self.scene_counts: dict[str, tuple[int, int]] = {}
        self._colmap = False
        for scene in scenes:
            if isinstance(scene, tuple):
                name, images = scene
            else:
                name, images = Path(scene).name, read_posed_folder(scene)
                self._colmap = self._colmap or posed_format(scene) == "colmap"
            self.scene_names.append(name)
            for im in images:
                check_pinhole(im, f"scene '{name}'")
            chosen = select_pairs(images, self.pair_options)
            self.scene_counts[name] = (len(images), len(chosen))
            if not chosen:
                warnings.warn(f"Expected pairs from scene '{name}' (got none of its "
                              f"{len(images)} images: {self._rules()})", stacklevel=2)
            for i, j in chosen:
                a, b = images[i], images[j]
                T = np.linalg.inv(b.T_c2w) @ a.T_c2w
                records.append(PairRecord(f"{name}/{i:04d}-{j:04d}", name, ImageSource(a.path),
                                          ImageSource(b.path), a.K, b.K, T))
        super().__init__(records, cache_dir=cache_dir, image_size=image_size,
                         transform=transform, kind="posed", **kwargs)

    def _make_fingerprint(self) -> dict[str, Any]:
        fp = super()._make_fingerprint()
        if self._colmap:
            # a pair's id holds the images' positions: COLMAP's order (numbers in names as
            # numbers) must not meet entries cached under the text order
            fp["colmap_order"] = "natural"
        return fp

    def _rules(self) -> str:
        o = self.pair_options
        return (f"pairs (i, i + k) for k in {list(o.gaps)}, i in steps of {o.stride}, relative "
                f"rotation {o.min_rotation_deg:g}-{o.max_rotation_deg:g} deg, optical axes "
                f"within {o.max_axis_angle_deg:g} deg, co-visible share >= {o.min_covisible:g}"
                f", baseline >= {o.min_baseline:g} x the median step")

    def no_pairs_reason(self) -> str:
        """Why the scenes gave no pair: each scene's images and kept pairs, and the rules."""
        scenes = ", ".join(f"{n}: {k} pairs of {m} images"
                           for n, (m, k) in self.scene_counts.items())
        kept = sum(k for _, k in self.scene_counts.values())
        if kept:  # the scenes gave pairs: the limit cut them
            return f"{scenes}; limit={len(self.records)} keeps {len(self.records)} of them"
        return f"{scenes}; the pair options keep {self._rules()}"
