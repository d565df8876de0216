"""The one configuration of :class:`~strl_pyg.inference.estimator.PoseEstimator`: the user's
options (:class:`EstimatorConfig`, checked once when built); what the checkpoint's metadata says
about estimation is :class:`~strl_pyg.inference.settings.CheckpointSettings`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from strl_pyg.estimation.uncertainty import MIN_BOOTSTRAP
from strl_pyg.inference.checks import check_device
from strl_pyg.inference.evidence import FOCAL_RANGE_FACTOR
from strl_pyg.inference.registry import checked_method_names
from strl_pyg.inference.settings import _is_int, _is_number
from strl_pyg.inference.support import CHEIRALITY_MIN, MIN_INLIER_RATIO, MIN_SUPPORT_INLIERS

__all__ = ["EstimatorConfig"]




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
