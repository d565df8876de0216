"""Generated two-view scenes with exact ground truth: textured planar quads (streets, rooms,
corridors, boxes, single objects) rendered on the CPU, with the relative pose and ground-truth
point and line correspondences; camera motions, intrinsics and photometry are knobs of
:class:`SceneConfig`, and :mod:`strl_pyg.synthetic.distributions` draws them per seed
(training preset ``"mixed"``, held-out evaluation distributions).

Conventions: ``T_0to1`` maps camera-0 points into camera 1 (``X1 = R X0 + t``); pixels follow
OpenCV (centre of the top-left pixel is ``(0, 0)``).

Names are imported on first use: the configuration (:mod:`strl_pyg.synthetic.config`, numpy
only) loads without OpenCV; rendering and matching load it when first touched.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from strl_pyg.utils.lazy import lazy_exports

_CONFIG = "strl_pyg.synthetic.config"
_DIST = "strl_pyg.synthetic.distributions"
_QUALITY = "strl_pyg.synthetic.match_quality"

_EXPORTS = {
    "SCENE_KINDS": _CONFIG,
    "LINE_SCENE_KINDS": _CONFIG,
    "MOTIONS": _CONFIG,
    "DEFAULT_MOTION": _CONFIG,
    "SceneConfig": _CONFIG,
    "SceneDistribution": _DIST,
    "DISTRIBUTIONS": _DIST,
    "EVAL_DISTRIBUTIONS": _DIST,
    "EVAL_SEED": _DIST,
    "scene_distribution": _DIST,
    "eval_distribution": _DIST,
    "sample_scene_config": _DIST,
    "SyntheticPair": "strl_pyg.synthetic.pair",
    "generate_pair": "strl_pyg.synthetic.pair",
    "apply_photometric": "strl_pyg.synthetic.photometric",
    "evaluate_matches": _QUALITY,
    "line_transfer_error": _QUALITY,
    "point_transfer_error": _QUALITY,
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # for type checkers and IDEs; never executed
    from strl_pyg.synthetic.config import (
        DEFAULT_MOTION,
        LINE_SCENE_KINDS,
        MOTIONS,
        SCENE_KINDS,
        SceneConfig,
    )
    from strl_pyg.synthetic.distributions import (
        DISTRIBUTIONS,
        EVAL_DISTRIBUTIONS,
        EVAL_SEED,
        SceneDistribution,
        eval_distribution,
        sample_scene_config,
        scene_distribution,
    )
    from strl_pyg.synthetic.match_quality import (
        evaluate_matches,
        line_transfer_error,
        point_transfer_error,
    )
    from strl_pyg.synthetic.pair import SyntheticPair, generate_pair
    from strl_pyg.synthetic.photometric import apply_photometric
