"""``watermark``: COLMAP's WATERMARK, a stamped overlay that carries the pose."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from strl_pyg.inference.evidence import (
    WATERMARK_BORDER,
    WATERMARK_MIN_MATCHES,
    WATERMARK_MOVING_PX,
    WATERMARK_SHARE,
    WATERMARK_STILL_PX,
)
from strl_pyg.inference.rules.base import PoseRule
from strl_pyg.inference.status import Status

__all__ = ["Watermark"]


class Watermark(PoseRule):
    """At least :data:`~strl_pyg.inference.evidence.WATERMARK_MIN_MATCHES` (and
    :data:`~strl_pyg.inference.evidence.WATERMARK_SHARE`) of the pose's inliers stay put
    (under :data:`~strl_pyg.inference.evidence.WATERMARK_STILL_PX`) near the image borders
    while the other matches move: a logo or time stamp matches itself and fits any pose
    without rotation, so it pulls the pose towards one. The configuration is ``"watermark"``
    and the pose ``"unreliable"``."""

    name = "watermark"
    summary = "a stamped overlay's still border matches carry the pose: refused"
    order = 10.0
    decides = "refuse"

    def __call__(self, estimate, run):
        pose, geo, matches = estimate.pose, run.geometry, run.matches
        if geo is None or pose.status is not Status.OK or not matches.has_intrinsics:
            return None
        p0, p1 = np.asarray(matches.points0), np.asarray(matches.points1)
        if len(p0) < WATERMARK_MIN_MATCHES:
            return None
        h, w = matches.image_size0
        still = np.linalg.norm(p1 - p0, axis=1) < WATERMARK_STILL_PX
        bx, by = WATERMARK_BORDER * w, WATERMARK_BORDER * h
        border = (p0[:, 0] < bx) | (p0[:, 0] > w - 1 - bx) | (p0[:, 1] < by) | \
            (p0[:, 1] > h - 1 - by)
        inl = run.pose_inliers(pose.T_0to1)
        stamp = still & border & inl
        others = ~(still & border)
        if stamp.sum() < max(WATERMARK_MIN_MATCHES, WATERMARK_SHARE * inl.sum()) or \
                others.sum() < WATERMARK_MIN_MATCHES or \
                np.median(np.linalg.norm(p1[others] - p0[others], axis=1)) < \
                WATERMARK_MOVING_PX:
            return None
        n = int(stamp.sum())
        estimate.geometry = replace(geo, configuration="watermark")
        estimate.pose = replace(pose, info={**pose.info, "watermark_matches": n}).unreliable(
            [f"a watermark (COLMAP's WATERMARK): {n} of the pose's inliers stay put (under "
             f"{WATERMARK_STILL_PX:g} px) near the image borders while the other matches "
             "move: a stamped overlay matches itself and fits any pose without rotation; "
             "crop or mask it"], rule=self.name,
            evidence={"still_border_inliers": n, "pose_inliers": int(inl.sum())})
        return estimate.pose.verdicts[-1]

