"""``focal``: how far the pose depends on the focal length the user gave.

Two views rarely verify a focal length (``strl_pyg.inference.evidence``'s module docstring).
The pose is solved again with both focal lengths scaled by the estimator's ``focal_range``
each way; where neither scaled solve explains clearly fewer matches, their spread about the pose
is added to a second covariance, :attr:`MethodResult.covariance_with_focal
<strl_pyg.inference.record.MethodResult.covariance_with_focal>` (``sigma_with_focal`` in the
JSON). The pose's own ``covariance`` / ``sigma`` stays its uncertainty for the K given: a right
pose with a calibrated K keeps a sharp sigma, and a user unsure of the focal length reads the
focal-inclusive one. The verdict (``"verified"`` / ``"not verified"``) is reported, never a
refusal.
"""

from __future__ import annotations

import numpy as np

from strl_pyg.inference.evidence import focal_sensitivity
from strl_pyg.inference.rules.base import PoseRule
from strl_pyg.inference.status import Action, Status, Verdict

__all__ = ["Focal"]


class Focal(PoseRule):
    """Module docstring."""

    name = "focal"
    summary = ("solves at f / range and f x range: the focal-inclusive sigma beside the pose's "
               "own (reported)")
    order = 40.0
    decides = "report"
    warns = False

    def enabled(self, config):
        return bool(config.focal_sensitivity)

    def __call__(self, estimate, run):
        pose = estimate.pose
        if pose.status is not Status.OK or pose.covariance is None:
            return None
        cfg = run.ctx.config
        key = ("focal", np.asarray(pose.T_0to1, np.float64).tobytes(), pose.method)
        done = run.once(key, lambda: focal_sensitivity(pose, run.matches, cfg.threshold_px,
                                                       cfg.seed, cfg.focal_range))
        if "focal" not in done.info:
            return None
        estimate.pose = pose = done
        focal = pose.info["focal"]
        sig = pose.sigma_with_focal or {}
        if focal["verdict"] == "verified":
            why = (f"focal length verified: solves with both focal lengths x{1 / cfg.focal_range:g}"
                   f" and x{cfg.focal_range:g} explain {focal['inliers_scaled']} of the "
                   f"{focal['inliers_given']} matches the given K's pose explains")
        else:
            why = (f"focal length not verified by the matches (solves with both focal lengths "
                   f"x{1 / cfg.focal_range:g} and x{cfg.focal_range:g} explain "
                   f"{focal['inliers_scaled']} of {focal['inliers_given']}): with that "
                   f"uncertainty the sigma would be {sig.get('rotation_deg', float('nan')):.1f}"
                   f" / {sig.get('translation_deg', float('nan')):.1f} deg (sigma_with_focal)")
        return Verdict(self.name, Action.REPORTED, Status.OK, why,
                       {**focal, "sigma_with_focal": sig})
