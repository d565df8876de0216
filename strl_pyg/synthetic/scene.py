"""Procedural 3D scenes of textured planar quads, rich in straight edges.

World frame: ``x`` right, ``y`` **down** (gravity is ``+y``), ``z`` forward, metres. Camera poses
are world-to-camera ``(R_cw, t_cw)`` with ``X_c = R_cw X_w + t_cw`` (OpenCV camera: ``x`` right,
``y`` down, ``z`` along the optical axis).

A :class:`Quad` is the parallelogram ``O + s U + t V`` for ``(s, t)`` in ``[0, 1]^2``. Its texture
is an image whose texel ``(i, j)`` (column, row) has its centre at
``(s, t) = ((i + 0.5) / W_tex, (j + 0.5) / H_tex)``; straight edges drawn into the texture are
kept as segments in ``(s, t)`` so that they become exact 3D ground-truth lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

__all__ = ["SceneConfig", "Quad", "Scene", "build_scene", "SCENE_KINDS"]

SCENE_KINDS = ("street", "indoor", "boxes")


@dataclass
class SceneConfig:
    """Knobs of a generated pair (see :func:`strl_pyg.synthetic.generate_pair`).

    Args:
        kind: ``"street"`` (buildings along a road, driving-like forward motion), ``"indoor"``
            (rooms and corridors with furniture, free hand-held motion) or ``"boxes"`` (boxes
            floating in front of a wall, Scenes11-like, free motion). (default: ``"street"``)
        image_size: ``(H, W)`` of both images. (default: ``(192, 640)``)
        focal_factor: focal length as a fraction of ``W``; ``None`` picks 0.58 for street
            (KITTI-like) and 0.85 otherwise (DeMoN-like). (default: ``None``)
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
        image_noise: std of the grey-level sensor noise added to the images. (default: 1.5)
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

    @property
    def focal(self) -> float:
        f = self.focal_factor
        if f is None:
            f = 0.58 if self.kind == "street" else 0.85
        return float(f) * self.image_size[1]


@dataclass
class Quad:
    """A textured parallelogram ``O + s U + t V`` (world frame, metres).

    ``pyramid`` holds the texture and its ``cv2.pyrDown`` levels (uint8 ``[H_l, W_l]``);
    ``segments`` are straight texture edges ``[M, 2, 2]`` in ``(s, t)``; ``edges`` says
    whether the four borders are ground-truth lines.
    """

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    pyramid: list[np.ndarray]
    segments: np.ndarray
    edges: bool = True

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(self.u, self.v)
        return n / np.linalg.norm(n)

    def corners(self) -> np.ndarray:
        """``[4, 3]`` corners in the order ``O, O+U, O+U+V, O+V``."""
        o, u, v = self.origin, self.u, self.v
        return np.stack([o, o + u, o + u + v, o + v])


@dataclass
class Scene:
    """Quads, 3D ground-truth segments and the two camera poses (world-to-camera).

    ``segments`` ``[S, 2, 3]`` world; ``segment_owner`` ``[S]`` is the index of the quad the
    segment lies on (for box edges, one of the two faces).
    """

    quads: list[Quad]
    segments: np.ndarray
    segment_owner: np.ndarray
    R_cw0: np.ndarray
    t_cw0: np.ndarray
    R_cw1: np.ndarray
    t_cw1: np.ndarray
    background: float = 215.0
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------- textures
class _TextureMaker:
    """Procedural grey textures with their straight edges, from one seeded generator."""

    def __init__(self, rng: np.random.Generator, cfg: SceneConfig) -> None:
        self.rng = rng
        self.cfg = cfg
        # One tile shared by every surface when the texture is repetitive.
        self.tile = self._noise(24, 24, 6, 60.0) if cfg.repetitive_texture else None

    def _noise(self, h: int, w: int, cell: int, amp: float) -> np.ndarray:
        small = self.rng.normal(0.0, 1.0, (max(2, h // cell), max(2, w // cell)))
        return amp * cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)

    def size(self, width_m: float, height_m: float) -> tuple[int, int]:
        tpm, cap = self.cfg.texels_per_metre, self.cfg.max_texture
        scale = min(tpm, cap / max(width_m, height_m))
        return max(8, int(round(height_m * scale))), max(8, int(round(width_m * scale)))

    def base(self, h: int, w: int, level: float) -> np.ndarray:
        rng, cfg = self.rng, self.cfg
        if cfg.low_texture:
            return level + self._noise(h, w, 32, 4.0)
        tex = level + self._noise(h, w, 32, 18.0)
        if cfg.repetitive_texture:
            reps = (h // self.tile.shape[0] + 1, w // self.tile.shape[1] + 1)
            return tex + np.tile(self.tile, reps)[:h, :w]
        cell = int(rng.integers(3, 7))
        return tex + self._noise(h, w, cell, float(rng.uniform(25.0, 45.0)))

    @staticmethod
    def rect(tex: np.ndarray, segs: list, x0: int, y0: int, x1: int, y1: int, value) -> None:
        """Fills texels ``[x0, x1) x [y0, y1)`` and records the four borders in ``(s, t)``."""
        h, w = tex.shape
        x0, x1 = max(0, x0), min(w, x1)
        y0, y1 = max(0, y0), min(h, y1)
        if x1 - x0 < 2 or y1 - y0 < 2:
            return
        tex[y0:y1, x0:x1] = value
        s0, s1, t0, t1 = x0 / w, x1 / w, y0 / h, y1 / h
        segs.extend([[(s0, t0), (s1, t0)], [(s1, t0), (s1, t1)], [(s1, t1), (s0, t1)],
                     [(s0, t1), (s0, t0)]])

    def make(self, style: str, width_m: float, height_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Returns a texture ``[H_t, W_t]`` float and its edges ``[M, 2, 2]`` in ``(s, t)``."""
        rng = self.rng
        h, w = self.size(width_m, height_m)
        level = float(rng.uniform(60, 190))
        tex = self.base(h, w, level)
        segs: list = []
        tpm_x, tpm_y = w / width_m, h / height_m
        if style == "facade":
            self._windows(tex, segs, tpm_x, tpm_y, level)
        elif style in ("floor", "sidewalk"):
            step = float(rng.uniform(0.6, 1.5))
            val = level + rng.choice([-1, 1]) * rng.uniform(25, 50)
            for i in range(1, int(width_m / step) + 1):
                x = int(i * step * tpm_x)
                self.rect(tex, segs, x, 0, x + max(2, int(0.04 * tpm_x)), h, val)
            for j in range(1, int(height_m / step) + 1):
                y = int(j * step * tpm_y)
                self.rect(tex, segs, 0, y, w, y + max(2, int(0.04 * tpm_y)), val)
        elif style == "road":
            # Dashed lane marks along t (the driving direction).
            for lane_s in rng.uniform(0.3, 0.7, size=1):
                x = int(lane_s * w)
                dash, gap = int(2.0 * tpm_y), int(2.5 * tpm_y)
                y = int(rng.integers(0, gap + dash))
                while y < h:
                    self.rect(tex, segs, x, y, x + max(3, int(0.15 * tpm_x)), y + dash, 235.0)
                    y += dash + gap
        elif style in ("wall", "box", "ceiling"):
            n = int(rng.integers(2, 7)) if style != "ceiling" else int(rng.integers(1, 4))
            for _ in range(n):
                rw = int(rng.uniform(0.15, 0.5) * w)
                rh = int(rng.uniform(0.15, 0.5) * h)
                x0 = int(rng.integers(0, max(1, w - rw)))
                y0 = int(rng.integers(0, max(1, h - rh)))
                val = np.clip(level + rng.choice([-1, 1]) * rng.uniform(40, 90), 5, 250)
                inner = self.base(rh, rw, float(val))
                self.rect(tex, segs, x0, y0, x0 + rw, y0 + rh, inner)
        tex = np.clip(tex, 0, 255)
        return tex, np.asarray(segs, dtype=np.float64).reshape(-1, 2, 2)

    def _windows(self, tex, segs, tpm_x, tpm_y, level) -> None:
        rng = self.rng
        h, w = tex.shape
        ww, wh = rng.uniform(0.8, 1.6), rng.uniform(1.0, 1.8)
        sx, sy = ww + rng.uniform(0.6, 2.0), wh + rng.uniform(1.2, 2.0)
        frame_val = np.clip(level + rng.uniform(40, 70), 0, 250)
        glass = float(rng.uniform(20, 60))
        x_m = rng.uniform(0.3, 1.0)
        while (x_m + ww) * tpm_x < w:
            y_m = rng.uniform(0.5, 1.5)
            while (y_m + wh) * tpm_y < h:
                x0, y0 = int(x_m * tpm_x), int(y_m * tpm_y)
                x1, y1 = int((x_m + ww) * tpm_x), int((y_m + wh) * tpm_y)
                f = max(2, int(0.08 * tpm_x))
                self.rect(tex, segs, x0, y0, x1, y1, frame_val)
                shade = glass if self.cfg.repetitive_texture else glass + rng.uniform(-15, 15)
                self.rect(tex, segs, x0 + f, y0 + f, x1 - f, y1 - f, shade)
                y_m += sy
            x_m += sx


def _pyramid(tex: np.ndarray) -> list[np.ndarray]:
    levels = [np.clip(tex, 0, 255).astype(np.uint8)]
    while min(levels[-1].shape) >= 16 and len(levels) < 6:
        levels.append(cv2.pyrDown(levels[-1]))
    return levels


# ---------------------------------------------------------------- scene builders
class _Builder:
    def __init__(self, rng: np.random.Generator, cfg: SceneConfig) -> None:
        self.rng = rng
        self.tex = _TextureMaker(rng, cfg)
        self.quads: list[Quad] = []
        self.segments: list[np.ndarray] = []
        self.owner: list[int] = []

    def quad(self, origin, u, v, style: str, edges: bool = True) -> int:
        origin, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
        tex, segs = self.tex.make(style, float(np.linalg.norm(u)), float(np.linalg.norm(v)))
        q = Quad(origin, u, v, _pyramid(tex), segs, edges)
        self.quads.append(q)
        idx = len(self.quads) - 1
        for (s0, t0), (s1, t1) in segs:
            self.segments.append(np.stack([origin + s0 * u + t0 * v, origin + s1 * u + t1 * v]))
            self.owner.append(idx)
        if edges:
            c = q.corners()
            for k in range(4):
                self.segments.append(np.stack([c[k], c[(k + 1) % 4]]))
                self.owner.append(idx)
        return idx

    def box(self, center, size, yaw: float = 0.0, style: str = "box", faces=None) -> None:
        """An axis-aligned-in-yaw box; ``faces`` limits which faces are built."""
        cy, sy_ = np.cos(yaw), np.sin(yaw)
        R = np.array([[cy, 0, sy_], [0, 1, 0], [-sy_, 0, cy]])
        hx, hy, hz = np.asarray(size, dtype=np.float64) / 2
        c = np.asarray(center, dtype=np.float64)

        def p(x, y, z):
            return c + R @ np.array([x, y, z])

        all_faces = {
            "front": (p(-hx, -hy, -hz), p(hx, -hy, -hz) - p(-hx, -hy, -hz),
                      p(-hx, hy, -hz) - p(-hx, -hy, -hz)),
            "back": (p(hx, -hy, hz), p(-hx, -hy, hz) - p(hx, -hy, hz),
                     p(hx, hy, hz) - p(hx, -hy, hz)),
            "left": (p(-hx, -hy, hz), p(-hx, -hy, -hz) - p(-hx, -hy, hz),
                     p(-hx, hy, hz) - p(-hx, -hy, hz)),
            "right": (p(hx, -hy, -hz), p(hx, -hy, hz) - p(hx, -hy, -hz),
                      p(hx, hy, -hz) - p(hx, -hy, -hz)),
            "top": (p(-hx, -hy, hz), p(hx, -hy, hz) - p(-hx, -hy, hz),
                    p(-hx, -hy, -hz) - p(-hx, -hy, hz)),
        }
        for name in faces or all_faces:
            self.quad(*all_faces[name], style=style)

    def scene(self, R0, t0, R1, t1, **extra) -> Scene:
        segs = np.asarray(self.segments, dtype=np.float64).reshape(-1, 2, 3)
        owner = np.asarray(self.owner, dtype=np.int64)
        return Scene(self.quads, segs, owner, R0, t0, R1, t1, extra=extra)


def _rot(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Camera-to-world rotation for a camera yawed about ``y``, pitched about ``x``, rolled
    about ``z`` (radians)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    Rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return Ry @ Rx @ Rz


def _w2c(R_wc: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return R_wc.T, -R_wc.T @ c


def _street(b: _Builder, rng: np.random.Generator) -> Scene:
    cam_h = 1.65
    road_half = float(rng.uniform(3.0, 6.0))
    walk = float(rng.uniform(1.5, 3.0))
    z0, z1, tile = -6.0, 90.0, 6.0
    for z in np.arange(z0, z1, tile):
        b.quad([-road_half, cam_h, z], [2 * road_half, 0, 0], [0, 0, tile], "road")
        for side in (-1, 1):
            x_in = side * road_half
            x_out = side * (road_half + walk)
            b.quad([min(x_in, x_out), cam_h - 0.15, z], [walk, 0, 0], [0, 0, tile], "sidewalk")
    for side in (-1, 1):  # curbs: long vertical strips, one texture per tile
        for z in np.arange(z0, z1, tile):
            b.quad([side * road_half, cam_h - 0.15, z], [0, 0, tile], [0, 0.15, 0], "box")
    for side in (-1, 1):
        z = float(rng.uniform(-8.0, 0.0))
        while z < z1:
            length = float(rng.uniform(6.0, 16.0))
            height = float(rng.uniform(5.0, 18.0))
            depth = 8.0
            setback = float(rng.uniform(0.0, 2.5))
            x_face = side * (road_half + walk + setback)
            center = [x_face + side * depth / 2, cam_h - 0.15 - height / 2, z + length / 2]
            # Only faces that can be seen from the road.
            faces = ["front", "back", "left" if side > 0 else "right"]
            b.box(center, [depth, height, length], style="facade", faces=faces)
            z += length + float(rng.uniform(0.0, 4.0))
        for _ in range(int(rng.integers(1, 4))):  # parked cars and poles
            zc = float(rng.uniform(4.0, 40.0))
            if rng.random() < 0.5:
                xc = side * (road_half - 1.2)
                b.box([xc, cam_h - 0.75, zc], [1.8, 1.5, 4.2], style="box",
                      faces=["front", "back", "left", "right", "top"])
            else:
                xc = side * (road_half + 0.5)
                b.box([xc, cam_h - 0.15 - 2.5, zc], [0.25, 5.0, 0.25], style="box",
                      faces=["front", "left", "right"])
    c0 = np.array([rng.uniform(-1.0, 1.0), 0.0, 0.0])
    yaw0 = rng.uniform(-0.08, 0.08)
    R_wc0 = _rot(yaw0, rng.uniform(-0.03, 0.03), rng.uniform(-0.02, 0.02))
    step = float(rng.uniform(0.6, 1.6))
    c1 = c0 + R_wc0 @ np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02), step])
    R_wc1 = R_wc0 @ _rot(rng.uniform(-0.05, 0.05), rng.uniform(-0.01, 0.01), 0.0)
    return b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc1, c1))


def _indoor(b: _Builder, rng: np.random.Generator) -> Scene:
    corridor = rng.random() < 0.35
    W = float(rng.uniform(1.8, 2.8) if corridor else rng.uniform(4.0, 8.0))
    D = float(rng.uniform(12.0, 20.0) if corridor else rng.uniform(5.0, 10.0))
    H = float(rng.uniform(2.5, 3.2))
    # Floor at y = 0, ceiling at y = -H, room spans x in [-W/2, W/2], z in [-D/2, D/2].
    x0, x1, z0, z1 = -W / 2, W / 2, -D / 2, D / 2
    b.quad([x0, 0, z0], [W, 0, 0], [0, 0, D], "floor")
    b.quad([x0, -H, z1], [W, 0, 0], [0, 0, -D], "ceiling")
    b.quad([x0, -H, z1], [W, 0, 0], [0, H, 0], "wall")  # far wall (z = z1)
    b.quad([x1, -H, z0], [-W, 0, 0], [0, H, 0], "wall")  # near wall (z = z0)
    wall_step = 4.0
    for zs in np.arange(z0, z1, wall_step):  # side walls in panels of <= 4 m
        dz = min(wall_step, z1 - zs)
        b.quad([x0, -H, zs + dz], [0, 0, -dz], [0, H, 0], "wall")
        b.quad([x1, -H, zs], [0, 0, dz], [0, H, 0], "wall")
    n_boxes = int(rng.integers(1, 4) if corridor else rng.integers(3, 8))
    for _ in range(n_boxes):
        sx, sy, sz = rng.uniform(0.4, 1.5), rng.uniform(0.4, 1.6), rng.uniform(0.4, 1.5)
        sx = min(sx, W / 3)
        side = rng.choice([-1, 1])
        cx = side * (W / 2 - sx / 2 - rng.uniform(0.0, 0.3 if corridor else W / 4))
        cz = rng.uniform(z0 + 1.0, z1 - 1.0)
        b.box([cx, -sy / 2, cz], [sx, sy, sz], yaw=float(rng.uniform(-0.4, 0.4)))
    margin = 0.5 if corridor else 1.0
    c0 = np.array([rng.uniform(x0 + margin / 2, x1 - margin / 2) * 0.5, -rng.uniform(1.2, 1.8),
                   rng.uniform(z0 + 1.0, z0 + D / 3)])
    yaw = rng.uniform(-0.3, 0.3) if corridor else rng.uniform(-0.9, 0.9)
    R_wc0 = _rot(yaw, rng.uniform(-0.15, 0.15), rng.uniform(-0.05, 0.05))
    d = rng.normal(size=3)
    d[2] = abs(d[2])  # mostly forward: the second view keeps looking into the room
    c1 = c0 + R_wc0 @ (d / np.linalg.norm(d) * rng.uniform(0.2, 0.7))
    R_wc1 = R_wc0 @ _rot(*rng.uniform(-0.12, 0.12, size=3))
    return b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc1, c1), corridor=bool(corridor))


def _boxes(b: _Builder, rng: np.random.Generator) -> Scene:
    b.quad([-14, -9, 18], [28, 0, 0], [0, 18, 0], "wall")
    for _ in range(int(rng.integers(6, 14))):
        size = rng.uniform(0.5, 2.5, size=3)
        center = [rng.uniform(-5, 5), rng.uniform(-2.5, 2.5), rng.uniform(4.0, 14.0)]
        b.box(center, size, yaw=float(rng.uniform(-np.pi, np.pi)),
              faces=["front", "back", "left", "right", "top"])
    c0 = np.zeros(3)
    R_wc0 = _rot(*rng.uniform(-0.1, 0.1, size=3))
    d = rng.normal(size=3)
    c1 = c0 + R_wc0 @ (d / np.linalg.norm(d) * rng.uniform(0.3, 1.0))
    R_wc1 = R_wc0 @ _rot(*rng.uniform(-0.1, 0.1, size=3))
    return b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc1, c1))


def build_scene(rng: np.random.Generator, cfg: SceneConfig) -> Scene:
    """Builds the quads, 3D segments and both camera poses of one scene from ``rng``."""
    builder = _Builder(rng, cfg)
    make = {"street": _street, "indoor": _indoor, "boxes": _boxes}[cfg.kind]
    return make(builder, rng)
