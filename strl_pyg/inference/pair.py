"""One pair's run through :class:`~strl_pyg.inference.PoseEstimator`: the matches checked once
(:func:`checked_pair`), the context every method of the pair shares (:class:`PairRun`), the
rules that hold for all of its methods (:func:`pair_rules`) and the fundamental matrix of a
pair without intrinsics (:func:`attach_fundamental`)."""

from __future__ import annotations

import contextvars
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from strl_pyg.data.matches import (
    DUPLICATE_TOLERANCE_PX,
    POINT_ROW_KEYS,
    PairMatches,
    first_unique_rows,
)
from strl_pyg.inference.checks import (
    BAD_INTRINSICS,
    ZERO_PARALLAX_PX,
    flipped_lines,
    input_warnings,
    intrinsics_problems,
    zero_parallax,
)
from strl_pyg.inference.methods.context import MethodContext
from strl_pyg.inference.record import MethodResult, PoseEstimate
from strl_pyg.inference.registry import METHODS
from strl_pyg.utils.threads import available_cores, shared_pool

__all__ = ["NO_INTRINSICS", "PairRun", "checked_pair", "pair_rules", "attach_fundamental",
           "spread_px", "unique_in_order"]


#: Why every pose of a pair without intrinsics is ``"unreliable"``.
NO_INTRINSICS = ("no metric pose without intrinsics K0, K1 (the network's pose from "
                 "coordinates normalised by the image size is not one): the pair's epipolar "
                 "geometry is its fundamental matrix, info['fundamental_matrix']")


def attach_fundamental(estimate: PoseEstimate, matches: PairMatches, threshold_px: float,
                        seed: int, rows: np.ndarray) -> None:
    """The route without intrinsics: the fundamental matrix of the (checked) point matches
    (OpenCV MAGSAC, pixels) in the recommended record's ``info``, with the number of distinct
    inliers and the inlier mask over the input's rows (``rows``: the checked row of each)."""
    from strl_pyg.estimation.classical import fundamental_matrix

    found = fundamental_matrix(matches, threshold_px, seed)
    info = dict(estimate.pose.info)  # the record may share its dict with a method's
    info["fundamental_matrix"] = None if found is None else found[0]
    if found is not None:
        info["fundamental_inliers"] = int(found[1].sum())
        info["fundamental_inlier_mask"] = np.asarray(found[1], dtype=bool)[rows]
    estimate.pose.info = info


def checked_pair(matches: PairMatches) -> tuple[PairMatches, list[str], np.ndarray,
                                                  str | None, list[str]]:
    """The pair's one input check: the matches with each correspondence once (every decision,
    minimum counts, support, bootstrap sigma, counts correspondences, not rows), the input
    warnings, the row of every input point in them, why the pair is degenerate (or ``None``)
    and what is wrong with its intrinsics (:func:`intrinsics_problems`), found once, in the
    frame the user gave (``matches.info["original_frame"]``: the sizes and K of images that
    were matched resized; the checks do not depend on the scale, their numbers do)."""
    o = matches.info.get("original_frame") or {
        "size0": matches.image_size0, "size1": matches.image_size1, "K0": matches.K0,
        "K1": matches.K1}
    problems = intrinsics_problems(o["size0"], o["size1"], o["K0"], o["K1"]) \
        if matches.has_intrinsics else []
    warnings = list(problems) if matches.has_intrinsics else input_warnings(
        matches.image_size0, matches.image_size1, None, None)
    matches, repeats, rows = matches.deduplicated()
    warnings += repeats
    warnings += flipped_lines(matches)
    n, degenerate = matches.num_distinct_points, None
    spread = spread_px(matches)
    if n and spread < 4.0 and min(*matches.image_size0, *matches.image_size1) >= 64:
        degenerate = (f"Expected pixel coordinates (got all {matches.num_points} point "
                      f"matches within {spread:.2g} px of each other in images of "
                      f"{matches.image_size0[0]}x{matches.image_size0[1]} px: normalised "
                      "coordinates? build the matches with PairMatches.from_normalized)")
    elif zero_parallax(matches):
        degenerate = (f"zero parallax: most of the {n} point matches moved less than "
                      f"{ZERO_PARALLAX_PX} px (identical or near-identical images): the "
                      "translation is undefined")
    if degenerate is not None:
        warnings.append(degenerate)
    return matches, warnings, rows, degenerate, problems


def start_geometry(checked: PairMatches, memo: dict, threshold_px: float,
                   seed: int) -> Any:
    """The pair's two-view configuration (:func:`~strl_pyg.inference.evidence.pair_geometry`),
    or, where there is a second core, the Future computing it in a worker thread while the
    methods run (:attr:`PairRun.geometry` waits for it: nothing reads it before the methods
    have run; the classical solve is single-threaded; OpenCV's random state is per thread).
    The pair is normalised first, here, into ``memo``: the methods and it read it there."""
    from strl_pyg.estimation.classical import normalisation_scope, normalised_matches
    from strl_pyg.inference.evidence import pair_geometry

    def configuration():
        with normalisation_scope(memo):
            return pair_geometry(checked, threshold_px, seed)

    with normalisation_scope(memo):
        normalised_matches(checked)
    if available_cores() > 1:
        return shared_pool("pair", 1).submit(contextvars.copy_context().run, configuration)
    return configuration()


def pair_rules(results: dict[str, MethodResult], matches: PairMatches,
                rows: np.ndarray, problems: list[str]) -> None:
    """What holds for every method of a pair, applied in place: intrinsics that fail the
    checks (``problems``: :func:`intrinsics_problems`) or none at all make every pose
    ``"unreliable"``; inlier masks go to the input's rows."""
    reasons = [f"{BAD_INTRINSICS}: " + "; ".join(problems)] if problems else []
    if not matches.has_intrinsics:
        # the network then reads coordinates normalised by the image size, not by K: its
        # rotation and its calibrated sigma are not those of a calibrated pair
        reasons.append(NO_INTRINSICS)
    rule = "intrinsics" if problems else "no_intrinsics"
    for name, res in results.items():
        new = [why for why in reasons if why not in res.warnings]  # a known result may
        results[name] = res = res.unreliable(new, rule=rule,  # carry them already
                                             evidence={"problems": list(problems)})
        res.bad_intrinsics = res.bad_intrinsics or bool(problems)
        if res.info.get("inlier_mask") is not None and res.inliers is None:
            res.inliers = np.asarray(res.info.pop("inlier_mask"), dtype=bool)[rows]


def spread_px(matches: PairMatches) -> float:
    """The larger extent (pixels) of the point matches in either image; ``inf`` without
    point matches."""
    if matches.num_points == 0:
        return float("inf")
    return float(max(np.ptp(matches.points0, axis=0).max(), np.ptp(matches.points1, axis=0).max()))


def unique_in_order(items: list[str]) -> list[str]:
    return list(dict.fromkeys(items))


@dataclass
class PairRun:
    """One pair's run, the estimator's one context per pair: the matches checked once
    (:func:`checked_pair`), their normalisation (the memo of
    :func:`~strl_pyg.estimation.classical.normalisation_scope`), the results of the methods run
    so far and what they share (:class:`MethodContext`)."""

    matches: PairMatches  # checked: each correspondence once
    warnings: list[str]
    rows: np.ndarray  # the checked row of every input point row
    degenerate: str | None
    problems: list[str]  # intrinsics_problems, found once
    ctx: MethodContext
    memo: dict = field(default_factory=dict)
    #: the two-view configuration (strl_pyg.inference.evidence), or the Future computing it
    #: beside the methods (:attr:`geometry` waits for it)
    pending_geometry: Any = None
    #: what the rules measured on this pair, by key (:meth:`once`)
    evidence: dict = field(default_factory=dict)

    @classmethod
    def start(cls, matches: PairMatches, ctx: MethodContext) -> PairRun:
        """The pair's one context: its input check (:func:`checked_pair`), its two-view
        configuration started beside the methods (:func:`start_geometry`; none for a degenerate
        pair, failing intrinsics or none) and ``ctx``, the context its methods share."""
        checked, warnings, rows, degenerate, problems = checked_pair(matches)
        memo: dict = {}
        cfg = ctx.config
        geometry = None if degenerate is not None or problems or not checked.has_intrinsics \
            else start_geometry(checked, memo, cfg.threshold_px, cfg.seed)
        return cls(checked, warnings, rows, degenerate, problems, ctx, memo, geometry)

    def once(self, key: Any, compute: Any) -> Any:
        """``compute()`` the first time ``key`` is asked for on this pair, its stored result
        after that: each evidence pass of the rules runs once per pair, however many steps
        the recommended walk takes (inside the pair's normalisation scope)."""
        if key not in self.evidence:
            from strl_pyg.estimation.classical import normalisation_scope

            with normalisation_scope(self.memo):
                self.evidence[key] = compute()
        return self.evidence[key]

    def pose_inliers(self, T: Any) -> np.ndarray:
        """The point matches within the inlier threshold (Sampson, pixels) of the pose ``T``
        ``[4, 4]``, once per pair and pose."""
        from strl_pyg.geometry.epipolar import epipolar_residuals

        T = np.asarray(T, dtype=np.float64)
        thr = self.ctx.config.threshold_px
        return self.once(("inliers", T.tobytes(), thr),
                         lambda: epipolar_residuals(self.matches, T)[0] < thr)

    @property
    def geometry(self) -> Any:
        """The pair's two-view configuration (``None`` where it was not computed)."""
        if isinstance(self.pending_geometry, Future):
            self.pending_geometry = self.pending_geometry.result()
        return self.pending_geometry

    def add_lines(self, lined: PairMatches) -> None:
        """Joins the line matches of ``lined`` (these point matches with lines added, e.g. by
        :func:`~strl_pyg.frontend.pipeline.add_lines`): the points, their check and
        normalisation and the results of the methods that read no lines stay."""
        first = self._first_rows()
        if not (lined.num_points == len(self.rows)
                and np.array_equal(lined.points0[first], self.matches.points0)
                and np.array_equal(lined.points1[first], self.matches.points1)):
            raise ValueError(f"Expected the pair's {len(self.rows)} point matches with lines "
                             f"added (got {lined.num_points} other point matches)")
        li = first_unique_rows(np.concatenate([lined.lines0, lined.lines1], axis=1),
                               DUPLICATE_TOLERANCE_PX)
        if len(li) < lined.num_lines:
            self.warnings.append(f"{lined.num_lines - len(li)} repeated line matches removed "
                                 "(a repeated match is one correspondence): "
                                 f"{len(li)} line matches remain")
        info = dict(lined.info)  # the point rows the check re-indexed stay re-indexed
        for key in POINT_ROW_KEYS:
            info.pop(key, None)
            if key in self.matches.info:
                info[key] = self.matches.info[key]
        # the same point arrays: their normalisation is found again in the memo
        self.matches = replace(self.matches, lines0=lined.lines0[li], lines1=lined.lines1[li],
                               line_scores=None if lined.line_scores is None
                               else lined.line_scores[li], info=info)
        self.ctx.results = {m: r for m, r in self.ctx.results.items()
                            if m in METHODS and not METHODS[m].reads_lines}
        self.ctx.forget_lines()

    def _first_rows(self) -> np.ndarray:
        """The input row kept for every checked row (the first of its repeats)."""
        return np.unique(self.rows, return_index=True)[1]
