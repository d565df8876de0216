"""Rigid two-view geometry as pure functions on batched torch tensors.

Conventions (fixed for the whole project):

* Image suffixes ``0`` (reference) and ``1`` (target). ``T_0to1`` is the 4x4 pose that maps a
  point of camera 0 into camera 1: ``X1 = R X0 + t``.
* ``T_w_c`` is **camera-to-world** (KITTI ``poses/NN.txt``); ``T_c_w`` is **world-to-camera**
  (DeMoN ``poses.txt``). Names say which one a function expects.
* Quaternions are ``(w, x, y, z)`` as kornia uses; :func:`rotation_to_quaternion` returns the
  canonical sign ``w >= 0``.
* Pixels follow OpenCV: the centre of the top-left pixel is ``(0, 0)``. Normalised camera
  coordinates are ``K^-1 [u, v, 1]^T`` without the trailing 1.
* The essential matrix is ``E = [t]_x R`` so that ``x1^T E x0 = 0`` for normalised
  homogeneous ``x0``, ``x1``; the fundamental matrix ``F = K1^-T E K0^-1`` satisfies the same
  relation in pixels.

Every public function accepts torch tensors with leading batch dimensions ``*`` and also numpy
arrays or nested lists (converted at the boundary: float numpy keeps its precision, anything
else becomes float64). Results are torch tensors unless documented otherwise.

Modules: :mod:`~strl_pyg.geometry.pose` (tensor boundary, rotations, :class:`Pose`),
:mod:`~strl_pyg.geometry.manifold` (``[w]_x``, SO(3) and sphere maps, tangent bases),
:mod:`~strl_pyg.geometry.epipolar` (``E``, ``F``, normalisation, projection, Sampson errors),
:mod:`~strl_pyg.geometry.camera` (the pinhole :class:`Camera`, COLMAP's models),
:mod:`~strl_pyg.geometry.distortion` (radial and OpenCV lens distortion of points and images,
numpy in and out) and :mod:`~strl_pyg.geometry.essential` (the weighted eight-point solve,
imported by its path); every other name is importable from ``strl_pyg.geometry``. Needs numpy
and torch only (kornia is imported on the first quaternion conversion, OpenCV on the first
undistortion).
"""

from __future__ import annotations

from strl_pyg.geometry import camera as _camera
from strl_pyg.geometry import distortion as _distortion
from strl_pyg.geometry import epipolar as _epipolar
from strl_pyg.geometry import manifold as _manifold
from strl_pyg.geometry import pose as _pose
from strl_pyg.geometry.camera import *  # noqa: F403
from strl_pyg.geometry.distortion import *  # noqa: F403
from strl_pyg.geometry.epipolar import *  # noqa: F403
from strl_pyg.geometry.manifold import *  # noqa: F403
from strl_pyg.geometry.pose import *  # noqa: F403

__all__ = [*_pose.__all__, *_manifold.__all__, *_epipolar.__all__, *_camera.__all__,
           *_distortion.__all__]
