"""Configuration of the image front end (:func:`strl_pyg.frontend.match_images`) and its
"no matches" error."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FrontendConfig", "NoMatchesError", "LINE_MATCHERS", "PRESETS"]

#: Fields added after caches of matches existed, with the value that reproduces the matches
#: made before them: a cache key names such a field only where it differs from this value.
_BEFORE_KEYED = {"contrast_threshold": 0.04, "rootsift": False, "upsample_below": 0,
                 "thorough_below": 0}

#: The line matchers of :class:`FrontendConfig` ``line_matcher``.
LINE_MATCHERS = ("epipolar", "descriptor")


class NoMatchesError(ValueError):
    """No point and no line match was found between the two images (featureless, all-black or
    unrelated images)."""


@dataclass
class FrontendConfig:
    """Configuration of :func:`match_images`.

    Args:
        detector: ``"sift"`` (default) or ``"orb"`` (faster, fewer and less precise matches).
        max_keypoints: keypoints detected per image (strongest first). (default: 2048)
        ratio: Lowe's ratio test threshold on nearest / second nearest descriptor distance.
            (default: 0.85)
        mutual: keep only mutual nearest neighbours. (default: True)
        max_points: cap on returned point matches, lowest ratio first. (default: 2048)
        filter_points: keep only the point matches consistent with the fitted ``F``
            (default: False, the learned model sees the outliers).
        ransac_threshold: epipolar threshold (px) of the ``F`` fit. (default: 1.0)
        ransac_confidence, ransac_max_iters: of the ``F`` fit. (default: 0.999, 10000)
        lsd_scale: image scale at which LSD runs (its ``scale`` parameter). (default: 1.0)
        min_line_length: shortest detected segment kept, pixels. (default: 15.0)
        max_detected_lines: segments kept per image, longest first. (default: 512)
        max_lines: cap on returned line matches, best score first. (default: 256)
        min_matched_length: shortest clipped segment kept, pixels. (default: 10.0)
        line_min_overlap: common part / shorter of the two segments (measured on the segment
            in image 1) below which a pair is discarded. (default: 0.5)
        line_min_angle_deg: smallest angle between a segment and the epipolar lines (a segment
            along its epipolar lines has no defined endpoints). (default: 10.0)
        line_polarity: require the same contrast polarity in both images. (default: True)
        line_guide_k: point matches near a segment whose median displacement predicts it in
            image 1; 0 disables the guidance. (default: 8)
        line_guide_tol: allowed distance (fraction of the image-1 diagonal) between the
            predicted midpoint and the supporting line of the candidate. (default: 0.05)
        line_samples: descriptor positions along a segment. (default: 12)
        line_profile: samples across a segment at each position. (default: 9)
        line_profile_halfwidth: half width of the profile, pixels. (default: 6.0)
        line_min_score: smallest normalised cross-correlation kept. (default: 0.6)
        seed: seeds OpenCV's RNG before the robust fit, for determinism. (default: 0)
        lines: detect and match line segments; ``False`` gives a points-only result (no LSD,
            for callers that use points only, e.g. the classical solvers). (default: True)
        concurrent: detect keypoints (and line segments) of both images at once, in two
            threads (OpenCV releases the GIL); the same result as one after the other.
            (default: True)
        line_matcher: ``"epipolar"`` (default): segments matched under the fundamental matrix
            of the point matches and clipped to their common part, so endpoint ``k`` matches
            endpoint ``k`` (needs >= 8 point matches); ``"descriptor"``: band descriptors
            without a fundamental matrix
            (:func:`~strl_pyg.frontend.lines.match_lines_by_descriptor`), also below 8 point
            matches, segments as detected: their endpoints do *not*
            correspond (``info["line_endpoints"]``), so only the line solvers (``vp``,
            ``vp_checked``) may read them; the network methods refuse them. Measured in
            ``benchmarks/studies/results_line_matchers.md``: better on real street pairs with very
            few
            points, worse where an F from 8-30 points exists. (default: ``"epipolar"``)
        line_descriptor_ratio: Lowe's ratio test of the descriptor matcher (nearest / second
            nearest descriptor distance). (default: 0.85)
        contrast_threshold: OpenCV SIFT's ``contrastThreshold``; lower keeps weaker blobs
            (0.02 is about COLMAP's peak threshold). (default: 0.04)
        rootsift: RootSIFT descriptors (L1-normalised, square-rooted; COLMAP's L1_ROOT),
            which match better than plain SIFT under the same ratio test. (default: True)
        upsample_below: detect keypoints on the image upsampled 2x where its longer side is
            at most this many pixels (small photographs hold more, smaller features than
            OpenCV finds at their size); 0 never. (default: 0)
        thorough_below: adaptive second pass: where the first pass leaves fewer than this
            many fundamental-matrix inliers, the points are matched again with the
            ``thorough`` preset's point settings and that result is used
            (``info["second_pass"]``); 0 never. (default: 200)

    The defaults are the ``adaptive`` preset. Presets (:meth:`preset`, :data:`PRESETS`,
    ``strl-pose predict --matcher``): ``fast``, ``thorough`` (more, smaller features: 2x
    upsampling of images up to 1024 px), ``adaptive`` (``fast``, then ``thorough`` where the
    first pass is short of inliers) and ``legacy`` (the settings before the presets).
    Measured on real pairs in ``benchmarks/results_frontend/README.md``.
    """

    detector: str = "sift"
    max_keypoints: int = 2048
    ratio: float = 0.85
    mutual: bool = True
    max_points: int = 2048
    filter_points: bool = False
    ransac_threshold: float = 1.0
    ransac_confidence: float = 0.999
    ransac_max_iters: int = 10000
    lsd_scale: float = 1.0
    min_line_length: float = 15.0
    max_detected_lines: int = 512
    max_lines: int = 256
    min_matched_length: float = 10.0
    line_min_overlap: float = 0.5
    line_min_angle_deg: float = 10.0
    line_polarity: bool = True
    line_guide_k: int = 8
    line_guide_tol: float = 0.05
    line_samples: int = 12
    line_profile: int = 9
    line_profile_halfwidth: float = 6.0
    line_min_score: float = 0.6
    seed: int = 0
    lines: bool = True
    concurrent: bool = True
    line_matcher: str = "epipolar"
    line_descriptor_ratio: float = 0.85
    contrast_threshold: float = 0.04
    rootsift: bool = True
    upsample_below: int = 0
    thorough_below: int = 200

    @classmethod
    def preset(cls, name: str, **overrides) -> FrontendConfig:
        """A named set of point settings (:data:`PRESETS`), other fields as given.

        ``FrontendConfig.preset("thorough", lines=False)``; the names are those of
        ``strl-pose predict --matcher``."""
        if name not in PRESETS:
            raise ValueError(f"Expected a front-end preset in {tuple(PRESETS)} (got {name!r})")
        return cls(**{**PRESETS[name], **overrides})

    def result_fields(self) -> dict:
        """The fields that decide the matches (every field but ``concurrent``): what caches of
        matches key on, so that a setting that only changes the speed keeps them valid. A field
        added later (``line_matcher``) enters only when it differs from its default, so the
        caches of earlier versions keep their keys; so do the descriptor matcher's settings,
        which change nothing with the epipolar matcher."""
        from dataclasses import asdict

        out = {k: v for k, v in asdict(self).items() if k != "concurrent"}
        if out["line_matcher"] == "epipolar":
            for k in ("line_matcher", "line_descriptor_ratio"):
                del out[k]
        for k, before in _BEFORE_KEYED.items():  # settings that did not exist: in the key
            if out[k] == before:  # only where they change the result
                del out[k]
        return out

    def __post_init__(self) -> None:
        if self.detector not in ("sift", "orb"):
            raise ValueError(f"Expected detector 'sift' or 'orb' (got {self.detector!r})")
        if not 0.0 < self.ratio <= 1.0:
            raise ValueError(f"Expected ratio in (0, 1] (got {self.ratio})")
        for name in ("max_keypoints", "max_points", "max_lines", "max_detected_lines"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"Expected {name} >= 0 (got {getattr(self, name)})")
        if self.line_samples < 2 or self.line_profile < 1:
            raise ValueError(
                "Expected line_samples >= 2 and line_profile >= 1 "
                f"(got {self.line_samples}, {self.line_profile})"
            )
        if not 0.0 < self.line_descriptor_ratio <= 1.0:
            raise ValueError(f"Expected line_descriptor_ratio in (0, 1] "
                             f"(got {self.line_descriptor_ratio})")
        if self.line_matcher not in LINE_MATCHERS:
            raise ValueError(f"Expected line_matcher in {LINE_MATCHERS} "
                             f"(got {self.line_matcher!r})")
        if not 0.0 < self.lsd_scale <= 1.0:
            raise ValueError(f"Expected lsd_scale in (0, 1] (got {self.lsd_scale})")
        if not 0.0 < self.contrast_threshold < 1.0:
            raise ValueError(f"Expected contrast_threshold in (0, 1) "
                             f"(got {self.contrast_threshold})")
        for name in ("upsample_below", "thorough_below"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"Expected {name} as an integer >= 0 (got {v!r})")



#: The front end's named presets (:meth:`FrontendConfig.preset`), as fields over the defaults.
#: ``legacy`` reproduces the matches of the versions before the presets.
PRESETS: dict[str, dict] = {
    "fast": {"max_keypoints": 2048, "contrast_threshold": 0.04, "rootsift": True,
             "upsample_below": 0, "ratio": 0.85, "mutual": True, "max_points": 2048,
             "thorough_below": 0},
    "thorough": {"max_keypoints": 8000, "contrast_threshold": 0.02, "rootsift": True,
                 "upsample_below": 1024, "ratio": 0.85, "mutual": True, "max_points": 4096,
                 "thorough_below": 0},
    "legacy": {"max_keypoints": 2048, "contrast_threshold": 0.04, "rootsift": False,
               "upsample_below": 0, "ratio": 0.8, "mutual": True, "max_points": 1024,
               "thorough_below": 0},
}
#: The default: ``fast``, then ``thorough`` where the first pass's fundamental matrix has
#: fewer than 200 inliers (chosen in ``benchmarks/results_frontend/README.md``).
PRESETS["adaptive"] = {**PRESETS["fast"], "thorough_below": 200}
PRESETS = {k: PRESETS[k] for k in ("fast", "thorough", "adaptive", "legacy")}
