"""PyG interop of pair graphs with implicit complete edges: every PyG path either gives the
result of the explicit edges (``materialize_complete_edges``) or refuses with an error naming
it; never a graph that silently lost its complete edges."""

from __future__ import annotations

import copy

import pytest
import torch
from test_data_graph import make
from torch import nn
from torch_geometric.data import Batch, HeteroData
from torch_geometric.nn import to_hetero

from strl_pyg.data import (
    CompleteEdges,
    ImplicitEdgesError,
    PairGraph,
    edge_index_dict,
    has_implicit_complete_edges,
    materialize_complete_edges,
)
from strl_pyg.data import keys as K
from strl_pyg.data.build import build_pair_graph, load_graph, save_graph
from strl_pyg.nn.attention import AttentionConv

SIZES = [(5, 2), (3, 0), (0, 3), (7, 1)]  # (points, lines): uneven, one graph without points


def pairs(complete: str) -> list[PairGraph]:
    return [build_pair_graph(make(n, m, seed=i), complete_edges=complete)
            for i, (n, m) in enumerate(SIZES)]


def batches() -> tuple[Batch, Batch]:
    return Batch.from_data_list(pairs("implicit")), Batch.from_data_list(pairs("explicit"))


def edge_set(edge_index: torch.Tensor, edge_type: torch.Tensor | None = None) -> list[tuple]:
    rows = edge_index if edge_type is None else torch.cat([edge_index, edge_type[None]])
    return sorted(map(tuple, rows.T.tolist()))


def features(data) -> dict[str, torch.Tensor]:
    return {nt: torch.cat([data[nt][K.POS0], data[nt][K.POS1]], -1) for nt in data.node_types}


class Net(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.lin = nn.Linear(4, 16)
        self.conv = AttentionConv(16, heads=2)

    def forward(self, x, edge_index):
        return self.conv(self.lin(x), edge_index)


class NetWithBatch(Net):
    def forward(self, x, edge_index, batch):
        return self.conv(self.lin(x), edge_index, batch)


def hetero(net_cls, metadata):
    torch.manual_seed(0)
    return to_hetero(net_cls(), metadata, aggr="sum")


# ----------------------------------------------------------------------------- to_hetero
def test_to_hetero_on_implicit_batch_equals_explicit_edges():
    implicit, explicit = batches()
    model = hetero(Net, implicit.metadata())
    ref = model(features(explicit), explicit.edge_index_dict)
    out = model(features(implicit), edge_index_dict(implicit))
    assert set(out) == set(ref) == set(K.NODE_TYPES)
    for nt in ref:
        torch.testing.assert_close(out[nt], ref[nt], atol=1e-5, rtol=1e-5)
    # the same with a batch argument (to_hetero hands a (src, dst) pair for bipartite types)
    model_b = hetero(NetWithBatch, implicit.metadata())
    out_b = model_b(features(implicit), edge_index_dict(implicit), implicit.batch_dict)
    ref_b = model_b(features(explicit), explicit.edge_index_dict, explicit.batch_dict)
    for nt in ref:
        torch.testing.assert_close(out_b[nt], ref_b[nt], atol=1e-5, rtol=1e-5)
    # a single graph too
    g, e = pairs("implicit")[0], pairs("explicit")[0]
    for nt, v in model(features(g), edge_index_dict(g)).items():
        torch.testing.assert_close(v, model(features(e), e.edge_index_dict)[nt], atol=1e-5,
                                   rtol=1e-5)


def test_to_hetero_with_plain_edge_index_dict_refuses():
    """The reproduced bug: PyG's own ``edge_index_dict`` lacks the implicit types, the layers
    then got ``None`` and attended across the pairs of the batch without an error."""
    implicit, _ = batches()
    model = hetero(Net, implicit.metadata())
    with pytest.raises(ValueError, match="materialize_complete_edges"):
        model(features(implicit), implicit.edge_index_dict)


def test_complete_edges_marker_disagreeing_with_batch_refuses():
    implicit, _ = batches()
    model = hetero(NetWithBatch, implicit.metadata())
    wrong = {nt: torch.zeros_like(b) for nt, b in implicit.batch_dict.items()}
    with pytest.raises(ValueError, match="graph ids"):
        model(features(implicit), edge_index_dict(implicit), wrong)


def test_edge_index_dict_values():
    implicit, explicit = batches()
    d = edge_index_dict(implicit)
    assert set(d) == set(K.EDGE_TYPES)
    assert torch.equal(d[K.LINE_EDGE], explicit[K.LINE_EDGE].edge_index)
    marker = d[(K.POINT, K.SELF_REL, K.ENDPOINT)]
    assert isinstance(marker, CompleteEdges)
    assert torch.equal(marker.batch_src, implicit[K.POINT].batch)
    assert torch.equal(marker.batch_dst, implicit[K.ENDPOINT].batch)
    assert all(torch.is_tensor(v) for v in edge_index_dict(explicit).values())


# ----------------------------------------------------------------------------- to_homogeneous
@pytest.mark.parametrize("single", [True, False])
def test_to_homogeneous_keeps_complete_edges(single):
    """The reproduced bug: ``to_homogeneous`` dropped the complete edges (4 of 53 left; of
    102 while the graph also carried the duplicated cross types)."""
    if single:
        implicit, explicit = build_pair_graph(make(3, 2)), build_pair_graph(
            make(3, 2), complete_edges="explicit")
    else:
        implicit, explicit = batches()
    h, he = implicit.to_homogeneous(), explicit.to_homogeneous()
    assert h.num_edges == he.num_edges
    if single:  # 3 points + 4 endpoints, complete: 7 ** 2, plus the 4 line edges (53, not 4)
        assert h.num_edges == 7 ** 2 + 4
    assert edge_set(h.edge_index, h.edge_type) == edge_set(he.edge_index, he.edge_type)
    assert set(h.keys()) == set(he.keys()) and K.DENSE not in h
    for key in (K.POS0, K.KPTS1, "node_type"):
        assert torch.equal(h[key], he[key])
    assert has_implicit_complete_edges(implicit)  # the input is left as it was


def test_pyg_edge_readers_refuse_or_agree():
    implicit, explicit = batches()
    for name in ("edge_index_dict",):
        with pytest.raises(ImplicitEdgesError, match="materialize_complete_edges"):
            getattr(implicit, name)
    with pytest.raises(ValueError, match="materialize_complete_edges"):
        implicit.collect(K.EDGE_INDEX)
    with pytest.raises(ValueError, match="materialize_complete_edges"):
        implicit.get_all_edge_attrs()  # the graph-store view that PyG's samplers read
    assert implicit.num_edges == explicit.num_edges
    g = pairs("implicit")[1]
    assert g.num_edges == pairs("explicit")[1].num_edges == 9  # 3 points, no lines
    assert implicit.has_isolated_nodes() == explicit.has_isolated_nodes()
    assert implicit.is_undirected() == explicit.is_undirected()
    one = build_pair_graph(make(1, 0))  # one node: only a self-loop, isolated in PyG's sense
    assert one.has_isolated_nodes() == materialize_complete_edges(copy.copy(one)) \
        .has_isolated_nodes()


# ----------------------------------------------------------------------------- other paths
def test_batch_roundtrip_subgraph_and_device():
    implicit, explicit = batches()
    assert isinstance(implicit, PairGraph) and isinstance(explicit, PairGraph)
    back = implicit.to_data_list()
    assert all(type(d) is PairGraph and has_implicit_complete_edges(d) for d in back)
    assert back[2][K.SELF_EDGE_TYPES[0]][K.DENSE].shape == (1,)
    for d, ref in zip(back, pairs("explicit"), strict=True):
        assert d.num_edges == ref.num_edges
    # subgraph of a complete graph is complete on the kept nodes
    keep = {K.POINT: torch.tensor([0, 2, 4, 6, 9]), K.ENDPOINT: torch.tensor([1, 2, 3, 7])}
    s, se = implicit.subgraph(keep), explicit.subgraph(keep)
    s = materialize_complete_edges(s)
    for et in K.EDGE_TYPES:
        assert edge_set(s[et].edge_index) == edge_set(se[et].edge_index), et
    moved = implicit.to("meta")
    assert moved[K.SELF_EDGE_TYPES[0]][K.DENSE].device.type == "meta"
    assert isinstance(moved, PairGraph)


def test_validate_checks_the_markers():
    g = build_pair_graph(make(3, 2))
    assert g.validate()
    both = copy.copy(g)
    both[K.SELF_EDGE_TYPES[0]].edge_index = torch.zeros(2, 0, dtype=torch.long)
    with pytest.raises(ValueError, match="either"):
        both.validate()
    neither = copy.copy(g)
    del neither[K.SELF_EDGE_TYPES[0]][K.DENSE]
    with pytest.raises(ValueError, match="either"):
        neither.validate()
    wrong = copy.copy(g)
    wrong[K.SELF_EDGE_TYPES[1]][K.DENSE] = torch.ones(2, dtype=torch.bool)
    with pytest.raises(ValueError, match="one bool per graph"):
        wrong.validate()
    assert not wrong.validate(raise_on_error=False)


def test_save_load_keeps_the_class(tmp_path):
    g = build_pair_graph(make(4, 2))
    r = load_graph(save_graph(g, tmp_path / "g.pt"))
    assert type(r) is PairGraph and has_implicit_complete_edges(r)
    assert r.to_homogeneous().num_edges == g.to_homogeneous().num_edges == (4 + 4) ** 2 + 4


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_on_cuda_equals_explicit_edges():
    implicit, explicit = batches()
    model = hetero(Net, implicit.metadata())
    ref = model(features(explicit), explicit.edge_index_dict)
    model, implicit = model.cuda(), implicit.to("cuda")
    out = model(features(implicit), edge_index_dict(implicit))
    for nt in ref:
        torch.testing.assert_close(out[nt].cpu(), ref[nt], atol=1e-4, rtol=1e-4)
    assert implicit.num_edges == explicit.num_edges
    h = implicit.to_homogeneous()
    assert h.edge_index.is_cuda and h.num_edges == explicit.to_homogeneous().num_edges


def test_materialize_complete_edges_on_a_users_graph_does_not_mutate_it():
    """Before: TypeError in zeros() on a 'kp' graph, and a 'point' node type added."""
    d = HeteroData()
    d["kp"].x = torch.randn(4, 3)
    d["kp", "all", "kp"].dense = torch.ones(1, dtype=torch.bool)
    out = materialize_complete_edges(d)
    assert out["kp", "all", "kp"].edge_index.shape == (2, 16)
    assert d.node_types == ["kp"] and "edge_index" not in d["kp", "all", "kp"]
    assert "dense" in d["kp", "all", "kp"] and "dense" not in out["kp", "all", "kp"]

