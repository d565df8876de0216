"""The front end's pipeline: two images -> :class:`~strl_pyg.data.PairMatches` (points,
fundamental matrix, lines), with per-stage timings."""

from __future__ import annotations

import time
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from strl_pyg.data.matches import (
    ENDPOINTS_AS_DETECTED,
    ENDPOINTS_CORRESPONDING,
    LINE_ENDPOINTS,
    PairMatches,
    first_unique_rows,
)
from strl_pyg.frontend.config import FrontendConfig, NoMatchesError
from strl_pyg.frontend.lines import detect_lines, match_lines, match_lines_by_descriptor
from strl_pyg.frontend.points import fit_fundamental, match_points, on_both
from strl_pyg.utils.images import FRONTEND_MIN_SIDE, check_image

__all__ = ["match_images", "add_lines", "check_frontend_image"]


def check_frontend_image(image: Any, name: str) -> np.ndarray:
    """``image`` as grey uint8 ``[H, W]`` for the detectors: the package's one image check
    (:func:`strl_pyg.utils.images.check_image`) with ``grayscale=True`` and
    ``min_side=FRONTEND_MIN_SIDE`` (16 px)."""
    return check_image(image, name, grayscale=True, min_side=FRONTEND_MIN_SIDE)


def match_images(
    image0: np.ndarray,
    image1: np.ndarray,
    K0: Any = None,
    K1: Any = None,
    config: FrontendConfig | None = None,
    features: tuple[Any, Any] | None = None,
) -> PairMatches:
    """Matches points and line segments between two images.

    Args:
        image0, image1: ``(H, W)``, ``(H, W, 1)`` or RGB ``(H, W, 3)`` images, numpy or torch,
            uint8 or float in ``[0, 1]``, at least 16x16 (:func:`check_frontend_image`); the
            two may have different sizes.
        K0, K1: optional intrinsics ``[3, 3]`` (pixels), attached to the result (both or none).
        config: :class:`FrontendConfig` (default ``FrontendConfig()``).
        features: the two images' feature sources (:mod:`strl_pyg.frontend.features`):
            keypoints, descriptors and segments computed once per image and setting (a photo
            collection), used instead of detecting them here; the same matches as without.

    Returns:
        :class:`PairMatches` with ``points0/1 [Np, 2]``, ``lines0/1 [Nl, 2, 2]`` (endpoint ``k``
        matches endpoint ``k``; not with ``line_matcher="descriptor"``), ``point_scores``
        (``1 - ratio``), ``line_scores`` (NCC; the descriptors' cosine similarity with
        ``line_matcher="descriptor"``), the
        grey images attached, and ``info`` holding ``timings_ms`` per stage
        (``points_detect``, ``points_match``, ``geometry``, ``lines_detect``, ``lines_match``,
        ``total``), counts, ``lines_status``, ``line_endpoints`` (``"corresponding"``, or
        ``"as detected"`` from the descriptor matcher) and the configuration. The default
        (epipolar) line matcher needs a fundamental matrix from at least 8 point matches;
        without one the result has points only.

    Raises:
        TypeError, ValueError: invalid images.
        NoMatchesError: no point and no line match (e.g. an all-black image).
    """
    cfg = config if config is not None else FrontendConfig()
    if not isinstance(cfg, FrontendConfig):
        raise TypeError(f"Expected a FrontendConfig (got {type(cfg).__name__})")
    gray0 = check_frontend_image(image0, "image0")
    gray1 = check_frontend_image(image1, "image1")
    t_start = time.perf_counter()
    p0, p1, p_scores, F, inl, stats, timings = _points(gray0, gray1, cfg, features)
    if cfg.thorough_below > 0 and int(inl.sum()) < cfg.thorough_below:
        # too few inliers for an easy pair: the thorough settings, once (the second pass
        # replaces the first, whose keypoints are a subset of its own)
        first = int(inl.sum())
        p0, p1, p_scores, F, inl, stats, more = _points(gray0, gray1, thorough_points(cfg),
                                                       features)
        timings = {k: timings.get(k, 0.0) + more.get(k, 0.0) for k in {*timings, *more}}
        stats["second_pass"] = {"first_pass_inliers": first,
                                "reason": f"fewer than thorough_below={cfg.thorough_below} "
                                          "fundamental-matrix inliers"}
    else:
        stats["second_pass"] = None
    if cfg.filter_points and F is not None:
        p0, p1, p_scores, inl = p0[inl], p1[inl], p_scores[inl], inl[inl]

    l0, l1, l_scores, seg0, seg1, status = _lines(gray0, gray1, F, p0[inl], p1[inl], cfg,
                                                  timings, features)
    timings["total"] = 1e3 * (time.perf_counter() - t_start)

    if len(p0) == 0 and len(l0) == 0:
        raise NoMatchesError(
            "Expected at least one point or line match (got none: "
            f"{stats['keypoints0']}/{stats['keypoints1']} keypoints, "
            f"{len(seg0)}/{len(seg1)} segments); the images may be featureless "
            "(e.g. all black) or show different scenes"
        )
    info = {
        "source": f"strl_pyg.frontend ({cfg.detector}+lsd)",
        "timings_ms": timings,
        **stats,
        "segments0": len(seg0),
        "segments1": len(seg1),
        "point_geometric_inliers": int(inl.sum()),
        # what add_lines needs to match the lines later exactly as here (one pass per pair)
        "fundamental": None if F is None else np.asarray(F, dtype=float).tolist(),
        "fundamental_inliers": np.flatnonzero(inl).tolist(),
        "lines_status": status,
        LINE_ENDPOINTS: (ENDPOINTS_AS_DETECTED if cfg.line_matcher == "descriptor"
                         else ENDPOINTS_CORRESPONDING),
        "config": asdict(cfg),
    }
    return PairMatches(
        p0, p1, lines0=l0, lines1=l1, point_scores=p_scores, line_scores=l_scores,
        K0=K0, K1=K1, image0=gray0, image1=gray1, info=info,
    )


def thorough_points(cfg: FrontendConfig) -> FrontendConfig:
    """The adaptive second pass's configuration: ``cfg`` with the ``thorough`` preset's
    detection (at least its keypoints, at most its contrast threshold, upsampling at least as
    far); the matching settings and caps stay the caller's."""
    from strl_pyg.frontend.config import PRESETS

    t = PRESETS["thorough"]
    return replace(cfg, thorough_below=0,
                   max_keypoints=max(int(cfg.max_keypoints), t["max_keypoints"]),
                   contrast_threshold=min(float(cfg.contrast_threshold),
                                          t["contrast_threshold"]),
                   upsample_below=max(int(cfg.upsample_below), t["upsample_below"]))


def _points(gray0: np.ndarray, gray1: np.ndarray, cfg: FrontendConfig,
            features: tuple[Any, Any] | None = None):
    """Point matches without repeats, their fundamental matrix and inliers, counts and
    timings: ``(p0, p1, scores, F, inliers, stats, timings_ms)``."""
    p0, p1, p_scores, stats = match_points(gray0, gray1, cfg, features=features)
    timings = dict(stats.pop("timings_ms"))
    # SIFT keeps one keypoint per dominant orientation at a location: two such keypoints that
    # match two such keypoints are one correspondence listed twice (~10 % of KITTI's matches)
    keep = first_unique_rows(np.concatenate([p0, p1], axis=1))
    stats["point_repeats_removed"] = int(len(p0) - len(keep))
    p0, p1, p_scores = p0[keep], p1[keep], p_scores[keep]
    t = time.perf_counter()
    F, inl = fit_fundamental(p0, p1, cfg)
    timings["geometry"] = 1e3 * (time.perf_counter() - t)
    return p0, p1, p_scores, F, inl, stats, timings


def _lines(gray0: np.ndarray, gray1: np.ndarray, F: np.ndarray | None, guide0: np.ndarray,
           guide1: np.ndarray, cfg: FrontendConfig, timings: dict,
           features: tuple[Any, Any] | None = None):
    """Detects and matches the line segments (``cfg.lines``) under ``F`` with the inlier
    points ``guide0/1``; returns ``(l0, l1, scores, seg0, seg1, status)`` and fills the
    ``lines_detect`` / ``lines_match`` timings."""
    t = time.perf_counter()
    if cfg.lines and features is not None:
        seg0, seg1 = features[0].lines(cfg), features[1].lines(cfg)
    elif cfg.lines:
        seg0, seg1 = on_both(lambda g: detect_lines(g, cfg), gray0, gray1, cfg.concurrent)
    else:
        seg0 = seg1 = np.zeros((0, 2, 2))
    timings["lines_detect"] = 1e3 * (time.perf_counter() - t)
    t = time.perf_counter()
    l0 = l1 = np.zeros((0, 2, 2))
    l_scores = np.zeros(0)
    if not cfg.lines:
        status = "skipped: lines=False in the FrontendConfig"
    elif cfg.line_matcher == "descriptor":
        l0, l1, l_scores = match_lines_by_descriptor(seg0, seg1, gray0, gray1, cfg)
        status = (f"ok (descriptor matcher: {len(l0)} matches, endpoints as detected, not "
                  "corresponding)")
    elif F is None:
        status = "skipped: fewer than 8 point matches or no fundamental matrix"
    else:
        l0, l1, l_scores = match_lines(seg0, seg1, gray0, gray1, F, cfg, guide=(guide0, guide1))
        status = "ok"
    timings["lines_match"] = 1e3 * (time.perf_counter() - t)
    return l0, l1, l_scores, seg0, seg1, status


def add_lines(matches: PairMatches, config: FrontendConfig | None = None,
              features: tuple[Any, Any] | None = None) -> PairMatches:
    """The line matches of a pair matched with ``lines=False`` by :func:`match_images`, added
    without detecting or matching the points again: the same result as matching the images
    with ``lines=True`` (the points, their fundamental matrix and inliers are the ones
    ``matches.info`` stores). ``matches`` must come from :func:`match_images` with its images;
    ``features`` as there.
    """
    cfg = config if config is not None else FrontendConfig()
    if not cfg.lines:
        return matches
    info = dict(matches.info)
    if "fundamental_inliers" not in info or not matches.has_images:
        raise ValueError("Expected matches of match_images with their images and "
                         "info['fundamental'] (got other matches)")
    if info.get("config", {}).get("detector", cfg.detector) != cfg.detector:
        raise ValueError(f"Expected the points' detector {info['config']['detector']!r} "
                         f"(got {cfg.detector!r})")
    F = None if info["fundamental"] is None else np.asarray(info["fundamental"])
    inl = np.asarray(info["fundamental_inliers"], dtype=np.int64).reshape(-1)
    if inl.size and (inl.min() < 0 or inl.max() >= matches.num_points):
        raise ValueError(f"Expected info['fundamental_inliers'] as rows of the "
                         f"{matches.num_points} point matches (got indices "
                         f"{inl.min()}..{inl.max()}): matches edited after match_images?")
    timings = dict(info.get("timings_ms", {}))
    t0 = time.perf_counter()
    l0, l1, l_scores, seg0, seg1, status = _lines(
        matches.image0, matches.image1, F, matches.points0[inl], matches.points1[inl], cfg,
        timings, features)
    timings["total"] = timings.get("total", 0.0) + 1e3 * (time.perf_counter() - t0)
    info.update(timings_ms=timings, segments0=len(seg0), segments1=len(seg1),
                lines_status=status, config=asdict(cfg))
    info[LINE_ENDPOINTS] = (ENDPOINTS_AS_DETECTED if cfg.line_matcher == "descriptor"
                            else ENDPOINTS_CORRESPONDING)
    return replace(matches, lines0=l0, lines1=l1, line_scores=l_scores, info=info)
