"""LineEndpointConv: the update rule, isolated nodes, bipartite inputs, validation."""

from __future__ import annotations

import pytest
import torch

from strl_pyg.nn import LineEndpointConv


def test_repr():
    assert repr(LineEndpointConv(32, 16)) == "LineEndpointConv(32, line_channels=16)"


def test_update_rule_by_hand():
    torch.manual_seed(0)
    conv = LineEndpointConv(8, 4).double()
    x = torch.randn(5, 8, dtype=torch.float64)
    f0 = torch.randn(5, 4, dtype=torch.float64)
    # Node 0 has two neighbours (mean), 1 and 2 one each, 3 and 4 none (unchanged).
    ei = torch.tensor([[1, 2, 0, 0], [0, 0, 1, 2]])
    out = conv(x, ei, f0)
    F = conv.mlp
    exp0 = x[0] + 0.5 * (F(torch.cat([x[0], x[1], f0[1]])) + F(torch.cat([x[0], x[2], f0[2]])))
    exp1 = x[1] + F(torch.cat([x[1], x[0], f0[0]]))
    torch.testing.assert_close(out[0], exp0)
    torch.testing.assert_close(out[1], exp1)
    torch.testing.assert_close(out[3:], x[3:])


def test_line_pairs_and_gradients():
    torch.manual_seed(1)
    conv = LineEndpointConv(16, 8)
    n_lines = 3
    src = torch.arange(2 * n_lines)
    ei = torch.stack([src, src ^ 1])
    x = torch.randn(2 * n_lines, 16, requires_grad=True)
    f0 = torch.randn(2 * n_lines, 8, requires_grad=True)
    out = conv(x, ei, f0)
    out.square().sum().backward()
    assert x.grad.abs().sum() > 0 and f0.grad.abs().sum() > 0
    assert all(p.grad is not None for p in conv.parameters())
    # Swapping the two endpoints of every line permutes the output the same way.
    perm = src ^ 1
    torch.testing.assert_close(conv(x[perm], ei, f0[perm]), out[perm])


def test_bipartite_and_validation():
    torch.manual_seed(2)
    conv = LineEndpointConv((6, 10), 3)
    x_src, x_dst, f0 = torch.randn(4, 6), torch.randn(2, 10), torch.randn(4, 3)
    ei = torch.tensor([[0, 3], [1, 1]])
    out = conv((x_src, x_dst), ei, f0)
    assert out.shape == (2, 10)
    torch.testing.assert_close(out[0], x_dst[0])
    with pytest.raises(ValueError, match="Expected one line feature per source node"):
        conv((x_src, x_dst), ei, f0[:3])


def test_widths_are_checked_at_construction_and_call():
    # reproduction: (-1, 16) built a Linear for width -1 + 16 + 4 that no input could match,
    # and 0 channels were accepted
    for bad in ((-1, 16), -1, 0, (8, 0)):
        with pytest.raises(ValueError, match="Expected .*channels as a positive int"):
            LineEndpointConv(bad, 4)
    with pytest.raises(ValueError, match="Expected line_channels as a positive int"):
        LineEndpointConv(8, 0)
    conv = LineEndpointConv(8, 4)
    ei = torch.tensor([[0, 1], [1, 0]])
    with pytest.raises(ValueError, match=r"Expected source features of shape \[N, 8\] "
                                         r"\(got \(2, 7\)\)"):
        conv(torch.randn(2, 7), ei, torch.randn(2, 4))
    with pytest.raises(ValueError, match=r"Expected line features of shape \[N, 4\]"):
        conv(torch.randn(2, 8), ei, torch.randn(2, 5))


def test_hetero_conv_on_an_edge_type_between_two_node_types():
    """Before: HeteroConv / to_hetero pass node-level arguments of an edge type whose source
    and target types differ as a (source, target) pair: "'tuple' object has no attribute
    'dim'". The source's line features are read; the result equals the bipartite call."""
    import torch
    from torch_geometric.nn import HeteroConv

    from strl_pyg.nn import LineEndpointConv

    torch.manual_seed(0)
    x = {"endpoint": torch.randn(6, 8), "point": torch.randn(4, 8)}
    line = {"endpoint": torch.randn(6, 5), "point": torch.randn(4, 5)}
    ei = torch.tensor([[0, 1, 2, 5], [0, 0, 3, 2]])
    conv = LineEndpointConv(8, 5)
    hetero = HeteroConv({("endpoint", "to", "point"): conv})
    out = hetero(x, {("endpoint", "to", "point"): ei}, line_feat_dict=line)
    ref = conv((x["endpoint"], x["point"]), ei, line["endpoint"])
    torch.testing.assert_close(out["point"], ref)
    with pytest.raises(ValueError, match="Expected line features of the source node type"):
        conv((x["endpoint"], x["point"]), ei, (None, line["point"]))
