"""Lens distortion of COLMAP's radial and OpenCV camera models, and its removal.

The models (:data:`DISTORTION_MODELS`) are Brown-Conrady's, as OpenCV and COLMAP write them,
on normalised coordinates ``(x, y) = K^-1 [u, v, 1]`` with ``r^2 = x^2 + y^2``:

.. math::

    x_d = x (1 + k_1 r^2 + k_2 r^4) + 2 p_1 x y + p_2 (r^2 + 2 x^2)

    y_d = y (1 + k_1 r^2 + k_2 r^4) + p_1 (r^2 + 2 y^2) + 2 p_2 x y

and back to pixels with the same ``K``. SIMPLE_RADIAL's ``k`` is ``k_1``; a term a model lacks
is zero. Every function takes the coefficients in OpenCV's order ``[k1, k2, p1, p2]``
(:func:`opencv_coefficients` builds them from a model's own terms).

Pixels follow OpenCV (the centre of the top-left pixel is ``(0, 0)``, as in
:mod:`strl_pyg.geometry.camera`; COLMAP's principal point is shifted by -0.5 px when read, its
distortion terms are unchanged since they act on normalised coordinates). ``K`` is
``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (OpenCV's distortion functions ignore skew, so a
skewed ``K`` is refused). A resized image keeps its coefficients: scale ``K`` alone.

Inputs are numpy arrays (or anything ``np.asarray`` takes); results are numpy float64 (points)
or the image's own dtype. OpenCV is imported on the first call, so importing this module needs
only numpy.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from types import MappingProxyType
from typing import Any

import numpy as np

__all__ = ["DISTORTION_MODELS", "opencv_coefficients", "distort_points", "undistort_points",
           "undistortion_maps", "undistort_image"]

#: COLMAP camera models whose distortion this module applies: name -> the model's distortion
#: terms, in COLMAP's parameter order (after the focal lengths and the principal point).
#: Fisheye, FOV, thin-prism and FULL_OPENCV models are not among them.
DISTORTION_MODELS = MappingProxyType({
    "SIMPLE_PINHOLE": (),
    "PINHOLE": (),
    "SIMPLE_RADIAL": ("k",),
    "RADIAL": ("k1", "k2"),
    "OPENCV": ("k1", "k2", "p1", "p2"),
})
#: Where each term sits in OpenCV's ``[k1, k2, p1, p2]``.
_OPENCV_INDEX = {"k": 0, "k1": 0, "k2": 1, "p1": 2, "p2": 3}
#: Fixed-point iterations of the inverse model and their stopping step (normalised units):
#: 20 reach 1e-10 px at ``k1 = -0.3`` in an image's corners, OpenCV's default 5 only 0.05 px.
_UNDISTORT_CRITERIA = (50, 1e-10)
#: Undistortion maps kept (a collection reuses one camera for many images; a 24 Mpx pair of
#: maps takes 190 MB).
_MAPS_CACHED = 4


def opencv_coefficients(model: str, distortion: Sequence[float]) -> np.ndarray:
    """OpenCV's distortion coefficients ``[4]`` ``[k1, k2, p1, p2]`` of a COLMAP model's
    distortion terms (module docstring), zeros where the model lacks a term.

    Args:
        model: A name in :data:`DISTORTION_MODELS`.
        distortion: The model's terms in COLMAP's order (``()`` for the pinhole models).

    Raises:
        ValueError: another model, another number of terms, or a term that is not a finite
            number (one line each).
    """
    if model not in DISTORTION_MODELS:
        raise ValueError(f"Expected a camera model among {', '.join(DISTORTION_MODELS)} to "
                         f"undistort (got {model!r})")
    terms = DISTORTION_MODELS[model]
    try:
        values = np.asarray(distortion, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"Expected numbers as the distortion terms of {model} (got "
                         f"{err})") from None
    if values.shape != (len(terms),):
        raise ValueError(f"Expected {len(terms)} distortion terms for {model} "
                         f"({', '.join(terms) or 'none'}) (got shape {values.shape})")
    if not np.isfinite(values).all():
        raise ValueError(f"Expected finite distortion terms for {model} (got "
                         f"{values.tolist()})")
    out = np.zeros(4)
    for name, value in zip(terms, values, strict=True):
        out[_OPENCV_INDEX[name]] = value
    return out


def _check_K(K: Any) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all():
        raise ValueError(f"Expected K as a finite (3, 3) matrix (got shape {K.shape}"
                         + ("" if K.shape != (3, 3) else ", non-finite entries") + ")")
    if not (K[0, 0] > 0 and K[1, 1] > 0) or K[1, 0] != 0 or not np.allclose(
            K[2], [0.0, 0.0, 1.0]):
        raise ValueError("Expected K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 "
                         f"(got {K.tolist()})")
    if abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise ValueError(f"Expected K without skew for lens distortion (got K[0, 1] = "
                         f"{K[0, 1]:g})")
    return K


def _check_coeffs(coeffs: Any) -> np.ndarray:
    c = np.asarray(coeffs, dtype=np.float64)
    if c.shape != (4,) or not np.isfinite(c).all():
        raise ValueError(f"Expected 4 finite OpenCV coefficients [k1, k2, p1, p2] (got "
                         f"{c.tolist() if c.size <= 8 else f'shape {c.shape}'})")
    return c


def _check_points(xy: Any) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or not np.isfinite(xy).all():
        raise ValueError(f"Expected finite pixel points of shape (N, 2) (got shape {xy.shape}"
                         + ("" if xy.ndim != 2 or xy.shape[1] != 2 else ", non-finite entries")
                         + ")")
    return xy


def distort_points(xy: Any, K: Any, coeffs: Any) -> np.ndarray:
    """Where the lens images the pinhole pixels ``xy``: the forward model of the module
    docstring, in closed form.

    Args:
        xy: ``[N, 2]`` pixels of the undistorted (pinhole) image, OpenCV pixel centres.
        K: ``[3, 3]`` intrinsics, without skew (shared by both images).
        coeffs: ``[4]`` OpenCV coefficients ``[k1, k2, p1, p2]`` (:func:`opencv_coefficients`).

    Returns:
        ``[N, 2]`` float64 pixels of the distorted image.
    """
    xy, K, (k1, k2, p1, p2) = _check_points(xy), _check_K(K), _check_coeffs(coeffs)
    x = (xy[:, 0] - K[0, 2]) / K[0, 0]
    y = (xy[:, 1] - K[1, 2]) / K[1, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + k2 * r2)
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd * K[0, 0] + K[0, 2], yd * K[1, 1] + K[1, 2]], axis=1)


def undistort_points(xy: Any, K: Any, coeffs: Any) -> np.ndarray:
    """The pinhole pixels that the lens images at ``xy``: the inverse of
    :func:`distort_points`, by OpenCV's fixed-point iteration (``cv2.undistortPoints`` with
    ``P = K``, 50 iterations or a step below 1e-10).

    Within the radius where the model is monotonic (every real lens's image area)
    ``distort_points(undistort_points(xy))`` returns ``xy`` to about 1e-9 px; beyond it the
    model has no inverse and the result is meaningless.

    Args:
        xy: ``[N, 2]`` pixels of the distorted image, OpenCV pixel centres.
        K: ``[3, 3]`` intrinsics, without skew (shared by both images).
        coeffs: ``[4]`` OpenCV coefficients ``[k1, k2, p1, p2]``.

    Returns:
        ``[N, 2]`` float64 pixels of the undistorted image.
    """
    xy, K, c = _check_points(xy), _check_K(K), _check_coeffs(coeffs)
    if len(xy) == 0 or not c.any():
        return xy.copy()
    import cv2

    count, eps = _UNDISTORT_CRITERIA
    out = cv2.undistortPoints(xy.reshape(-1, 1, 2), K, c, R=None, P=K,
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                        count, eps))
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)


@lru_cache(maxsize=_MAPS_CACHED)
def _maps(K: tuple[float, ...], coeffs: tuple[float, ...], size: tuple[int, int]
          ) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    Km = np.asarray(K).reshape(3, 3)
    map_x, map_y = cv2.initUndistortRectifyMap(Km, np.asarray(coeffs), None, Km,
                                               (size[1], size[0]), cv2.CV_32FC1)
    for m in (map_x, map_y):
        m.setflags(write=False)  # shared by every caller of the cache
    return map_x, map_y


def undistortion_maps(K: Any, coeffs: Any, size: tuple[int, int]
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The maps of :func:`undistort_image`: for each pixel of the undistorted image, the
    pixel of the distorted image it samples (:func:`distort_points` on the pixel grid).

    The last few ``(K, coeffs, size)`` are cached; the arrays are read-only.

    Args:
        K: ``[3, 3]`` intrinsics, without skew (shared by both images).
        coeffs: ``[4]`` OpenCV coefficients ``[k1, k2, p1, p2]``.
        size: ``(H, W)`` of both images.

    Returns:
        ``(map_x, map_y)``, each float32 ``[H, W]``: the x and y pixel sampled.
    """
    K, c = _check_K(K), _check_coeffs(coeffs)
    try:
        h, w = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"Expected the image size as (H, W) (got {size!r})") from None
    if h < 1 or w < 1 or h >= 2**15 or w >= 2**15:  # remap's coordinate limit
        raise ValueError(f"Expected an image size (H, W) between 1 and 32767 px (got {size!r})")
    return _maps(tuple(K.ravel().tolist()), tuple(c.tolist()), (h, w))


_IMAGE_DTYPES = (np.uint8, np.uint16, np.float32, np.float64)


def undistort_image(image: Any, K: Any, coeffs: Any) -> np.ndarray:
    """The image a pinhole camera with the same ``K`` and size would take: each pixel
    sampled, bilinearly, where the lens images it (:func:`undistortion_maps`,
    ``cv2.remap``); pixels whose source falls outside the image are 0.

    Points matched in the result are pinhole pixels of ``K``: no other correction is needed.
    A pinhole camera (``coeffs`` all zero) returns a copy of the image.

    Args:
        image: ``[H, W]`` or ``[H, W, C]`` (``C <= 4``) numpy array, uint8, uint16, float32 or
            float64 (floats finite).
        K: ``[3, 3]`` intrinsics of the image, without skew, OpenCV pixel centres.
        coeffs: ``[4]`` OpenCV coefficients ``[k1, k2, p1, p2]`` (:func:`opencv_coefficients`).

    Returns:
        The undistorted image, of the input's shape and dtype.
    """
    if not isinstance(image, np.ndarray):
        raise TypeError(f"Expected the image as a numpy array (got {type(image).__name__})")
    if image.dtype not in _IMAGE_DTYPES:
        raise TypeError(f"Expected an image of dtype uint8, uint16, float32 or float64 (got "
                        f"{image.dtype})")
    if not (image.ndim == 2 or (image.ndim == 3 and 1 <= image.shape[2] <= 4)) \
            or image.size == 0:
        raise ValueError(f"Expected an image of shape (H, W) or (H, W, C) with C <= 4, not "
                         f"empty (got {image.shape})")
    if image.dtype.kind == "f" and not np.isfinite(image).all():
        raise ValueError("Expected a float image with finite values (got NaN or inf)")
    K, c = _check_K(K), _check_coeffs(coeffs)
    if not c.any():
        return image.copy()
    map_x, map_y = undistortion_maps(K, c, image.shape[:2])
    import cv2

    out = cv2.remap(np.ascontiguousarray(image), map_x, map_y, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out.reshape(image.shape)  # remap drops a trailing channel axis of 1
