"""Helpers of bench_status.py and bench_inlier_ranking.py: the rule a refusal names, the
neighbourhood-consensus score and the ROC-AUC, on known answers."""

from __future__ import annotations

import bench_inlier_ranking as bir
import bench_status as bs
import numpy as np
import pytest


def test_each_refusal_names_its_rule():
    """The rule is the record's own (no warning text is matched)."""
    assert bs.rules_of({"status": "ok", "rule": None}) == []
    assert bs.rules_of({"status": "unreliable", "rule": "multiple"}) == ["multiple"]
    assert bs.rules_of({"status": "failed", "rule": "support"}) == ["support"]
    assert bs.rules_of({"status": "failed", "rule": None}) == ["unnamed"]


def test_replaying_multiple_refuses_only_ok_poses_from_the_share():
    def row(status, share, repeated=False):
        return {"status": status, "rule": None, "rec": 2.0 if status == "ok" else 180.0,
                "refused": None, "sigma": [1.0, 2.0], "sigma_with_focal": [1.0, 2.0],
                "verdicts": [{"rule": "multiple", "action": "reported", "status": "ok",
                              "evidence": {"share": share, "repeated_structure": repeated}}]}

    out = bs.replay_multiple([row("ok", 0.5), row("ok", 0.1), row("ok", 0.9, True),
                              row("unreliable", 0.9)], 0.2)
    assert [r["status"] for r in out] == ["unreliable", "ok", "ok", "unreliable"]
    assert out[0]["rule"] == "multiple" and out[0]["refused"] == 2.0 and out[0]["rec"] == 180.0
    assert out[3]["rule"] is None  # refused by another rule before: left as it was


def test_perturbed_intrinsics():
    from strl_pyg import PairMatches

    K = np.array([[500.0, 0, 320], [0, 510.0, 240], [0, 0, 1]])
    m = PairMatches(np.zeros((8, 2)) + 5, np.zeros((8, 2)) + 6, K0=K, K1=K,
                    image_size0=(480, 640), image_size1=(480, 640))
    assert bs.perturbed(m, "f/2").K0[0, 0] == 250 and bs.perturbed(m, "2f").K1[1, 1] == 1020
    sw = bs.perturbed(m, "swap").K0
    assert (sw[0, 2], sw[1, 2]) == (240, 320)
    assert bs.perturbed(m, "true") is m
    with pytest.raises(ValueError, match="Expected a variant among"):
        bs.perturbed(m, "half")
    with pytest.raises(SystemExit):
        bs.main(["run", "--variants", "true,half", "--out", "/nonexistent"])


def test_consensus_of_one_motion_and_of_random_matches():
    rng = np.random.default_rng(0)
    p0 = rng.uniform(0, 500, (200, 2))
    assert np.all(bir.consensus(p0, p0 + [7.0, -3.0]) == 1.0)  # neighbours move together
    shuffled = bir.consensus(p0, rng.permutation(p0))
    assert np.median(shuffled) < 0.2


def test_roc_auc_known_answers():
    y = np.array([True, True, False, False])
    assert bir.roc_auc(np.array([0.9, 0.8, 0.1, 0.2]), y) == 1.0
    assert bir.roc_auc(np.array([0.1, 0.2, 0.9, 0.8]), y) == 0.0
    assert bir.roc_auc(np.ones(4), y) == 0.5
    assert np.isnan(bir.roc_auc(np.ones(4), np.ones(4, bool)))
