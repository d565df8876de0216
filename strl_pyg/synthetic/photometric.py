"""Photometric change of one rendered view (gain, gamma, blur, grey-level noise)."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["apply_photometric"]


def apply_photometric(
    image: np.ndarray,
    gain: float = 1.0,
    gamma: float = 1.0,
    blur: float = 0.0,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """``255 gain (I / 255) ^ gamma``, then a Gaussian blur of std ``blur`` pixels, then
    Gaussian noise of std ``noise`` grey levels (from ``rng``), rounded and clipped.

    Args:
        image: uint8 ``[H, W]``.
        gain, gamma: positive; blur, noise: non-negative.
        rng: required when ``noise > 0``.

    Returns:
        uint8 ``[H, W]``, a new array.
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 2:
        raise TypeError(f"Expected a uint8 [H, W] image (got {getattr(image, 'dtype', type(image))}"
                        f" {getattr(image, 'shape', '')})")
    if gain <= 0 or gamma <= 0 or blur < 0 or noise < 0:
        raise ValueError(
            f"Expected gain, gamma > 0 and blur, noise >= 0 (got {gain}, {gamma}, {blur}, "
            f"{noise})"
        )
    if noise > 0 and rng is None:
        raise ValueError("Expected an rng for noise > 0 (got None)")
    img = image.astype(np.float32) / 255.0
    img = 255.0 * gain * np.power(img, np.float32(gamma))
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
