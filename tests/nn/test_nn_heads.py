"""WeightedFusion pooling and the output heads (PoseHead, InlierHead)."""

from __future__ import annotations

import pytest
import torch

from strl_pyg.nn import InlierHead, PoseHead, WeightedFusion, reset_mlp


def test_pose_head_starts_at_the_identity_rotation_after_its_own_reset():
    """The identity-rotation bias is the head's own initialisation: resetting the head alone
    (not only the whole model) adds it, once per reset, never twice."""
    head = PoseHead(32, 32)
    for _ in range(2):
        torch.manual_seed(0)
        head.reset_parameters()
        with_offset = head.pose_mlp[-1].bias.detach().clone()
        torch.manual_seed(0)
        reset_mlp(head.pose_mlp)  # the same draws, without the head's own initialisation
        plain = head.pose_mlp[-1].bias.detach()
        torch.testing.assert_close(with_offset - plain, torch.tensor([1.0, 0, 0, 0, 0, 0, 0]))
    head.reset_parameters()
    assert torch.equal(head.var_mlp[-1].bias, torch.zeros(7))  # near unit variance at start
    assert head.var_mlp[-1].weight.abs().max() < 0.01
    q, t, _ = head(torch.randn(64, 32))
    assert q[:, 0].mean() > q[:, 1:].abs().mean(0).max()  # w dominates: near the identity
    torch.testing.assert_close(t.norm(dim=-1), torch.ones(64))


def test_pose_head_normalises_and_canonicalises():
    head = PoseHead(8, 16)
    with torch.no_grad():
        head.pose_mlp[-1].weight.zero_()
        head.pose_mlp[-1].bias.copy_(torch.tensor([-2.0, 0, 0, 0, 3, 0, 4]))
    q, t, log_var = head(torch.randn(2, 8))
    torch.testing.assert_close(q, torch.tensor([[1.0, 0, 0, 0]] * 2))  # w >= 0
    torch.testing.assert_close(t, torch.tensor([[0.6, 0, 0.8]] * 2))
    assert log_var.shape == (2, 7)
    metric = PoseHead(8, 16, translation="metric")
    with torch.no_grad():
        metric.pose_mlp[-1].weight.zero_()
        metric.pose_mlp[-1].bias.copy_(torch.tensor([1.0, 0, 0, 0, 3, 0, 4]))
    torch.testing.assert_close(metric(torch.randn(1, 8))[1], torch.tensor([[3.0, 0, 4]]))
    with pytest.raises(ValueError, match="Expected translation in"):
        PoseHead(8, 16, translation="scaled")


def test_weighted_fusion_pools_per_graph():
    fusion = WeightedFusion(4, 2, weighted=False)
    assert fusion.out_channels == 6 and not list(fusion.parameters())
    g, v = torch.arange(12.0).view(3, 4), torch.ones(3, 2)
    z = fusion(g, v, torch.tensor([0, 0, 2]), 3)
    torch.testing.assert_close(z[0], torch.tensor([2.0, 3, 4, 5, 1, 1]))
    torch.testing.assert_close(z[1], torch.zeros(6))  # a graph without nodes pools to zeros
    torch.testing.assert_close(z[2], torch.tensor([8.0, 9, 10, 11, 1, 1]))
    gated = WeightedFusion(4, 0)
    with torch.no_grad():
        gated.gate_geo.weight.zero_()
        gated.gate_geo.bias.fill_(100.0)  # gate 1
    torch.testing.assert_close(gated(g, None, None, 1), g.mean(0, keepdim=True))
    with pytest.raises(ValueError, match="visual node features"):
        WeightedFusion(4, 2)(g, None, None, 1)


def test_inlier_head_gives_one_logit_per_node():
    head = InlierHead(12, 8)
    assert head(torch.randn(5, 12)).shape == (5,)
    before = head[-1].weight.detach().clone()
    head.reset_parameters()
    assert not torch.equal(before, head[-1].weight)
