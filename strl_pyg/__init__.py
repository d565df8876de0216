"""strl-pyg: Str-L Pose relative pose from matched points and line segments, on PyG.

The main entry points::

    from strl_pyg import PairMatches, build_pair_graph, StrLPose, StrLPoseConfig
"""

from strl_pyg.data import PairMatches, build_pair_graph
from strl_pyg.geometry import Pose
from strl_pyg.model import ABLATIONS, PoseOutput, StrLPose, StrLPoseConfig

__version__ = "0.1.0"

__all__ = [
    "PairMatches",
    "build_pair_graph",
    "Pose",
    "StrLPose",
    "StrLPoseConfig",
    "PoseOutput",
    "ABLATIONS",
    "__version__",
]
