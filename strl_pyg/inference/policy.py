"""The recommended-order policy: which method fills the recommended pose of a pair.

The first ``"ok"`` method of the checkpoint's measured order (``metadata["recommended_order"]``,
written by ``benchmarks/bench_pose.py --calibrate``), else :data:`RECOMMENDED_ORDER`; the line
solver first where the points are few (:data:`POINT_POOR_ORDER`); OpenCV in PoseLib's place
where PoseLib is not installed. What a method must show to fill it is the estimator's
(:mod:`strl_pyg.inference.evidence`: a learned pose needs the matches' support).
"""

from __future__ import annotations

from typing import Any

from strl_pyg.inference.methods.classical import OpenCV, PoseLib
from strl_pyg.inference.methods.context import POINT_POOR_MAX_POINTS
from strl_pyg.inference.methods.regression import Regression
from strl_pyg.inference.methods.vanishing_point import VanishingPoint
from strl_pyg.inference.registry import METHODS
from strl_pyg.inference.settings import CheckpointSettings

__all__ = ["RECOMMENDED_ORDER", "POINT_POOR_ORDER", "POSELIB_MISSING", "recommended_order",
           "stored_order", "measured_with_missing_poselib"]

#: Which method fills the recommended pose: the first ``"ok"`` one (unavailable ones skipped).
RECOMMENDED_ORDER: tuple[str, ...] = (PoseLib.name, OpenCV.name, Regression.name)
#: Where a pair has at most :data:`POINT_POOR_MAX_POINTS` point matches, these methods come
#: before the recommended order. Fitted on the point-poor calibration split of
#: ``benchmarks/studies/bench_vanishing.py --sets calibration`` (100 generated pairs of other
#: seeds than the evaluation's, <= 30 point and >= 20 line matches; the bound 30 is that split's
#: definition, not a fit): the recommended pose with ``vp`` first beats PoseLib beyond the
#: paired-bootstrap noise, without it it does not (``benchmarks/studies/results_vanishing.md``).
POINT_POOR_ORDER: tuple[str, ...] = (VanishingPoint.name,)


def recommended_order(model: Any, num_points: int | None = None) -> tuple[str, ...]:
    """The order in which methods fill the recommended pose (``model``: a model, its
    :class:`CheckpointSettings` or ``None``): the checkpoint's
    ``metadata["recommended_order"]`` (measured on held-out data when the checkpoint was
    calibrated, see ``benchmarks/bench_pose.py --calibrate``), else :data:`RECOMMENDED_ORDER`;
    with ``num_points`` at most :data:`POINT_POOR_MAX_POINTS`, :data:`POINT_POOR_ORDER` first.
    Methods that are not installed are skipped when the estimate is made."""
    order = stored_order(model) or RECOMMENDED_ORDER
    if num_points is not None and num_points <= POINT_POOR_MAX_POINTS:
        order = POINT_POOR_ORDER + tuple(m for m in order if m not in POINT_POOR_ORDER)
    if PoseLib.name in order and not METHODS[PoseLib.name].available():
        # measured with PoseLib, which fused and guided also start from: without it those are
        # other, unmeasured methods, so OpenCV (the remaining classical default) takes its place
        i, opencv = order.index(PoseLib.name), OpenCV.name
        order = tuple(m for m in order[:i] if m != opencv) + (opencv,) + tuple(
            m for m in order[i + 1:] if m != opencv)
    return order


#: Added to the recommended pose's warnings when the order was measured with PoseLib and it is
#: not installed here.
POSELIB_MISSING = ("PoseLib is not installed: the recommended order was measured with it, so "
                   "OpenCV takes its place (pip install 'strl-pyg[poselib]' for the measured "
                   "default)")


def stored_order(model: Any) -> tuple[str, ...]:
    """The checkpoint's measured ``metadata["recommended_order"]`` (``()`` when absent);
    ``model`` may also be its :class:`CheckpointSettings`."""
    settings = model if isinstance(model, CheckpointSettings) else CheckpointSettings.of(model)
    return settings.recommended_order


def measured_with_missing_poselib(model: Any) -> bool:
    return PoseLib.name in stored_order(model) and not METHODS[PoseLib.name].available()
