"""Each row of docs/layers.md's table "PyG's transforms and loaders on pair graphs": what a
standard PyG transform or loader feature does on a pair graph with implicit complete edges and
on the same graph with explicit ones. No row changes a graph silently: a transform that reads
edges either refuses the implicit graph, naming ``materialize_complete_edges``, or gives the
explicit graph's result."""

from __future__ import annotations

import copy
import pickle

import pytest
import torch
import torch_geometric.transforms as T
from test_data_graph import make
from torch_geometric.data import Batch
from torch_geometric.loader import DataLoader

from strl_pyg.data import (
    ImplicitEdgesError,
    MixedEdgesError,
    PairGraph,
    build_pair_graph,
    has_implicit_complete_edges,
    materialize_complete_edges,
)
from strl_pyg.data import keys as K


def graphs(points: int = 6, lines: int = 2):
    g = build_pair_graph(make(points, lines, seed=1))
    return g, materialize_complete_edges(g)


def node_counts(d) -> dict[str, int]:
    return {nt: d[nt].num_nodes for nt in d.node_types}


#: transforms that read edges: implicit refuses, explicit works on every node
EDGE_TRANSFORMS = [T.RemoveIsolatedNodes(), T.RemoveDuplicatedEdges(), T.ToUndirected(),
                   T.AddSelfLoops(), T.AddRemainingSelfLoops(), T.RemoveSelfLoops(),
                   T.ToSparseTensor()]


@pytest.mark.parametrize("transform", EDGE_TRANSFORMS, ids=lambda t: type(t).__name__)
def test_edge_transforms_refuse_implicit_graphs(transform):
    implicit, explicit = graphs()
    with pytest.raises(ImplicitEdgesError, match="materialize_complete_edges"):
        transform(implicit)
    assert has_implicit_complete_edges(implicit)  # the input is untouched
    out = transform(explicit)
    assert node_counts(out) == node_counts(explicit)
    assert out.validate()


def test_remove_isolated_nodes_keeps_every_node_of_a_complete_graph():
    """The bug: the implicit edges looked like no edges, every point node was removed and
    the model still answered for the empty graph."""
    implicit, explicit = graphs(points=30, lines=0)
    with pytest.raises(ImplicitEdgesError):
        T.RemoveIsolatedNodes()(implicit)
    assert node_counts(T.RemoveIsolatedNodes()(explicit))[K.POINT] == 30


def test_edge_counting_transforms_on_explicit_graphs():
    _, explicit = graphs()
    et = K.SELF_EDGE_TYPES[0]
    n = explicit[K.POINT].num_nodes
    assert explicit[et].edge_index.shape[1] == n * n  # self-loops included
    assert T.RemoveDuplicatedEdges()(explicit)[et].edge_index.shape[1] == n * n
    assert T.RemoveSelfLoops()(explicit)[et].edge_index.shape[1] == n * (n - 1)
    assert T.AddRemainingSelfLoops()(explicit)[et].edge_index.shape[1] == n * n


@pytest.mark.parametrize("transform", [T.NormalizeFeatures(), T.ToDevice("cpu"), T.Constant()],
                         ids=lambda t: type(t).__name__)
def test_node_transforms_keep_the_markers(transform):
    implicit, explicit = graphs()
    out = transform(implicit)
    assert isinstance(out, PairGraph) and has_implicit_complete_edges(out)
    assert node_counts(out) == node_counts(implicit)
    assert out.num_edges == transform(explicit).num_edges


def test_mixed_batches_refuse_in_one_line():
    implicit, explicit = graphs()
    with pytest.raises(MixedEdgesError, match="materialize_complete_edges") as err:
        Batch.from_data_list([implicit, explicit])
    assert "\n" not in str(err.value) and not str(err.value).startswith("'")
    with pytest.raises(ImplicitEdgesError, match="batching"):
        Batch.from_data_list([explicit, implicit])
    both = Batch.from_data_list([materialize_complete_edges(implicit), explicit])
    assert both.num_graphs == 2


def test_data_loader_and_round_trips():
    implicit, explicit = graphs()
    batch = next(iter(DataLoader([implicit, copy.copy(implicit)], batch_size=2)))
    assert isinstance(batch, PairGraph) and has_implicit_complete_edges(batch)
    assert batch.num_edges == 2 * explicit.num_edges
    assert all(has_implicit_complete_edges(d) for d in batch.to_data_list())
    back = pickle.loads(pickle.dumps(implicit))
    with pytest.raises(ImplicitEdgesError):  # the store's class survives pickling
        T.RemoveIsolatedNodes()(back)
    plain = PairGraph.from_dict(implicit.to_dict())
    with pytest.raises(ImplicitEdgesError):
        T.RemoveIsolatedNodes()(plain)


def test_subgraphs_stay_implicit_and_agree():
    implicit, explicit = graphs()
    keep = {K.POINT: torch.tensor([0, 2, 3]), K.ENDPOINT: torch.tensor([1, 2])}
    s = implicit.subgraph(keep)
    assert has_implicit_complete_edges(s)
    assert s.num_edges == explicit.subgraph(keep).num_edges
    with pytest.raises(ImplicitEdgesError):  # the subgraph is not left answering natively
        T.RemoveIsolatedNodes()(s)
    only = implicit.node_type_subgraph([K.POINT])
    assert only.node_types == [K.POINT] and has_implicit_complete_edges(only)
    assert only.validate()
    kept = implicit.edge_type_subgraph([K.SELF_EDGE_TYPES[0]])
    assert kept.edge_types == [K.SELF_EDGE_TYPES[0]] and has_implicit_complete_edges(kept)


def test_graph_queries_answer_as_the_explicit_graph():
    implicit, explicit = graphs()
    assert implicit.num_edges == explicit.num_edges
    assert implicit.has_isolated_nodes() == explicit.has_isolated_nodes() is False
    assert implicit.is_undirected() == explicit.is_undirected()
    assert len(implicit.connected_components()) == len(explicit.connected_components())
    assert implicit.to_homogeneous().num_edges == explicit.to_homogeneous().num_edges
