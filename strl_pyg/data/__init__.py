"""Match containers, pair graphs, transforms and match files of other tools (datasets of
pair graphs live in :mod:`strl_pyg.datasets`).

Names are imported on first use: ``from strl_pyg.data import PairMatches`` needs only numpy;
graphs and transforms load torch and PyG when first touched.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from strl_pyg.utils.lazy import lazy_exports

_GRAPH = "strl_pyg.data.build"
_TRANSFORMS = "strl_pyg.data.transforms"

_EXPORTS = {
    "keys": "",
    "PairMatches": "strl_pyg.data.matches",
    "build_pair_graph": _GRAPH,
    "PairGraph": "strl_pyg.data.pair_graph",
    "ImplicitEdgesError": "strl_pyg.data.pair_graph",
    "MixedEdgesError": "strl_pyg.data.pair_graph",
    "CompleteEdges": "strl_pyg.data.pair_graph",
    "drop_legacy_cross_edges": "strl_pyg.data.pair_graph",
    "edge_index_dict": "strl_pyg.data.pair_graph",
    "complete_edge_index": "strl_pyg.data.pair_graph",
    "has_implicit_complete_edges": "strl_pyg.data.pair_graph",
    "materialize_complete_edges": "strl_pyg.data.pair_graph",
    "save_graph": _GRAPH,
    "load_graph": _GRAPH,
    "FixedSizeResample": _TRANSFORMS,
    "MaterializeCompleteEdges": _TRANSFORMS,
    "RandomRoll": _TRANSFORMS,
    "RandomSwap": _TRANSFORMS,
    "roll_cameras": _TRANSFORMS,
    "roll_pose": _TRANSFORMS,
    "swap_images": _TRANSFORMS,
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # for type checkers and IDEs; never executed
    from strl_pyg.data import keys
    from strl_pyg.data.build import build_pair_graph, load_graph, save_graph
    from strl_pyg.data.matches import PairMatches
    from strl_pyg.data.pair_graph import (
        CompleteEdges,
        ImplicitEdgesError,
        MixedEdgesError,
        PairGraph,
        complete_edge_index,
        drop_legacy_cross_edges,
        edge_index_dict,
        has_implicit_complete_edges,
        materialize_complete_edges,
    )
    from strl_pyg.data.transforms import (
        FixedSizeResample,
        MaterializeCompleteEdges,
        RandomRoll,
        RandomSwap,
        roll_cameras,
        roll_pose,
        swap_images,
    )
