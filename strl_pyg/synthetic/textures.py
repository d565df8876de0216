"""Procedural grey textures with their straight edges (in texture coordinates ``(s, t)``).

A texture is an image whose texel ``(i, j)`` (column, row) has its centre at
``(s, t) = ((i + 0.5) / W_tex, (j + 0.5) / H_tex)``; the straight edges drawn into it are kept
as segments in ``(s, t)`` so that they become exact 3D ground-truth lines.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from strl_pyg.synthetic.config import SceneConfig

__all__ = ["TextureMaker", "pyramid"]

class TextureMaker:
    """Procedural grey textures with their straight edges, from one seeded generator.

    ``density`` multiplies ``cfg.texels_per_metre`` (the object kind raises it for small
    objects seen from close).
    """

    def __init__(self, rng: np.random.Generator, cfg: SceneConfig) -> None:
        self.rng = rng
        self.cfg = cfg
        self.density = 1.0
        # One tile shared by every surface when the texture is repetitive.
        self.tile = self._noise(24, 24, 6, 60.0) if cfg.repetitive_texture else None

    def _noise(self, h: int, w: int, cell: int, amp: float) -> np.ndarray:
        small = self.rng.normal(0.0, 1.0, (max(2, h // cell), max(2, w // cell)))
        return amp * cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)

    def size(self, width_m: float, height_m: float) -> tuple[int, int]:
        tpm, cap = self.cfg.texels_per_metre, self.cfg.max_texture
        if self.density != 1.0:
            tpm = tpm * self.density
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
        if style in ("weak", "dark"):
            return self._plain(style, h, w)
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

    def _plain(self, style: str, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
        """``"weak"``: a nearly uniform surface (plaster-like, few corners); ``"dark"``: a dark,
        weakly textured backdrop or turntable. No straight edges inside."""
        level = float(self.rng.uniform(90, 200) if style == "weak" else self.rng.uniform(8, 40))
        amp = 8.0 if style == "weak" else 3.0
        tex = level + self._noise(h, w, 32, amp) + self._noise(h, w, 4, amp / 2)
        return np.clip(tex, 0, 255), np.zeros((0, 2, 2))

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


def pyramid(tex: np.ndarray) -> list[np.ndarray]:
    levels = [np.clip(tex, 0, 255).astype(np.uint8)]
    while min(levels[-1].shape) >= 16 and len(levels) < 6:
        levels.append(cv2.pyrDown(levels[-1]))
    return levels
