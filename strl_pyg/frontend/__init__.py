"""Image front end: two images -> matched points and line segments (:class:`PairMatches`).

Points: OpenCV SIFT (or ORB) with Lowe's ratio test and a mutual nearest-neighbour check
(:mod:`~strl_pyg.frontend.points`). Lines: OpenCV's LSD detector and our own matcher under the
fundamental matrix fitted to the point matches (:mod:`~strl_pyg.frontend.lines`), scored by
descriptors sampled along the segments (:mod:`~strl_pyg.frontend.line_descriptors`).
:func:`match_images` (:mod:`~strl_pyg.frontend.pipeline`) runs the stages;
:class:`FrontendConfig` (:mod:`~strl_pyg.frontend.config`) holds every setting.

Conventions: pixels with OpenCV's convention (centre of the top-left pixel is ``(0, 0)``);
image suffixes 0 (reference) and 1 (target); ``T_0to1`` maps camera-0 points into camera 1.

Errors: images go through the package's one image check (:func:`strl_pyg.utils.images.check_image`,
grey uint8 out, at least 16x16 pixels): another type, dtype, shape or an empty image raises
``TypeError``/``ValueError`` with an ``Expected ... (got ...)`` message. Images of different
sizes are allowed (the two cameras may differ; each image keeps its own size in the result).
When neither a point nor a line match is found (all-black, featureless or unrelated images)
:class:`NoMatchesError` is raised, because an empty :class:`PairMatches` is invalid.

:func:`fundamental_from_pose` and :func:`epipolar_residuals` live in
:mod:`strl_pyg.geometry.epipolar`.
"""

from __future__ import annotations

from strl_pyg.data.matches import PairMatches as PairMatches  # the result type
from strl_pyg.frontend.config import LINE_MATCHERS, FrontendConfig, NoMatchesError
from strl_pyg.frontend.line_descriptors import band_descriptors, line_descriptor_scores
from strl_pyg.frontend.lines import (
    candidate_pairs,
    detect_lines,
    match_lines,
    match_lines_by_descriptor,
)
from strl_pyg.frontend.pipeline import check_frontend_image, match_images
from strl_pyg.frontend.points import fit_fundamental, match_points

__all__ = [
    "FrontendConfig",
    "NoMatchesError",
    "match_images",
    "detect_lines",
    "match_points",
    "match_lines",
    "match_lines_by_descriptor",
    "band_descriptors",
    "LINE_MATCHERS",
    "fit_fundamental",
    "candidate_pairs",
    "line_descriptor_scores",
    "check_frontend_image",
]

