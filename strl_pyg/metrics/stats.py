"""Summary statistics of per-pair pose errors: the one implementation behind the training log's
validation metrics (:func:`strl_pyg.training.validation.evaluate_model`) and the evaluation tables
(:meth:`strl_pyg.evaluation.run.EvalReport.summary`), which only rename its keys.

Per pair the inputs are the rotation error and the translation-direction error in degrees
(:func:`~strl_pyg.metrics.relative_pose_error`) and whether the estimate succeeded; an estimate
without a finite rotation error (a non-finite prediction) counts as failed too. The statistics
are the number of failures, the mean and the median of each error over the other pairs (a
translation error that is ``NaN`` because the direction is undefined is left out of the
translation's), and the pose AUC (:func:`~strl_pyg.metrics.two_view.pose_auc`) of ``max(rotation,
translation)``, where a failure or a non-finite translation error counts as beyond every
threshold.

Small evaluation sets (30-50 pairs) make these figures noisy, so two intervals go with them:
:func:`coverage_interval` (Wilson score interval of a fraction of pairs, e.g. the pairs inside
their 2-sigma region) and :func:`median_ratio_interval` (paired bootstrap of the ratio of two
methods' median errors over the same pairs), :func:`seeded_median_ratio_interval` (the same
ratio for two trained rows of several seeds each, the seeds resampled with the pairs, so the
interval holds the seed-to-seed spread of training too), and :func:`auc_difference_interval`
(the difference of two methods' pose AUC).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from strl_pyg.metrics.two_view import pose_auc

__all__ = ["AUC_THRESHOLDS", "pose_error_stats", "coverage_interval", "median_ratio_interval",
           "seeded_median_ratio_interval", "auc_difference_interval", "roc_auc"]

#: Thresholds (degrees) of the pose AUC in the training log and the evaluation tables.
AUC_THRESHOLDS = (5.0, 10.0, 20.0)


def _vector(x: Any, name: str, dtype: type = np.float64) -> np.ndarray:
    if hasattr(x, "detach"):  # a torch tensor, without importing torch here
        x = x.detach().cpu().numpy()
    try:
        a = np.asarray(x, dtype=dtype)
    except (TypeError, ValueError):
        raise TypeError(f"Expected {name} as numbers of shape (n,) (got "
                        f"{type(x).__name__})") from None
    if a.ndim != 1:
        raise ValueError(f"Expected {name} of shape (n,) (got shape {a.shape})")
    return a


def _agg(fn: Any, a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(fn(a)) if a.size else float("nan")


def pose_error_stats(rot_err: Any, trans_err: Any, success: Any = None,
                     thresholds: Sequence[float] = AUC_THRESHOLDS) -> dict[str, float]:
    """Mean, median and AUC statistics of per-pair pose errors (module docstring).

    Args:
        rot_err: rotation errors in degrees, shape ``(n,)`` (array, list or tensor).
        trans_err: translation-direction errors in degrees, shape ``(n,)``; ``NaN`` where the
            direction is undefined (e.g. a zero translation).
        success: ``(n,)`` booleans, ``False`` for a failed estimate (its errors are left out of
            the means and medians and count as infinite in the AUC); default: all succeeded
            (the pairs with a non-finite rotation error are failures either way).
        thresholds: AUC thresholds in degrees (default :data:`AUC_THRESHOLDS`).

    Returns:
        ``{"n", "failures", "rot_mean", "rot_median", "trans_mean", "trans_median",
        "auc<t>" for each threshold t (``auc5``, ``auc10``, ``auc20``)}``, in that order; AUCs
        are fractions in ``[0, 1]``, a mean or median with no finite error to average is
        ``NaN``. The median of an even count is the mean of the two middle values.
    """
    rot = _vector(rot_err, "rot_err")
    trans = _vector(trans_err, "trans_err")
    ok = np.ones(rot.shape, bool) if success is None else _vector(success, "success", bool)
    if not (rot.shape == trans.shape == ok.shape):
        raise ValueError(f"Expected rot_err, trans_err and success of one length (got "
                         f"{rot.size}, {trans.size} and {ok.size})")
    if rot.size == 0:
        raise ValueError("Expected at least one pose error (got none)")
    for name, a in (("rot_err", rot), ("trans_err", trans)):
        if np.any(a[np.isfinite(a)] < 0):
            raise ValueError(f"Expected non-negative errors in {name} (got min {np.nanmin(a)})")
    ok = ok & np.isfinite(rot)  # no rotation error to score: a failed estimate
    worst = np.where(ok & np.isfinite(trans), np.maximum(rot, trans), np.inf)
    auc = pose_auc(worst, tuple(thresholds))
    return {
        "n": int(rot.size),
        "failures": int((~ok).sum()),
        "rot_mean": _agg(np.mean, rot[ok]),
        "rot_median": _agg(np.median, rot[ok]),
        "trans_mean": _agg(np.mean, trans[ok]),
        "trans_median": _agg(np.median, trans[ok]),
        **{f"auc{t:g}": float(a) for t, a in zip(thresholds, auc, strict=True)},
    }


def coverage_interval(hits: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval ``(low, high)`` of the fraction ``hits / n`` (default 95 %:
    ``z = 1.96``). Unlike the normal approximation it stays inside ``[0, 1]`` and is not
    empty at 0 or ``n`` hits: 30 of 30 pairs inside the 2-sigma region give ``(0.886, 1.0)``,
    consistent with a true 95 % coverage."""
    if not (isinstance(n, (int, np.integer)) and n > 0):
        raise ValueError(f"Expected a positive number of pairs n (got {n!r})")
    if not (isinstance(hits, (int, np.integer)) and 0 <= hits <= n):
        raise ValueError(f"Expected hits as an integer in [0, {n}] (got {hits!r})")
    if not z > 0:
        raise ValueError(f"Expected z > 0 (got {z})")
    p = hits / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return float(max(centre - half, 0.0)), float(min(centre + half, 1.0))


def median_ratio_interval(a: Any, b: Any, level: float = 0.95, resamples: int = 2000,
                          seed: int = 0) -> tuple[float, float, float]:
    """``median(a) / median(b)`` of paired per-pair errors and its percentile bootstrap
    interval at ``level`` (pairs resampled with replacement, the same indices for both).

    Args:
        a, b: errors of two methods on the same pairs, shape ``(n,)``, finite and
            non-negative (drop the pairs where either failed first).
        level: coverage of the interval, in ``(0, 1)``.
        resamples: bootstrap resamples (default 2000).
        seed: of the resampling (the interval is reproducible).

    Returns:
        ``(ratio, low, high)``; ``inf`` where a median of ``b`` is 0.
    """
    x, y = _vector(a, "a"), _vector(b, "b")
    if x.shape != y.shape:
        raise ValueError(f"Expected a and b of one length (got {x.size} and {y.size})")
    # one seed per row: the same resamples and checks as the seeds' version
    return seeded_median_ratio_interval(x[None], y[None], level, resamples, seed)


def seeded_median_ratio_interval(a: Any, b: Any, level: float = 0.95, resamples: int = 2000,
                                 seed: int = 0) -> tuple[float, float, float]:
    """Ratio of two trained rows' median errors over the same pairs, each row trained with
    several seeds, and its two-level percentile bootstrap interval at ``level``.

    The statistic is ``mean_s median_i a[s, i] / mean_s median_i b[s, i]``: the mean over a
    row's seeds of its median error. Each resample draws the pairs with replacement (the same
    indices for both rows and all their seeds: paired) and, independently for each row, its
    seeds with replacement, so an interval that excludes 1 says the rows differ beyond both the
    pairs' sampling noise and the spread between training seeds. With one seed per row it is
    :func:`median_ratio_interval` (the same resampled pairs for the same ``seed``).

    Args:
        a, b: per-pair errors of the two rows, shape ``(seeds_a, n)`` and ``(seeds_b, n)``
            (the seeds may differ in number, the pairs may not), finite and non-negative (drop
            the pairs where any run failed first).
        level, resamples, seed: as in :func:`median_ratio_interval`.

    Returns:
        ``(ratio, low, high)``; ``inf`` where the median of ``b`` is 0.
    """
    x, y = (_matrix(v, name) for v, name in ((a, "a"), (b, "b")))
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"Expected a and b over the same pairs (got {x.shape[1]} and "
                         f"{y.shape[1]} pairs)")
    if x.shape[1] == 0:
        raise ValueError("Expected at least one pair (got none)")
    if not (np.isfinite(x).all() and np.isfinite(y).all()) or (x < 0).any() or (y < 0).any():
        raise ValueError("Expected finite, non-negative errors in a and b (drop failed pairs)")
    if not 0 < level < 1:
        raise ValueError(f"Expected level in (0, 1) (got {level})")
    if not (isinstance(resamples, (int, np.integer)) and resamples >= 1):
        raise ValueError(f"Expected resamples >= 1 (got {resamples!r})")

    def ratio(mx: np.ndarray, my: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(my > 0, mx / np.where(my > 0, my, 1.0), np.inf)

    rng = np.random.default_rng(seed)
    n = x.shape[1]
    idx = rng.integers(0, n, size=(resamples, n))
    # [resamples, seeds]: each seed's median over the resampled pairs
    med_x = np.median(x[:, idx], axis=2).T
    med_y = np.median(y[:, idx], axis=2).T
    pick_x = rng.integers(0, x.shape[0], size=(resamples, x.shape[0]))
    pick_y = rng.integers(0, y.shape[0], size=(resamples, y.shape[0]))
    rows = np.arange(resamples)[:, None]
    boot = ratio(med_x[rows, pick_x].mean(axis=1), med_y[rows, pick_y].mean(axis=1))
    if np.isfinite(boot).all():
        lo, hi = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
    else:  # no interpolation between an infinite ratio and another (inf - inf)
        lo = np.quantile(boot, (1 - level) / 2, method="lower")
        hi = np.quantile(boot, (1 + level) / 2, method="higher")
    r = float(ratio(np.median(x, axis=1).mean(), np.median(y, axis=1).mean()))
    return r, float(lo), float(hi)


def _matrix(x: Any, name: str) -> np.ndarray:
    try:
        m = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"Expected {name} as numbers of shape (seeds, n) (got "
                        f"{type(x).__name__})") from None
    if m.ndim != 2 or m.shape[0] == 0:
        raise ValueError(f"Expected {name} of shape (seeds, n) with at least one seed (got "
                         f"shape {m.shape})")
    return m


def auc_difference_interval(worst_a: Any, worst_b: Any, threshold: float = 10.0,
                            level: float = 0.95, resamples: int = 2000,
                            seed: int = 0) -> tuple[float, float, float]:
    """``AUC_a - AUC_b`` at ``threshold`` degrees of two methods' per-pair errors on the same
    pairs, with its percentile paired-bootstrap interval at ``level``.

    Args:
        worst_a, worst_b: per-pair ``max(rotation, translation)`` errors in degrees, shape
            ``(n,)``; ``inf`` or ``NaN`` for a failed pair (beyond every threshold).
        threshold, level, resamples, seed: as in :func:`median_ratio_interval`.

    Returns:
        ``(difference, low, high)`` in AUC units (fractions); ``low > 0``: ``a`` is better
        beyond the sampling noise of these pairs.
    """
    x, y = _vector(worst_a, "worst_a"), _vector(worst_b, "worst_b")
    if x.shape != y.shape:
        raise ValueError(f"Expected worst_a and worst_b of one length (got {x.size} and "
                         f"{y.size})")
    if x.size == 0:
        raise ValueError("Expected at least one pair (got none)")
    if not 0 < level < 1:
        raise ValueError(f"Expected level in (0, 1) (got {level})")
    if not (isinstance(resamples, (int, np.integer)) and resamples >= 1):
        raise ValueError(f"Expected resamples >= 1 (got {resamples!r})")
    x, y = np.where(np.isfinite(x), x, np.inf), np.where(np.isfinite(y), y, np.inf)

    def auc(e: np.ndarray) -> float:
        return pose_auc(e, (threshold,))[0]

    idx = np.random.default_rng(seed).integers(0, x.size, size=(resamples, x.size))
    boot = np.array([auc(x[i]) - auc(y[i]) for i in idx])
    lo, hi = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
    return float(auc(x) - auc(y)), float(lo), float(hi)


def roc_auc(score: Any, label: Any) -> float:
    """The ROC-AUC of ``score`` ``(n,)`` against the bool ``label`` ``(n,)``: the chance that a
    positive scores above a negative, ties counting half (the Mann-Whitney statistic from
    average ranks); NaN where only one class is present."""
    s = _vector(score, "score")
    y = np.asarray(label, dtype=bool).reshape(-1)
    if s.shape != y.shape:
        raise ValueError(f"Expected score and label of one length (got {s.size} and {y.size})")
    npos, nneg = int(y.sum()), int((~y).sum())
    if npos == 0 or nneg == 0:
        return float("nan")
    order = np.argsort(s, kind="mergesort")
    _, first, counts = np.unique(s[order], return_index=True, return_counts=True)
    ranks = np.empty(len(s))
    ranks[order] = np.repeat(first + (counts + 1) / 2.0, counts)
    return float((ranks[y].sum() - npos * (npos + 1) / 2) / (npos * nneg))
