"""Generated two-view scenes with exact ground truth: textured planar quads (streets, rooms,
corridors, boxes) rendered on the CPU, with the relative pose and ground-truth point and line
correspondences.

Conventions: ``T_0to1`` maps camera-0 points into camera 1 (``X1 = R X0 + t``); pixels follow
OpenCV (centre of the top-left pixel is ``(0, 0)``).
"""

from strl_pyg.synthetic.metrics import (
    evaluate_matches,
    line_transfer_error,
    point_transfer_error,
)
from strl_pyg.synthetic.pair import SyntheticPair, generate_pair
from strl_pyg.synthetic.scene import SCENE_KINDS, SceneConfig

__all__ = [
    "SCENE_KINDS",
    "SceneConfig",
    "SyntheticPair",
    "generate_pair",
    "evaluate_matches",
    "line_transfer_error",
    "point_transfer_error",
]
