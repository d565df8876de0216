"""AttentionConv: the dense fast path against explicit-edge message passing and a naive loop."""

from __future__ import annotations

import math

import pytest
import torch

from strl_pyg.data import CompleteEdges
from strl_pyg.nn import DenseLayout
from strl_pyg.nn.attention import AttentionConv


def complete_edges(b_src: torch.Tensor, b_dst: torch.Tensor) -> torch.Tensor:
    """Reference complete bipartite edges (j, i) with equal graph ids; any batch order."""
    j, i = torch.nonzero(b_src[:, None] == b_dst[None, :], as_tuple=True)
    return torch.stack([j, i])


def naive_messages(conv: AttentionConv, x_src, x_dst, edge_index, query=None) -> torch.Tensor:
    """Eq. 10 by a loop over target nodes and heads, for the math itself."""
    g = x_dst if query is None else query
    H, D = conv.heads, conv.head_dim
    q = conv.lin_q(g).view(-1, H, D)
    k = conv.lin_k(x_src).view(-1, H, D)
    v = conv.lin_v(x_src).view(-1, H, D)
    m = torch.zeros(x_dst.shape[0], H, D, dtype=x_dst.dtype)
    for i in range(x_dst.shape[0]):
        js = edge_index[0, edge_index[1] == i]
        if js.numel() == 0:
            continue
        for h in range(H):
            a = torch.softmax(k[js, h] @ q[i, h] / math.sqrt(D), dim=0)
            m[i, h] = a @ v[js, h]
    m = conv.lin_out(m.view(-1, H * D))
    return x_dst + conv.update_mlp(torch.cat([x_dst, m], -1))


def run_both(conv, x, batch, query=None):
    """Outputs and gradients (inputs and parameters) of the dense and the explicit path."""
    results = []
    x_src, x_dst = x if isinstance(x, tuple) else (x, x)
    b_src, b_dst = batch if isinstance(batch, tuple) else (batch, batch)
    ei = complete_edges(b_src, b_dst)
    for edge_index in (CompleteEdges(), ei):
        conv.zero_grad()
        xs = x_src.detach().clone().requires_grad_()
        xd = xs if x_src is x_dst else x_dst.detach().clone().requires_grad_()
        qq = None if query is None else query.detach().clone().requires_grad_()
        inp = xs if x_src is x_dst else (xs, xd)
        out = conv(inp, edge_index, batch, query=qq)
        (out * torch.linspace(-1, 1, out.numel(), dtype=out.dtype).view_as(out)).sum().backward()
        grads = [xs.grad, xd.grad] + ([qq.grad] if qq is not None else [])
        grads += [p.grad.clone() for p in conv.parameters()]
        results.append((out.detach(), grads))
    return results


def assert_paths_agree(results, atol):
    (out_d, g_d), (out_e, g_e) = results
    torch.testing.assert_close(out_d, out_e, atol=atol, rtol=atol)
    for a, b in zip(g_d, g_e, strict=True):
        torch.testing.assert_close(a, b, atol=atol, rtol=atol)


def test_repr_and_heads_check():
    assert repr(AttentionConv(32, heads=4)) == "AttentionConv(32, heads=4, mlp_ratio=2)"
    assert repr(AttentionConv((16, 32), heads=2)) == "AttentionConv((16, 32), heads=2, mlp_ratio=2)"
    with pytest.raises(ValueError, match="Expected heads to divide"):
        AttentionConv(30, heads=4)


def test_explicit_path_matches_naive_loop_on_sparse_graph():
    torch.manual_seed(0)
    conv = AttentionConv(16, heads=2).double()
    x = torch.randn(7, 16, dtype=torch.float64)
    # Arbitrary sparse graph, node 6 has no incoming edge (message 0).
    ei = torch.tensor([[0, 1, 2, 3, 4, 5, 0, 2, 6], [1, 0, 0, 2, 2, 2, 3, 4, 5]])
    torch.testing.assert_close(conv(x, ei), naive_messages(conv, x, x, ei))


@pytest.mark.parametrize("dtype,atol", [(torch.float32, 1e-5), (torch.float64, 1e-10)])
def test_dense_matches_explicit_uneven_unsorted_batch(dtype, atol):
    torch.manual_seed(1)
    conv = AttentionConv(32, heads=4).to(dtype)
    sizes = [5, 1, 9, 3]
    batch = torch.repeat_interleave(torch.arange(4), torch.tensor(sizes))
    perm = torch.randperm(batch.numel())
    batch = batch[perm]  # unsorted: the dense path must sort and unsort
    x = torch.randn(batch.numel(), 32, dtype=dtype)
    assert_paths_agree(run_both(conv, x, batch), atol)


def test_dense_matches_explicit_single_node_graphs():
    torch.manual_seed(2)
    conv = AttentionConv(16, heads=2)
    batch = torch.arange(3)
    x = torch.randn(3, 16)
    assert_paths_agree(run_both(conv, x, batch), 1e-5)
    # One node attends only to itself: the message is its own value.
    one = conv(x[:1], complete=True)
    ref = naive_messages(conv, x[:1], x[:1], torch.tensor([[0], [0]]))
    torch.testing.assert_close(one, ref)


def test_dense_matches_explicit_bipartite_with_empty_source_graph():
    torch.manual_seed(3)
    conv = AttentionConv((8, 16), heads=4)
    b_src = torch.tensor([0, 0, 2, 2, 2, 3])  # graph 1 has no source nodes
    b_dst = torch.tensor([0, 1, 1, 2, 3, 3, 3])
    x_src, x_dst = torch.randn(6, 8), torch.randn(7, 16)
    results = run_both(conv, (x_src, x_dst), (b_src, b_dst))
    assert_paths_agree(results, 1e-5)
    out = results[0][0]
    assert torch.isfinite(out).all()
    # Nodes of graph 1 receive message 0.
    zero_msg = conv.lin_out(torch.zeros(1, 16))
    expected = x_dst[1:3] + conv.update_mlp(torch.cat([x_dst[1:3], zero_msg.expand(2, 16)], -1))
    torch.testing.assert_close(out[1:3], expected.detach())


def test_dense_with_query_matches_explicit():
    torch.manual_seed(4)
    conv = AttentionConv(16, heads=2)
    batch = torch.tensor([1, 0, 0, 1, 1, 2, 0])
    x, g = torch.randn(7, 16), torch.randn(7, 16)
    assert_paths_agree(run_both(conv, (x, x.clone()), batch, query=g), 1e-5)
    ei = complete_edges(batch, batch)
    torch.testing.assert_close(conv((x, x), ei, query=g), naive_messages(conv, x, x, ei, g))


def test_no_source_nodes_at_all():
    conv = AttentionConv((8, 16), heads=2)
    x_src = torch.zeros(0, 8, requires_grad=True)
    x_dst = torch.randn(3, 16, requires_grad=True)
    batch = (torch.zeros(0, dtype=torch.long), torch.tensor([0, 0, 1]))
    dense = conv((x_src, x_dst), None, batch, complete=True)
    explicit = conv((x_src, x_dst), torch.zeros(2, 0, dtype=torch.long), batch)
    torch.testing.assert_close(dense, explicit)
    dense.sum().backward()
    assert torch.isfinite(x_dst.grad).all()


def test_mask_blocks_attention_across_graphs():
    """Changing graph 1's nodes must not change graph 0's outputs (padding/mask honoured)."""
    torch.manual_seed(5)
    conv = AttentionConv(16, heads=4)
    batch = torch.tensor([0, 0, 0, 1, 1, 1, 1, 1])
    x = torch.randn(8, 16)
    x2 = x.clone()
    x2[3:] = 100 * torch.randn(5, 16)
    out, out2 = conv(x, None, batch, complete=True), conv(x2, CompleteEdges(batch))
    torch.testing.assert_close(out[:3], out2[:3])
    assert not torch.allclose(out[3:], out2[3:])
    # Graph 0 alone gives the same as graph 0 inside the batch (padded keys carry no weight).
    torch.testing.assert_close(conv(x[:3], complete=True), out[:3], atol=1e-6, rtol=1e-6)


def test_reset_parameters_reinitialises():
    conv = AttentionConv(16, heads=2)
    before = [p.detach().clone() for p in conv.parameters()]
    conv.reset_parameters()
    changed = [not torch.equal(a, b) for a, b in zip(before, conv.parameters(), strict=True)]
    assert sum(changed) >= 4  # every linear weight; LayerNorm defaults are constants


# -------------------------------------------------------------------------- complete-attention API
def test_missing_edge_index_is_an_error_not_complete_attention():
    """The reproduced bug: ``conv(x, None)`` (a forgotten edge_index) meant complete attention."""
    conv = AttentionConv(16, heads=2)
    x = torch.randn(5, 16)
    batch = torch.zeros(5, dtype=torch.long)
    for call in (lambda: conv(x, None), lambda: conv(x), lambda: conv(x, None, batch)):
        with pytest.raises(ValueError, match=r"Expected an edge_index \[2, E\].*complete=True"):
            call()
    with pytest.raises(ValueError, match="edge_index=None with complete=True"):
        conv(x, complete_edges(torch.zeros(5).long(), torch.zeros(5).long()), complete=True)


def test_complete_edges_marker_carries_the_graph_ids():
    torch.manual_seed(6)
    conv = AttentionConv((8, 16), heads=2)
    b_src, b_dst = torch.tensor([0, 0, 1, 2, 2]), torch.tensor([0, 1, 1, 1, 2, 2])
    x_src, x_dst = torch.randn(5, 8), torch.randn(6, 16)
    ref = conv((x_src, x_dst), complete_edges(b_src, b_dst))
    for out in (conv((x_src, x_dst), CompleteEdges(b_src, b_dst)),
                conv((x_src, x_dst), CompleteEdges(b_src, b_dst), (b_src, b_dst)),
                conv((x_src, x_dst), CompleteEdges(), (b_src, b_dst)),
                conv((x_src, x_dst), None, (b_src, b_dst), complete=True)):
        torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)
    # marker and batch argument disagree, or ids of the wrong length: one-line errors
    with pytest.raises(ValueError, match="agree with the graph ids"):
        conv((x_src, x_dst), CompleteEdges(b_src, b_dst), (b_src, torch.zeros(6).long()))
    with pytest.raises(ValueError, match="one target graph id per target node"):
        conv((x_src, x_dst), CompleteEdges(b_src))  # batch_dst defaults to batch_src
    with pytest.raises(ValueError, match="one source graph id per source node"):
        conv((x_src, x_dst), None, (b_src[:4], b_dst), complete=True)
    with pytest.raises(ValueError, match="together with 'batch_dst'"):
        CompleteEdges(None, b_dst)
    with pytest.raises(TypeError, match="1-D long tensor"):
        CompleteEdges(b_src.float())
    assert repr(CompleteEdges(b_src, b_dst)) == "CompleteEdges(batch_src=[5], batch_dst=[6])"


# -------------------------------------------------------------------------- prebuilt layouts
def outputs_and_grads(conv, x_src, x_dst, query, call):
    """``call(conv, inp, query)`` on fresh leaf copies; its output and every gradient."""
    conv.zero_grad()
    xs = x_src.detach().clone().requires_grad_()
    xd = xs if x_dst is x_src else x_dst.detach().clone().requires_grad_()
    qq = None if query is None else query.detach().clone().requires_grad_()
    out = call(conv, xs if xd is xs else (xs, xd), qq)
    (out * torch.linspace(-1, 1, out.numel(), dtype=out.dtype).view_as(out)).sum().backward()
    grads = [xs.grad] + ([xd.grad] if xd is not xs else []) + ([qq.grad] if qq is not None else [])
    return out.detach(), grads + [p.grad.clone() for p in conv.parameters()]


@pytest.mark.parametrize("bipartite", [False, True])
def test_a_prebuilt_layout_agrees_with_graph_ids_and_explicit_edges(bipartite):
    """The fast path (a DenseLayout built once) against the graph-id path and message passing
    over explicit edges, outputs and gradients; unsorted, uneven graphs, one without nodes."""
    torch.manual_seed(7)
    conv = AttentionConv(16, heads=4).double()
    b_dst = torch.repeat_interleave(torch.tensor([0, 1, 3, 4]), torch.tensor([5, 1, 7, 2]))
    b_dst = b_dst[torch.randperm(b_dst.numel())]  # graph 2 has no nodes
    b_src = b_dst[torch.randperm(b_dst.numel())][:-3] if bipartite else b_dst
    x_dst = torch.randn(b_dst.numel(), 16, dtype=torch.float64)
    x_src = torch.randn(b_src.numel(), 16, dtype=torch.float64) if bipartite else x_dst
    query = torch.randn_like(x_dst)
    lay = (DenseLayout.from_batch(b_src, b_src.numel(), 5),
           DenseLayout.from_batch(b_dst, b_dst.numel(), 5))
    ei = complete_edges(b_src, b_dst)
    calls = [
        lambda c, x, q: c(x, CompleteEdges(), query=q, layout=lay if bipartite else lay[1]),
        lambda c, x, q: c(x, CompleteEdges(b_src, b_dst), query=q),
        lambda c, x, q: c(x, ei, query=q),
    ]
    ref = outputs_and_grads(conv, x_src, x_dst, query, calls[-1])
    for call in calls[:-1]:
        assert_paths_agree((outputs_and_grads(conv, x_src, x_dst, query, call), ref), 1e-10)


def test_dense_layout_blocks_and_errors():
    batch = torch.tensor([2, 0, 2, 2, 0])
    lay = DenseLayout.from_batch(batch, 5)
    assert (lay.num_graphs, lay.max_nodes) == (3, 3)
    assert lay.index.tolist() == [0, 0, 1, 2, 1]  # rank inside the graph, storage order
    assert lay.mask.tolist() == [[True, True, False], [False] * 3, [True] * 3]
    x = torch.arange(10.0).view(5, 2)
    dense = lay.to_dense(x)
    assert dense[2].tolist() == [[0, 1], [4, 5], [6, 7]] and dense[1].abs().sum() == 0
    assert torch.equal(lay.from_dense(dense), x)
    assert torch.equal(DenseLayout.single(5).to_dense(x)[0], x)
    assert DenseLayout.from_batch(batch[:0], 0, 2).max_nodes == 0
    assert repr(lay) == "DenseLayout(num_nodes=5, num_graphs=3, max_nodes=3)"
    with pytest.raises(ValueError, match=r"Expected graph ids in \[0, 2\)"):
        DenseLayout.from_batch(batch, 5, 2)
    with pytest.raises(ValueError, match="graph ids in"):
        DenseLayout.from_batch(batch - 1, 5)
    with pytest.raises(TypeError, match="1-D long tensor"):
        DenseLayout.from_batch(batch.float(), 5)
    with pytest.raises(ValueError, match="one graph id per node"):
        DenseLayout.from_batch(batch, 4)
    with pytest.raises(ValueError, match="Expected 5 node rows"):
        lay.to_dense(x[:4])


def test_layout_misuse_is_a_one_line_error():
    conv = AttentionConv(16, heads=2)
    x, batch = torch.randn(5, 16), torch.tensor([0, 0, 1, 1, 1])
    lay = DenseLayout.from_batch(batch, 5)
    with pytest.raises(ValueError, match="either a layout or graph ids"):
        conv(x, None, batch, complete=True, layout=lay)
    with pytest.raises(ValueError, match="either a layout or graph ids"):
        conv(x, CompleteEdges(batch), layout=lay)
    with pytest.raises(ValueError, match="only with complete attention"):
        conv(x, complete_edges(batch, batch), layout=lay)
    with pytest.raises(ValueError, match="target layout of 5 nodes"):
        conv(x, None, complete=True, layout=(lay, DenseLayout.from_batch(batch[:4], 4)))
    with pytest.raises(ValueError, match="as many graphs"):
        conv(x, None, complete=True, layout=(lay, DenseLayout.from_batch(batch, 5, 3)))
    with pytest.raises(TypeError, match="Expected a DenseLayout"):
        conv(x, None, complete=True, layout=batch)


@pytest.mark.slow  # a training run: the slow tier
def test_the_layout_path_does_not_break_a_compiled_graph():
    """No host synchronisation inside the layer once the layout is built: dynamo traces the
    dense path of an uneven batch as one graph (the graph-id path breaks it)."""
    torch.manual_seed(8)
    conv = AttentionConv(16, heads=2).eval()
    batch = torch.tensor([1, 0, 0, 1, 1, 2, 0])
    x, g = torch.randn(7, 16), torch.randn(7, 16)
    lay = DenseLayout.from_batch(batch, 7)
    torch._dynamo.reset()
    with torch.no_grad():
        fast = torch._dynamo.explain(conv)((x, x), None, query=g, complete=True, layout=lay)
        slow = torch._dynamo.explain(conv)((x, x), None, batch, query=g, complete=True)
    assert fast.graph_break_count == 0 and fast.graph_count == 1
    assert slow.graph_break_count >= 1


def test_another_aggregation_is_refused_not_computed_two_ways():
    # reproduction: aggr="mean" was accepted; the explicit path averaged the softmax-weighted
    # messages while complete attention summed them (outputs 0.27 apart), and asking for the
    # attention weights switched paths and so changed the output
    for aggr in ("mean", "max", "min"):
        with pytest.raises(ValueError, match="Expected aggr='add'"):
            AttentionConv(16, aggr=aggr)
    assert AttentionConv(16, aggr="add").aggr == "add"


@pytest.mark.parametrize("kwargs, match", [
    ({"heads": 0}, "Expected heads as a positive int"),
    ({"heads": 2.0}, "Expected heads as a positive int"),
    ({"dropout": 1.5}, r"Expected dropout in \[0, 1\)"),
    ({"dropout": -0.1}, r"Expected dropout in \[0, 1\)"),
    ({"mlp_ratio": 0}, "Expected mlp_ratio as a positive int"),
    ({"node_dim": -2}, "Expected no node_dim"),
])
def test_bad_construction_is_a_one_line_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        AttentionConv(16, **kwargs)


def test_feature_widths_are_checked_with_the_expected_shape():
    conv = AttentionConv(16, heads=4)
    ei = torch.tensor([[0, 1], [1, 0]])
    with pytest.raises(ValueError, match=r"Expected target features of shape \[N, 16\].*"
                                         r"\(got \(2, 8\)\)"):
        conv(torch.randn(2, 8), ei)
    lazy = AttentionConv((-1, 16), heads=4)
    out = lazy((torch.randn(3, 5), torch.randn(2, 16)), torch.tensor([[0, 2], [1, 0]]))
    assert out.shape == (2, 16)
    with pytest.raises(ValueError, match=r"Expected target features of shape \[N, 16\]"):
        lazy(torch.randn(3, 8), ei)  # homogeneous 8-wide input: the residual needs 16
    with pytest.raises(ValueError, match=r"Expected query features of shape \[N, 16\]"):
        conv(torch.randn(2, 16), ei, query=torch.randn(2, 4))


def test_complete_edges_marker_moves_like_a_tensor():
    b = torch.tensor([0, 0, 1])
    m = CompleteEdges(b, torch.tensor([0, 1]))
    moved = m.to("cpu")
    assert isinstance(moved, CompleteEdges) and moved is not m
    assert torch.equal(moved.batch_src, b) and torch.equal(moved.batch_dst, torch.tensor([0, 1]))
    assert CompleteEdges().to(torch.device("cpu")).batch_src is None
    edges = {("a", "to", "a"): m, ("a", "near", "a"): torch.tensor([[0], [1]])}
    assert set({k: v.to("cpu") for k, v in edges.items()}) == set(edges)


def _complete(bs, bd):
    from strl_pyg.data.pair_graph import complete_edge_index

    return complete_edge_index(bs, bd, int(max(bs.max(), bd.max())) + 1)


def test_attention_conv_lazy_channels_and_attention_weights():
    torch.manual_seed(0)
    lazy = AttentionConv((-1, 16), heads=2)
    xs, xd = torch.randn(5, 7), torch.randn(4, 16)
    bs, bd = torch.tensor([0, 0, 1, 1, 1]), torch.tensor([0, 0, 1, 1])
    dense = lazy((xs, xd), complete=True, batch=(bs, bd))
    assert lazy.lin_k.weight.shape == (16, 7)
    ei = _complete(bs, bd)
    sparse, (ei2, alpha) = lazy((xs, xd), ei, return_attention_weights=True)
    torch.testing.assert_close(dense, sparse, atol=1e-5, rtol=1e-5)
    assert torch.equal(ei2, ei) and alpha.shape == (ei.shape[1], 2)
    sums = torch.zeros(4, 2).index_add_(0, ei[1], alpha)
    torch.testing.assert_close(sums, torch.ones(4, 2))
    out, (ei3, alpha3) = lazy((xs, xd), complete=True, batch=(bs, bd),
                              return_attention_weights=True)
    torch.testing.assert_close(out, dense, atol=1e-5, rtol=1e-5)
    assert torch.equal(ei3, ei) and torch.allclose(alpha3, alpha)
    with pytest.raises(ValueError, match="target channels"):
        AttentionConv(-1)


def test_attention_conv_edge_features():
    torch.manual_seed(1)
    conv = AttentionConv(16, heads=4, edge_dim=3)
    x = torch.randn(4, 16)
    ei = torch.tensor([[0, 1, 2, 0], [1, 2, 3, 3]])
    ea = torch.randn(4, 3)
    a, b = conv(x, ei, edge_attr=ea), conv(x, ei, edge_attr=2 * ea)
    assert a.shape == (4, 16) and not torch.allclose(a[1:], b[1:])
    torch.testing.assert_close(a[0], b[0])  # node 0 receives no edge
    assert "edge_dim=3" in repr(conv)
    with pytest.raises(ValueError, match="edge_attr of shape"):
        conv(x, ei, edge_attr=ea[:2])
    with pytest.raises(ValueError, match="edge_attr exactly when"):
        conv(x, ei)
    with pytest.raises(ValueError, match="explicit edges with edge_attr"):
        conv(x, complete=True, edge_attr=ea)
    gx = torch.randn(4, 16, dtype=torch.float64, requires_grad=True)
    conv64 = conv.double()
    assert torch.autograd.gradcheck(lambda t: conv64(t, ei, edge_attr=ea.double()), (gx,))


def test_complete_edges_of_unsorted_graph_ids_join_only_one_graphs_nodes():
    """Before: complete_edge_index assumed sorted ids, so AttentionConv's attention weights
    on a user's unsorted batch came with edges between graphs."""
    bs, bd = torch.tensor([1, 0, 1, 0, 2, 1]), torch.tensor([2, 0, 1, 1, 0])
    ei = _complete(bs, bd)
    want = {(j, i) for j in range(6) for i in range(5) if bs[j] == bd[i]}
    assert {tuple(e) for e in ei.t().tolist()} == want and ei.shape[1] == len(want)
    torch.manual_seed(0)
    conv = AttentionConv(8, heads=2)
    xs, xd = torch.randn(6, 8), torch.randn(5, 8)
    dense = conv((xs, xd), complete=True, batch=(bs, bd))
    out, (ei2, alpha) = conv((xs, xd), complete=True, batch=(bs, bd),
                             return_attention_weights=True)
    torch.testing.assert_close(out, dense, atol=1e-5, rtol=1e-5)
    assert {tuple(e) for e in ei2.t().tolist()} == want
    torch.testing.assert_close(torch.zeros(5, 2).index_add_(0, ei2[1], alpha),
                               torch.ones(5, 2))


def test_attention_conv_pyg_habits_get_one_line_each():
    """Before: `AttentionConv(32, 64)` (GATConv's in, out) said "got 64 heads for 32
    channels" without saying the second argument is heads; `out_channels=64` was a raw
    TypeError from MessagePassing.__init__; an int32 edge_index was
    `RuntimeError: expected scalar type Long but found Int` from PyG's scatter."""
    import torch

    from strl_pyg.nn import AttentionConv, LineEndpointConv

    with pytest.raises(ValueError, match=r"got 64 heads for 32 channels\) \(AttentionConv"
                                         r"\(channels, heads\): the second argument"):
        AttentionConv(32, 64)
    with pytest.raises(TypeError, match=r"^Expected no out_channels .*\(got out_channels=64\)$"):
        AttentionConv(32, out_channels=64)
    torch.manual_seed(0)
    conv = AttentionConv(32, heads=4)
    x = torch.randn(6, 32)
    ei = torch.tensor([[0, 1, 2, 3, 4, 5, 0], [1, 2, 3, 4, 5, 0, 3]])
    torch.testing.assert_close(conv(x, ei.int()), conv(x, ei))
    from torch_geometric import EdgeIndex

    torch.testing.assert_close(conv(x, EdgeIndex(ei.int(), sparse_size=(6, 6))), conv(x, ei))
    with pytest.raises(ValueError, match=r"^Expected an integer edge_index \(got torch.float32\)$"):
        conv(x, ei.float())
    line = LineEndpointConv(32, line_channels=8)
    lf = torch.randn(6, 8)
    torch.testing.assert_close(line(x, ei.int(), lf), line(x, ei, lf))



@pytest.mark.parametrize("layout", ["csr", "coo"])
def test_attention_weights_in_the_sparse_adjacency_layout(layout):
    """A sparse adjacency's attention comes back as GATConv's does: ``(adj, alpha)``, ``adj``
    in the adjacency's layout, [N_dst, N_src, H] (it returned the adjacency alone, not the
    pair GATConv returns)."""
    from torch_geometric.nn import GATConv
    from torch_geometric.utils import to_torch_coo_tensor, to_torch_csr_tensor

    torch.manual_seed(0)
    x = torch.randn(6, 16)
    ei = torch.tensor([[0, 1, 2, 3, 4, 5, 1], [1, 0, 3, 2, 5, 4, 2]])
    conv = AttentionConv(16, heads=2).eval()
    ref, (_, alpha) = conv(x, ei, return_attention_weights=True)
    make = to_torch_csr_tensor if layout == "csr" else to_torch_coo_tensor
    adj_t = make(ei.flip(0), size=(6, 6))  # adj_t[dst, src], PyG's convention
    out, (weights, flat) = conv(x, adj_t, return_attention_weights=True)
    torch.testing.assert_close(out, ref, atol=1e-5, rtol=1e-5)
    assert weights.layout == adj_t.layout and weights.shape == (6, 6, 2)
    assert flat.shape == alpha.shape
    # GATConv's form on the same adjacency: (out, (adj, alpha))
    gat = GATConv(16, 4, heads=2, add_self_loops=False)
    _, (gat_adj, gat_alpha) = gat(x, adj_t, return_attention_weights=True)
    assert gat_adj.layout == weights.layout and gat_alpha.shape == flat.shape
    dense = weights.to_dense()
    torch.testing.assert_close(dense[ei[1], ei[0]], alpha, atol=1e-6, rtol=1e-5)
    assert float(dense.sum()) == pytest.approx(float(alpha.sum()), abs=1e-5)  # nothing else


def test_an_out_of_range_edge_index_is_a_one_line_error():
    """Before: PyG's raw IndexError from inside its gather."""
    conv = AttentionConv(8, heads=2)
    x = torch.randn(4, 8)
    with pytest.raises(ValueError, match=r"Expected edge_index\[0\] \(source nodes\) in "
                                         r"\[0, 3\] \(got values from 0 to 7\)"):
        conv(x, torch.tensor([[0, 7], [1, 2]]))
    with pytest.raises(ValueError, match=r"Expected edge_index\[1\] \(target nodes\) in "
                                         r"\[0, 2\] \(got values from -1 to 1\)"):
        conv((x, x[:3]), torch.tensor([[0, 1], [1, -1]]))
    assert conv(x, torch.tensor([[0, 3], [1, 2]])).shape == (4, 8)


def test_complete_attention_without_graph_ids_is_one_graph():
    """``complete=True`` with no ``batch`` nor ``layout``: all the nodes are one graph
    (documented), the same as graph ids of zeros."""
    torch.manual_seed(0)
    conv = AttentionConv(8, heads=2).eval()
    x = torch.randn(6, 8)
    one = conv(x, complete=True)
    zeros = conv(x, complete=True, batch=torch.zeros(6, dtype=torch.long))
    torch.testing.assert_close(one, zeros)
    two = conv(x, complete=True, batch=torch.tensor([0, 0, 0, 1, 1, 1]))
    assert not torch.allclose(one, two)
