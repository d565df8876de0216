"""``opencv`` and ``poselib``: the classical essential-matrix solvers
(:mod:`strl_pyg.estimation.classical`)."""

from __future__ import annotations

import time
from dataclasses import replace

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.classical import OPENCV, POSELIB, have_poselib
from strl_pyg.estimation.uncertainty import bootstrap_resamples
from strl_pyg.inference.methods.base import PoseMethod
from strl_pyg.inference.methods.context import MethodContext, _add_bootstrap, _solve
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.status import Status

__all__ = ["Classical", "OpenCV", "PoseLib", "LazyBootstrap"]


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
        if cov is None or not ctx.config.bootstrap:
            return _add_bootstrap(rec, None, ctx.config.bootstrap, "first-order")
        # first order (noise around a right solution) + bootstrap (instability of the
        # solution itself), see strl_pyg.estimation.uncertainty; computed once, when first
        # asked for (guided and fused reuse it)
        boot = ctx.bootstraps[name] = LazyBootstrap(matches, res.pose, name,
                                                    ctx.config.bootstrap, thr, ctx.config.seed)
        if _unsupported(rec, matches, ctx):
            # the support check refuses this pose after the method (running.run_methods), so
            # its sigma is never given: its resamples (RANSAC run `bootstrap` times more, at
            # its most iterations on unrelated images) are not computed for it
            rec.info["bootstrap"] = "skipped: the matches do not support the pose"
            return _add_bootstrap(rec, None, 0, "first-order")
        start = time.perf_counter()
        resamples = boot()
        rec.time_ms += (time.perf_counter() - start) * 1e3
        return _add_bootstrap(rec, resamples, ctx.config.bootstrap, "first-order")


def _unsupported(rec: MethodResult, matches: PairMatches, ctx: MethodContext) -> bool:
    """Whether the support check (:func:`~strl_pyg.inference.support.check_support`, with the
    estimator's settings) will refuse ``rec``'s pose."""
    from strl_pyg.inference.support import check_support

    checked = check_support(replace(rec, info=dict(rec.info)), matches,
                            ctx.config.threshold_px, *ctx.config.support, checked=True)
    return checked.status is Status.FAILED


class LazyBootstrap:
    """A classical pose's bootstrap resamples
    (:func:`~strl_pyg.estimation.uncertainty.bootstrap_resamples`), computed on the first call
    and kept: the classical record, ``guided`` and ``fused`` read the same."""

    def __init__(self, matches: PairMatches, pose, method: str, n: int, threshold_px: float,
                 seed: int) -> None:
        self._args = (matches, pose, method, n, threshold_px, seed)
        self._done, self._value = False, None

    def __call__(self):
        if not self._done:
            self._value, self._done = bootstrap_resamples(*self._args), True
        return self._value


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
