"""The network on a batch of pairs (strl_pyg.inference.network_poses): the same poses as one
pair at a time, the network's sigma in degrees, the inlier weights mapped to the input rows,
and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from strl_pyg.estimation.pose_fusion import network_covariance
from strl_pyg.geometry import tangent_basis
from strl_pyg.inference import network_pose, network_poses
from strl_pyg.model import PoseOutput, StrLPose


@pytest.fixture(scope="module")
def model():
    return StrLPose.from_pretrained()


@pytest.fixture(scope="module")
def pairs(generated_pair):
    return [generated_pair(seed).matches for seed in (2_000_017, 2_000_018)]


def test_a_batch_gives_the_poses_of_one_pair_at_a_time(model, pairs):
    batch = network_poses(model, pairs)
    assert batch.T_0to1.shape == (2, 4, 4) and batch.sigma_deg.shape == (2, 2)
    for i, m in enumerate(pairs):
        one = network_pose(model, m)
        np.testing.assert_allclose(batch.T_0to1[i], one.T_0to1[0].double().numpy(), atol=1e-6)
        np.testing.assert_allclose(batch.sigma_deg[i], one.sigma_deg[0].double().numpy(),
                                   rtol=1e-4)
        w, rows = batch.point_weights[i], batch.point_rows[i]
        assert w.shape == rows.shape and ((w >= 0) & (w <= 1)).all()
        assert rows.max() < m.num_points
        # the weights of pair i are its own graph's point logits
        logits = one.geometric.point_logits.double()
        np.testing.assert_allclose(w, torch.sigmoid(logits).numpy(), atol=1e-5)


def test_sigma_deg_is_the_trace_of_the_network_covariance():
    torch.manual_seed(0)
    q = torch.nn.functional.normalize(torch.randn(4, 4, dtype=torch.float64), dim=-1)
    t, lv = torch.randn(4, 3, dtype=torch.float64), torch.randn(4, 7, dtype=torch.float64)
    sig = PoseOutput(q, t, lv).sigma_deg
    for i in range(4):
        cov = network_covariance(q[i], t[i], lv[i], tangent_basis(t[i] / t[i].norm()))
        ref = np.degrees(np.sqrt([np.trace(cov[:3, :3]), np.trace(cov[3:, 3:])]))
        np.testing.assert_allclose(sig[i].numpy(), ref, rtol=1e-9)


def test_bad_batches_are_one_line_errors(model, pairs):
    with pytest.raises(TypeError, match="Expected a non-empty list of PairMatches"):
        network_poses(model, [])
    with pytest.raises(TypeError, match="Expected a non-empty list of PairMatches"):
        network_poses(model, [pairs[0], "pair.npz"])
    bare = pairs[0]._derived(image0=None, image1=None)
    with pytest.raises(ValueError, match="Expected images in the matches for a model with "
                                         "visual='pixel'"):
        network_poses(model, [bare])
