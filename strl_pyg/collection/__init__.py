"""Photo collections: features once per image, a recommended pose for every pair, and a COLMAP
database for COLMAP's and GLOMAP's mappers.

- :mod:`~strl_pyg.collection.images`: the images and their cameras (:func:`read_collection`);
- :mod:`~strl_pyg.collection.pairs`: exhaustive, sequential, hloc and SuperGlue pairs;
- :mod:`~strl_pyg.collection.scene`: :func:`run_scene` (features, pairs, outputs; resumable);
- :mod:`~strl_pyg.collection.database`: the COLMAP database writer;
- :mod:`~strl_pyg.collection.distributed`: the same run split across ``torchrun`` ranks.

``strl-pose scene`` is the command line of :func:`run_scene`.
"""

from __future__ import annotations

from strl_pyg.collection.images import CollectionImage, read_collection
from strl_pyg.collection.pairs import (
    Pair,
    exhaustive_pairs,
    read_pairs_file,
    sequential_pairs,
)
from strl_pyg.collection.scene import SceneOptions, SceneSummary, run_scene

__all__ = ["CollectionImage", "read_collection", "Pair", "exhaustive_pairs",
           "sequential_pairs", "read_pairs_file", "SceneOptions", "SceneSummary", "run_scene"]
