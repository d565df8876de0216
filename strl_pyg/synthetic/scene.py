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

import numpy as np

from strl_pyg.synthetic.config import SceneConfig
from strl_pyg.synthetic.motion import _rot, look_at, move_camera, scene_depth
from strl_pyg.synthetic.textures import TextureMaker, pyramid

__all__ = ["Quad", "Scene", "build_scene"]

#: Per kind: the range the scene depth ``d`` of view 0 is clamped to (metres). The builders
#: store the largest translation of the new motions as ``extra["room"]`` (free space).
_DEPTH_RANGE = {"street": (4.0, 20.0), "indoor": (1.0, 6.0), "boxes": (3.0, 15.0)}


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
    gradient: float = 12.0  # background gradient, +- grey levels from top to bottom


# ---------------------------------------------------------------- scene builders
class _Builder:
    def __init__(self, rng: np.random.Generator, cfg: SceneConfig) -> None:
        self.rng = rng
        self.tex = TextureMaker(rng, cfg)
        self.quads: list[Quad] = []
        self.segments: list[np.ndarray] = []
        self.owner: list[int] = []

    def quad(self, origin, u, v, style: str, edges: bool = True) -> int:
        origin, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
        tex, segs = self.tex.make(style, float(np.linalg.norm(u)), float(np.linalg.norm(v)))
        q = Quad(origin, u, v, pyramid(tex), segs, edges)
        self.quads.append(q)
        idx = len(self.quads) - 1
        if len(segs):  # every segment's two endpoints at once: [K, 2, 3]
            st = np.asarray(segs, dtype=np.float64).reshape(-1, 2, 2)
            ends = origin + st[..., 0:1] * u + st[..., 1:2] * v
            self.segments.extend(ends)
            self.owner.extend([idx] * len(ends))
        if edges:
            c = q.corners()
            for k in range(4):
                self.segments.append(np.stack([c[k], c[(k + 1) % 4]]))
                self.owner.append(idx)
        return idx

    def box(self, center, size, yaw: float = 0.0, style: str = "box", faces=None) -> None:
        """An axis-aligned-in-yaw box; ``faces`` limits which faces are built (default: all but
        ``"bottom"``)."""
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
            "bottom": (p(-hx, hy, -hz), p(hx, hy, -hz) - p(-hx, hy, -hz),
                       p(-hx, hy, hz) - p(-hx, hy, -hz)),
        }
        for name in faces or ("front", "back", "left", "right", "top"):
            self.quad(*all_faces[name], style=style)

    def scene(self, R0, t0, R1, t1, **extra) -> Scene:
        segs = np.asarray(self.segments, dtype=np.float64).reshape(-1, 2, 3)
        owner = np.asarray(self.owner, dtype=np.int64)
        return Scene(self.quads, segs, owner, R0, t0, R1, t1, extra=extra)


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
    room = max(1.0, road_half - 1.0 - abs(float(c0[0])))
    return b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc1, c1), room=room)


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
    return b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc1, c1), corridor=bool(corridor),
                   room=0.35 * min(W, H))


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
    return b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc1, c1), room=2.5)


_ALL_FACES = ("front", "back", "left", "right", "top", "bottom")


def _object(b: _Builder, rng: np.random.Generator, cfg: SceneConfig) -> Scene:
    """One object made of boxes (a box, a stack, a cross or an L) standing on ``y = 0``, with
    textured or weak (plaster-like) faces, on an empty dark background, a dark turntable or a
    dark backdrop; camera 0 on a sphere around it, looking at its centre."""
    size = float(np.exp(rng.uniform(np.log(0.2), np.log(3.0))))  # object scale, metres
    b.tex.density = max(1.0, 5.3 / size)  # about 256 texels across the object
    style = "weak" if rng.random() < 0.4 else "box"
    shape = str(rng.choice(["box", "stack", "cross", "ell"]))
    backdrop = str(rng.choice(["none", "ground", "backdrop"], p=[0.5, 0.3, 0.2]))
    faces = _ALL_FACES[:5] if backdrop == "ground" else _ALL_FACES
    if shape == "box":
        sx, sy, sz = size * rng.uniform([0.5, 0.5, 0.5], [1.0, 1.2, 1.0])
        b.box([0, -sy / 2, 0], [sx, sy, sz], yaw=float(rng.uniform(-np.pi, np.pi)),
              style=style, faces=faces)
    elif shape == "stack":
        y, foot = 0.0, size
        for _ in range(int(rng.integers(2, 5))):
            sy = size * rng.uniform(0.2, 0.5)
            sx, sz = foot * rng.uniform(0.6, 1.0), foot * rng.uniform(0.6, 1.0)
            b.box([0, y - sy / 2, 0], [sx, sy, sz], yaw=float(rng.uniform(-np.pi, np.pi)),
                  style=style, faces=faces)
            y, foot = y - sy, 0.75 * min(sx, sz)
    else:
        yaw = float(rng.uniform(-np.pi, np.pi))
        sy = size * rng.uniform(0.3, 0.8)
        long, thin = size, size * rng.uniform(0.25, 0.4)
        b.box([0, -sy / 2, 0], [long, sy, thin], yaw=yaw, style=style, faces=faces)
        if shape == "cross":
            b.box([0, -sy * 0.6, 0], [long * 0.8, sy * 1.2, thin], yaw=yaw + np.pi / 2,
                  style=style, faces=faces)
        else:
            off = np.array([np.cos(yaw), 0, -np.sin(yaw)]) * (long - thin) / 2
            b.box([off[0], -sy, off[2]], [thin, 2 * sy, thin * 1.5], yaw=yaw, style=style,
                  faces=faces)
    n_object = len(b.quads)
    corners = np.concatenate([q.corners() for q in b.quads])
    lo, hi = corners.min(0), corners.max(0)
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(corners - centre, axis=1).max())
    # Camera 0: the object spans a fraction `fill` of the shorter image side.
    fill = rng.uniform(0.8, 1.4)
    dist = max(1.5 * radius, radius * cfg.focal / (fill * min(cfg.image_size) / 2))
    az, el = rng.uniform(-np.pi, np.pi), rng.uniform(5, 50) * np.pi / 180
    c0 = centre + dist * np.array([np.cos(el) * np.sin(az), -np.sin(el), -np.cos(el) * np.cos(az)])
    target = centre + rng.normal(0.0, 0.05 * radius, 3)
    R_wc0 = look_at(c0, target, rng.uniform(-5, 5) * np.pi / 180)
    if backdrop == "ground":  # a dark turntable just below the object
        half = 0.8 * max(hi[0] - lo[0], hi[2] - lo[2])
        g = 0.01 * size
        b.quad([centre[0] - half, g, centre[2] - half], [2 * half, 0, 0], [0, 0, 2 * half], "dark")
    elif backdrop == "backdrop":  # a dark screen behind the object, facing camera 0
        x, y = R_wc0[:, 0] * 2.5 * radius, R_wc0[:, 1] * 2.5 * radius
        o = centre + R_wc0[:, 2] * 1.5 * radius - (x + y) / 2
        b.quad(o, x, y, "dark")
    scene = b.scene(*_w2c(R_wc0, c0), *_w2c(R_wc0, c0), centre=centre, radius=dist,
                    object_quads=n_object, backdrop=backdrop, shape=shape, style=style)
    scene.background = float(rng.uniform(0.0, 30.0))
    scene.gradient = float(rng.uniform(0.0, 3.0))
    return scene


def build_scene(rng: np.random.Generator, cfg: SceneConfig) -> Scene:
    """Builds the quads, 3D segments and both camera poses of one scene from ``rng``.

    The kind's builder places camera 0 (and, for the legacy motions, camera 1); any other
    motion then redraws camera 1 (:func:`strl_pyg.synthetic.motion.move_camera`, its
    translation capped at the kind's free space, an orbit centred near enough to fit it),
    ``baseline_scale`` scales the translation and ``swap_views`` swaps the two cameras.
    """
    builder = _Builder(rng, cfg)
    if cfg.kind == "object":
        scene = _object(builder, rng, cfg)
    else:
        scene = {"street": _street, "indoor": _indoor, "boxes": _boxes}[cfg.kind](builder, rng)
    motion = cfg.resolved_motion
    scale = cfg.baseline_scale
    if motion != "legacy" or scale != 1.0:
        R_wc0, c0 = scene.R_cw0.T, -scene.R_cw0.T @ scene.t_cw0
        R_wc1, c1 = scene.R_cw1.T, -scene.R_cw1.T @ scene.t_cw1
        if motion != "legacy":
            centre = scene.extra.get("centre")
            room = scene.extra.get("room", np.inf)
            if centre is not None:
                depth = scene.extra["radius"]
            else:
                lo, hi = _DEPTH_RANGE[cfg.kind]
                depth = float(np.clip(scene_depth(scene.quads, c0, R_wc0), lo, hi))
            R_wc1, c1 = move_camera(motion, rng, R_wc0, c0, depth, centre, room)
            scene.extra["depth"] = depth
        step = (c1 - c0) * scale
        room = scene.extra.get("room", np.inf) if motion != "legacy" else np.inf
        if np.linalg.norm(step) > room:
            step = step * (room / np.linalg.norm(step))
        scene.R_cw1, scene.t_cw1 = _w2c(R_wc1, c0 + step)
    if cfg.swap_views:
        scene.R_cw0, scene.t_cw0, scene.R_cw1, scene.t_cw1 = (
            scene.R_cw1, scene.t_cw1, scene.R_cw0, scene.t_cw0)
    scene.extra["motion"] = motion
    return scene
