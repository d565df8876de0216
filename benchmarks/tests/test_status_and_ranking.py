"""Helpers of bench_status.py and bench_inlier_ranking.py: the rule a refusal names, the
neighbourhood-consensus score and the ROC-AUC, on known answers."""

from __future__ import annotations

import bench_inlier_ranking as bir
import bench_status as bs
import numpy as np


def test_each_refusal_names_its_rule():
    assert bs.rule_of("poselib bootstrap: 3 of 8 resamples found another pose") == "bootstrap"
    assert bs.rule_of("12 of 40 point matches lie behind a camera (more than 10 %)") == \
        "cheirality"
    assert bs.rule_of("two motions (COLMAP's MULTIPLE): 80 of the 199 matches") == "multiple"
    assert bs.rule_of("a watermark (COLMAP's WATERMARK): 40 of the pose's inliers") == \
        "watermark"
    assert bs.rule_of("something new") == "other"
    assert bs.rules_of({"status": "failed", "rules": []}) == ["no pose (failed)"]
    assert bs.rules_of({"status": "unreliable", "rules": ["other"],
                        "reasons": ["two motions (COLMAP's MULTIPLE): 8 of 9"]}) == ["multiple"]


def test_perturbed_intrinsics():
    from strl_pyg import PairMatches

    K = np.array([[500.0, 0, 320], [0, 510.0, 240], [0, 0, 1]])
    m = PairMatches(np.zeros((8, 2)) + 5, np.zeros((8, 2)) + 6, K0=K, K1=K,
                    image_size0=(480, 640), image_size1=(480, 640))
    assert bs.perturbed(m, "f/2").K0[0, 0] == 250 and bs.perturbed(m, "2f").K1[1, 1] == 1020
    sw = bs.perturbed(m, "swap").K0
    assert (sw[0, 2], sw[1, 2]) == (240, 320)
    assert bs.perturbed(m, "true") is m


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
