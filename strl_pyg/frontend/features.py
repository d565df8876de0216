"""One image's features for the front end, computed once and handed to the matcher.

:func:`~strl_pyg.frontend.match_images` detects SIFT keypoints and LSD segments in both
images of a pair. In a photo collection an image takes part in many pairs, so its features are
computed once per setting and reused: a *feature source* gives :func:`match_images` an image's
keypoints and segments for a :class:`FrontendConfig`. Two settings decide them:

- :func:`points_settings`: the fields that decide the keypoints and descriptors (``detector``,
  ``max_keypoints``, ``contrast_threshold``, ``upsample_below``, ``rootsift``); the adaptive
  second pass (:func:`~strl_pyg.frontend.pipeline.thorough_points`) has its own;
- :func:`lines_settings`: the fields that decide the LSD segments (``lsd_scale``,
  ``min_line_length``, ``max_detected_lines``).

:func:`settings_key` names each setting by a short hash; stores key every array by it, so a
changed setting never meets features of another.

Sources: :class:`Detect` (detects on demand, caching per setting in memory: what
:func:`match_images` does without a source) and :class:`Precomputed` (arrays computed
elsewhere, e.g. read from :class:`~strl_pyg.frontend.store.FeatureStore` by another process:
a setting it does not hold raises :class:`MissingFeatures`, so the caller computes it once and
retries). Keypoints are pixels of the image given (OpenCV's convention: the top-left pixel's
centre is ``(0, 0)``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from strl_pyg.frontend.config import FrontendConfig

__all__ = ["points_settings", "lines_settings", "settings_key", "PointFeatures", "Detect",
           "Precomputed", "MissingFeatures", "POINTS", "LINES"]

#: The two kinds of per-image features.
POINTS, LINES = "points", "lines"

_POINT_FIELDS = ("detector", "max_keypoints", "contrast_threshold", "upsample_below", "rootsift")
_LINE_FIELDS = ("lsd_scale", "min_line_length", "max_detected_lines")


def points_settings(cfg: FrontendConfig) -> dict[str, Any]:
    """The fields of ``cfg`` that decide an image's keypoints and descriptors."""
    out = {k: getattr(cfg, k) for k in _POINT_FIELDS}
    if cfg.detector != "sift":  # rootsift and the contrast threshold are SIFT's
        out.pop("rootsift")
        out.pop("contrast_threshold")
    return out


def lines_settings(cfg: FrontendConfig) -> dict[str, Any]:
    """The fields of ``cfg`` that decide an image's LSD segments."""
    return {k: getattr(cfg, k) for k in _LINE_FIELDS}


def settings_key(kind: str, cfg: FrontendConfig) -> str:
    """``"points-<12 hex>"`` or ``"lines-<12 hex>"``: the kind and a hash of its settings."""
    if kind == POINTS:
        settings = points_settings(cfg)
    elif kind == LINES:
        settings = lines_settings(cfg)
    else:
        raise ValueError(f"Expected the kind {POINTS!r} or {LINES!r} (got {kind!r})")
    digest = hashlib.sha1(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:12]
    return f"{kind}-{digest}"


@dataclass(frozen=True)
class PointFeatures:
    """Keypoints ``[K, 2]`` (float64 pixels) and descriptors ``[K, D]`` (float32 for SIFT,
    uint8 for ORB; ``None`` where nothing was found)."""

    keypoints: np.ndarray
    descriptors: np.ndarray | None

    def __len__(self) -> int:
        return len(self.keypoints)


class MissingFeatures(LookupError):
    """A :class:`Precomputed` source holds no features of the asked setting.

    Attributes:
        kind: :data:`POINTS` or :data:`LINES`; ``key``: :func:`settings_key`; ``config``: the
            :class:`FrontendConfig` asked for.
    """

    def __init__(self, name: str, kind: str, key: str, config: FrontendConfig) -> None:
        super().__init__(f"Expected {kind} features {key} of image '{name}' (got none: "
                         "compute them first)")
        self.name, self.kind, self.key, self.config = name, kind, key, config


@dataclass
class Detect:
    """Detects an image's features on first use, once per setting (in memory).

    Args:
        gray: The grey uint8 image ``[H, W]`` (as :func:`check_frontend_image` returns it).
        name: What errors call the image.
    """

    gray: np.ndarray
    name: str = "image"
    cache: dict[str, Any] = field(default_factory=dict, repr=False)

    def points(self, cfg: FrontendConfig) -> PointFeatures:
        key = settings_key(POINTS, cfg)
        if key not in self.cache:
            from strl_pyg.frontend.points import detect_points

            self.cache[key] = PointFeatures(*detect_points(self.gray, cfg))
        return self.cache[key]

    def lines(self, cfg: FrontendConfig) -> np.ndarray:
        key = settings_key(LINES, cfg)
        if key not in self.cache:
            from strl_pyg.frontend.lines import detect_lines

            self.cache[key] = detect_lines(self.gray, cfg)
        return self.cache[key]


@dataclass
class Precomputed:
    """Features computed elsewhere, by :func:`settings_key`: ``arrays`` maps a points key to
    a :class:`PointFeatures` and a lines key to segments ``[S, 2, 2]``. A setting it does not
    hold raises :class:`MissingFeatures` (never a silent detection)."""

    arrays: dict[str, Any]
    name: str = "image"

    def points(self, cfg: FrontendConfig) -> PointFeatures:
        return self._get(POINTS, cfg)

    def lines(self, cfg: FrontendConfig) -> np.ndarray:
        return self._get(LINES, cfg)

    def _get(self, kind: str, cfg: FrontendConfig) -> Any:
        key = settings_key(kind, cfg)
        if key not in self.arrays:
            raise MissingFeatures(self.name, kind, key, cfg)
        return self.arrays[key]
