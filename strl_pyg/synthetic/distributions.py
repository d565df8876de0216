"""Distributions of scene configs: a :class:`SceneDistribution` draws one
:class:`~strl_pyg.synthetic.SceneConfig` per seed (kind, image size, intrinsics, motion, view
order, photometry, texture, match corruption), deterministically, from its own random stream.

Named distributions (:func:`scene_distribution`); the held-out evaluation ones
(:func:`eval_distribution`) are meant for seeds from :data:`EVAL_SEED` on (training uses seeds
below it):

=============== ======================= ==================== ================== ===============
name            kinds                   motions              image sizes (H, W) other
=============== ======================= ==================== ================== ===============
``mixed``       all four                all, per-kind        240x320, 192x640,  training preset
                                        weights              480x640, 370x1226,
                                                             768x1024
``mixed_small`` all four                as ``mixed``         240x320, 192x640   cheap CPU
                                                                                training
``lines_small`` all four                as ``mixed``         240x320            low texture
                                                                                0.35: the
                                                                                ablation's
                                                                                training mix
``driving``     street                  forward              370x1226           f 0.55-0.62 W,
                                                                                KITTI-like
``indoor``      indoor                  forward, lateral,    480x640            f 0.8-1.0 W,
                                        handheld, rotation,                     DeMoN-like
                                        orbit
``object``      object                  orbit                480x640            f 0.8-6 W,
                                                                                dino-like
``wide``        all four                wide (20-40 deg)     480x640
``outliers50``  all four                all                  480x640            50 % outliers,
                                                                                1 px noise
``low_texture`` all four                all                  480x640            low_texture
=============== ======================= ==================== ================== ===============

Common to all unless noted: focal log-uniform in 0.5-1.5 W (object kind: 0.5-6 W, the
Middlebury dino has 5.2 W), principal point within +-5 % of the size, ``baseline_scale``
log-uniform in 0.5-2 (1 for orbit and wide), views swapped with probability 0.5 (backward
motion), a photometric change of image 1 with probability 0.7 (gain 0.6-1.5, gamma 0.7-1.4,
blur 0-1.5 px, noise 0-4 grey levels), sensor noise 0.5-3 grey levels, low / repetitive
texture with probability 0.15 / 0.05, ground-truth match noise 0-1 px and outliers 0-30 %
(used by ``matches="ground_truth"`` only; front-end matches come from the images). The
evaluation distributions give the ground-truth matches 0.5 px of noise and no outliers (but
``outliers50``) and swap no views for ``driving`` and ``object``; change any field with
``eval_distribution(name, field=value)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from strl_pyg.synthetic.config import MOTIONS, SCENE_KINDS, SceneConfig

__all__ = [
    "SceneDistribution",
    "scene_distribution",
    "eval_distribution",
    "sample_scene_config",
    "DISTRIBUTIONS",
    "EVAL_DISTRIBUTIONS",
    "EVAL_SEED",
    "KIND_MOTIONS",
    "DEFAULT_SIZES",
]

#: First seed of the held-out evaluation pairs (training uses seeds below it).
EVAL_SEED = 2_000_000

DEFAULT_SIZES = ((240, 320), (192, 640), (480, 640), (370, 1226), (768, 1024))

#: Relative weight of each motion per kind in the mixed distributions.
KIND_MOTIONS = {
    "street": {"forward": 0.45, "lateral": 0.1, "orbit": 0.05, "handheld": 0.1,
               "rotation": 0.15, "wide": 0.15},
    "indoor": {"forward": 0.2, "lateral": 0.15, "orbit": 0.15, "handheld": 0.25,
               "rotation": 0.15, "wide": 0.1},
    "boxes": {"forward": 0.15, "lateral": 0.15, "orbit": 0.2, "handheld": 0.2,
              "rotation": 0.15, "wide": 0.15},
    "object": {"forward": 0.05, "lateral": 0.05, "orbit": 0.5, "handheld": 0.1,
               "rotation": 0.1, "wide": 0.2},
}


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) if hi > lo else float(lo)


@dataclass
class SceneDistribution:
    """Draws one :class:`SceneConfig` per seed (see the module table).

    Args:
        name: label, used in pair ids (``synthetic/<name>/<kind>/<seed>``).
        kinds, motions: allowed scene kinds and motions (motions weighted per kind by
            :data:`KIND_MOTIONS`).
        sizes: image sizes ``(H, W)``, drawn uniformly.
        focal_range, object_focal_range: focal length as a fraction of ``W``, log-uniform.
        principal_offset: largest ``|dx|``, ``|dy|`` of the principal point (fractions).
        baseline_scale_range: log-uniform ``SceneConfig.baseline_scale``.
        swap_prob: probability of ``swap_views``.
        photometric_prob, gain_range, gamma_range, blur_max, photo_noise_max: photometric
            change of image 1.
        image_noise_range, low_texture_prob, repetitive_prob: texture and sensor noise.
        noise_px_range, outlier_range: corruption of the ground-truth matches.
        overrides: other :class:`SceneConfig` fields, fixed (e.g. ``{"max_points": 256}``).
    """

    name: str = "mixed"
    kinds: tuple[str, ...] = SCENE_KINDS
    motions: tuple[str, ...] = MOTIONS
    sizes: tuple[tuple[int, int], ...] = DEFAULT_SIZES
    focal_range: tuple[float, float] = (0.5, 1.5)
    object_focal_range: tuple[float, float] = (0.5, 6.0)
    principal_offset: float = 0.05
    baseline_scale_range: tuple[float, float] = (0.5, 2.0)
    swap_prob: float = 0.5
    photometric_prob: float = 0.7
    gain_range: tuple[float, float] = (0.6, 1.5)
    gamma_range: tuple[float, float] = (0.7, 1.4)
    blur_max: float = 1.5
    photo_noise_max: float = 4.0
    image_noise_range: tuple[float, float] = (0.5, 3.0)
    low_texture_prob: float = 0.15
    repetitive_prob: float = 0.05
    noise_px_range: tuple[float, float] = (0.0, 1.0)
    outlier_range: tuple[float, float] = (0.0, 0.3)
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.kinds, self.motions = tuple(self.kinds), tuple(self.motions)
        self.sizes = tuple(tuple(int(v) for v in s) for s in self.sizes)
        bad = [k for k in self.kinds if k not in SCENE_KINDS]
        if not self.kinds or bad:
            raise ValueError(f"Expected kinds from {SCENE_KINDS} (got {self.kinds!r})")
        bad = [m for m in self.motions if m not in MOTIONS]
        if not self.motions or bad:
            raise ValueError(f"Expected motions from {MOTIONS} (got {self.motions!r})")
        if not self.sizes or any(len(s) != 2 or min(s) < 16 for s in self.sizes):
            raise ValueError(f"Expected sizes (H, W), both >= 16 (got {self.sizes!r})")
        for name in ("focal_range", "object_focal_range", "baseline_scale_range",
                     "gain_range", "gamma_range"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ValueError(f"Expected 0 < lo <= hi for {name} (got {(lo, hi)})")
        for name in ("swap_prob", "photometric_prob", "low_texture_prob", "repetitive_prob"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"Expected {name} in [0, 1] (got {getattr(self, name)})")
        known = {f.name for f in fields(SceneConfig)}
        unknown = sorted(set(self.overrides) - known)
        if unknown:
            raise ValueError(f"Expected SceneConfig fields in overrides (got {unknown})")
        SceneConfig(**self.overrides)  # invalid values fail here, not per seed

    def config(self, seed: int) -> SceneConfig:
        """The :class:`SceneConfig` of pair ``seed`` (deterministic)."""
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"Expected a non-negative integer seed (got {seed!r})")
        rng = np.random.default_rng([int(seed), 0x5D157])
        kind = str(self.kinds[rng.integers(len(self.kinds))])
        w = np.array([KIND_MOTIONS[kind][m] for m in self.motions])
        w = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
        motion = str(self.motions[rng.choice(len(self.motions), p=w)])
        size = self.sizes[rng.integers(len(self.sizes))]
        focal = _loguniform(rng, *(self.object_focal_range if kind == "object"
                                   else self.focal_range))
        off = tuple(float(v) for v in rng.uniform(-1, 1, 2) * self.principal_offset)
        photo = {}
        if rng.random() < self.photometric_prob:
            photo = dict(photo_gain=_loguniform(rng, *self.gain_range),
                         photo_gamma=_loguniform(rng, *self.gamma_range),
                         photo_blur=float(rng.uniform(0, self.blur_max)),
                         photo_noise=float(rng.uniform(0, self.photo_noise_max)))
        low = bool(rng.random() < self.low_texture_prob)
        rep = bool(not low and rng.random() < self.repetitive_prob)
        fields = dict(
            kind=kind, motion=motion, image_size=size, focal_factor=focal,
            principal_offset=off,
            baseline_scale=(1.0 if motion in ("orbit", "wide")
                            else _loguniform(rng, *self.baseline_scale_range)),
            swap_views=bool(rng.random() < self.swap_prob),
            image_noise=float(rng.uniform(*self.image_noise_range)),
            low_texture=low, repetitive_texture=rep,
            noise_px=float(rng.uniform(*self.noise_px_range)),
            outlier_fraction=float(rng.uniform(*self.outlier_range)),
            **photo,
        )
        return SceneConfig(**{**fields, **self.overrides})

    __call__ = config


_CLEAN = dict(noise_px_range=(0.5, 0.5), outlier_range=(0.0, 0.0))
_EVAL = dict(sizes=((480, 640),), swap_prob=0.5)
DISTRIBUTIONS: dict[str, SceneDistribution] = {
    "mixed": SceneDistribution("mixed"),
    "mixed_small": SceneDistribution("mixed_small", sizes=((240, 320), (192, 640))),
    # the ablation study's training mix: point-poor low-texture scenes (structural edges, few
    # corners) over twice as often as in mixed; one image size, so that the +R rows (a CNN
    # over whole images) can batch their images
    "lines_small": SceneDistribution("lines_small", sizes=((240, 320),),
                                     low_texture_prob=0.35),
}
EVAL_DISTRIBUTIONS: dict[str, SceneDistribution] = {
    "driving": SceneDistribution("driving", kinds=("street",), motions=("forward",),
                                 sizes=((370, 1226),), focal_range=(0.55, 0.62),
                                 principal_offset=0.01, swap_prob=0.0, **_CLEAN),
    "indoor": SceneDistribution("indoor", kinds=("indoor",),
                                motions=("forward", "lateral", "handheld", "rotation", "orbit"),
                                focal_range=(0.8, 1.0), **_EVAL, **_CLEAN),
    "object": SceneDistribution("object", kinds=("object",), motions=("orbit",),
                                object_focal_range=(0.8, 6.0), sizes=((480, 640),),
                                swap_prob=0.0, **_CLEAN),
    "wide": SceneDistribution("wide", motions=("wide",), **_EVAL, **_CLEAN),
    "outliers50": SceneDistribution("outliers50", noise_px_range=(1.0, 1.0),
                                    outlier_range=(0.5, 0.5), **_EVAL),
    "low_texture": SceneDistribution("low_texture", low_texture_prob=1.0, **_EVAL, **_CLEAN),
}


def scene_distribution(name: str, **changes: Any) -> SceneDistribution:
    """A named distribution (training or evaluation), with optional field changes, e.g.
    ``scene_distribution("mixed", sizes=((240, 320),))``."""
    table = {**DISTRIBUTIONS, **EVAL_DISTRIBUTIONS}
    if name not in table:
        raise ValueError(f"Expected a distribution name in {tuple(table)} (got {name!r})")
    changes.setdefault("overrides", dict(table[name].overrides))  # no shared dict
    return replace(table[name], **changes)


def eval_distribution(name: str, **changes: Any) -> SceneDistribution:
    """A held-out evaluation distribution (use seeds from :data:`EVAL_SEED` on)."""
    if name not in EVAL_DISTRIBUTIONS:
        raise ValueError(
            f"Expected an evaluation distribution in {tuple(EVAL_DISTRIBUTIONS)} (got {name!r})"
        )
    return scene_distribution(name, **changes)


def sample_scene_config(seed: int, distribution: str | SceneDistribution = "mixed"
                        ) -> SceneConfig:
    """The :class:`SceneConfig` of pair ``seed`` under a (named) distribution."""
    dist = scene_distribution(distribution) if isinstance(distribution, str) else distribution
    if not isinstance(dist, SceneDistribution):
        raise TypeError(f"Expected a SceneDistribution or a name (got {type(dist).__name__})")
    return dist.config(seed)
