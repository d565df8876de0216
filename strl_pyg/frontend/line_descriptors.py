"""Line descriptors of the front end: grey-level profiles across a clipped segment, sampled
at evenly spaced positions along it, compared by normalised cross-correlation (NCC).

Sampling is bilinear on a lightly blurred image (Gaussian, sigma 1 px) with the package's one
sampler (:func:`strl_pyg.data.sampling.sample_bilinear`, OpenCV pixel convention, border
pixels repeated outside the image), in float64.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from strl_pyg.data.sampling import sample_bilinear
from strl_pyg.frontend.config import FrontendConfig

__all__ = ["line_descriptor_scores", "sample_image", "band_descriptors"]


def sample_image(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples (float64) of a grey image ``[H, W]`` at pixels ``xy [..., 2]``
    (OpenCV convention, border pixels repeated)."""
    maps = torch.from_numpy(np.ascontiguousarray(img, dtype=np.float64))[None, None]
    pts = torch.from_numpy(np.ascontiguousarray(xy, dtype=np.float64)).reshape(1, -1, 2)
    return sample_bilinear(maps, pts, padding="border")[0, 0].numpy().reshape(xy.shape[:-1])


def _blurred(gray: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(gray.astype(np.float32), (0, 0), 1.0)


def line_descriptor_scores(c0: np.ndarray, c1: np.ndarray, flip: np.ndarray, gray0: np.ndarray,
                           gray1: np.ndarray, cfg: FrontendConfig) -> np.ndarray:
    """NCC ``[C]`` in ``[-1, 1]`` of the profiles across the clipped segments ``c0``, ``c1``
    ``[C, 2, 2]`` (endpoint ``k`` matches endpoint ``k``) at corresponding positions along
    them: ``line_samples`` positions, ``line_profile`` samples across each within
    ``line_profile_halfwidth`` pixels; the profile of segment 1 is scaled by the length ratio
    (clipped to ``[0.5, 2]``) and mirrored when ``flip`` says that it runs the other way.
    A flat pair of profiles scores ``-1``."""
    g0, g1 = _blurred(gray0), _blurred(gray1)
    u = np.linspace(0.0, 1.0, cfg.line_samples + 2)[1:-1]
    off = np.linspace(-1.0, 1.0, cfg.line_profile) * cfg.line_profile_halfwidth
    len0 = np.linalg.norm(c0[:, 1] - c0[:, 0], axis=1)
    len1 = np.linalg.norm(c1[:, 1] - c1[:, 0], axis=1)
    scale1 = np.clip(len1 / np.maximum(len0, 1e-9), 0.5, 2.0)
    descs = []
    for c, g, scale, sign in ((c0, g0, np.ones_like(scale1), np.ones(len(c0))),
                              (c1, g1, scale1, np.where(flip, -1.0, 1.0))):
        d = c[:, 1] - c[:, 0]
        n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.linalg.norm(d, axis=1, keepdims=True)
        n = n * (sign * scale)[:, None]
        pos = c[:, None, 0] + u[None, :, None] * d[:, None]  # [C, S, 2]
        xy = pos[:, :, None, :] + off[None, None, :, None] * n[:, None, None, :]
        descs.append(sample_image(g, xy).reshape(len(c), -1))
    a, b = descs
    a = a - a.mean(1, keepdims=True)
    b = b - b.mean(1, keepdims=True)
    den = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    return np.where(den > 1e-6, (a * b).sum(1) / np.maximum(den, 1e-12), -1.0)


def band_descriptors(lines: np.ndarray, gray: np.ndarray, bands: int = 9, band_width: int = 5,
                     samples: int = 16) -> np.ndarray:
    """Descriptors ``[N, 8 * bands]`` (float64, unit norm) of segments ``[N, 2, 2]`` that need
    no correspondence of their endpoints: the band descriptor of LBD (Zhang & Koch 2013) in a
    simpler form of our own.

    Around each segment, ``bands`` strips of ``band_width`` pixels run parallel to it. The
    image gradient (Sobel on the blurred image) is sampled at ``samples`` positions along the
    segment and on every pixel row across it, expressed along the segment and along its
    normal (LSD orients the normal by the contrast, so the frame is the same in both images),
    weighted by a Gaussian across the strips, and split into its positive and negative parts:
    four sums per strip and position. The descriptor holds their mean and their standard
    deviation over the positions, each half normalised, clipped at 0.4 and normalised again.
    Means and deviations along the segment do not depend on where it starts or ends, so two
    fragments of one edge of different lengths describe alike."""
    lines = np.asarray(lines, dtype=np.float64)
    if lines.size == 0:
        return np.zeros((0, 8 * bands))
    if lines.ndim != 3 or lines.shape[1:] != (2, 2):
        raise ValueError(f"Expected segments of shape [N, 2, 2] (got {list(lines.shape)})")
    if not np.isfinite(lines).all():
        raise ValueError("Expected finite segment endpoints (got NaN or inf)")
    length = np.linalg.norm(lines[:, 1] - lines[:, 0], axis=1)
    if (length < 1.0).any():
        raise ValueError(f"Expected segments at least 1 px long (got {int((length < 1).sum())} "
                         f"shorter, the shortest {length.min():.3g} px)")
    gray = np.asarray(gray)
    if gray.ndim != 2:
        raise ValueError(f"Expected a grey image [H, W] (got shape {list(gray.shape)})")
    g = _blurred(gray)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    d = lines[:, 1] - lines[:, 0]
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    rows = bands * band_width
    off = np.arange(rows) - (rows - 1) / 2.0
    u = (np.arange(samples) + 0.5) / samples
    pos = lines[:, None, 0] + u[None, :, None] * (lines[:, 1] - lines[:, 0])[:, None]  # [N,S,2]
    xy = pos[:, :, None, :] + off[None, None, :, None] * n[:, None, None, :]  # [N, S, R, 2]
    sx, sy = sample_image(gx, xy), sample_image(gy, xy)  # [N, S, R]
    along = sx * d[:, 0, None, None] + sy * d[:, 1, None, None]
    across = sx * n[:, 0, None, None] + sy * n[:, 1, None, None]
    w = np.exp(-0.5 * (off / (rows / 2.0)) ** 2)  # Gaussian across the strips
    parts = np.stack([np.maximum(along, 0), np.maximum(-along, 0), np.maximum(across, 0),
                      np.maximum(-across, 0)], axis=-1) * w[None, None, :, None]  # [N,S,R,4]
    per_band = parts.reshape(len(lines), samples, bands, band_width, 4).sum(3)  # [N,S,B,4]
    halves = []
    for stat in (per_band.mean(1), per_band.std(1)):  # [N, B, 4]
        h = stat.reshape(len(lines), -1)
        h = h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
        halves.append(h)
    desc = np.minimum(np.concatenate(halves, axis=1), 0.4)
    return desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
