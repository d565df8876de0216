"""The line solvers where points are too few (``vp``, ``vp_checked``), beside PoseLib and the
recommended pose, on the same matches (issue "Do lines help?", item 4).

    python benchmarks/studies/bench_vanishing.py --fit 100 \\
        --out benchmarks/studies/results_vanishing.md

For every pair of the point-poor sets (``point_poor``: generated pairs with <= 30 point and
>= 20 line matches; ``kitti06_kp40`` / ``demon_kp40`` / ``dino_kp40``: the real slices with the
front end limited to 40 keypoints per image) and of the full real sets (where a line solver
must not make the answer worse), it scores:

- ``PoseLib``: PoseLib's raw pose (any pose it returns);
- ``vp``: the method ``vp``'s raw pose (:func:`~strl_pyg.estimation.vanishing.vanishing_point_pose`
  with the supported classical pose as its second start), before its support check;
- ``vp_checked``: the method of that name when ``"ok"`` (PoseLib's pose, or vp's where the
  points are few and the lines' strongest vanishing direction contradicts PoseLib's rotation);
- ``recommended (points' order)``: :class:`~strl_pyg.inference.PoseEstimator`'s recommended
  pose with every method but the line solvers (the shipped model and its calibrated order:
  the recommended pose before the point-poor order), and ``(vp_checked first)`` / ``(vp
  first)``: the same with ``vp_checked`` / ``vp`` in front of the order on every pair;
- ``recommended``: the shipped recommended pose (every method; ``POINT_POOR_ORDER`` first with
  at most ``POINT_POOR_MAX_POINTS`` point matches). A pose that is not ``"ok"`` counts as no
  pose.

``--fit N`` first fits, on N point-poor pairs of other seeds (the calibration split,
:data:`CALIBRATION_SEED`), the lines' weight in vp's joint refinement (``VP_LINE_SIGMA_PX``,
:data:`FIT_SIGMAS`) and then ``vp_checked``'s two constants (angle, support slack), and prints
both grids and the split's line statistics (the references of
:func:`~strl_pyg.estimation.line_refine.line_sigmas`); the evaluation sets play no part in
it, and the evaluation then uses the fitted constants (the run says where they differ from the
package's: set them there).

AUC@20 of max(rotation, translation) error with no pose = 180 deg, [95 % bootstrap interval
over pairs]; medians over the pairs with a pose; the paired AUC differences to PoseLib with
their paired-bootstrap intervals. A second table gives target (b) of the issue: the ratio of
the recommended pose's median rotation and translation errors to PoseLib's on the pairs both
solved, with 95 % paired-bootstrap intervals, and on how many pairs the point-poor order fired
(<= ``POINT_POOR_MAX_POINTS`` point matches). ``--sets`` also takes the generated evaluation
sets (:data:`GENERATED`, 50 pairs each, the ablation's).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/

METHODS = ("PoseLib", "vp", "vp_checked", "recommended (points' order)",
           "recommended (vp_checked first)", "recommended (vp first)", "recommended")
#: The recommended poses compared with PoseLib's (paired differences).
RECOMMENDED = METHODS[3:]
#: The calibration split of ``--fit``: point-poor pairs selected like ``point_poor`` from other
#: seeds (``point_poor`` starts at 2,100,000 and tries at most 1500).
CALIBRATION_SEED = 2_300_000
#: The sets scored by default (``--sets``).
SETS = ("point_poor", "kitti06_kp40", "demon_kp40", "dino_kp40", "kitti06", "demon", "dino")
#: The generated evaluation sets (the ablation's 50 pairs each, ``ablation_eval.GENERATED_SETS``):
#: scored on request, for target (b) (the point-poor order fires on some of their pairs).
GENERATED = ("driving", "indoor", "object", "wide", "low_texture", "outliers50")
#: The grid of ``--fit``: (VP_CHECK_ANGLE_DEG, VP_CHECK_SUPPORT_SLACK).
FIT_ANGLES = (2.0, 3.0, 5.0, 8.0, 10.0, 15.0)
FIT_SLACKS = (0, 1, 2, 3, 5, 1000)
#: The grid of ``--fit`` for the lines' weight in vp's joint refinement
#: (VP_LINE_SIGMA_PX; ``None``: the points alone).
FIT_SIGMAS = (None, 1.0, 0.5, 0.25, 0.1, 0.03, 0.01)


def score_pairs(pairs, model, progress: bool = True) -> dict[str, list]:
    """``method -> [(rot, trans) or None]`` over ``pairs``: PoseLib's and vp's raw poses
    (any pose they return), ``vp_checked`` when ``"ok"`` (support-checked), the recommended
    pose of the points' order (the run without the line solvers, the order before the
    point-poor order), the same with ``vp_checked`` or ``vp`` in front (on every pair), and
    the shipped recommended pose (every method; ``vp`` first with at most 30 point matches)."""
    import bench_pose as bp

    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.inference import METHODS as REGISTRY
    from strl_pyg.inference import POINT_POOR_MAX_POINTS, PoseEstimator

    lines_only = ("vp", "vp_checked")
    without = tuple(m for m in REGISTRY if m not in lines_only and REGISTRY[m].available())
    est_without = PoseEstimator(model, methods=without)
    est_with = PoseEstimator(model, methods=(*without, *lines_only))
    out = {k: [] for k in (*METHODS, "recommended_method", "vp_checked_source", "point_poor")}
    for _, m, T in tqdm(pairs, desc="pairs", disable=not progress, leave=False):
        if m is None or m.num_points < 5:
            for k in out:
                out[k].append(None)
            out["point_poor"][-1] = m is not None
            continue
        out["point_poor"].append(m.num_points <= POINT_POOR_MAX_POINTS)
        err = lambda T_est, T=T: list(bp.errors(np.asarray(T_est), T))  # noqa: E731
        res = estimate_relative_pose(m, "poselib")
        out["PoseLib"].append(err(res.T_0to1.matrix().numpy()) if res.success else None)
        # the recommended pose without the line solvers in the run (their refusals would
        # keep the regression out of it), then the line solvers on the same results
        a = est_without.estimate(m)
        b = est_with.estimate(m, known=a.methods)
        raw = b.methods["vp"].raw  # the solver's pose before the support check
        out["vp"].append(err(raw.T_0to1.matrix().numpy())
                         if raw is not None and raw.success else None)
        vc = b.methods["vp_checked"]
        out["vp_checked"].append(err(vc.T_0to1) if vc.status == "ok" else None)
        out["vp_checked_source"].append(vc.info.get("source") if vc.status == "ok" else None)
        rec = a.pose if a.pose.status == "ok" else None
        out["recommended (points' order)"].append(err(rec.T_0to1) if rec is not None else None)
        shipped = b.pose if b.pose.status == "ok" else None
        out["recommended"].append(err(shipped.T_0to1) if shipped is not None else None)
        out["recommended_method"].append(shipped.method if shipped is not None else None)
        first = vc if vc.status == "ok" else rec
        out["recommended (vp_checked first)"].append(err(first.T_0to1) if first is not None
                                                    else None)
        vp = b.methods["vp"]
        first = vp if vp.status == "ok" else rec
        out["recommended (vp first)"].append(err(first.T_0to1) if first is not None else None)
    return out


def fit_line_sigma(pairs) -> tuple[float | None, str]:
    """Fits VP_LINE_SIGMA_PX on the calibration split: the grid value with the highest AUC@20
    of vp's raw pose (no pose = 180 deg) as the method ``vp`` runs it (the supported classical
    pose as its second start, none with ``None``); ties go to the larger sigma (the points'
    weight)."""
    import bench_pose as bp

    from strl_pyg.estimation import line_refine as L
    from strl_pyg.estimation import vanishing as V
    from strl_pyg.inference import PoseEstimator

    base = PoseEstimator(methods=("poselib",))
    est = PoseEstimator(methods=("poselib", "vp"))
    known = [base.estimate(m).methods if m is not None and m.num_lines
             and m.num_points >= V.VP_MIN_POINTS else None for _, m, _ in pairs]
    auc, saved = {}, L.VP_LINE_SIGMA_PX
    try:
        for sigma in tqdm(FIT_SIGMAS, desc="line sigma"):
            L.VP_LINE_SIGMA_PX = sigma  # read by the method vp at every call
            worst = []
            for (_, m, T), k in zip(pairs, known, strict=True):
                raw = est.estimate(m, known=k).methods["vp"].raw if k is not None else None
                worst.append(max(bp.errors(raw.T_0to1.matrix().numpy(), T))
                             if raw is not None and raw.success else 180.0)
            auc[sigma] = _auc(np.array(worst))
    finally:
        L.VP_LINE_SIGMA_PX = saved
    best = max(auc, key=lambda s: (round(auc[s], 6), float("inf") if s is None else s))
    text = ("VP_LINE_SIGMA_PX (AUC@20 % of vp's raw pose as the method runs it, on the same "
            "split; none: the points alone): " + ", ".join(
                f"{'none' if s is None else f'{s:g}'}: {a:.1f}" for s, a in auc.items())
            + f". Fit: {best}.")
    return best, text


def line_statistics(pairs) -> str:
    """The calibration split's line noise and lines per direction (medians over the vanishing
    directions of its pairs), beside the package's ``LINE_NOISE_REF_PX`` and
    ``LINE_COUNT_REF`` (:func:`~strl_pyg.estimation.line_refine.line_sigmas`)."""
    from strl_pyg.estimation import line_refine as L
    from strl_pyg.estimation.vanishing import VP_MIN_POINTS, vanishing_directions

    noise, count = [], []
    for _, m, _ in pairs:
        if m is None or not m.num_lines or m.num_points < VP_MIN_POINTS:
            continue
        K0 = np.asarray(m.K0, float)
        ends, mids, _ = L.segment_geometry(np.asarray(m.lines0, float), K0)
        for d0, _, mk in vanishing_directions(m):
            noise.append(np.median(L.vp_residual_px(d0[None], K0, ends[mk], mids[mk])[0]))
            count.append(int(mk.sum()))
    return (f"Line statistics of the split ({len(noise)} vanishing directions): median line "
            f"noise {np.median(noise):.3f} px (LINE_NOISE_REF_PX {L.LINE_NOISE_REF_PX}), median "
            f"lines per direction {np.median(count):.0f} (LINE_COUNT_REF {L.LINE_COUNT_REF}).")


def fit(cache: Path, n: int) -> tuple[float, int, str]:
    """Fits (VP_CHECK_ANGLE_DEG, VP_CHECK_SUPPORT_SLACK) on the calibration split: the grid
    point with the highest AUC@20 of ``vp_checked`` (no supported pose = 180 deg); ties go to
    the larger angle, then the smaller slack (the pose closer to PoseLib's). Returns the fit
    and a markdown table of the grid."""
    import ablation_eval as ae
    import bench_pose as bp

    from strl_pyg.estimation import line_refine as L
    from strl_pyg.inference import EstimatorConfig, PoseEstimator
    from strl_pyg.inference.methods import context as M
    from strl_pyg.inference.methods import vanishing_point as LM
    from strl_pyg.inference.support import check_support

    pairs = ae.point_poor_pairs(cache, n, seed0=CALIBRATION_SEED)
    stats = line_statistics(pairs)
    sigma, sigma_text = fit_line_sigma(pairs)
    sigma_text = stats + "\n\n" + sigma_text
    print(sigma_text)
    if sigma != L.VP_LINE_SIGMA_PX:
        print(f"note: the fit ({sigma}) differs from the package's VP_LINE_SIGMA_PX "
              f"({L.VP_LINE_SIGMA_PX}); vp_checked's constants and the evaluation use the fit")
    L.VP_LINE_SIGMA_PX = sigma  # read by the method vp at every call
    est = PoseEstimator(methods=("poselib", "vp"))
    base = [(m, T, est.estimate(m).methods) for _, m, T in tqdm(pairs, desc="calibration")]
    saved = (LM.VanishingPointChecked.angle_deg, LM.VanishingPointChecked.support_slack)
    grid = {}
    try:
        for ang in FIT_ANGLES:
            for slack in FIT_SLACKS:
                checker = LM.VanishingPointChecked()  # this grid point's thresholds
                checker.angle_deg, checker.support_slack = ang, slack
                worst = []
                for m, T, known in base:
                    ctx = M.MethodContext(EstimatorConfig(), results=dict(known))
                    rec = check_support(checker(m, ctx), m)
                    worst.append(max(bp.errors(rec.T_0to1, T)) if rec.status == "ok"
                                 else 180.0)
                grid[ang, slack] = _auc(np.array(worst))
    finally:
        LM.VanishingPointChecked.angle_deg, LM.VanishingPointChecked.support_slack = saved
    poselib = _auc(np.array([max(bp.errors(k["poselib"].T_0to1, T))
                             if k["poselib"].status == "ok" else 180.0 for _, T, k in base]))
    best = max(grid, key=lambda g: (round(grid[g], 6), g[0], -g[1]))
    lines = [f"Calibration split: {len(pairs)} point-poor pairs (seeds from {CALIBRATION_SEED}); "
             f"AUC@20 (%) of vp_checked, no supported pose = 180 deg; PoseLib (supported) "
             f"{poselib:.1f}. Rows: VP_CHECK_ANGLE_DEG, columns: VP_CHECK_SUPPORT_SLACK "
             f"(1000: no support condition). Fit: {best}.", "",
             "| angle \\ slack | " + " | ".join(str(s) for s in FIT_SLACKS) + " |",
             "|---" * (len(FIT_SLACKS) + 1) + "|"]
    for ang in FIT_ANGLES:
        lines.append(f"| {ang:g} | " + " | ".join(f"{grid[ang, s]:.1f}" for s in FIT_SLACKS)
                     + " |")
    return best[0], best[1], sigma_text + "\n\n" + "\n".join(lines)


def _worst(rows: list) -> np.ndarray:
    return np.array([180.0 if r is None else max(r) for r in rows])


def _auc(worst: np.ndarray) -> float:
    import ablation_eval as ae

    return 100 * ae.auc20(worst)


def auc_interval(worst: np.ndarray, resamples: int = 1000, seed: int = 0):
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(worst), (resamples, len(worst)))
    boots = [_auc(worst[i]) for i in idx]
    return _auc(worst), *np.percentile(boots, [2.5, 97.5])


def paired_auc_diff(a: np.ndarray, b: np.ndarray, resamples: int = 1000, seed: int = 0):
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(a), (resamples, len(a)))
    boots = [_auc(a[i]) - _auc(b[i]) for i in idx]
    return _auc(a) - _auc(b), *np.percentile(boots, [2.5, 97.5])


def main(argv: list[str] | None = None) -> int:
    import ablation_eval as ae
    import bench_pose as bp
    from strl_bench_common import banner

    from strl_pyg.estimation import line_refine as L
    from strl_pyg.frontend import FrontendConfig
    from strl_pyg.inference import POINT_POOR_MAX_POINTS
    from strl_pyg.inference.methods import vanishing_point as LM
    from strl_pyg.metrics.stats import median_ratio_interval
    from strl_pyg.model.strl_pose import StrLPose

    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "strl-pyg" / "eval_cache"),
                    help="front-end match cache (shared with benchmarks/ablation.py eval)")
    ap.add_argument("--point-poor", type=int, default=ae.POINT_POOR_PAIRS,
                    help="pairs of the generated point_poor set")
    ap.add_argument("--out", default=None, help="write the markdown table here")
    ap.add_argument("--fit", type=int, default=0, metavar="N",
                    help="first fit vp_checked's angle and slack on N calibration pairs and "
                         "print the grid (the package's constants are not changed: set them "
                         "in strl_pyg/inference/methods/vanishing_point.py)")
    ap.add_argument("--sets", default=",".join(SETS),
                    help=f"comma-separated sets to score, of {', '.join(SETS)} and "
                         "'calibration' (the --fit split: the evidence for an order)")
    args = ap.parse_args(argv)
    wanted = [x.strip() for x in args.sets.split(",") if x.strip()]
    unknown = [x for x in wanted if x not in (*SETS, *GENERATED, "calibration")]
    if unknown:
        ap.error(f"unknown set(s) {', '.join(unknown)} (expected some of "
                 f"{', '.join((*SETS, *GENERATED))}, calibration)")
    cache = Path(args.cache)
    fit_text = ""
    if args.fit:
        ang, slack, fit_text = fit(cache, args.fit)
        print(fit_text)
        checked = LM.VanishingPointChecked
        if (ang, slack) != (checked.angle_deg, checked.support_slack):
            print(f"note: the fit ({ang}, {slack}) differs from the package's "
                  f"({checked.angle_deg}, {checked.support_slack}); the evaluation uses "
                  "the fit: set the fitted constants in the package")
        LM.VanishingPointChecked.angle_deg, LM.VanishingPointChecked.support_slack = ang, slack
    few = FrontendConfig.preset("legacy", max_keypoints=ae.FEW_KEYPOINTS)
    load = {"point_poor": lambda: ae.point_poor_pairs(cache, args.point_poor),
            "kitti06_kp40": lambda: bp.kitti_pairs(1, cache, config=few),
            "demon_kp40": lambda: bp.demon_pairs(cache, config=few),
            "dino_kp40": lambda: bp.dino_pairs(cache, config=few),
            "kitti06": lambda: bp.kitti_pairs(1, cache),
            "demon": lambda: bp.demon_pairs(cache),
            "dino": lambda: bp.dino_pairs(cache),
            "calibration": lambda: ae.point_poor_pairs(cache, args.fit or 100,
                                                       seed0=CALIBRATION_SEED),
            **{g: (lambda g=g: bp.generated_pairs(g, ae.GENERATED_PAIRS, cache))
               for g in GENERATED}}
    sets = {k: load[k]() for k in wanted}
    sets = {k: v for k, v in sets.items() if v}
    model = StrLPose.from_pretrained()
    scores = {}
    for name, pairs in tqdm(sets.items(), desc="sets"):
        scores[name] = score_pairs(pairs, model)
    lines = ["# The vanishing-point solver where points are too few", "", "```", banner(),
             "```", "", "`python benchmarks/studies/bench_vanishing.py` (module docstring). AUC@20 "
             "(%) of max(rotation, translation) error, no pose (or a non-ok recommended "
             "pose) = 180 deg, [95 % bootstrap interval]; median max-error (deg) over the "
             "pairs with a pose, and how many of the pairs have one. Constants: "
             f"VP_LINE_SIGMA_PX {L.VP_LINE_SIGMA_PX}, VP_CHECK_ANGLE_DEG "
             f"{LM.VanishingPointChecked.angle_deg}, VP_CHECK_SUPPORT_SLACK "
             f"{LM.VanishingPointChecked.support_slack}.", "",
             "| set | pairs | " + " | ".join(METHODS) + " | "
             + " | ".join(f"{k} - PoseLib (AUC)" for k in RECOMMENDED) + " |",
             "|---|---" + "|---" * (len(METHODS) + len(RECOMMENDED)) + "|"]
    for name, sc in scores.items():
        cells = []
        for k in METHODS:
            w = _worst(sc[k])
            a, lo, hi = auc_interval(w)
            have = [max(r) for r in sc[k] if r is not None]
            med = f"{np.median(have):.1f}" if have else "-"
            cells.append(f"{a:.1f} [{lo:.1f}-{hi:.1f}]; med {med} ({len(have)})")
        diffs = []
        for k in RECOMMENDED:
            d, lo, hi = paired_auc_diff(_worst(sc[k]), _worst(sc["PoseLib"]))
            diffs.append(f"{d:+.1f} [{lo:+.1f}-{hi:+.1f}]")
        lines.append(f"| {name} | {len(sc['PoseLib'])} | " + " | ".join(cells)
                     + " | " + " | ".join(diffs) + " |")

    def counts(key):
        return "; ".join(f"{name}: " + ", ".join(f"{m} {c}" for m, c in zip(*np.unique(
            [str(x) for x in sc[key]], return_counts=True), strict=True))
            for name, sc in scores.items())

    lines += ["", "Target (b): median error of the recommended pose / PoseLib's, on the pairs both "
              "solved (n), rotation then translation direction, [95 % paired bootstrap]; "
              f"'point-poor': the pairs with <= {POINT_POOR_MAX_POINTS} point matches (where "
              "the point-poor order puts vp first).", "",
              "| set | point-poor | n | " + " | ".join(
                  f"{k} / PoseLib (rot; trans)" for k in ("recommended (points' order)",
                                                          "recommended")) + " |",
              "|---|---|---|---|---|"]
    for name, sc in scores.items():
        cells = []
        for k in ("recommended (points' order)", "recommended"):
            both = [(a, b) for a, b in zip(sc[k], sc["PoseLib"], strict=True)
                    if a is not None and b is not None]
            if len(both) < 3:
                cells.append("-")
                continue
            e = np.array(both, dtype=float)  # [n, 2 (method, PoseLib), 2 (rot, trans)]
            rot = median_ratio_interval(e[:, 0, 0], e[:, 1, 0])
            tra = median_ratio_interval(e[:, 0, 1], e[:, 1, 1])
            cells.append("; ".join(f"{r:.2f} [{lo:.2f}-{hi:.2f}]" for r, lo, hi in (rot, tra)))
        n_both = sum(a is not None and b is not None
                     for a, b in zip(sc["recommended"], sc["PoseLib"], strict=True))
        lines.append(f"| {name} | {sum(sc['point_poor'])} of {len(sc['PoseLib'])} | {n_both} | "
                     + " | ".join(cells) + " |")
    lines += ["", f"Which method gave the recommended pose: {counts('recommended_method')}.",
              "", f"Whose pose vp_checked gave: {counts('vp_checked_source')}."]
    if fit_text:
        lines += ["", "## The fit of vp_checked's two constants", "", fit_text]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
