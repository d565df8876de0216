"""Deprecated alias of :mod:`strl_pyg.pose_fusion` (network + classical pose fusion).

Renamed so that it is not confused with :mod:`strl_pyg.nn.fusion`, the paper's
feature-weighted fusion layer; import from :mod:`strl_pyg.pose_fusion` (and the SO(3) and
sphere maps from :mod:`strl_pyg.geometry`) instead.
"""

import warnings

from strl_pyg.pose_fusion import *  # noqa: F403
from strl_pyg.pose_fusion import __all__  # noqa: F401

warnings.warn(
    "strl_pyg.fusion is deprecated: import from strl_pyg.pose_fusion instead",
    DeprecationWarning,
    stacklevel=2,
)
