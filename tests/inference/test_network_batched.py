"""The regression's swap check runs in the same batched forward pass as the pair: each half
of the batch equals the pair's own forward pass (the reference path)."""

from __future__ import annotations

import torch

from strl_pyg import PairMatches
from strl_pyg.inference import PoseEstimator
from strl_pyg.inference.network import network_pose, network_pose_both_ways
from strl_pyg.model.strl_pose import StrLPose
from strl_pyg.synthetic import generate_pair


def _pair():
    p = generate_pair(2_000_017)
    m = p.matches
    return PairMatches(m.points0, m.points1, m.lines0, m.lines1, K0=p.K, K1=p.K,
                       image0=p.image0, image1=p.image1)


def test_both_ways_in_one_pass_equals_two_passes():
    model = StrLPose.from_pretrained()
    m = _pair()
    fwd, back = network_pose_both_ways(model, m)
    ref_f, ref_b = network_pose(model, m), network_pose(model, m.swapped())
    for got, want in ((fwd, ref_f), (back, ref_b)):
        for key in ("quaternion", "translation", "log_var"):
            torch.testing.assert_close(getattr(got, key), getattr(want, key), atol=1e-4,
                                       rtol=1e-4)
    est = PoseEstimator(model, methods=("regression",)).estimate(m)
    info = est.methods["regression"].info
    assert "swap_disagreement_deg" in info and info["swap_disagreement_deg"]["rotation"] < 5
