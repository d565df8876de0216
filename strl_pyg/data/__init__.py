"""Match containers, pair graphs, transforms and datasets."""

from strl_pyg.data import keys
from strl_pyg.data.matches import PairMatches, load_external_matches

__all__ = ["keys", "PairMatches", "load_external_matches"]
