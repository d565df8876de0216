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

__all__ = [
    "keys",
    "PairMatches",
    "load_external_matches",
    "load_hloc_matches",
    "from_lightglue",
    "MatchFormatError",
    "build_pair_graph",
    "PairGraph",
    "ImplicitEdgesError",
    "CompleteEdges",
    "drop_legacy_cross_edges",
    "edge_index_dict",
    "complete_edge_index",
    "has_implicit_complete_edges",
    "materialize_complete_edges",
    "save_graph",
    "load_graph",
    "FixedSizeResample",
    "MaterializeCompleteEdges",
    "RandomRoll",
    "RandomSwap",
    "roll_cameras",
    "roll_pose",
    "swap_images",
]

__getattr__, __dir__ = lazy_exports(__name__, {
    "keys": "",
    "PairMatches": "strl_pyg.data.matches",
    "load_external_matches": "strl_pyg.data.external.formats",
    "load_hloc_matches": "strl_pyg.data.external.hloc",
    "from_lightglue": "strl_pyg.data.external.formats",
    "MatchFormatError": "strl_pyg.data.external.formats",
    "build_pair_graph": _GRAPH,
    "PairGraph": _GRAPH,
    "ImplicitEdgesError": _GRAPH,
    "CompleteEdges": "strl_pyg.data.pair_graph",
    "drop_legacy_cross_edges": "strl_pyg.data.pair_graph",
    "edge_index_dict": _GRAPH,
    "complete_edge_index": _GRAPH,
    "has_implicit_complete_edges": _GRAPH,
    "materialize_complete_edges": _GRAPH,
    "save_graph": _GRAPH,
    "load_graph": _GRAPH,
    "FixedSizeResample": _TRANSFORMS,
    "MaterializeCompleteEdges": _TRANSFORMS,
    "RandomRoll": _TRANSFORMS,
    "RandomSwap": _TRANSFORMS,
    "roll_cameras": _TRANSFORMS,
    "roll_pose": _TRANSFORMS,
    "swap_images": _TRANSFORMS,
}, globals())

if TYPE_CHECKING:  # for type checkers and IDEs; never executed
    from strl_pyg.data import keys
    from strl_pyg.data.build import (
        ImplicitEdgesError,
        PairGraph,
        build_pair_graph,
        complete_edge_index,
        edge_index_dict,
        has_implicit_complete_edges,
        load_graph,
        materialize_complete_edges,
        save_graph,
    )
    from strl_pyg.data.external.formats import (
        MatchFormatError,
        from_lightglue,
        load_external_matches,
    )
    from strl_pyg.data.external.hloc import load_hloc_matches
    from strl_pyg.data.matches import PairMatches
    from strl_pyg.data.pair_graph import CompleteEdges, drop_legacy_cross_edges
    from strl_pyg.data.transforms import (
        FixedSizeResample,
        MaterializeCompleteEdges,
        RandomRoll,
        RandomSwap,
        roll_cameras,
        roll_pose,
        swap_images,
    )
