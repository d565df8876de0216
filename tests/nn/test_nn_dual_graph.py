"""DualGraphLayer: the update order of one dual-graph layer and the cross-attention direction."""

from __future__ import annotations

import pytest
import torch

from strl_pyg.data import CompleteEdges
from strl_pyg.nn import DenseLayout, DualGraphLayer

C, CL = 16, 8


def inputs(seed=0):
    """Two graphs (5 + 4 nodes); in graph 0 nodes 1, 2 are the endpoints of one line."""
    torch.manual_seed(seed)
    batch = torch.tensor([0, 0, 0, 0, 0, 1, 1, 1, 1])
    g, v = torch.randn(9, C), torch.randn(9, C)
    line_edges = torch.tensor([[1, 2, 6, 7], [2, 1, 7, 6]])
    line_feat = torch.zeros(9, CL)
    line_feat[[1, 2, 6, 7]] = torch.randn(4, CL)
    return batch, g, v, line_edges, line_feat


def run(layer, g, v, batch, line_edges, line_feat):
    return layer(g, v, self_edges=CompleteEdges(), cross_edges=CompleteEdges(),
                 line_edges=line_edges, line_feat=line_feat,
                 layout=DenseLayout.from_batch(batch, batch.numel()))


def test_the_layer_is_its_four_steps_in_order():
    batch, g, v, le, lf = inputs()
    layer = DualGraphLayer(C, heads=2, line_channels=CL)
    g_out, v_out = run(layer, g, v, batch, le, lf)
    g1 = layer.geo_self(g, None, batch, complete=True)
    g2 = layer.line_conv(g1, le, lf)
    v1 = layer.vis_self(v, None, batch, complete=True)
    v2 = layer.vis_cross((v1, v1), None, batch, query=g2, complete=True)
    torch.testing.assert_close(g_out, g2)
    torch.testing.assert_close(v_out, v2)


def test_cross_attention_queries_are_geometric_and_update_the_visual_stream():
    batch, g, v, le, lf = inputs(1)
    layer = DualGraphLayer(C, heads=2, line_channels=CL).eval()
    g_out, v_out = run(layer, g, v, batch, le, lf)
    # the geometric stream never reads the visual one
    g_out2, v_out2 = run(layer, g, v + torch.randn_like(v), batch, le, lf)
    torch.testing.assert_close(g_out, g_out2)
    assert not torch.allclose(v_out, v_out2)
    # the geometric features reach the visual output only through the cross-attention
    # queries: with a zero query projection the visual output no longer depends on them
    g_other = g + torch.randn_like(g)
    assert not torch.allclose(v_out, run(layer, g_other, v, batch, le, lf)[1])
    with torch.no_grad():
        layer.vis_cross.lin_q.weight.zero_()
        layer.vis_cross.lin_q.bias.zero_()
    torch.testing.assert_close(run(layer, g, v, batch, le, lf)[1],
                               run(layer, g_other, v, batch, le, lf)[1])


def test_optional_parts_and_errors():
    batch, g, v, le, lf = inputs(2)
    geo_only = DualGraphLayer(C, heads=2, visual=False)
    assert geo_only.line_conv is None and geo_only.vis_self is None
    g_out, v_out = run(geo_only, g, None, batch, le, lf)
    assert v_out is None
    torch.testing.assert_close(g_out, geo_only.geo_self(g, None, batch, complete=True))
    # without lines in the batch the line step is skipped
    layer = DualGraphLayer(C, heads=2, line_channels=CL)
    g_out, _ = run(layer, g, v, batch, None, None)
    torch.testing.assert_close(g_out, layer.geo_self(g, None, batch, complete=True))
    with pytest.raises(ValueError, match="line_feat together with line_edges"):
        run(layer, g, v, batch, le, None)
    with pytest.raises(ValueError, match="visual features and cross_edges"):
        run(layer, g, None, batch, le, lf)
    assert repr(layer) == "DualGraphLayer(16, line=True, visual=True)"


def test_reset_parameters_reaches_every_part():
    layer = DualGraphLayer(C, heads=2, line_channels=CL)
    parts = (layer.geo_self.lin_q, layer.line_conv.mlp[0], layer.vis_self.lin_k,
             layer.vis_cross.lin_v)
    before = [p.weight.detach().clone() for p in parts]
    layer.reset_parameters()
    assert all(not torch.equal(b, p.weight) for b, p in zip(before, parts, strict=True))


def test_one_layer_traces_as_one_graph():
    batch, g, v, le, lf = inputs(3)
    layer = DualGraphLayer(C, heads=2, line_channels=CL).eval()
    lay = DenseLayout.from_batch(batch, batch.numel())
    torch._dynamo.reset()
    with torch.no_grad():
        ex = torch._dynamo.explain(layer)(g, v, self_edges=CompleteEdges(),
                                          cross_edges=CompleteEdges(), line_edges=le,
                                          line_feat=lf, layout=lay)
    assert ex.graph_break_count == 0 and ex.graph_count == 1
