"""One graph design: one set of complete edges serves every attention of the dual graph.

Before, a pair graph carried 4 ``cross`` edge types holding exactly the edges of its 4 ``self``
types; the model then merged them again. Now the graph carries the ``self`` types only, the
cross-attention runs over them, graphs of strl-pyg 0.1.x (with implicit ``cross`` markers) give
the same output, and explicit ``cross`` edges, if a user brings them, are used as given.
"""

from __future__ import annotations

import copy

import pytest
import torch
from test_model import collate, make_pair, small

from strl_pyg.data import (
    build_pair_graph,
    drop_legacy_cross_edges,
    load_graph,
    materialize_complete_edges,
    save_graph,
)
from strl_pyg.data import keys as K
from strl_pyg.model.strl_pose import StrLPose


def _with_legacy_cross(g):
    """A graph as strl-pyg 0.1.x built it: implicit cross markers beside the self markers."""
    old = copy.copy(g)
    n = old[K.SELF_EDGE_TYPES[0]][K.DENSE].shape[0]
    for et in K.CROSS_EDGE_TYPES:
        old[et][K.DENSE] = torch.ones(n, dtype=torch.bool)
    return old


def test_built_graph_has_no_duplicated_edge_types():
    g = build_pair_graph(_matches(), complete_edges="explicit")
    assert set(g.edge_types) == set(K.SELF_EDGE_TYPES) | {K.LINE_EDGE}
    edge_sets = [frozenset(map(tuple, g[et].edge_index.t().tolist())) | {et[0] + et[2]}
                 for et in g.edge_types]
    assert len(set(edge_sets)) == len(edge_sets)  # no two edge types hold the same edges


def _matches():
    import numpy as np

    from strl_pyg.data import PairMatches

    rng = np.random.default_rng(0)
    p0 = rng.uniform(0, 100, (6, 2))
    l0 = rng.uniform(0, 100, (3, 2, 2))
    return PairMatches(p0, p0 + 1.0, l0, l0 + 1.0, image_size0=(120, 160),
                       image_size1=(120, 160))


@pytest.mark.parametrize("batched", [False, True])
def test_legacy_cross_markers_give_the_same_output(batched):
    torch.manual_seed(0)
    model = StrLPose(small("full")).eval()
    graphs = [make_pair(s, n, nl) for s, (n, nl) in enumerate([(12, 5), (3, 0), (20, 2)])]
    new = collate(graphs) if batched else graphs[0]
    old = collate([_with_legacy_cross(g) for g in graphs]) if batched \
        else _with_legacy_cross(graphs[0])
    with torch.no_grad():
        a, b = model(new), model(old)
    assert torch.allclose(a.quaternion, b.quaternion, atol=1e-6)
    assert torch.allclose(a.translation, b.translation, atol=1e-6)


def test_load_graph_drops_legacy_cross_markers(tmp_path):
    g = _with_legacy_cross(make_pair(0, 5, 2))
    assert set(K.CROSS_EDGE_TYPES) <= set(g.edge_types)
    r = load_graph(save_graph(g, tmp_path / "old.pt"))
    assert set(r.edge_types) == set(K.EDGE_TYPES)
    # explicit cross edges are the user's own and stay
    e = make_pair(0, 5, 2, complete="explicit")
    e[K.CROSS_EDGE_TYPES[0]].edge_index = torch.zeros(2, 1, dtype=torch.long)
    assert K.CROSS_EDGE_TYPES[0] in drop_legacy_cross_edges(e).edge_types


def test_materialize_also_materialises_legacy_markers():
    g = materialize_complete_edges(_with_legacy_cross(make_pair(0, 5, 2)))
    for et in K.CROSS_EDGE_TYPES:
        assert K.DENSE not in g[et] and torch.equal(
            g[et].edge_index, g[(et[0], K.SELF_REL, et[2])].edge_index)


def test_explicit_cross_edges_are_used():
    """Complete explicit cross edges equal the default; a pruned set changes the output,
    and changes only the visual stream's input (a model without GGVG ignores them)."""
    torch.manual_seed(0)
    model = StrLPose(small("full")).eval()
    g = make_pair(1, 10, 3, complete="explicit")
    with torch.no_grad():
        ref = model(g).quaternion
        full = copy.copy(g)
        for et in K.CROSS_EDGE_TYPES:
            full[et].edge_index = g[(et[0], K.SELF_REL, et[2])].edge_index
        assert torch.allclose(model(full).quaternion, ref, atol=1e-6)
        pruned = copy.copy(full)
        for et in K.CROSS_EDGE_TYPES:
            ei = full[et].edge_index
            pruned[et].edge_index = ei[:, ei[0] == ei[1]] if et[0] == et[2] else ei[:, :0]
        assert not torch.allclose(model(pruned).quaternion, ref, atol=1e-4)
        geo_only = StrLPose(small("LP")).eval()
        assert torch.allclose(geo_only(pruned).quaternion, geo_only(g).quaternion, atol=1e-6)


def test_legacy_implicit_cross_beside_explicit_self_edges_stays_complete(tmp_path):
    """0.1.x: implicit cross markers meant complete cross-attention whatever the self edges
    were; a graph with pruned explicit self edges keeps that meaning (model and load_graph)."""
    torch.manual_seed(0)
    model = StrLPose(small("full")).eval()
    g = make_pair(2, 8, 2, complete="explicit")
    pruned = copy.copy(g)
    for et in K.SELF_EDGE_TYPES:  # self-attention over self-loops only
        ei = g[et].edge_index
        pruned[et].edge_index = ei[:, ei[0] == ei[1]] if et[0] == et[2] else ei[:, :0]
    legacy = copy.copy(pruned)
    for et in K.CROSS_EDGE_TYPES:
        legacy[et][K.DENSE] = torch.ones(1, dtype=torch.bool)
    reference = copy.copy(pruned)  # the same meaning, spelled out: explicit complete cross edges
    for et in K.CROSS_EDGE_TYPES:
        reference[et].edge_index = g[(et[0], K.SELF_REL, et[2])].edge_index
    with torch.no_grad():
        out = model(legacy).quaternion
        assert torch.allclose(out, model(reference).quaternion, atol=1e-5)
        assert not torch.allclose(out, model(pruned).quaternion, atol=1e-4)
    r = load_graph(save_graph(legacy, tmp_path / "legacy.pt"))
    assert set(K.CROSS_EDGE_TYPES) <= set(r.edge_types)
