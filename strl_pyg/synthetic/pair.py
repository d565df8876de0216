"""Generated image pairs with the exact relative pose and ground-truth matches.

Conventions: ``T_0to1`` maps camera-0 points into camera 1, ``X1 = R X0 + t``; pixels follow
OpenCV (centre of the top-left pixel is ``(0, 0)``); both images share ``K``. Photometric
changes (``SceneConfig.photo_*``) touch image 1 only and never the geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from strl_pyg.data.matches import PairMatches
from strl_pyg.geometry.epipolar import fundamental_from_pose
from strl_pyg.synthetic import SceneConfig
from strl_pyg.synthetic.photometric import apply_photometric
from strl_pyg.synthetic.render import View, project, render_view
from strl_pyg.synthetic.scene import Scene, build_scene

__all__ = ["SyntheticPair", "generate_pair", "SceneGenerationError"]


class SceneGenerationError(RuntimeError):
    """A seed whose scene has no usable view pair (the generator's retries ran out)."""

#: A pair must keep at least this many ground-truth point matches, else the scene is
#: regenerated from the next sub-seed (deterministically).
_MIN_POINTS = 16
_MAX_ATTEMPTS = 8


@dataclass
class SyntheticPair:
    """One generated pair.

    Attributes:
        image0, image1: uint8 ``[H, W]`` grey images.
        K: ``[3, 3]`` float64 intrinsics of both cameras (pixels).
        T_0to1: ``[4, 4]`` float64, ``X1 = R X0 + t``.
        matches: the ground-truth :class:`PairMatches` after noise and outliers, with images and
            ``K0 = K1 = K`` attached; ``info`` holds ``seed``, ``kind``.
        point_inliers: bool ``[Np]``, False for the injected outliers.
        line_inliers: bool ``[Nl]``, False for the injected outliers.
        depth0, depth1: float32 ``[H, W]`` depth ``z`` in metres, ``inf`` on the background.
        plane_id0, plane_id1: int32 ``[H, W]`` index into ``planes`` (``-1``: background).
        planes: ``[Q, 4]`` float64 planes ``(n, d)`` in the **camera-0** frame, ``n . X0 = d``.
        T_w_c0, T_w_c1: ``[4, 4]`` camera-to-world poses (world ``y`` points down).
        lines_clean0, lines_clean1: ``[Nl, 2, 2]`` the line matches before noise/outliers.
        points_clean0, points_clean1: ``[Np, 2]`` the point matches before noise/outliers.
        kind: the scene kind; seed: the seed it was generated from.
        info: ``num_quads``, ``motion`` (``"legacy"`` or one of ``MOTIONS``), ``swapped``,
            ``depth`` (the scene depth ``d`` the motion was scaled by; new motions only),
            and for the object kind ``object_quads`` (quads ``0 .. object_quads - 1`` of
            ``plane_id*`` are the object; the others are the turntable or backdrop).
    """

    image0: np.ndarray
    image1: np.ndarray
    K: np.ndarray
    T_0to1: np.ndarray
    matches: PairMatches
    point_inliers: np.ndarray
    line_inliers: np.ndarray
    depth0: np.ndarray
    depth1: np.ndarray
    plane_id0: np.ndarray
    plane_id1: np.ndarray
    planes: np.ndarray
    T_w_c0: np.ndarray
    T_w_c1: np.ndarray
    points_clean0: np.ndarray
    points_clean1: np.ndarray
    lines_clean0: np.ndarray
    lines_clean1: np.ndarray
    kind: str = "street"
    seed: int = 0
    info: dict = field(default_factory=dict)


def _to_uint8(view: View, rng: np.random.Generator, noise: float) -> np.ndarray:
    img = cv2.GaussianBlur(view.image, (0, 0), 0.6)  # mild anti-aliasing of polygon edges
    if noise > 0:
        img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _lookup(arr: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``arr`` at the 2x2 pixels around each ``uv`` ``[N, 2]`` -> ``[N, 4]``, plus
    a mask of the ``uv`` inside the image."""
    h, w = arr.shape
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    safe = np.where(inside[:, None], uv, 0.0)
    x0 = np.floor(safe[:, 0]).astype(int)
    y0 = np.floor(safe[:, 1]).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    vals = np.stack([arr[y0, x0], arr[y0, x1], arr[y1, x0], arr[y1, x1]], axis=1)
    return vals, inside


def _visible(view: View, uv: np.ndarray, z: np.ndarray, owner: np.ndarray, near: float):
    """Visibility of 3D samples projected at ``uv`` with depth ``z`` lying on quad ``owner``:
    their quad is among the 2x2 pixels around them, or nothing nearer hides them there."""
    ids, inside = _lookup(view.ids, uv)
    zb, _ = _lookup(view.depth, uv)
    own = (ids == owner[:, None]).any(1)
    unhidden = z <= zb.max(1) * (1 + 1e-3)
    return inside & (z > near) & (own | unhidden)


def _gt_lines(scene: Scene, K, views, cfg: SceneConfig):
    v0, v1 = views
    h, w = cfg.image_size
    poses = ((scene.R_cw0, scene.t_cw0), (scene.R_cw1, scene.t_cw1))
    segs, owner = scene.segments, scene.segment_owner
    # Box faces share their edges: keep one copy of each 3D segment.
    ends = np.sort(np.round(segs, 6), axis=1).reshape(len(segs), 6)
    _, first = np.unique(ends, axis=0, return_index=True)
    keep = np.sort(first)
    segs, owner = segs[keep], owner[keep]
    # Cull segments that cannot be seen in one of the views, and size the sampling.
    span = np.zeros(len(segs))
    for R, t in poses:
        uv, z = project(K, R, t, segs.reshape(-1, 3))
        uv, z = uv.reshape(-1, 2, 2), z.reshape(-1, 2)
        front = (z > cfg.near).all(1)
        lo, hi = uv.min(1), uv.max(1)
        off = front & ((hi[:, 0] < 0) | (lo[:, 0] > w - 1) | (hi[:, 1] < 0) | (lo[:, 1] > h - 1))
        dead = (z <= cfg.near).all(1) | off
        length = np.linalg.norm(uv[:, 1] - uv[:, 0], axis=1)
        span = np.maximum(span, np.where(front, length, 2000.0))
        segs, owner, span = segs[~dead], owner[~dead], span[~dead]
    n = np.clip(span / 2.0, 16, 600).astype(int)
    seg_id = np.repeat(np.arange(len(segs)), n)
    first_sample = np.cumsum(n) - n
    s = (np.arange(len(seg_id)) - first_sample[seg_id]) / (n[seg_id] - 1)
    X = segs[seg_id, 0] + s[:, None] * (segs[seg_id, 1] - segs[seg_id, 0])
    vis = np.ones(len(X), bool)
    uvs = []
    for view, (R, t) in zip((v0, v1), poses, strict=True):
        uv, z = project(K, R, t, X)
        vis &= _visible(view, uv, z, owner[seg_id], cfg.near)
        uvs.append(uv)
    # The longest run of samples seen in both views, per segment.
    new_seg = np.ones(len(vis), bool)
    new_seg[1:] = seg_id[1:] != seg_id[:-1]
    prev_off = np.concatenate([[True], ~vis[:-1]])
    run_start = vis & (new_seg | prev_off)
    run_first = np.flatnonzero(run_start)
    run_len = np.bincount(np.cumsum(run_start)[vis] - 1, minlength=len(run_first))
    run_seg = seg_id[run_first]
    order = np.lexsort((-run_len, run_seg))  # per segment, its longest run first
    head = np.ones(len(order), bool)
    head[1:] = run_seg[order][1:] != run_seg[order][:-1]
    best = order[head]
    best = best[run_len[best] >= 2]
    a, b = run_first[best], run_first[best] + run_len[best] - 1
    p0 = np.stack([uvs[0][a], uvs[0][b]], axis=1).reshape(-1, 2, 2)
    p1 = np.stack([uvs[1][a], uvs[1][b]], axis=1).reshape(-1, 2, 2)
    long_enough = np.minimum(
        np.linalg.norm(p0[:, 1] - p0[:, 0], axis=1), np.linalg.norm(p1[:, 1] - p1[:, 0], axis=1)
    ) >= cfg.min_line_length
    return p0[long_enough], p1[long_enough]


def _gt_points(scene: Scene, K, views, planes_c0, cfg: SceneConfig, rng):
    v0, v1 = views
    h, w = cfg.image_size
    img = np.clip(v0.image, 0, 255).astype(np.uint8)
    mask = None
    if cfg.kind == "object":
        # Corners of object-face interiors only: the strong silhouette against the dark
        # background would otherwise set the quality threshold above every corner of a weak
        # texture (the dark turntable / backdrop get no ground-truth points, as on black).
        ids = v0.ids
        inner = (ids >= 0) & (ids < scene.extra["object_quads"])
        inner[1:-1, 1:-1] &= (
            (ids[1:-1, 1:-1] == ids[:-2, 1:-1]) & (ids[1:-1, 1:-1] == ids[2:, 1:-1])
            & (ids[1:-1, 1:-1] == ids[1:-1, :-2]) & (ids[1:-1, 1:-1] == ids[1:-1, 2:])
        )
        mask = cv2.erode(inner.astype(np.uint8), np.ones((5, 5), np.uint8))
    corners = cv2.goodFeaturesToTrack(img, maxCorners=4 * max(cfg.max_points, 1),
                                      qualityLevel=0.005, minDistance=3, mask=mask)
    uv0 = np.zeros((0, 2)) if corners is None else corners.reshape(-1, 2).astype(np.float64)
    # Interior pixels only: all 3x3 neighbours on the same quad (no border ambiguity).
    xi, yi = np.round(uv0[:, 0]).astype(int), np.round(uv0[:, 1]).astype(int)
    ok = (xi >= 1) & (xi <= w - 2) & (yi >= 1) & (yi <= h - 2)
    uv0, xi, yi = uv0[ok], xi[ok], yi[ok]
    q = v0.ids[yi, xi]
    same = np.ones(len(q), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            same &= v0.ids[yi + dy, xi + dx] == q
    keep = same & (q >= 0)
    uv0, q = uv0[keep], q[keep]
    # Exact back-projection onto the quad's plane (camera-0 frame).
    rays = np.column_stack([uv0, np.ones(len(uv0))]) @ np.linalg.inv(K).T
    n, d = planes_c0[q, :3], planes_c0[q, 3]
    X0 = rays * (d / np.einsum("ij,ij->i", rays, n))[:, None]
    Xw = (X0 - scene.t_cw0) @ scene.R_cw0  # R^T (X - t)
    uv1, z1 = project(K, scene.R_cw1, scene.t_cw1, Xw)
    ids1, inside = _lookup(v1.ids, uv1)
    vis = inside & (z1 > cfg.near) & (ids1 == q[:, None]).all(1)
    uv0, uv1 = uv0[vis], uv1[vis]
    if len(uv0) > cfg.max_points:
        pick = np.sort(rng.choice(len(uv0), cfg.max_points, replace=False))
        uv0, uv1 = uv0[pick], uv1[pick]
    return uv0, uv1


def _planes_c0(scene: Scene) -> np.ndarray:
    out = np.zeros((len(scene.quads), 4))
    for i, quad in enumerate(scene.quads):
        n = scene.R_cw0 @ quad.normal
        out[i, :3] = n
        out[i, 3] = n @ (scene.R_cw0 @ quad.origin + scene.t_cw0)
    return out


def _corrupt(x0, x1, cfg: SceneConfig, rng, size, F, lines: bool):
    """Adds pixel noise and replaces ``round(outlier_fraction * N)`` matches with wrong ones
    (points: a random location in image 1 far from the epipolar line; lines: another line's
    image-1 segment, or a random segment when there is no other line)."""
    h, w = size
    n = len(x0)
    x0, x1 = x0.copy(), x1.copy()
    if cfg.noise_px > 0 and n:
        x0 += rng.normal(0.0, cfg.noise_px, x0.shape)
        x1 += rng.normal(0.0, cfg.noise_px, x1.shape)
    inl = np.ones(n, bool)
    n_out = int(round(cfg.outlier_fraction * n))
    if n_out:
        idx = np.sort(rng.choice(n, n_out, replace=False))
        inl[idx] = False
        for i in idx:
            for _ in range(100):  # rejection: keep only clearly wrong matches
                if lines:
                    cand = x1[rng.integers(n)] if n > 1 else rng.uniform(0, 1, (2, 2)) * [w, h]
                    if rng.random() < 0.5:
                        cand = cand[::-1]
                    pts0, pts1 = x0[i], cand
                else:
                    cand = rng.uniform(0, 1, 2) * [w - 1, h - 1]
                    pts0, pts1 = x0[i][None], cand[None]
                l1 = np.column_stack([pts0, np.ones(len(pts0))]) @ F.T
                dist = np.abs(np.einsum("ij,ij->i", l1[:, :2], pts1) + l1[:, 2])
                dist /= np.linalg.norm(l1[:, :2], axis=1)
                if dist.min() > 10.0 and (not lines or np.linalg.norm(cand[1] - cand[0]) > 1):
                    break
            x1[i] = cand
    lim = np.array([w - 1, h - 1], dtype=np.float64)
    return np.clip(x0, 0, lim), np.clip(x1, 0, lim), inl


def _c2w(R_cw, t_cw):
    T = np.eye(4)
    T[:3, :3] = R_cw.T
    T[:3, 3] = -R_cw.T @ t_cw
    return T


def generate_pair(seed: int, config: SceneConfig | None = None) -> SyntheticPair:
    """Generates one deterministic pair from ``seed``.

    The scene is rendered into both views; ground-truth points are corners of image 0
    back-projected exactly onto their quad and kept where the same quad is seen around their
    projection in image 1; ground-truth lines are 3D texture and quad edges sampled densely,
    tested for visibility in both views (near plane, image bounds, depth buffer), and cut to the
    longest run seen in both, so endpoint ``k`` in both images is the same 3D point. Noise and
    outliers are applied afterwards (``point_inliers``/``line_inliers`` mark them). If a scene
    yields fewer than 16 point matches it is regenerated from a derived seed.

    Args:
        seed: any non-negative integer.
        config: :class:`SceneConfig`; defaults to ``SceneConfig()``.

    Returns:
        :class:`SyntheticPair`.
    """
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"Expected a non-negative integer seed (got {seed!r})")
    cfg = config if config is not None else SceneConfig()
    if not isinstance(cfg, SceneConfig):
        raise TypeError(f"Expected a SceneConfig (got {type(cfg).__name__})")
    h, w = cfg.image_size
    K = cfg.intrinsics()
    for attempt in range(_MAX_ATTEMPTS):
        rng = np.random.default_rng([int(seed), attempt])
        scene = build_scene(rng, cfg)
        views = tuple(
            render_view(scene.quads, K, R, t, (h, w), cfg.near, scene.background,
                        scene.gradient)
            for R, t in ((scene.R_cw0, scene.t_cw0), (scene.R_cw1, scene.t_cw1))
        )
        planes = _planes_c0(scene)
        p0, p1 = _gt_points(scene, K, views, planes, cfg, rng)
        if len(p0) >= min(_MIN_POINTS, cfg.max_points) or attempt == _MAX_ATTEMPTS - 1:
            break
    l0, l1 = _gt_lines(scene, K, views, cfg)
    if len(l0) > cfg.max_lines:
        pick = np.sort(rng.choice(len(l0), cfg.max_lines, replace=False))
        l0, l1 = l0[pick], l1[pick]
    T_w_c0, T_w_c1 = _c2w(scene.R_cw0, scene.t_cw0), _c2w(scene.R_cw1, scene.t_cw1)
    T_0to1 = np.linalg.inv(T_w_c1) @ T_w_c0
    F = fundamental_from_pose(T_0to1, K, K)
    image0 = _to_uint8(views[0], rng, cfg.image_noise)
    image1 = _to_uint8(views[1], rng, cfg.image_noise)
    if cfg.has_photometric:  # its own stream: the ground truth stays that of no change
        image1 = apply_photometric(
            image1, cfg.photo_gain, cfg.photo_gamma, cfg.photo_blur, cfg.photo_noise,
            np.random.default_rng([int(seed), attempt, 1]),
        )
    n0, n1, p_inl = _corrupt(p0, p1, cfg, rng, (h, w), F, lines=False)
    m0, m1, l_inl = _corrupt(l0, l1, cfg, rng, (h, w), F, lines=True)
    if len(n0) + len(m0) == 0:
        raise SceneGenerationError(
            f"Scene of seed {seed} has no visible correspondences; try another")
    matches = PairMatches(
        n0, n1, lines0=m0, lines1=m1, K0=K, K1=K, image0=image0, image1=image1,
        info={"seed": int(seed), "kind": cfg.kind, "attempt": attempt, "source": "synthetic",
              "motion": scene.extra["motion"]},
    )
    return SyntheticPair(
        image0=image0, image1=image1, K=K, T_0to1=T_0to1, matches=matches,
        point_inliers=p_inl, line_inliers=l_inl,
        depth0=views[0].depth, depth1=views[1].depth,
        plane_id0=views[0].ids, plane_id1=views[1].ids, planes=planes,
        T_w_c0=T_w_c0, T_w_c1=T_w_c1,
        points_clean0=p0, points_clean1=p1, lines_clean0=l0, lines_clean1=l1,
        kind=cfg.kind, seed=int(seed),
        info={"num_quads": len(scene.quads), "motion": scene.extra["motion"],
              "swapped": bool(cfg.swap_views),
              **{k: scene.extra[k] for k in ("object_quads", "backdrop", "depth")
                 if k in scene.extra}},
    )
