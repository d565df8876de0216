"""One pinhole camera for the command line and the datasets: intrinsics in this package's
pixel convention (OpenCV's: the centre of the top-left pixel at ``(0, 0)``), the image size,
COLMAP's camera models read in one place, and the one rescale of K for a resized image
(its distortion terms are unchanged: they act on normalised coordinates,
:mod:`~strl_pyg.geometry.distortion`).

COLMAP puts the centre of the top-left pixel at ``(0.5, 0.5)``, so a COLMAP principal point
is ``c = c_colmap - 0.5`` here. A resize by ``(s_x, s_y)`` maps ``x' = (x + 0.5) s_x - 0.5``:
``f' = s f`` and ``c' = (c + 0.5) s - 0.5``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from strl_pyg.geometry.distortion import opencv_coefficients

__all__ = ["Camera", "COLMAP_CAMERA_MODELS", "scale_intrinsics"]

#: COLMAP's camera models: id -> (name, number of parameters, focal lengths among them, 1 or
#: 2: ``f, cx, cy, ...`` or ``fx, fy, cx, cy, ...``; the rest are distortion terms).
COLMAP_CAMERA_MODELS = {
    0: ("SIMPLE_PINHOLE", 3, 1), 1: ("PINHOLE", 4, 2), 2: ("SIMPLE_RADIAL", 4, 1),
    3: ("RADIAL", 5, 1), 4: ("OPENCV", 8, 2), 5: ("OPENCV_FISHEYE", 8, 2),
    6: ("FULL_OPENCV", 12, 2), 7: ("FOV", 5, 2), 8: ("SIMPLE_RADIAL_FISHEYE", 4, 1),
    9: ("RADIAL_FISHEYE", 5, 1), 10: ("THIN_PRISM_FISHEYE", 12, 2),
    11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16, 2),
}
_BY_NAME = {name: (n, focals) for name, n, focals in COLMAP_CAMERA_MODELS.values()}


def scale_intrinsics(K: Any, sx: float, sy: float) -> np.ndarray:
    """``K`` of an image resized by ``(sx, sy)`` (new size / old size), pixel centres at
    integer coordinates (module docstring); skew scales with ``sx``."""
    S = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
    return S @ np.asarray(K, dtype=np.float64)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera (module docstring).

    Attributes:
        fx, fy, cx, cy: focal lengths and principal point, pixels.
        size: the image's ``(H, W)``, or ``None`` where unknown.
        model: the camera model it was read as (COLMAP's names; ``"PINHOLE"`` otherwise).
        distortion: the model's distortion terms in COLMAP's order, as given. ``K`` is the
            pinhole part: matches must come from undistorted images, which
            :func:`~strl_pyg.geometry.distortion.undistort_image` makes with ``K`` and
            :attr:`opencv_distortion` (models in
            :data:`~strl_pyg.geometry.distortion.DISTORTION_MODELS`).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    size: tuple[int, int] | None = None
    model: str = "PINHOLE"
    distortion: tuple[float, ...] = ()

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def distorted(self) -> bool:
        return any(abs(d) > 0 for d in self.distortion)

    @property
    def opencv_distortion(self) -> np.ndarray:
        """OpenCV's ``[k1, k2, p1, p2]`` of :attr:`distortion`
        (:func:`~strl_pyg.geometry.distortion.opencv_coefficients`: a one-line
        ``ValueError`` for a model outside ``DISTORTION_MODELS``)."""
        return opencv_coefficients(self.model, self.distortion)

    @classmethod
    def from_K(cls, K: Any, size: tuple[int, int] | None = None) -> Camera:
        K = np.asarray(K, dtype=np.float64)
        return cls(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), size)

    @classmethod
    def from_colmap(cls, model: str, params: Sequence[Any], size: tuple[int, int] | None = None,
                    where: str = "the camera") -> Camera:
        """The camera of a COLMAP model name and its parameters (text or numbers); a one-line
        ``ValueError`` naming ``where`` for an unknown model, a wrong count or a non-number."""
        if model not in _BY_NAME:
            raise ValueError(f"Expected a COLMAP camera model among {sorted(_BY_NAME)} in "
                             f"{where} (got {model!r})")
        n, focals = _BY_NAME[model]
        try:
            p = [float(v) for v in params]
        except (TypeError, ValueError) as err:
            raise ValueError(f"Expected numbers as the camera parameters in {where} (got "
                             f"{err})") from None
        if len(p) != n:
            raise ValueError(f"Expected {n} parameters for COLMAP model {model} in {where} "
                             f"(got {len(p)})")
        fx, fy = (p[0], p[0]) if focals == 1 else (p[0], p[1])
        cx, cy = p[focals], p[focals + 1]
        return cls(fx, fy, cx - 0.5, cy - 0.5, size, model, tuple(p[focals + 2:]))

    def scaled(self, sx: float, sy: float) -> Camera:
        """The camera of the image resized by ``(sx, sy)`` (:func:`scale_intrinsics`)."""
        K = scale_intrinsics(self.K, sx, sy)
        size = None if self.size is None else (round(self.size[0] * sy),
                                                round(self.size[1] * sx))
        return Camera(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), size,
                      self.model, self.distortion)
