"""``geometric`` (the weighted eight-point solve of the geometric head, refined) and
``guided`` (the classical solver guided by the head's inlier weights)."""

from __future__ import annotations

import time

import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.estimation.uncertainty import bootstrap_resamples
from strl_pyg.inference.methods.base import CLASSICAL, PoseMethod
from strl_pyg.inference.methods.context import (
    MethodContext,
    _add_bootstrap,
    _full_forward,
    _no_head,
    classical_base,
    with_covariance,
)
from strl_pyg.inference.record import MethodResult
from strl_pyg.inference.status import Status

__all__ = ["Geometric", "Guided"]


class Geometric(PoseMethod):
    """The geometric head's weighted eight-point solve, refined, with a first-order covariance."""

    name = "geometric"
    label = "the network's weighted eight-point"
    summary = ("the network's geometric head: inlier weights, a weighted eight-point solve, "
               "refinement")
    uses_network = True
    reads_lines = True
    needs_geometric_head = True

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.classical import normalised_matches
        from strl_pyg.geometry import Pose
        from strl_pyg.geometry.essential import DEGENERATE, refine_pose

        bad = _no_head(self.name, ctx)
        if bad is not None:
            return bad
        out, ms = _full_forward(matches, ctx)
        geo = out.geometric
        status = int(geo.status[0])
        if status != 0:
            why = "degenerate weighted solve (too few effective matches or rank-deficient)" \
                if status == DEGENERATE else "no intrinsics: the weighted solve needs K0, K1"
            return MethodResult(self.name,
                                Status.DEGENERATE if status == DEGENERATE else Status.FAILED,
                                time_ms=ms, warnings=[f"geometric: {why}"], raw=out)
        start = time.perf_counter()
        w = torch.sigmoid(geo.point_logits.double().cpu())
        x0, x1, focal = normalised_matches(matches)
        R, t = refine_pose(geo.R[:1].cpu(), geo.t[:1].cpu(), x0[None], x1[None], w[None],
                           iterations=10, tau=ctx.config.threshold_px / focal)
        T = Pose(R[0], t[0])
        ms += (time.perf_counter() - start) * 1e3
        return with_covariance(self.name, T, matches, ctx.config.threshold_px, time_ms=ms,
                                info={"mean_weight": float(w.mean())}, raw=out)


class Guided(PoseMethod):
    """The classical solver guided by the geometric head's inlier weights
    (:func:`~strl_pyg.estimation.guided.guided_estimate`)."""

    name = "guided"
    label = "network-guided classical solve"
    summary = "the classical solver guided by the geometric head's inlier weights"
    uses_network = True
    reads_lines = True
    bootstrapped = True
    classical_base = True
    depends_on = (CLASSICAL,)
    needs_geometric_head = True

    def __call__(self, matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.estimation.guided import guided_estimate

        bad = _no_head(self.name, ctx)
        if bad is not None:
            return bad
        base = classical_base(ctx)
        out, ms = _full_forward(matches, ctx)
        w = torch.sigmoid(out.geometric.point_logits.double().cpu()).numpy()
        prior = ctx.results.get(base)
        classical = prior.raw if prior is not None and prior.status == Status.OK else None
        res = guided_estimate(matches, w, base, ctx.config.threshold_px, seed=ctx.config.seed,
                              classical=classical)
        ms += res.time_ms
        if not res.success:
            return MethodResult(self.name, Status.FAILED, time_ms=ms, raw=res,
                                warnings=[f"guided {base}: no hypothesis found"])
        info = {"base": base, "candidate": res.info["candidate"], "refined": res.info["refined"]}
        rec = with_covariance(self.name, res.pose, matches,
                               ctx.config.threshold_px, time_ms=ms, info=info, raw=res)
        boot, n_boot, resampled = None, ctx.config.bootstrap, None
        if rec.covariance is not None and n_boot:
            # the same bootstrap as the classical records, of the solve guided kept: on all the
            # matches (then it is the base method's own, computed once) or on the network's top
            # matches; the refinement, when kept, is not re-run per resample
            start = time.perf_counter()
            subset = res.info.get("point_index")
            if (subset is None and res.info["candidate"] == "all" and not res.info["refined"]
                    and base in ctx.bootstraps):
                boot, resampled = ctx.bootstraps[base](), base
            else:
                sub = matches if subset is None else matches.select(point_index=subset)
                boot = bootstrap_resamples(sub, res.pose, base, n_boot,
                                           ctx.config.threshold_px, ctx.config.seed)
            rec.time_ms += (time.perf_counter() - start) * 1e3
        return _add_bootstrap(rec, boot, n_boot, "first-order", resampled=resampled)
