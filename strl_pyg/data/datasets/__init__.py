"""Datasets of pair graphs: KITTI odometry, DeMoN (DeepSfM folders and original HDF5) and
generated scenes, with an on-disk, resumable, parallel match cache."""

from strl_pyg.data.datasets import base as _base
from strl_pyg.data.datasets import cache as _cache
from strl_pyg.data.datasets import demon as _demon
from strl_pyg.data.datasets import kitti as _kitti
from strl_pyg.data.datasets import synthetic as _synthetic
from strl_pyg.data.datasets.base import *  # noqa: F403
from strl_pyg.data.datasets.cache import *  # noqa: F403
from strl_pyg.data.datasets.demon import *  # noqa: F403
from strl_pyg.data.datasets.kitti import *  # noqa: F403
from strl_pyg.data.datasets.synthetic import *  # noqa: F403

__all__ = [*_base.__all__, *_cache.__all__, *_demon.__all__, *_kitti.__all__,
           *_synthetic.__all__]
