"""Datasets of pair graphs: KITTI odometry, DeMoN (DeepSfM folders and original HDF5), posed
photographs (real_scenes, COLMAP, NeRF, LLFF camera files) and generated scenes, with an
on-disk, resumable, parallel match cache."""

from strl_pyg.datasets import base as _base
from strl_pyg.datasets import cache as _cache
from strl_pyg.datasets import camera_files as _camera_files
from strl_pyg.datasets import demon as _demon
from strl_pyg.datasets import kitti as _kitti
from strl_pyg.datasets import posed as _posed
from strl_pyg.datasets import synthetic as _synthetic
from strl_pyg.datasets.base import *  # noqa: F403
from strl_pyg.datasets.cache import *  # noqa: F403
from strl_pyg.datasets.camera_files import *  # noqa: F403
from strl_pyg.datasets.demon import *  # noqa: F403
from strl_pyg.datasets.kitti import *  # noqa: F403
from strl_pyg.datasets.posed import *  # noqa: F403
from strl_pyg.datasets.synthetic import *  # noqa: F403

__all__ = [*_base.__all__, *_cache.__all__, *_camera_files.__all__, *_demon.__all__,
           *_kitti.__all__, *_posed.__all__, *_synthetic.__all__]
