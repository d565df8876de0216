"""``regression``: the network's pose head, with the swap check and the data check."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.uncertainty import data_covariance, swap_covariance
from strl_pyg.inference.methods.base import PoseMethod
from strl_pyg.inference.methods.context import (
    DATA_CHECK_MIN_POINTS,
    MethodContext,
    _solve,
    classical_base,
)
from strl_pyg.inference.network import network_pose
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.status import Status

__all__ = ["Regression", "swap_term"]


class Regression(PoseMethod):
    """The network's pose head on the pair's resampled graph (as in training), with its covariance
    from the predicted log-variances, the swap check and the data check."""

    name = "regression"
    label = "the network's pose head"
    summary = ("the paper's network: pose and per-component variance regressed from pooled "
               "features")
    needs_intrinsics = False
    uses_network = True
    reads_lines = True
    support_checked = False

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.pose_fusion import network_covariance
        from strl_pyg.geometry import Pose, tangent_basis

        model = ctx.model
        start = time.perf_counter()
        # the swap check runs its own forward pass: one batch of both pairs measured 2x slower on
        # a CPU (330 ms against 81 + 80 ms on KITTI: the batched graph loses the one-pair path)
        out = network_pose(model, matches, ctx.config.seed, ctx.config.resample, ctx.config.device)
        ms = (time.perf_counter() - start) * 1e3
        q, t, lv = (x[0].detach().cpu().double() for x in (out.quaternion, out.translation,
                                                           out.log_var))
        if not all(bool(torch.isfinite(x).all()) for x in (q, t, lv)) or float(t.norm()) < 1e-12:
            return MethodResult(self.name, Status.FAILED, time_ms=ms, raw=out,
                                warnings=["the network returned a non-finite or zero pose"],
                                support_checked=self.support_checked)
        cov = network_covariance(q, t, lv, tangent_basis(t)).numpy()
        info = {"quaternion": q, "translation": t, "log_var": lv,
                "sigma_components": torch.exp(0.5 * lv),
                "translation_kind": model.config.translation}
        pose = Pose.from_quaternion(q, t)
        warnings = []
        if ctx.config.swap_check:
            start = time.perf_counter()
            try:
                found = _swap_disagreement(model, matches, ctx, pose)
            except Exception as err:  # the forward pose stands; only its check is missing
                found = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            # its own time: time_ms stays the forward pass's, comparable with runs without it
            info["swap_check_ms"] = (time.perf_counter() - start) * 1e3
            if found is None or isinstance(found, str):
                why = ("the swapped pair's forward pass gave a non-finite or zero pose"
                       if found is None else f"the swapped pair's forward pass raised {found}")
                warnings.append(f"regression: no swap check ({why}); its covariance is the "
                                "network's own")
            else:
                rot, trans = found
                cov = cov + swap_covariance(rot, trans)
                info["swap_disagreement_deg"] = {"rotation": math.degrees(rot),
                                                 "translation": math.degrees(trans)}
        if ctx.config.data_check:
            start = time.perf_counter()
            try:
                found = _data_disagreement(matches, pose, ctx)
            except Exception as err:  # the forward pose stands; only its check is missing
                found = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            info["data_check_ms"] = (time.perf_counter() - start) * 1e3
            if isinstance(found, str):
                info["data_check"] = f"not run: {found}"
                if matches.has_intrinsics:  # without K the pose is "unreliable" anyway
                    warnings.append(f"regression: no data check ({found}); its covariance does "
                                    "not hold the distance to the classical pose")
            else:
                cov = cov + data_covariance(*found)
                info["data_disagreement_deg"] = {"rotation": math.degrees(found[0]),
                                                 "translation": math.degrees(found[1])}
        return MethodResult(self.name, Status.OK, pose, cov, warnings, time_ms=ms, info=info,
                            raw=out,
                            support_checked=self.support_checked)


#: Fewest distinct point matches for the regression's data check (a 5-dof pose needs 5; the
#: classical solvers need more to be worth comparing with).


def _data_disagreement(matches: PairMatches, pose: Any,
                       ctx: MethodContext) -> tuple[float, float] | str:
    """Angles (rad) between ``pose`` and the pose the point matches support: the classical
    solver's (PoseLib's where installed, else OpenCV's; robust, so a global answer, with its
    sign of ``t`` from cheirality), rotation and translation direction. A string says why it
    did not run."""

    if not matches.has_intrinsics:
        return "no intrinsics"
    n = matches.num_distinct_points
    if n < DATA_CHECK_MIN_POINTS:
        return f"{n} distinct point matches (fewer than {DATA_CHECK_MIN_POINTS})"
    name = classical_base(ctx)
    res = _solve(name, matches, ctx)
    if not res.success:
        return f"{name} found no pose"
    return _angles_rad(pose.R, pose.t, res.pose.R, res.pose.t)


def swap_term(regression: MethodResult) -> np.ndarray | None:
    """The swap check's :func:`swap_covariance` of a regression record (``None`` when it ran
    without one): what the fusion adds to the network's variance, as the record did."""
    swap = regression.info.get("swap_disagreement_deg")
    return None if swap is None else swap_covariance(math.radians(swap["rotation"]),
                                                     math.radians(swap["translation"]))


def _swap_disagreement(model: torch.nn.Module, matches: PairMatches, ctx: MethodContext,
                       pose: Any, back: Any = None) -> tuple[float, float] | None:
    """Angles (rad) between ``pose`` and the inverse of the network's pose of the swapped
    pair (``back``, its ``PoseOutput``, or computed here): rotation, translation direction;
    ``None`` when that pose is not finite."""
    from strl_pyg.geometry import Pose

    if back is None:
        cfg = ctx.config
        back = network_pose(model, matches.swapped(), cfg.seed, cfg.resample, cfg.device)
    qb, tb = (x[0].detach().cpu().double() for x in (back.quaternion, back.translation))
    if not (bool(torch.isfinite(qb).all()) and bool(torch.isfinite(tb).all())
            and float(tb.norm()) > 1e-12):
        return None
    inv = Pose.from_quaternion(qb, tb).inv()
    return _angles_rad(pose.R, pose.t, inv.R, inv.t)


def _angles_rad(R0: torch.Tensor, t0: torch.Tensor, R1: torch.Tensor,
                t1: torch.Tensor) -> tuple[float, float]:
    """The rotation angle between ``R0`` and ``R1`` (:func:`~strl_pyg.geometry.rotation_angle_deg`)
    and the angle between the translation directions, in radians."""
    from strl_pyg.geometry.pose import rotation_angle_deg

    t0, t1 = t0.double(), t1.double()
    cos_t = (t0 @ t1 / (t0.norm() * t1.norm())).clamp(-1, 1)
    angle = float(rotation_angle_deg(R0.double().T @ R1.double()))
    return math.radians(angle), float(torch.arccos(cos_t))
