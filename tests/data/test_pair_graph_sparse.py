"""PyG's sparse layouts on explicit pair graphs: ``validate`` accepts the ``adj_t`` that
``T.ToSparseTensor`` makes (it refused it: "Expected edge type ... to carry either 'dense'
or 'edge_index' (got neither)") and still refuses an edge type with neither."""

from __future__ import annotations

import pytest
import torch
import torch_geometric.transforms as T

from strl_pyg import PairMatches
from strl_pyg.data import build_pair_graph, materialize_complete_edges


@pytest.fixture(scope="module")
def graph(generated_pair):
    p = generated_pair(2_000_017)
    m = p.matches
    pm = PairMatches(m.points0[:30], m.points1[:30], m.lines0[:5], m.lines1[:5], K0=p.K,
                     K1=p.K, image_size0=p.image0.shape[:2], image_size1=p.image1.shape[:2])
    return materialize_complete_edges(build_pair_graph(pm))


def test_validate_accepts_to_sparse_tensor(graph):
    sparse = T.ToSparseTensor(layout=torch.sparse_csr)(graph.clone())
    et = ("point", "self", "point")
    assert "adj_t" in sparse[et] and "edge_index" not in sparse[et]
    assert sparse.validate()
    dense = sparse[et].adj_t.to_dense()
    assert int(dense.sum()) == graph[et].edge_index.shape[1]  # every edge kept


def test_validate_refuses_an_edge_type_without_edges(graph):
    g = graph.clone()
    del g[("point", "self", "point")].edge_index
    g[("point", "self", "point")].weight = torch.ones(3)
    with pytest.raises(ValueError, match=r"carry either 'dense' or 'edge_index' / a sparse "
                                         r"adjacency 'adj_t' \(got neither\)"):
        g.validate()
