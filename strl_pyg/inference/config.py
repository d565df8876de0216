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
    arguments are these fields, documented below), checked when built: a bad
    value is a one-line ``ValueError``. ``methods`` ``None`` or ``"all"``: every installed
    method; a ``str`` is one method or comma-separated names (as ``--methods`` takes them).
    ``device`` is kept as a ``torch.device`` (or ``None``).

    Args:
        methods: names from :data:`~strl_pyg.inference.registry.METHODS` to run (default: all
            installed ones); one name as a ``str`` is one method.
        seed: resampling and RANSAC seed (same input, same result).
        threshold_px: inlier threshold of the classical solvers, pixels.
        device: where the network runs: the model is moved there (``model.to(device)``, in
            place); default: the model's device. A device this machine does not have (``"cuda"``
            without CUDA) is a ``ValueError`` here, not a failure of every network method later.
        raise_errors: re-raise a method's exception instead of recording ``"failed"``.
        bootstrap: resamples of the point matches behind the ``poselib`` / ``opencv``
            covariances (first order + bootstrap, :mod:`strl_pyg.estimation.uncertainty`);
            ``0``: first order only. Their calibration scales apply only when the checkpoint's
            ``metadata["calibration_bootstrap"]`` (0 when absent) equals it; otherwise the
            record keeps the uncalibrated covariance and says so in ``warnings``.
        min_inlier_ratio, min_inliers: a solver's pose (``PoseMethod.support_checked``) is
            ``"failed"`` when the matches do not support it: fewer of the point matches lie
            within :data:`~strl_pyg.inference.support.SUPPORT_BAND` x ``threshold_px`` of it
            (Sampson distance; the band keeps correct poses of 2 px matches) than this fraction
            of them, or than ``min(min_inliers, number of matches)`` (with fewer matches than
            that, every match must agree). Random matches give RANSAC a few percent (11 of 300),
            and on a few dozen its 5-point sample plus a handful (9 of 32 on two unrelated
            images). When no checked solver is left ``"ok"`` for that reason, the regression is
            not used as the recommended pose either. Defaults 0.1 and 12; ``0`` switches either
            off. Only matches in front of both cameras count (as in the solvers' own counts).
        min_in_front: a checked pose is ``"unreliable"`` when fewer than this fraction of the
            point matches within the support band lie in front of both cameras (its sign or
            decomposition is wrong; default :data:`~strl_pyg.inference.support.CHEIRALITY_MIN`,
            ``0`` = off). Every pose is ``"unreliable"`` when the intrinsics fail
            :func:`~strl_pyg.inference.checks.intrinsics_problems`.
        resample: the regression's input graph: ``"model"`` (default: the point / line counts
            the checkpoint was trained with, seeded by ``seed``), ``(points, lines)`` or
            ``None`` (every match).
        swap_check: the regression also runs on the swapped pair (image 1 first) and its
            covariance grows by the disagreement of the two passes
            (:func:`~strl_pyg.estimation.uncertainty.swap_covariance`; default ``True``): the
            network's own variances are fitted on its training distribution and stay small away
            from it.
        data_check: the regression's covariance also grows by its distance to the classical pose
            of the same matches (PoseLib's, else OpenCV's; one solve per pair, shared with that
            method) (:func:`~strl_pyg.estimation.uncertainty.data_covariance`; default ``True``;
            needs intrinsics and 8 distinct point matches).
        focal_sensitivity, focal_range: the ``focal`` rule
            (:mod:`strl_pyg.inference.rules.focal`): the recommended pose is solved again with
            both focal lengths scaled by ``focal_range`` (default 2) each way; where the matches
            do not verify the focal length, the spread is added to its ``covariance_with_focal``
            (``sigma_with_focal``), never to its own ``covariance`` (default ``True``; two more
            solves per pair).
    """

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
