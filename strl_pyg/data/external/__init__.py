"""Match files of other tools (SuperGlue, LightGlue, GlueStick, LoFTR, hloc, ...):
format detection and assembly into a :class:`~strl_pyg.data.PairMatches`
(:mod:`.formats`), per-layout readers (:mod:`.readers`), shared checks (:mod:`.checks`) and
hloc's HDF5 files (:mod:`.hloc`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "MatchFormatError": "strl_pyg.data.external.checks",
    "FORMATS": "strl_pyg.data.external.formats",
    "detect_format": "strl_pyg.data.external.formats",
    "load_external_matches": "strl_pyg.data.external.formats",
    "from_lightglue": "strl_pyg.data.external.formats",
    "RANKS": "strl_pyg.data.external.readers",
    "READERS": "strl_pyg.data.external.readers",
    "as_numpy": "strl_pyg.data.external.checks",
    "unbatch": "strl_pyg.data.external.checks",
    "index_per_node": "strl_pyg.data.external.checks",
    "index_pairs": "strl_pyg.data.external.checks",
    "as_indices": "strl_pyg.data.external.checks",
    "scores_at": "strl_pyg.data.external.checks",
    "keypoints": "strl_pyg.data.external.checks",
    "image_size_from": "strl_pyg.data.external.checks",
    "build_matches": "strl_pyg.data.external.checks",
    "filter_scores": "strl_pyg.data.external.checks",
    "load_hloc_matches": "strl_pyg.data.external.hloc",
    "hloc_pair_names": "strl_pyg.data.external.hloc",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
