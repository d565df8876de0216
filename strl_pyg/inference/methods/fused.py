"""``fused``: the network's pose and the first ``"ok"`` classical pose combined in
information form (:func:`~strl_pyg.estimation.pose_fusion.fuse_poses`)."""

from __future__ import annotations

import time

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import OPENCV, POSELIB
from strl_pyg.inference.methods.base import CLASSICAL, PoseMethod
from strl_pyg.inference.methods.context import MethodContext, _add_bootstrap
from strl_pyg.inference.methods.regression import Regression, swap_term
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.settings import CheckpointSettings
from strl_pyg.inference.status import Status

__all__ = ["Fused"]


class Fused(PoseMethod):
    """The network's pose and the first ``"ok"`` classical pose combined in information form
    (:func:`~strl_pyg.estimation.pose_fusion.fuse_poses`)."""

    name = "fused"
    label = "network + classical, information form"
    summary = ("the network's regression fused with the classical pose in information form, "
               "gated by their agreement")
    uses_network = True
    reads_lines = True
    bootstrapped = True
    classical_base = True
    depends_on = (Regression.name, CLASSICAL)

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.pose_fusion import fuse_poses

        net = ctx.results.get(Regression.name)
        cls = next((ctx.results[c] for c in (POSELIB, OPENCV)
                    if c in ctx.results and ctx.results[c].status == Status.OK), None)
        if net is None or net.status != Status.OK or cls is None:
            return MethodResult(self.name, Status.FAILED, warnings=[
                "fused needs an 'ok' regression and an 'ok' classical estimate (poselib or "
                "opencv)"])
        start = time.perf_counter()
        # the regression's calibrated variance, times the fusion's own inflation (fitted on the
        # held-out calibration pairs by benchmarks/bench_pose.py --calibrate: the smallest that
        # keeps the 95 % upper bound of the median change against the classical pose <= +5 %)
        settings = ctx.settings if ctx.settings is not None else CheckpointSettings.of(ctx.model)
        scale = settings.calibration.get(Regression.name, 1.0) * settings.fusion_inflation
        f = fuse_poses(net.raw, None, cls.raw, matches, threshold_px=ctx.config.threshold_px,
                       network_scale=scale, network_extra=swap_term(net))
        ms = (time.perf_counter() - start) * 1e3 + net.time_ms + cls.time_ms
        if f.source == "network":
            return MethodResult(self.name, Status.FAILED, time_ms=ms, raw=f, warnings=[
                f"fused: too few {cls.method} inliers for a covariance ({f.info['num_inliers']})"])
        gate = f.info.get("gate", {})
        info = {"classical": cls.method, "network_weight": f.weights,
                "sign_disagreement": f.info["sign_disagreement"], "used": f.source,
                "gate_d2": gate.get("d2"), "network_variance_scale": scale}
        warnings = [] if f.source == "fused" else [f"fused: {gate.get('reason')}"]
        rec = MethodResult(self.name, Status.OK, f.pose, f.covariance.numpy(),
                           warnings, time_ms=ms, num_inliers=f.info["num_inliers"], info=info,
                           raw=f)
        # the fused pose stays near the classical one and moves with it when the matches change:
        # the classical bootstrap term (instability of the solve, which the information form
        # cannot see) is added, as for the classical record itself (its warning, if any, is there)
        lazy = ctx.bootstraps.get(cls.method)
        boot = None if lazy is None else lazy()
        rec = _add_bootstrap(rec, boot, 0 if boot is None else ctx.config.bootstrap,
                             "information form", f"{cls.method} ")
        return rec
