"""``opencv`` and ``poselib``: the classical essential-matrix solvers
(:mod:`strl_pyg.estimation.classical`)."""

from __future__ import annotations

import time

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import OPENCV, POSELIB, have_poselib
from strl_pyg.estimation.uncertainty import bootstrap_resamples
from strl_pyg.inference.methods.base import PoseMethod
from strl_pyg.inference.methods.context import MethodContext, _add_bootstrap, _solve
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.status import Status

__all__ = ["Classical", "OpenCV", "PoseLib"]


class Classical(PoseMethod):
    """A classical essential-matrix solver (:mod:`strl_pyg.estimation.classical`), with the
    first-order covariance of its inliers and the bootstrap: :class:`OpenCV` (MAGSAC) and
    :class:`PoseLib` (LO-RANSAC, where installed); ``Classical.of(name)`` is the one of that
    name."""

    bootstrapped = True

    @staticmethod
    def of(name: str) -> Classical:
        """The classical method called ``name`` (``"opencv"`` or ``"poselib"``)."""
        for cls in (OpenCV, PoseLib):
            if cls.name == name:
                return cls()
        raise ValueError(f"Expected a classical solver in {[OPENCV, POSELIB]} (got {name!r})")

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        name = self.name
        from strl_pyg.estimation.pose_fusion import classical_covariance

        thr = ctx.config.threshold_px
        res = _solve(name, matches, ctx)
        if not res.success:
            return MethodResult(name, Status.FAILED, time_ms=res.time_ms, num_inliers=0, raw=res,
                                warnings=[f"{name} found no pose (no essential matrix with "
                                          "points in front of both cameras)"])
        warnings, cov, info = [], None, dict(res.info)
        try:
            cov = classical_covariance(res.pose, matches, res.inliers, threshold_px=thr)[1]
            cov = cov.numpy()
        except ValueError as err:
            warnings.append(f"{name}: no covariance ({err})")
        rec = MethodResult(name, Status.OK, res.pose, cov, warnings, res.time_ms,
                           res.num_inliers, info=info, raw=res)
        if cov is not None and ctx.config.bootstrap:
            # first order (noise around a right solution) + bootstrap (instability of the
            # solution itself), see strl_pyg.estimation.uncertainty
            start = time.perf_counter()
            boot = bootstrap_resamples(matches, res.pose, name, ctx.config.bootstrap, thr,
                                       ctx.config.seed)
            rec.time_ms += (time.perf_counter() - start) * 1e3
            ctx.bootstraps[name] = boot  # guided and fused reuse it
        else:
            boot = None
        return _add_bootstrap(rec, boot, ctx.config.bootstrap, "first-order")


class OpenCV(Classical):
    """``opencv``: OpenCV's MAGSAC essential matrix (always installed)."""

    name = OPENCV
    label = "OpenCV MAGSAC"
    summary = "OpenCV's USAC_MAGSAC essential matrix, then `recoverPose`"


class PoseLib(Classical):
    """``poselib``: PoseLib's LO-RANSAC with non-linear refinement (optional dependency)."""

    name = POSELIB
    label = "PoseLib"
    summary = "PoseLib's LO-RANSAC essential matrix with non-linear refinement"
    requires = "PoseLib"

    def available(self) -> bool:
        return have_poselib()
