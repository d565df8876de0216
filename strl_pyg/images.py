"""The one image reader of the package: files and encoded bytes to uint8 arrays.

Every image the package reads (the command line's inputs, the datasets' files and HDF5
groups) goes through :func:`decode_image`, so all of them follow one set of rules:

* 8-bit images as they are, 16-bit ones scaled to 8 bits (``v / 257``, truncated); any other
  depth (float or 32-bit TIFF, EXR) is refused;
* an alpha channel is dropped; grey + alpha becomes grey;
* colour comes back as RGB ``(H, W, 3)`` (OpenCV decodes BGR), grey as ``(H, W)``;
  ``grayscale=True`` converts colour to grey (OpenCV's BT.601 weights).

OpenCV is imported on the first read, so importing this module needs only numpy.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["decode_image", "read_image_file"]


def decode_image(buf: np.ndarray, name: str, grayscale: bool = False) -> np.ndarray:
    """Decodes encoded image bytes ``buf`` (uint8 ``[n]``) to uint8 ``(H, W)`` or RGB
    ``(H, W, 3)`` (module docstring); ``name`` (a path, or path and key) names the source in
    the ``ValueError`` of undecodable bytes or an unsupported depth."""
    import cv2

    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if img is None or img.size == 0:
        raise ValueError(f"Expected a decodable image at '{name}' (got bytes OpenCV cannot "
                         "decode)")
    if img.dtype == np.uint16:
        img = (img / 257).astype(np.uint8)
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
