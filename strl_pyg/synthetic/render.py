"""A small CPU renderer for textured planar quads: plane homographies plus a z-buffer.

Each quad is clipped against the near plane, its texture is warped into the image with
``cv2.warpPerspective`` through the homography ``K [R U | R V | R O + t] A`` (``A`` maps texels
to ``(s, t)``), blending mip-map levels per pixel by the local texel footprint, and composited
where its exact per-pixel plane depth is nearest. Pixel convention: OpenCV, the centre of the
top-left pixel is ``(0, 0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from strl_pyg.synthetic.scene import Quad

__all__ = ["View", "render_view", "project"]


@dataclass
class View:
    """One rendered view.

    Attributes:
        image: ``[H, W]`` float32 grey levels in ``[0, 255]`` before sensor noise.
        depth: ``[H, W]`` float32 depth ``z`` (metres) along the optical axis; ``inf`` where
            no quad is seen.
        ids: ``[H, W]`` int32 index of the quad seen at each pixel, ``-1`` for background.
    """

    image: np.ndarray
    depth: np.ndarray
    ids: np.ndarray


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray):
    """Projects world points ``X`` ``[N, 3]`` with ``X_c = R X + t``; returns pixels ``[N, 2]``
    and depths ``[N]`` (pixels are meaningless where the depth is not positive)."""
    Xc = X @ R.T + t
    z = Xc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (Xc @ K.T)[:, :2] / z[:, None]
    return uv, z


def _clip_near(P: np.ndarray, near: float) -> np.ndarray:
    """Sutherland-Hodgman clipping of a convex polygon ``[N, 3]`` (camera frame) to
    ``z >= near``."""
    out = []
    n = len(P)
    for i in range(n):
        p, q = P[i], P[(i + 1) % n]
        pin, qin = p[2] >= near, q[2] >= near
        if pin:
            out.append(p)
        if pin != qin:
            a = (near - p[2]) / (q[2] - p[2])
            out.append(p + a * (q - p))
    return np.asarray(out).reshape(-1, 3)


def _mip_homographies(H0: np.ndarray, levels: int) -> list[np.ndarray]:
    """Homographies from texels of each ``pyrDown`` level to pixels: a level-``l`` texel
    centre ``x_l`` sits at ``2^l x_l + (2^l - 1) / 2`` on level 0."""
    out = []
    for lvl in range(levels):
        s = 2.0**lvl
        S = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1]])
        out.append(H0 @ S)
    return out


def _maybe_visible(quads: list[Quad], K: np.ndarray, R: np.ndarray, t: np.ndarray,
                   size: tuple[int, int], near: float) -> np.ndarray:
    """Per quad, ``False`` where :func:`render_view` would draw nothing of it for certain,
    all quads at once: every corner in front of ``near`` is missing, or every corner is in
    front and the projection lies more than 2 pixels outside the image (a margin that the
    per-quad path's rounding cannot cross); ``True`` otherwise (the per-quad path decides)."""
    if not quads:
        return np.zeros(0, dtype=bool)
    Cc = np.stack([q.corners() for q in quads]) @ R.T + t  # [N, 4, 3]
    z = Cc[..., 2]
    behind = (z < near).all(axis=1)
    front = (z >= near).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (Cc @ K.T)[..., :2] / z[..., None]
    h, w = size
    lo, hi = uv.min(axis=1), uv.max(axis=1)
    outside = ((hi[:, 0] < -2) | (lo[:, 0] > w + 1) | (hi[:, 1] < -2) | (lo[:, 1] > h + 1))
    return ~(behind | (front & outside))


def render_view(
    quads: list[Quad],
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    size: tuple[int, int],
    near: float = 0.05,
    background: float = 215.0,
    gradient: float = 12.0,
) -> View:
    """Renders ``quads`` seen by the camera ``X_c = R X_w + t`` with intrinsics ``K`` ``[3, 3]``
    into an ``(H, W) = size`` view; pixels that see no quad get ``background`` plus a vertical
    gradient from ``-gradient`` (top) to ``+gradient`` (bottom), ``ids = -1``, ``depth = inf``."""
    h, w = size
    image = np.full((h, w), background, np.float32)
    image += np.linspace(-gradient, gradient, h, dtype=np.float32)[:, None]  # sky-like
    depth = np.full((h, w), np.inf, np.float32)
    ids = np.full((h, w), -1, np.int32)
    K_inv = np.linalg.inv(K)
    visible = _maybe_visible(quads, K, R, t, size, near)
    for qi, quad in enumerate(quads):
        if not visible[qi]:
            continue
        corners_c = quad.corners() @ R.T + t
        poly = _clip_near(corners_c, near)
        if len(poly) < 3:
            continue
        uv = (poly @ K.T)[:, :2] / poly[:, 2:3]
        uv = np.clip(uv, -1e6, 1e6)
        x0, y0 = np.floor(uv.min(0)).astype(int)
        x1, y1 = np.ceil(uv.max(0)).astype(int)
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w - 1), min(y1, h - 1)
        if x1 < x0 or y1 < y0:
            continue
        bw, bh = x1 - x0 + 1, y1 - y0 + 1
        mask = np.zeros((bh, bw), np.uint8)
        pts = np.round((uv - [x0, y0]) * 16).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=4)
        if not mask.any():
            continue
        # Plane n . X = d in the camera frame; depth along a pixel ray r = K^-1 x is d/(n . r).
        n = R @ quad.normal
        d = float(n @ corners_c[0])
        a, b, c = n @ K_inv
        us = np.arange(x0, x1 + 1, dtype=np.float64)
        vs = np.arange(y0, y1 + 1, dtype=np.float64)
        den = a * us[None, :] + b * vs[:, None] + c
        with np.errstate(divide="ignore", invalid="ignore"):
            z = d / den
        m = mask.astype(bool) & (z > near) & (z < depth[y0 : y1 + 1, x0 : x1 + 1])
        if not m.any():
            continue
        tex0 = quad.pyramid[0]
        th, tw = tex0.shape
        A = np.array([[1 / tw, 0, 0.5 / tw], [0, 1 / th, 0.5 / th], [0, 0, 1]])
        M = np.column_stack([R @ quad.u, R @ quad.v, R @ quad.origin + t])
        Tb = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1]], dtype=np.float64)
        H0 = Tb @ K @ M @ A
        # Texels per pixel from the Jacobian of the pixel -> texel map G = H0^-1:
        # |det J| = |det G| / |g3 . p|^3.
        G = np.linalg.inv(H0)
        g3 = G[2, 0] * (us - x0)[None, :] + G[2, 1] * (vs - y0)[:, None] + G[2, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            footprint = np.sqrt(np.abs(np.linalg.det(G)) / np.abs(g3) ** 3)
        lod = np.log2(np.clip(footprint, 1.0, None))
        lod = np.clip(np.nan_to_num(lod, nan=0.0), 0, len(quad.pyramid) - 1)
        lo_needed = int(np.floor(lod[m].min()))
        hi_needed = int(np.ceil(lod[m].max()))
        Hs = _mip_homographies(H0, len(quad.pyramid))
        warped = {}
        for lvl in range(lo_needed, hi_needed + 1):
            warped[lvl] = cv2.warpPerspective(
                quad.pyramid[lvl].astype(np.float32), Hs[lvl], (bw, bh),
                flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101,
            )
        if len(warped) == 1:
            colour = warped[lo_needed]
        else:
            lo = np.floor(lod).astype(int)
            frac = (lod - lo).astype(np.float32)
            colour = np.zeros((bh, bw), np.float32)
            for lvl, img in warped.items():
                wgt = np.where(lo == lvl, 1 - frac, 0) + np.where(lo + 1 == lvl, frac, 0)
                colour += wgt.astype(np.float32) * img
        sub = (slice(y0, y1 + 1), slice(x0, x1 + 1))
        image[sub][m] = colour[m]
        depth[sub][m] = z[m]
        ids[sub][m] = qi
    return View(image, depth, ids)
