"""``sigma_cap``: no ``"ok"`` pose whose sigma reached the cap.

A covariance is capped at an RMS angle of
:data:`~strl_pyg.estimation.uncertainty.MAX_SIGMA_DEG` (180 deg: no rotation or direction is
further from another). A pose whose rotation or translation sigma (for the K given) reached it
says nothing about where the pose is: its resamples, its plane's decompositions or its
calibration spread over every direction. It is ``"unreliable"``, with the computed pose in
``info["unreliable_T_0to1"]``. The focal-inclusive sigma (``sigma_with_focal``) is not read
here: a focal length the matches cannot verify widens that one, not the pose's own.
"""

from __future__ import annotations

from strl_pyg.estimation.uncertainty import MAX_SIGMA_DEG
from strl_pyg.inference.rules.base import PoseRule
from strl_pyg.inference.status import Status

__all__ = ["SigmaCap", "CAPPED_AT"]

#: A sigma within this share of :data:`MAX_SIGMA_DEG` counts as capped (the cap is applied to
#: the trace, so a capped sigma reads 180 deg up to rounding).
CAPPED_AT = 0.999


class SigmaCap(PoseRule):
    """Module docstring."""

    name = "sigma_cap"
    summary = f"a sigma at the {MAX_SIGMA_DEG:g}-deg cap says nothing: refused"
    order = 90.0
    decides = "refuse"

    def __call__(self, estimate, run):
        pose = estimate.pose
        if pose.status is not Status.OK or pose.sigma is None:
            return None
        sig = pose.sigma
        capped = [k for k in ("rotation_deg", "translation_deg")
                  if sig.get(k) is not None and sig[k] >= CAPPED_AT * MAX_SIGMA_DEG]
        if not capped:
            return None
        parts = " and ".join(k.replace("_deg", "") for k in capped)
        estimate.pose = pose.unreliable([
            f"its {parts} sigma reached the {MAX_SIGMA_DEG:g}-deg cap "
            f"({sig['rotation_deg']:.0f} / {sig['translation_deg']:.0f} deg): the matches do "
            "not locate this pose (its resamples or decompositions spread over every "
            "direction)"], rule=self.name, evidence={"sigma": dict(sig)})
        return estimate.pose.verdicts[-1]
