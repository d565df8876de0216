"""Generated two-view scenes with exact ground truth: textured planar quads (streets, rooms,
corridors, boxes, single objects) rendered on the CPU, with the relative pose and ground-truth
point and line correspondences; camera motions, intrinsics and photometry are knobs of
:class:`SceneConfig`, and :mod:`strl_pyg.synthetic.distributions` draws them per seed
(training preset ``"mixed"``, held-out evaluation distributions).

Conventions: ``T_0to1`` maps camera-0 points into camera 1 (``X1 = R X0 + t``); pixels follow
OpenCV (centre of the top-left pixel is ``(0, 0)``).
"""

from strl_pyg.synthetic.config import DEFAULT_MOTION, MOTIONS, SCENE_KINDS, SceneConfig
from strl_pyg.synthetic.distributions import (
    DISTRIBUTIONS,
    EVAL_DISTRIBUTIONS,
    EVAL_SEED,
    SceneDistribution,
    eval_distribution,
    sample_scene_config,
    scene_distribution,
)
from strl_pyg.synthetic.metrics import (
    evaluate_matches,
    line_transfer_error,
    point_transfer_error,
)
from strl_pyg.synthetic.pair import SyntheticPair, generate_pair
from strl_pyg.synthetic.photometric import apply_photometric

__all__ = [
    "SCENE_KINDS",
    "MOTIONS",
    "DEFAULT_MOTION",
    "SceneConfig",
    "SceneDistribution",
    "DISTRIBUTIONS",
    "EVAL_DISTRIBUTIONS",
    "EVAL_SEED",
    "scene_distribution",
    "eval_distribution",
    "sample_scene_config",
    "SyntheticPair",
    "generate_pair",
    "apply_photometric",
    "evaluate_matches",
    "line_transfer_error",
    "point_transfer_error",
]
