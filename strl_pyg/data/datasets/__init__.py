"""Datasets of pair graphs: KITTI odometry, DeMoN (DeepSfM folders and original HDF5) and
generated scenes, with an on-disk, resumable, parallel match cache."""

from strl_pyg.data.datasets.base import (
    PAIR_ID,
    SUBSET,
    CachedPairDataset,
    ImageSource,
    PairDataset,
    PairRecord,
    load_pair_images,
    read_image,
    resize_image,
    scale_intrinsics,
)
from strl_pyg.data.datasets.cache import (
    CacheBuildReport,
    MatchCache,
    PairFailedError,
    cache_key,
    fingerprint_hash,
)
from strl_pyg.data.datasets.demon import (
    DEMON_SUBSETS,
    DeMoNFolder,
    DeMoNHDF5,
    demon_subset,
    pair_indices,
    read_demon_camera,
)
from strl_pyg.data.datasets.kitti import (
    KITTI_SPLITS,
    KITTIOdometry,
    read_kitti_calib,
    read_kitti_poses,
)
from strl_pyg.data.datasets.synthetic import InfiniteSyntheticPairs, SyntheticPairs

__all__ = [
    "PAIR_ID",
    "SUBSET",
    "ImageSource",
    "PairRecord",
    "CachedPairDataset",
    "PairDataset",
    "read_image",
    "resize_image",
    "scale_intrinsics",
    "load_pair_images",
    "MatchCache",
    "CacheBuildReport",
    "PairFailedError",
    "cache_key",
    "fingerprint_hash",
    "KITTI_SPLITS",
    "KITTIOdometry",
    "read_kitti_calib",
    "read_kitti_poses",
    "DEMON_SUBSETS",
    "DeMoNFolder",
    "DeMoNHDF5",
    "demon_subset",
    "pair_indices",
    "read_demon_camera",
    "SyntheticPairs",
    "InfiniteSyntheticPairs",
]
