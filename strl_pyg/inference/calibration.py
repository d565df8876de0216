"""The calibration of a method's covariance: the checkpoint's measured scale applied where it
holds (:func:`calibrate`), and the shipped checkpoint's header that supplies the scales a
checkpoint lacks (:func:`shipped_header`)."""

from __future__ import annotations

from typing import Any

from strl_pyg.estimation.uncertainty import MAX_SIGMA_DEG, cap_covariance
from strl_pyg.inference.policy import measured_with_missing_poselib
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.registry import METHODS
from strl_pyg.inference.settings import CheckpointSettings

__all__ = ["calibrate", "shipped_header"]


_SHIPPED_METADATA: list = []


def shipped_header() -> Any:
    """The default shipped checkpoint's metadata and config, as an object with ``metadata``
    (what the calibration and order helpers read) and ``config``, read once per process
    without building the model."""
    if not _SHIPPED_METADATA:
        from types import SimpleNamespace

        from strl_pyg.model.strl_pose import StrLPose

        config, metadata = StrLPose.pretrained_header()
        _SHIPPED_METADATA.append(SimpleNamespace(metadata=metadata, config=config))
    return _SHIPPED_METADATA[0]


def calibrate(name: str, res: MethodResult, settings: CheckpointSettings,
              bootstrap: int) -> MethodResult:
    """``res`` with its covariance scaled by the checkpoint's calibration where it applies
    (``settings``: the checkpoint's scales; ``bootstrap``: the resamples this estimate used),
    or a warning why not (``res.calibrated``), then capped at :data:`MAX_SIGMA_DEG` per
    block."""
    scale, fitted_boot, shipped = settings.scale_of(name)
    spec = METHODS[name]
    which = "the shipped weights' scale" if shipped else "the checkpoint's scale"
    if (scale is not None and spec.bootstrapped and res.covariance is not None
            and fitted_boot != bootstrap):
        res.warnings.append(
            f"{name}: covariance not calibrated ({which} was fitted with "
            f"bootstrap={fitted_boot}, this estimate used bootstrap={bootstrap})")
        scale, res.calibrated = None, False
    if (scale is not None and spec.classical_base and res.covariance is not None
            and measured_with_missing_poselib(settings)):
        res.warnings.append(
            f"{name}: covariance not calibrated ({which} was fitted with "
            "PoseLib as its classical base, which is not installed here)")
        scale, res.calibrated = None, False
    if scale is not None and res.covariance is not None:
        res.covariance = res.covariance * scale
        res.info["calibration_scale"] = scale
        res.calibrated = True
        if shipped:
            res.info["calibration_from"] = "shipped"
    elif (res.covariance is not None and res.info.get("calibration_scale") is None
          and res.calibrated is not False):
        # (a record that carries another method's calibrated covariance, vp_checked's
        # copy of the classical one, has its scale already)
        res.warnings.append(f"{name}: covariance not calibrated (no scale of it in the "
                            "checkpoint's metadata): its sigma is not a measured one")
        res.calibrated = False
    if res.covariance is not None:
        res.covariance, capped = cap_covariance(res.covariance)
        if capped:
            res.info["sigma_capped"] = True
            res.warnings.append(f"{name}: sigma capped at {MAX_SIGMA_DEG:g} deg (its "
                                "covariance stated more: the pose is ambiguous)")
    return res
