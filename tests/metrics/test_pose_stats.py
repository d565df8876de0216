"""strl_pyg.metrics.stats: the one statistics function behind the training log's validation
metrics and the evaluation tables; both give the same numbers under their own key names."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from strl_pyg.evaluation.report import PairResult, _stats
from strl_pyg.metrics.stats import pose_error_stats
from strl_pyg.training.validation import _summary

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


def test_coverage_interval_known_answers_and_bad_input():
    from strl_pyg.metrics.stats import coverage_interval

    lo, hi = coverage_interval(30, 30)  # by hand: n/(n+z^2) = 30/33.8416
    assert hi == 1.0 and lo == pytest.approx(30 / (30 + 1.96**2), rel=1e-12)
    assert coverage_interval(0, 30)[0] == 0.0
    lo, hi = coverage_interval(15, 30)  # symmetric about 1/2
    assert lo + hi == pytest.approx(1.0, rel=1e-12) and 0.33 < lo < 0.34
    # the normal approximation for a large n
    lo, hi = coverage_interval(9500, 10000)
    half = 1.96 * math.sqrt(0.95 * 0.05 / 10000)
    assert (lo, hi) == pytest.approx((0.95 - half, 0.95 + half), abs=5e-4)
    for bad in ((31, 30), (-1, 30), (1, 0), (1.5, 30)):
        with pytest.raises(ValueError, match="Expected"):
            coverage_interval(*bad)


def test_median_ratio_interval_brackets_the_ratio_and_is_paired():
    from strl_pyg.metrics.stats import median_ratio_interval

    rng = np.random.default_rng(1)
    b = rng.gamma(2.0, 1.0, size=200)
    r, lo, hi = median_ratio_interval(1.5 * b, b)
    assert r == pytest.approx(1.5, rel=1e-12)
    assert lo == pytest.approx(1.5, rel=1e-12) and hi == pytest.approx(1.5, rel=1e-12)  # paired
    noisy = b * rng.uniform(0.8, 1.4, size=200)
    r, lo, hi = median_ratio_interval(noisy, b)
    assert lo < r < hi and hi - lo < 0.3
    assert median_ratio_interval(noisy, b) == median_ratio_interval(noisy, b)  # seeded
    assert median_ratio_interval([1.0], [0.0]) == (math.inf, math.inf, math.inf)  # no NaN
    r, lo, hi = median_ratio_interval([1.0, 2.0, 3.0], [0.0, 1.0, 1.0])
    assert r == 2.0 and lo <= r <= hi == math.inf and not math.isnan(lo)
    with pytest.raises(ValueError, match="one length"):
        median_ratio_interval([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="finite"):
        median_ratio_interval([1.0, math.nan], [1.0, 1.0])


def test_seeded_median_ratio_interval_holds_the_spread_between_seeds():
    from strl_pyg.metrics.stats import median_ratio_interval, seeded_median_ratio_interval

    rng = np.random.default_rng(3)
    b = rng.gamma(2.0, 1.0, size=(3, 120))
    # three identical seeds, a 1.5x b: the ratio is exact whatever is resampled
    same = np.repeat(b[:1], 3, axis=0)
    r, lo, hi = seeded_median_ratio_interval(1.5 * same, same)
    assert (r, lo, hi) == pytest.approx((1.5, 1.5, 1.5), rel=1e-12)
    # seed s of a 1.5x seed s of b, the seeds different: 1.5 inside an interval that the
    # independent draws of the two rows' seeds widen
    r, lo, hi = seeded_median_ratio_interval(1.5 * b, b)
    assert r == pytest.approx(1.5, rel=1e-12) and lo < 1.5 < hi
    # one seed each: the paired bootstrap over pairs alone (written out here)
    noisy = b[0] * rng.uniform(0.8, 1.4, size=120)
    idx = np.random.default_rng(0).integers(0, 120, size=(2000, 120))
    boot = np.median(noisy[idx], axis=1) / np.median(b[0][idx], axis=1)
    want = (np.median(noisy) / np.median(b[0]), *np.quantile(boot, [0.025, 0.975]))
    assert seeded_median_ratio_interval(noisy[None], b[:1]) == pytest.approx(want, rel=1e-12)
    assert median_ratio_interval(noisy, b[0]) == pytest.approx(want, rel=1e-12)
    # seeds of a at 0.6x, 1.0x and 1.4x of one b: on average equal; seed 0 alone says 0.6
    # with a degenerate interval, the seeds resampled give an interval around 1 this wide
    spread = np.stack([0.6 * b[0], b[0], 1.4 * b[0]])
    r, lo, hi = seeded_median_ratio_interval(spread, b[:1])
    assert r == pytest.approx(1.0, rel=1e-12)
    assert lo < 0.8 and hi > 1.2 and lo == pytest.approx(0.6, rel=0.05)
    assert median_ratio_interval(spread[0], b[0])[1:] == pytest.approx((0.6, 0.6))
    # the statistic: mean over the seeds of each seed's median
    r, _, _ = seeded_median_ratio_interval([[1.0, 2.0, 3.0], [3.0, 4.0, 5.0]],
                                           [[1.0, 1.0, 1.0]], resamples=10)
    assert r == pytest.approx(3.0)
    assert seeded_median_ratio_interval(spread, b) == seeded_median_ratio_interval(spread, b)
    with pytest.raises(ValueError, match="same pairs"):
        seeded_median_ratio_interval(b[:, :10], b[:, :11])
    with pytest.raises(ValueError, match="finite"):
        seeded_median_ratio_interval([[1.0, math.nan]], [[1.0, 1.0]])
    with pytest.raises(ValueError, match=r"shape \(seeds, n\)"):
        seeded_median_ratio_interval([1.0, 2.0], [[1.0, 2.0]])


def test_auc_difference_interval_sees_a_real_gain_and_not_a_tie():
    from strl_pyg.metrics.stats import auc_difference_interval
    from strl_pyg.metrics.two_view import pose_auc

    rng = np.random.default_rng(2)
    b = rng.gamma(2.0, 3.0, size=80)
    d, lo, hi = auc_difference_interval(0.5 * b, b)  # a halves every error: clearly better
    assert d == pytest.approx(pose_auc(0.5 * b, (10.0,))[0] - pose_auc(b, (10.0,))[0])
    assert 0 < lo <= d <= hi
    tie = b.copy()
    tie[0] *= 0.9  # one pair a little better: within the noise
    d, lo, hi = auc_difference_interval(tie, b)
    assert d >= 0 and lo <= 0 <= hi
    # failures count as beyond the threshold
    d, _, _ = auc_difference_interval([math.inf, 1.0], [math.nan, 1.0])
    assert d == 0.0
    with pytest.raises(ValueError, match="one length"):
        auc_difference_interval([1.0], [1.0, 2.0])
