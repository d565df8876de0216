"""PyG's own module checks (``torch_geometric.testing.assert_module``) on our layers: output
shape, invariance to the order of the edges, and the same output for every sparse layout of
the adjacency (torch.sparse CSC / COO; torch_sparse where installed); plus the invariance to
the order of the nodes, which ``assert_module`` leaves unimplemented."""

from __future__ import annotations

import torch
from torch_geometric.testing import assert_module

from strl_pyg.nn import AttentionConv, LineEndpointConv

LAYOUTS = ["torch_sparse", torch.sparse_csc, torch.sparse_coo]


def permuted(conv, x, ei, **node_kw):
    """``conv`` on the same graph with its nodes renumbered, mapped back."""
    n = x.shape[0]
    perm = torch.randperm(n, generator=torch.Generator().manual_seed(1))
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(n)
    kw = {k: v[perm] for k, v in node_kw.items()}
    return conv(x[perm], inv[ei], **kw)[inv]


def test_attention_conv_passes_assert_module():
    torch.manual_seed(0)
    x = torch.randn(6, 16)
    ei = torch.tensor([[0, 1, 2, 3, 4, 5, 1, 0], [1, 0, 3, 2, 5, 4, 2, 5]])
    conv = AttentionConv(16, heads=2).eval()
    assert str(conv) == "AttentionConv(16, heads=2, mlp_ratio=2)"
    out = assert_module(conv, x, ei, expected_size=(6, 16), test_sparse_layouts=LAYOUTS,
                        atol=1e-5)
    torch.testing.assert_close(permuted(conv, x, ei), out, atol=1e-5, rtol=1e-5)
    # bipartite: 4 sources, 3 targets
    bi = torch.tensor([[0, 1, 2, 3, 3], [0, 0, 1, 2, 1]])
    conv2 = AttentionConv((8, 16), heads=2).eval()
    assert_module(conv2, (torch.randn(4, 8), torch.randn(3, 16)), bi, expected_size=(3, 16),
                  test_sparse_layouts=LAYOUTS, sparse_size=(4, 3), atol=1e-5)


def test_line_endpoint_conv_passes_assert_module():
    torch.manual_seed(0)
    x = torch.randn(9, 16)  # 3 lines' endpoints (0-5) and 3 nodes without lines
    ei = torch.tensor([[0, 1, 2, 3, 4, 5], [1, 0, 3, 2, 5, 4]])  # endpoints 2i <-> 2i+1
    conv = LineEndpointConv(16, line_channels=8).eval()
    line_feat = torch.randn(9, 8)
    out = assert_module(conv, x, ei, expected_size=(9, 16), test_sparse_layouts=LAYOUTS,
                        line_feat=line_feat, atol=1e-5)
    torch.testing.assert_close(permuted(conv, x, ei, line_feat=line_feat), out, atol=1e-5,
                               rtol=1e-5)
    torch.testing.assert_close(out[6:], x[6:])  # nodes without edges unchanged
