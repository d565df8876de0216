"""The knobs of one generated pair: :class:`SceneConfig`, the scene kinds and camera motions.

Every new knob defaults to "off", so ``SceneConfig(kind=...)`` with the legacy fields gives the
same pairs, bit for bit, as before the knobs existed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SceneConfig", "SCENE_KINDS", "LINE_SCENE_KINDS", "MOTIONS", "DEFAULT_MOTION"]

#: Every scene kind.
SCENE_KINDS = ("street", "indoor", "boxes", "object")
#: The kinds built of long straight structure (all but the single textured object): the
#: default mix of training on one kind each, of the evaluation tables and of the front-end
#: benchmark.
LINE_SCENE_KINDS = SCENE_KINDS[:3]

#: Camera motions (see :mod:`strl_pyg.synthetic.motion` for their ranges).
MOTIONS = ("forward", "lateral", "orbit", "handheld", "rotation", "wide")

#: The motion of each kind when ``SceneConfig.motion`` is ``None``: ``"legacy"`` is the kind's
#: original motion (street: driving forward; indoor: hand-held, mostly forward; boxes: free).
DEFAULT_MOTION = {"street": "legacy", "indoor": "legacy", "boxes": "legacy", "object": "orbit"}


@dataclass
class SceneConfig:
    """Knobs of a generated pair (see :func:`strl_pyg.synthetic.generate_pair`).

    Args:
        kind: ``"street"`` (buildings along a road), ``"indoor"`` (rooms and corridors with
            furniture), ``"boxes"`` (boxes floating in front of a wall, Scenes11-like) or
            ``"object"`` (one object made of boxes on a dark or empty background, seen from a
            camera orbiting it, Middlebury-dino-like). (default: ``"street"``)
        image_size: ``(H, W)`` of both images. (default: ``(192, 640)``)
        focal_factor: focal length as a fraction of ``W``; ``None`` picks 0.58 for street
            (KITTI-like) and 0.85 otherwise (DeMoN-like). (default: ``None``)
        principal_offset: ``(dx, dy)`` offset of the principal point from the image centre
            ``((W - 1) / 2, (H - 1) / 2)`` as fractions of ``(W, H)``, each in
            ``[-0.25, 0.25]``. (default: ``(0.0, 0.0)``)
        motion: camera motion from view 0 to view 1, one of :data:`MOTIONS`, or ``None`` for
            the kind's own (:data:`DEFAULT_MOTION`). (default: ``None``)
        baseline_scale: factor on the camera translation after the motion is drawn: the scene
            depth relative to the baseline (``> 1``: more parallax). Must be 1 for the orbit
            and wide motions (and the object kind's default, orbit), whose baseline follows
            from the orbit angle with camera 1 fixating the centre. (default: ``1.0``)
        swap_views: render view 1 as image 0 and view 0 as image 1 (forward motion becomes
            backward motion). (default: False)
        noise_px: std of the Gaussian noise added to every ground-truth coordinate, pixels.
            (default: ``0.0``)
        outlier_fraction: fraction of point and line matches replaced by wrong ones, in
            ``[0, 1)``. (default: ``0.0``)
        low_texture: flat, weakly textured surfaces (few blobs; edges remain). (default: False)
        repetitive_texture: one small pattern tiled over all surfaces, identical windows.
            (default: False)
        max_points, max_lines: caps on the ground-truth matches kept. (default: 512, 256)
        min_line_length: shortest ground-truth segment kept, pixels in both images.
            (default: 15.0)
        texels_per_metre: texture resolution before the cap of ``max_texture`` texels.
            (default: 48.0, 512)
        image_noise: std of the grey-level sensor noise added to both images. (default: 1.5)
        photo_gain, photo_gamma, photo_blur, photo_noise: photometric change of **image 1
            only**, applied after rendering and sensor noise: ``255 gain (I / 255) ^ gamma``,
            then a Gaussian blur of std ``photo_blur`` pixels, then Gaussian grey-level noise of
            std ``photo_noise`` (seeded by the pair's seed). (default: ``1.0, 1.0, 0.0, 0.0``,
            no change)
        near: near clipping distance, metres. (default: 0.05)
    """

    kind: str = "street"
    image_size: tuple[int, int] = (192, 640)
    focal_factor: float | None = None
    noise_px: float = 0.0
    outlier_fraction: float = 0.0
    low_texture: bool = False
    repetitive_texture: bool = False
    max_points: int = 512
    max_lines: int = 256
    min_line_length: float = 15.0
    texels_per_metre: float = 48.0
    max_texture: int = 512
    image_noise: float = 1.5
    near: float = 0.05
    principal_offset: tuple[float, float] = (0.0, 0.0)
    motion: str | None = None
    baseline_scale: float = 1.0
    swap_views: bool = False
    photo_gain: float = 1.0
    photo_gamma: float = 1.0
    photo_blur: float = 0.0
    photo_noise: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in SCENE_KINDS:
            raise ValueError(f"Expected kind in {SCENE_KINDS} (got {self.kind!r})")
        size = tuple(int(v) for v in self.image_size)
        if len(size) != 2 or min(size) < 16:
            raise ValueError(f"Expected image_size (H, W) both >= 16 (got {self.image_size!r})")
        self.image_size = size
        if not 0.0 <= self.outlier_fraction < 1.0:
            raise ValueError(
                f"Expected outlier_fraction in [0, 1) (got {self.outlier_fraction})"
            )
        if self.noise_px < 0 or self.image_noise < 0:
            raise ValueError(
                f"Expected noise_px, image_noise >= 0 (got {self.noise_px}, {self.image_noise})"
            )
        if self.max_points < 0 or self.max_lines < 0:
            raise ValueError(
                f"Expected max_points, max_lines >= 0 (got {self.max_points}, {self.max_lines})"
            )
        if self.max_points + self.max_lines == 0:
            raise ValueError("Expected max_points + max_lines > 0 (got 0)")
        if self.focal_factor is not None and not (
            np.isfinite(self.focal_factor) and self.focal_factor > 0
        ):
            raise ValueError(f"Expected a positive focal_factor (got {self.focal_factor})")
        off = tuple(float(v) for v in self.principal_offset)
        if len(off) != 2 or not all(abs(v) <= 0.25 for v in off):
            raise ValueError(
                f"Expected principal_offset (dx, dy) in [-0.25, 0.25] (got "
                f"{self.principal_offset!r})"
            )
        self.principal_offset = off
        if self.motion is not None and self.motion not in MOTIONS:
            raise ValueError(f"Expected motion in {MOTIONS} or None (got {self.motion!r})")
        if not (np.isfinite(self.baseline_scale) and self.baseline_scale > 0):
            raise ValueError(f"Expected a positive baseline_scale (got {self.baseline_scale})")
        if self.baseline_scale != 1.0 and self.resolved_motion in ("orbit", "wide"):
            raise ValueError(
                f"Expected baseline_scale 1.0 with the {self.resolved_motion!r} motion, whose "
                f"baseline follows from the orbit angle (got {self.baseline_scale})"
            )
        if not (self.photo_gain > 0 and self.photo_gamma > 0):
            raise ValueError(
                f"Expected photo_gain, photo_gamma > 0 (got {self.photo_gain}, "
                f"{self.photo_gamma})"
            )
        if self.photo_blur < 0 or self.photo_noise < 0:
            raise ValueError(
                f"Expected photo_blur, photo_noise >= 0 (got {self.photo_blur}, "
                f"{self.photo_noise})"
            )

    @property
    def focal(self) -> float:
        f = self.focal_factor
        if f is None:
            f = 0.58 if self.kind == "street" else 0.85
        return float(f) * self.image_size[1]

    @property
    def resolved_motion(self) -> str:
        """The motion used: :attr:`motion`, or the kind's default (``"legacy"`` or
        ``"orbit"``)."""
        return self.motion if self.motion is not None else DEFAULT_MOTION[self.kind]

    @property
    def has_photometric(self) -> bool:
        return (self.photo_gain, self.photo_gamma, self.photo_blur, self.photo_noise) != (
            1.0, 1.0, 0.0, 0.0)

    def intrinsics(self) -> np.ndarray:
        """``K [3, 3]`` float64 of both views (pixels, OpenCV convention)."""
        h, w = self.image_size
        f = self.focal
        cx, cy = (w - 1) / 2, (h - 1) / 2
        if self.principal_offset != (0.0, 0.0):
            cx, cy = cx + self.principal_offset[0] * w, cy + self.principal_offset[1] * h
        return np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]])
