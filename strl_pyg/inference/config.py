"""The one configuration of :class:`~strl_pyg.inference.estimator.PoseEstimator`: the user's
options (:class:`EstimatorConfig`, checked once when built) and what the checkpoint's metadata
says about estimation (:class:`CheckpointSettings`, read once per estimator: the calibration
scales, the bootstrap they were fitted with, the measured recommended order and the fusion's
variance inflation)."""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from strl_pyg.estimation.uncertainty import MIN_BOOTSTRAP
from strl_pyg.inference.checks import check_device
from strl_pyg.inference.evidence import FOCAL_RANGE_FACTOR
from strl_pyg.inference.registry import checked_method_names
from strl_pyg.inference.support import CHEIRALITY_MIN, MIN_INLIER_RATIO, MIN_SUPPORT_INLIERS

__all__ = ["EstimatorConfig", "CheckpointSettings"]


def _is_int(v: Any) -> bool:
    """An integer, numpy's included, not a bool."""
    return isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))


def _is_number(v: Any) -> bool:
    """A real number, numpy's included, not a bool."""
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


@dataclass(frozen=True)
class EstimatorConfig:
    """Every option of :class:`~strl_pyg.inference.estimator.PoseEstimator` (its keyword
    arguments are these fields; their meaning is documented there), checked when built: a bad
    value is a one-line ``ValueError``. ``methods`` ``None`` or ``"all"``: every installed
    method; a ``str`` is one method or comma-separated names (as ``--methods`` takes them).
    ``device`` is kept as a ``torch.device`` (or ``None``)."""

    methods: tuple[str, ...] | None = None
    seed: int = 0
    threshold_px: float = 1.0
    bootstrap: int = 8
    min_inlier_ratio: float = MIN_INLIER_RATIO
    min_inliers: int = MIN_SUPPORT_INLIERS
    min_in_front: float = CHEIRALITY_MIN
    resample: Any = "model"
    device: Any = None
    raise_errors: bool = False
    swap_check: bool = True
    data_check: bool = True
    focal_sensitivity: bool = True
    focal_range: float = FOCAL_RANGE_FACTOR

    @property
    def support(self) -> tuple[float, int, float]:
        """The support check's ``(min_inlier_ratio, min_inliers, min_in_front)``."""
        return self.min_inlier_ratio, self.min_inliers, self.min_in_front

    def __post_init__(self) -> None:
        if self.methods is not None:
            object.__setattr__(self, "methods", checked_method_names(self.methods))
        if not _is_int(self.seed):
            raise ValueError(f"Expected seed as an integer (got {self.seed!r})")
        object.__setattr__(self, "seed", int(self.seed))
        if _is_int(self.bootstrap):
            object.__setattr__(self, "bootstrap", int(self.bootstrap))
        if _is_int(self.min_inliers):
            object.__setattr__(self, "min_inliers", int(self.min_inliers))
        if not (_is_number(self.threshold_px) and self.threshold_px > 0):
            raise ValueError(f"Expected threshold_px > 0 (got {self.threshold_px!r})")
        if not _is_int(self.bootstrap) or not (self.bootstrap == 0
                                               or self.bootstrap >= MIN_BOOTSTRAP):
            raise ValueError(f"Expected bootstrap = 0 (off) or an integer >= {MIN_BOOTSTRAP} "
                             f"(got {self.bootstrap!r})")
        if not (_is_number(self.min_inlier_ratio) and 0 <= self.min_inlier_ratio < 1):
            raise ValueError(f"Expected min_inlier_ratio in [0, 1) (got "
                             f"{self.min_inlier_ratio!r})")
        if not _is_int(self.min_inliers) or self.min_inliers < 0:
            raise ValueError(f"Expected min_inliers as an integer >= 0 (got "
                             f"{self.min_inliers!r})")
        if not (_is_number(self.min_in_front) and 0 <= self.min_in_front <= 1):
            raise ValueError(f"Expected min_in_front in [0, 1] (got {self.min_in_front!r})")
        r = self.resample
        if not (r is None or (isinstance(r, str) and r == "model")):
            if isinstance(r, str) or not hasattr(r, "__len__") or len(r) != 2 or not all(
                    _is_int(v) and v >= 0 for v in r):
                raise ValueError(f"Expected resample 'model', None or (points, lines) >= 0 "
                                 f"(got {r!r})")
            object.__setattr__(self, "resample", (int(r[0]), int(r[1])))
        for name in ("raise_errors", "swap_check", "data_check", "focal_sensitivity"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"Expected {name} as a bool (got {value!r})")
            object.__setattr__(self, name, bool(value))
        if not (_is_number(self.focal_range) and 1 < self.focal_range <= 10):
            raise ValueError(f"Expected focal_range, a factor each way, in (1, 10] (got "
                             f"{self.focal_range!r})")
        object.__setattr__(self, "focal_range", float(self.focal_range))
        object.__setattr__(self, "threshold_px", float(self.threshold_px))
        object.__setattr__(self, "min_inlier_ratio", float(self.min_inlier_ratio))
        object.__setattr__(self, "min_in_front", float(self.min_in_front))
        object.__setattr__(self, "device", check_device(self.device))

    def replace(self, **options: Any) -> EstimatorConfig:
        """A copy with ``options`` changed (checked again); an unknown name is a one-line
        ``TypeError`` that lists the known ones."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(options) - names)
        if unknown:
            raise TypeError(f"Expected options from {sorted(names)} (got {unknown})")
        return dataclasses.replace(self, **options)


@dataclass(frozen=True)
class CheckpointSettings:
    """What a checkpoint's ``metadata`` says about estimation (defaults where it says
    nothing): per-method covariance ``calibration`` scales, the ``calibration_bootstrap``
    they were fitted with, the measured ``recommended_order`` (``()``: the package default)
    and the ``fusion_inflation`` of the network's variance in the fusion."""

    calibration: dict[str, float] = field(default_factory=dict)
    calibration_bootstrap: int = 0
    recommended_order: tuple[str, ...] = ()
    fusion_inflation: float = 1.0
    #: whether the metadata has a ``calibration`` entry at all (an empty one included: a
    #: calibration fit in progress reads raw covariances; :meth:`with_fallback`)
    has_calibration: bool = False
    #: ``name -> (scale, bootstrap)`` for methods this checkpoint has no scale of and whose
    #: covariance does not depend on the network (PoseLib, OpenCV): the shipped checkpoint's
    #: (:meth:`with_fallback`)
    fallback_calibration: dict[str, tuple[float, int]] = field(default_factory=dict)

    def with_fallback(self, shipped: CheckpointSettings,
                      names: Any) -> CheckpointSettings:
        """These settings with ``shipped``'s calibration scales of ``names`` (the methods
        whose covariance does not read the network) where this checkpoint has none: a
        checkpoint of one's own (no ``--calibrate``) does not change PoseLib's sigma. Only
        for a checkpoint whose metadata has no ``calibration`` entry: one that has one, even
        empty, is taken at its word."""
        if self.has_calibration:
            return self
        fallback = {n: (shipped.calibration[n], shipped.calibration_bootstrap) for n in names
                    if n not in self.calibration and n in shipped.calibration}
        return dataclasses.replace(self, fallback_calibration=fallback) if fallback else self

    def scale_of(self, name: str) -> tuple[float | None, int, bool]:
        """The calibration scale of ``name`` (``None``: none), the bootstrap count it was
        fitted with, and whether it is the shipped checkpoint's fallback."""
        if name in self.calibration:
            return self.calibration[name], self.calibration_bootstrap, False
        if name in self.fallback_calibration:
            scale, boot = self.fallback_calibration[name]
            return scale, boot, True
        return None, self.calibration_bootstrap, False

    @classmethod
    def from_metadata(cls, md: Any) -> CheckpointSettings:
        """From a metadata dict (anything else: the defaults); malformed entries fall back
        to their defaults, as the checkpoint loader only checks the keys it owns."""
        if not isinstance(md, dict):
            return cls()
        cal = md.get("calibration", {})
        cal = ({str(k): float(v) for k, v in cal.items() if _is_number(v)}
               if isinstance(cal, dict) else {})
        boot = md.get("calibration_bootstrap", 0)
        order = md.get("recommended_order")
        order = (tuple(order) if isinstance(order, (list, tuple))
                 and all(isinstance(m, str) for m in order) else ())
        k = md.get("fusion_inflation", 1.0)
        return cls(cal, int(boot) if _is_int(boot) else 0, order,
                   float(k) if _is_number(k) and k > 0 else 1.0,
                   has_calibration="calibration" in md)

    @classmethod
    def of(cls, model: Any) -> CheckpointSettings:
        """The settings of a model (or anything with ``metadata``); ``None``: the defaults."""
        return cls.from_metadata(getattr(model, "metadata", None) if model is not None
                                 else None)
