"""The one image reader of the package (files and encoded bytes to uint8 arrays) and the one
check of in-memory images.

Every image the package reads (the command line's inputs, the datasets' files and HDF5
groups) goes through :func:`decode_image`, so all of them follow one set of rules:

* 8-bit images as they are, 16-bit ones scaled to 8 bits by the bit depth their values use
  (:func:`to_uint8`: 8, 10, 12, 14 or 16 bits, ``v * 255 // (2^bits - 1)``: a 12-bit image
  in a 16-bit file maps 4095 -> 255, a full 16-bit one 65535 -> 255 as ``v // 257``); any
  other depth (float or 32-bit TIFF, EXR) is refused;
* an alpha channel is dropped; grey + alpha becomes grey;
* colour comes back as RGB ``(H, W, 3)`` (OpenCV decodes BGR), grey as ``(H, W)``;
  ``grayscale=True`` converts colour to grey (OpenCV's BT.601 weights).

Every in-memory image the package is given (:class:`~strl_pyg.data.PairMatches` images, the
front end's inputs) goes through :func:`check_image`, so all of them follow one set of rules too:

* a numpy array or a torch tensor (anything else is a ``TypeError``);
* dtype uint8, uint16 (scaled to uint8 as a 16-bit file is: :func:`to_uint8`), or float32 /
  float64 with finite values in ``[0, 1]``;
* shape ``(H, W)``, ``(H, W, 1)`` (becomes ``(H, W)``) or RGB ``(H, W, 3)``, not empty, both
  sides at least ``min_side`` pixels.

The callers differ by parameter only: the front end asks for ``grayscale=True`` (grey uint8 for
OpenCV's detectors) and ``min_side=16`` (:data:`FRONTEND_MIN_SIDE`); ``PairMatches`` keeps the
image as given (``min_side=1``).

OpenCV is imported on the first read (or colour-to-grey conversion), so importing this module
needs only numpy.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["decode_image", "read_image_file", "check_image", "to_uint8", "FRONTEND_MIN_SIDE"]

#: Smallest side (pixels) of an image the front end matches: SIFT's and LSD's smallest scales.
FRONTEND_MIN_SIDE = 16

_DTYPES = (np.uint8, np.uint16, np.float32, np.float64)


def to_uint8(img: np.ndarray) -> np.ndarray:
    """A uint16 image as uint8, scaled by the bit depth its values use (the smallest of 8, 10,
    12, 14, 16 bits that holds its maximum): ``v * 255 // (2^bits - 1)``, so a 12-bit camera's
    4095 and a 16-bit file's 65535 both become 255 (the one 16-bit rule of files and arrays
    alike; ``v // 257`` turned 12-bit data into a dark, "featureless" image); other dtypes
    unchanged."""
    if img.dtype == np.uint16:
        top = int(img.max()) if img.size else 0
        bits = next(b for b in (8, 10, 12, 14, 16) if top < 2 ** b)
        return (img.astype(np.uint32) * 255 // (2 ** bits - 1)).astype(np.uint8)
    return img


def decode_image(buf: np.ndarray, name: str, grayscale: bool = False) -> np.ndarray:
    """Decodes encoded image bytes ``buf`` (uint8 ``[n]``) to uint8 ``(H, W)`` or RGB
    ``(H, W, 3)`` (module docstring); ``name`` (a path, or path and key) names the source in
    the ``ValueError`` of undecodable bytes or an unsupported depth."""
    import cv2

    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if img is None or img.size == 0:
        raise ValueError(f"Expected a decodable image at '{name}' (got bytes OpenCV cannot "
                         "decode)")
    img = to_uint8(img)
    if img.dtype != np.uint8:
        raise ValueError(f"Expected an 8- or 16-bit image at '{name}' (got dtype {img.dtype})")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim == 3 and img.shape[2] in (1, 2):  # grey, grey + alpha
        img = img[..., 0]
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if grayscale else cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img)


def read_image_file(path: str | os.PathLike, grayscale: bool = False) -> np.ndarray:
    """Reads an image file with :func:`decode_image`. A folder raises ``IsADirectoryError``,
    a missing file ``FileNotFoundError``, an empty or undecodable one ``ValueError``; each
    message is one line naming the path."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"Expected an image file at '{path}' (got a folder)")
    if not path.is_file():
        raise FileNotFoundError(f"Expected an image file at '{path}' (got no such file)")
    if path.stat().st_size == 0:
        raise ValueError(f"Expected a readable image at '{path}' (got an empty file)")
    return decode_image(np.fromfile(path, dtype=np.uint8), str(path), grayscale)


def check_image(value: Any, name: str, *, grayscale: bool = False, min_side: int = 1
                ) -> np.ndarray:
    """Validates an in-memory image with the package's one set of rules (module docstring).

    Args:
        value: numpy array or torch tensor, ``(H, W)``, ``(H, W, 1)`` or RGB ``(H, W, 3)``;
            uint8, uint16 (returned as uint8, :func:`to_uint8`), or float32/float64 in
            ``[0, 1]``.
        name: the argument's name in error messages.
        grayscale: return grey uint8 ``(H, W)`` (C-contiguous): floats scaled by 255 and
            rounded, RGB converted with OpenCV's BT.601 weights. ``False``: the image as given,
            ``(H, W, 1)`` squeezed to ``(H, W)``.
        min_side: smallest allowed height and width, pixels.

    Raises:
        TypeError: not an array or tensor, or another dtype.
        ValueError: another shape, empty, smaller than ``min_side``, float values outside
            ``[0, 1]`` or not finite. Each message is one ``Expected ... (got ...)`` line.
    """
    if hasattr(value, "detach") and hasattr(value, "numpy"):  # torch tensor
        value = value.detach().cpu().numpy()
    if not isinstance(value, np.ndarray):
        raise TypeError(f"Expected '{name}' as a numpy array or torch tensor "
                        f"(got {type(value).__name__})")
    img = value
    if img.dtype not in _DTYPES:
        raise TypeError(f"Expected '{name}' of dtype uint8, float32 or float64, or uint16 "
                        f"(got {img.dtype})")
    if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (1, 3))):
        raise ValueError(f"Expected '{name}' of shape (H, W) or (H, W, 1|3) "
                         f"(got {tuple(img.shape)})")
    if img.size == 0:
        raise ValueError(f"Expected a non-empty '{name}' (got shape {tuple(img.shape)})")
    if min(img.shape[:2]) < min_side:
        raise ValueError(f"Expected '{name}' of at least {min_side}x{min_side} pixels "
                         f"(got {tuple(img.shape[:2])})")
    img = to_uint8(img)
    if img.dtype != np.uint8:
        if not np.isfinite(img).all():
            raise ValueError(f"Expected float '{name}' with finite values in [0, 1] "
                             "(got NaN or inf)")
        lo, hi = float(img.min()), float(img.max())
        if lo < 0.0 or hi > 1.0:
            raise ValueError(f"Expected float '{name}' with finite values in [0, 1] "
                             f"(got values in [{lo:.4g}, {hi:.4g}])")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if not grayscale:
        return img
    if img.dtype != np.uint8:
        img = np.round(img * 255.0).astype(np.uint8)
    if img.ndim == 3:
        import cv2

        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img)
