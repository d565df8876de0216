"""strl-pyg: Str-L Pose relative pose from matched points and line segments, on PyG.

The main entry points::

    from strl_pyg import PairMatches, build_pair_graph, StrLPose, StrLPoseConfig

The names are imported on first use, so ``import strl_pyg`` (and the ``strl-pose`` command's
``--help``) does not load torch, PyG, OpenCV or kornia.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from strl_pyg.utils.lazy import lazy_exports

__version__ = "0.4.0.dev0"

_EXPORTS = {
    "PairMatches": "strl_pyg.data.matches",
    "build_pair_graph": "strl_pyg.data.build",
    "Pose": "strl_pyg.geometry.pose",
    "StrLPose": "strl_pyg.model.strl_pose",
    "StrLPoseConfig": "strl_pyg.model.config",
    "PoseOutput": "strl_pyg.model.config",
    "ABLATIONS": "strl_pyg.model.config",
}

__all__ = [*_EXPORTS, "__version__"]

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # for type checkers and IDEs; never executed
    from strl_pyg.data.build import build_pair_graph
    from strl_pyg.data.matches import PairMatches
    from strl_pyg.geometry import Pose
    from strl_pyg.model import ABLATIONS, PoseOutput, StrLPoseConfig
    from strl_pyg.model.strl_pose import StrLPose
