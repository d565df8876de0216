"""Match containers, pair graphs, transforms and datasets."""

from strl_pyg.data import datasets, keys
from strl_pyg.data.graph import (
    build_pair_graph,
    complete_edge_index,
    has_implicit_complete_edges,
    load_graph,
    materialize_complete_edges,
    save_graph,
)
from strl_pyg.data.matches import PairMatches, load_external_matches
from strl_pyg.data.transforms import (
    FixedSizeResample,
    MaterializeCompleteEdges,
    RandomSwap,
    swap_images,
)

__all__ = [
    "datasets",
    "keys",
    "PairMatches",
    "load_external_matches",
    "build_pair_graph",
    "complete_edge_index",
    "has_implicit_complete_edges",
    "materialize_complete_edges",
    "save_graph",
    "load_graph",
    "FixedSizeResample",
    "MaterializeCompleteEdges",
    "RandomSwap",
    "swap_images",
]
