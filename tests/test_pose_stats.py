"""strl_pyg.pose_stats: the one statistics function behind the training log's validation
metrics and the evaluation tables; both give the same numbers under their own key names."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from strl_pyg.eval_report import PairResult, _stats
from strl_pyg.pose_stats import pose_error_stats
from strl_pyg.validation import _summary

# four successful pairs; the second has an undefined translation direction (NaN)
ROT = [1.0, 2.0, 3.0, 10.0]
TRANS = [4.0, math.nan, 1.0, 30.0]
# by hand: max errors [4, inf, 3, 30]; recall polyline (0, 0), (3, 1/4), (4, 1/2), flat after
# AUC@5 = (0.375 + 0.375 + 0.5) / 5, AUC@10 = (1.25 + 5 * 0.5) / 10, AUC@20 = (1.25 + 15 * 0.5) / 20
EXPECTED = {"n": 4, "failures": 0, "rot_mean": 4.0, "rot_median": 2.5,  # mean of 2 and 3
            "trans_mean": 35.0 / 3.0, "trans_median": 4.0,
            "auc5": 0.25, "auc10": 0.375, "auc20": 0.4375}
VALIDATION_KEYS = {"rot_mean": "rot_err_deg", "rot_median": "rot_err_med",
                   "trans_mean": "trans_err_deg", "trans_median": "trans_err_med",
                   "auc5": "auc5", "auc10": "auc10", "auc20": "auc20",
                   "failures": "failures"}


def _rows(rot, trans, success=None):
    success = [True] * len(rot) if success is None else success
    return [PairResult(f"p{i}", "s", "m", r, t, 1.0, ok, np.eye(4))
            for i, (r, t, ok) in enumerate(zip(rot, trans, success, strict=True))]


def test_known_answer_and_numpy_reference():
    s = pose_error_stats(ROT, TRANS)
    assert list(s) == list(EXPECTED)
    assert s == pytest.approx(EXPECTED, rel=1e-12)
    rot, trans = np.array(ROT), np.array(TRANS)
    assert s["rot_median"] == np.median(rot) and s["trans_median"] == np.nanmedian(trans)
    assert s["trans_mean"] == pytest.approx(np.nanmean(trans), rel=1e-15)


def test_training_log_and_evaluation_table_give_the_same_numbers():
    """Before the shared function the training log's median was torch's lower median (2.0
    here) while the evaluation table's was numpy's (2.5)."""
    for prefix in ("", "trivial_", "geo_"):
        logged = _summary(torch.tensor(ROT), torch.tensor(TRANS), prefix)
        assert list(logged) == [f"{prefix}{k}" for k in VALIDATION_KEYS.values()]  # log.csv
        for ours, theirs in VALIDATION_KEYS.items():
            assert logged[prefix + theirs] == pytest.approx(EXPECTED[ours], rel=1e-12), theirs
    table = _stats(_rows(ROT, TRANS))
    assert table == pytest.approx({**EXPECTED, "time_ms": 1.0}, rel=1e-12)
    # float32 tensors (the model's errors) give the same statistics
    logged32 = _summary(torch.tensor(ROT, dtype=torch.float32),
                        torch.tensor(TRANS, dtype=torch.float32), "")
    assert logged32["rot_err_med"] == 2.5 and logged32["auc10"] == 0.375


def test_failures_leave_the_means_and_count_as_infinite():
    rot, trans = ROT + [math.nan], TRANS + [math.nan]
    s = _stats(_rows(rot, trans, [True] * 4 + [False]))
    # by hand with n = 5: max errors [3, 4, 30, inf, inf], steps of 1/5
    assert s["n"] == 5 and s["failures"] == 1
    assert s["rot_mean"] == 4.0 and s["rot_median"] == 2.5 and s["trans_median"] == 4.0
    assert (s["auc5"], s["auc10"], s["auc20"]) == pytest.approx((0.2, 0.3, 0.35), rel=1e-12)
    # a failure's errors are ignored even when finite; a NaN rotation is a failure too
    s2 = pose_error_stats(ROT + [0.0], TRANS + [0.0], [True] * 4 + [False])
    s3 = pose_error_stats(ROT + [math.nan], TRANS + [0.0])
    for other in (s2, s3):
        assert other["failures"] == 1 and other["rot_median"] == 2.5
        assert other["auc20"] == pytest.approx(0.35, rel=1e-12)


def test_training_log_counts_the_failures_it_leaves_out():
    """Before: a NaN network output left the validation means and medians without a trace in
    log.csv (the summary had no failure count); now ``failures`` says how many."""
    rot = torch.tensor(ROT + [math.nan, math.nan])
    trans = torch.tensor(TRANS + [math.nan, 5.0])
    logged = _summary(rot, trans, "geo_")
    assert logged["geo_failures"] == 2.0
    assert logged["geo_rot_err_med"] == 2.5  # the 4 finite pairs
    assert logged["geo_auc20"] == pytest.approx(0.4375 * 4 / 6, rel=1e-12)
    assert _summary(torch.tensor(ROT), torch.tensor(TRANS), "")["failures"] == 0.0


def test_all_failed_gives_nan_statistics_and_zero_auc():
    s = pose_error_stats([math.nan, 1.0], [math.nan, 2.0], [False, False])
    assert s["failures"] == 2 and math.isnan(s["rot_mean"]) and math.isnan(s["trans_median"])
    assert s["auc5"] == s["auc20"] == 0.0


def test_other_thresholds_name_their_keys():
    s = pose_error_stats([1.0], [1.0], thresholds=(2.5, 30.0))
    assert list(s)[-2:] == ["auc2.5", "auc30"]


@pytest.mark.parametrize("args, exc, match", [
    (([1.0, 2.0], [1.0]), ValueError, "Expected rot_err, trans_err and success of one length"),
    (([1.0], [1.0], [True, False]), ValueError, "of one length"),
    (([], []), ValueError, "Expected at least one pose error"),
    (([[1.0]], [[1.0]]), ValueError, r"Expected rot_err of shape \(n,\)"),
    ((["a"], [1.0]), TypeError, "Expected rot_err as numbers"),
    (([-1.0], [1.0]), ValueError, "Expected non-negative errors"),
])
def test_bad_input_gets_a_one_line_error(args, exc, match):
    with pytest.raises(exc, match=match):
        pose_error_stats(*args)
