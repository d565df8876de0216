"""Summary statistics of per-pair pose errors: the one implementation behind the training log's
validation metrics (:func:`strl_pyg.validation.evaluate_model`) and the evaluation tables
(:meth:`strl_pyg.evaluation.EvalReport.summary`), which only rename its keys.

Per pair the inputs are the rotation error and the translation-direction error in degrees
(:func:`~strl_pyg.metrics.relative_pose_error`) and whether the estimate succeeded; an estimate
without a finite rotation error (a non-finite prediction) counts as failed too. The statistics
are the number of failures, the mean and the median of each error over the other pairs (a
translation error that is ``NaN`` because the direction is undefined is left out of the
translation's), and the pose AUC (:func:`~strl_pyg.metrics.pose_auc`) of ``max(rotation,
translation)``, where a failure or a non-finite translation error counts as beyond every
threshold.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from strl_pyg.metrics import pose_auc

__all__ = ["AUC_THRESHOLDS", "pose_error_stats"]

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
