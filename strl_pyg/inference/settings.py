"""What a checkpoint's metadata says about estimation (:class:`CheckpointSettings`, read once per
estimator: the calibration scales, the bootstrap they were fitted with, the measured recommended
order and the fusion's variance inflation); the user's options are
:class:`~strl_pyg.inference.config.EstimatorConfig`."""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["CheckpointSettings"]


def _is_int(v: Any) -> bool:
    """An integer, numpy's included, not a bool."""
    return isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))


def _is_number(v: Any) -> bool:
    """A real number, numpy's included, not a bool."""
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


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
