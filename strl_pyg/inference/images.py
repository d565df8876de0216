"""Two images to a pose: :func:`estimate_images`, the body of
:meth:`PoseEstimator.estimate_images
<strl_pyg.inference.estimator.PoseEstimator.estimate_images>`."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from strl_pyg.inference.checks import input_warnings
from strl_pyg.inference.record import PoseEstimate
from strl_pyg.inference.registry import METHODS, RECOMMENDED, methods_needed
from strl_pyg.inference.running import refused_record
from strl_pyg.inference.status import Status

__all__ = ["estimate_images"]


def estimate_images(estimator: Any, image0: np.ndarray, image1: np.ndarray, K0: Any = None,
                    K1: Any = None, frontend_config: Any = None, methods: Any = None,
                    original: Any = None, features: Any = None) -> PoseEstimate:
    """Matches two images with :func:`~strl_pyg.frontend.match_images`, then
    :meth:`estimator.estimate <strl_pyg.inference.estimator.PoseEstimator.estimate>`
    (``methods`` as there). ``K1`` defaults to ``K0`` (one camera). No matches at all gives
    status ``"degenerate"``. ``original``: where the images are a
    resized copy, the sizes and intrinsics the user gave (``{"size0", "size1", "K0",
    "K1"}``, ``matches.info["original_frame"]``): the intrinsics warnings quote them. With
    :data:`RECOMMENDED`, the images
    are matched once: the points first, the line segments added to them (without
    detecting the points again) only when a method that reads lines is about to run and
    ``frontend_config.lines`` is on. ``features``: the two images' feature sources
    (:mod:`strl_pyg.frontend.features`), as :func:`~strl_pyg.frontend.match_images` takes
    them."""
    from strl_pyg.data.checks import check_K
    from strl_pyg.frontend import FrontendConfig, NoMatchesError, match_images
    from strl_pyg.frontend.pipeline import add_lines

    names = estimator._names(methods)
    cfg = frontend_config if frontend_config is not None else FrontendConfig()
    if not isinstance(cfg, FrontendConfig):
        raise TypeError(f"Expected a FrontendConfig (got {type(cfg).__name__})")
    if K0 is None and K1 is not None:
        raise ValueError("Expected K0 with K1 (got K1 only)")
    K0 = check_K(K0, "K0")  # before any use: the no-match path reads them too
    K1 = K0 if K1 is None else check_K(K1, "K1")
    recommended = names == RECOMMENDED
    if recommended:  # the first method's matches first (points only unless it reads lines)
        order = estimator._installed_order()
        names = methods_needed(order[:1]) if order else estimator.method_names
        first = replace(cfg, lines=cfg.lines and any(METHODS[m].reads_lines
                                                     for m in names))
    else:
        first = cfg
    try:
        matches = match_images(image0, image1, K0=K0, K1=K1, config=first,
                               features=features)
        if original is not None:
            matches.info["original_frame"] = dict(original)
    except NoMatchesError as err:
        o = original or {"size0": np.shape(image0)[:2], "size1": np.shape(image1)[:2],
                         "K0": K0, "K1": K1}
        warnings = input_warnings(o["size0"], o["size1"], o["K0"], o["K1"])
        why = f"no matches: {str(err).splitlines()[0]}"
        records = {m: refused_record(m, Status.DEGENERATE, "no_matches", why)
                   for m in names}
        return PoseEstimate(refused_record(None, Status.DEGENERATE, "no_matches", why,
                                           warnings=warnings), records, 0, 0, None)
    if not recommended:
        return estimator.estimate(matches, methods=names)
    more = (lambda: add_lines(matches, cfg, features)) if cfg.lines and not first.lines else None
    return estimator._recommended(estimator._pair(matches), more)

