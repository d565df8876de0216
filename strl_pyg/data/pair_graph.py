"""The pair-graph class and its complete edge types, implicit or explicit.

Complete edge types (the ``self`` types: every node of a pair to every node of it, the edges of
all three attentions of the dual graph) are **implicit** by default: each such edge type
carries only a ``dense`` marker (one bool per graph) and layers run dense attention over
per-graph blocks, so a graph's memory grows O(N), not O(N^2).
:func:`materialize_complete_edges` turns the markers into explicit ``edge_index`` tensors.

PyG reads edges through ``edge_index`` alone, so on a plain ``HeteroData`` an implicit edge type
looks like an edge type without edges: ``to_homogeneous`` drops it, ``edge_index_dict`` omits it
(and a model made with ``to_hetero`` then receives ``None`` for it). :class:`PairGraph` closes
these paths:

* ``to_homogeneous``, ``has_isolated_nodes``, ``is_undirected``, ``connected_components`` and
  ``num_edges`` give the result of the explicit edges (the first four on a materialised copy;
  the input is left implicit);
* ``edge_index_dict``, ``collect("edge_index")`` and the graph-store view that PyG's samplers
  read (``get_all_edge_attrs``) raise :class:`ImplicitEdgesError`, naming
  :func:`materialize_complete_edges` and :func:`edge_index_dict`, instead of leaving edge
  types out;
* ``validate`` also checks the markers.

Batching (``Batch.from_data_list``), ``to_data_list``, ``subgraph``, ``node_type_subgraph``,
``.to(device)``, copying and pickling keep the class and the markers (a subgraph of a complete
graph is complete on the kept nodes, which is what the marker says).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import torch
from torch import Tensor
from torch_geometric.data import Batch, HeteroData
from torch_geometric.data.storage import EdgeStorage

from strl_pyg.data import keys as keys_

__all__ = [
    "PairGraph",
    "CompleteEdges",
    "ImplicitEdgesError",
    "MixedEdgesError",
    "PairEdgeStorage",
    "complete_edge_index",
    "drop_legacy_cross_edges",
    "edge_index_dict",
    "has_implicit_complete_edges",
    "implicit_edge_types",
    "materialize_complete_edges",
]


class CompleteEdges:
    """An ``edge_index`` stand-in that asks :class:`~strl_pyg.nn.AttentionConv` for complete
    attention: every source node to every target node **of the same graph**, without an O(N^2)
    edge list. It is data (the implicit edges of a pair graph), so it lives here; ``strl_pyg.nn``
    re-exports it.

    It carries the graph ids itself, so that code that hands edges around per edge type
    (:func:`torch_geometric.nn.to_hetero`, :func:`strl_pyg.data.edge_index_dict`) cannot
    lose them and attend across the graphs of a batch.

    Args:
        batch_src: Graph id of each source node ``[N_src]``, or ``None``: take the layer's
            ``batch`` argument (no ``batch`` either: all nodes form one graph).
        batch_dst: Graph id of each target node ``[N_dst]`` (default: ``batch_src``, for
            self-attention on one node set).
    """

    __slots__ = ("batch_src", "batch_dst")

    def __init__(self, batch_src: Tensor | None = None, batch_dst: Tensor | None = None) -> None:
        if batch_src is None and batch_dst is not None:
            raise ValueError("Expected 'batch_src' together with 'batch_dst' (got only batch_dst)")
        for name, b in (("batch_src", batch_src), ("batch_dst", batch_dst)):
            if b is not None and (not isinstance(b, Tensor) or b.dim() != 1
                                  or b.dtype != torch.long):
                got = f"{b.dtype} {tuple(b.shape)}" if isinstance(b, Tensor) else type(b).__name__
                raise TypeError(f"Expected '{name}' as a 1-D long tensor or None (got {got})")
        self.batch_src = batch_src
        self.batch_dst = batch_src if batch_dst is None else batch_dst

    def to(self, device: torch.device | str, non_blocking: bool = False) -> CompleteEdges:
        """The marker with its graph ids on ``device`` (a new marker; ``None`` stays), so that
        ``{k: v.to(device) for k, v in edge_index_dict.items()}`` works as for tensors."""
        def move(b):
            return None if b is None else b.to(device, non_blocking=non_blocking)

        src = move(self.batch_src)  # ids shared by source and target move once
        return CompleteEdges(src, src if self.batch_dst is self.batch_src
                             else move(self.batch_dst))

    def __repr__(self) -> str:
        def n(b):
            return "None" if b is None else f"[{b.numel()}]"

        return f"CompleteEdges(batch_src={n(self.batch_src)}, batch_dst={n(self.batch_dst)})"


class ImplicitEdgesError(ValueError):
    """A PyG path that reads ``edge_index`` met implicit complete edge types."""


class MixedEdgesError(KeyError):
    """A batch mixes graphs whose complete edges are implicit with graphs whose are explicit."""

    def __str__(self) -> str:  # a KeyError quotes its message; this one is a sentence
        return str(self.args[0])


def stored(store: Any, key: str) -> bool:
    """Whether ``store`` holds ``key`` (what it holds, not what a :class:`PairEdgeStorage` of
    an implicit complete edge type answers PyG's edge-based code)."""
    return key in store._mapping


class PairEdgeStorage(EdgeStorage):
    """The edge store of a :class:`PairGraph`. An implicit complete edge type (a ``dense``
    marker, no ``edge_index``) does not look edgeless to PyG's edge-based transforms and
    utilities: ``"edge_index" in store`` is true and reading it raises
    :class:`ImplicitEdgesError`, naming :func:`materialize_complete_edges`. An explicit store
    asked for a ``dense`` marker it lacks (a batch that mixes both kinds) raises
    :class:`MixedEdgesError`."""

    def _implicit(self) -> bool:
        m = self._mapping
        return keys_.DENSE in m and keys_.EDGE_INDEX not in m and not _native_now(self)

    def __contains__(self, key: object) -> bool:
        if key == keys_.EDGE_INDEX and self._implicit():
            return True
        return super().__contains__(key)

    def __getitem__(self, key: str) -> Any:
        if key == keys_.EDGE_INDEX and self._implicit():
            raise ImplicitEdgesError(
                f"Expected an explicit 'edge_index' on edge type {self._key} (got an implicit "
                f"complete edge type, a '{keys_.DENSE}' marker: every node to every node of its "
                "graph): call strl_pyg.data.materialize_complete_edges(data) first (also before "
                "batching such a graph with explicit ones)")
        if key == keys_.DENSE and keys_.DENSE not in self._mapping \
                and keys_.EDGE_INDEX in self._mapping and not _native_now(self):
            raise MixedEdgesError(
                f"Expected the complete edge type {self._key} implicit ('{keys_.DENSE}') in every "
                "graph of a batch or explicit in every one (got both): call "
                "strl_pyg.data.materialize_complete_edges(data) on the implicit ones first")
        return super().__getitem__(key)


def _native_now(store: EdgeStorage) -> bool:
    parent = store.__dict__.get("_parent")
    graph = parent() if parent is not None else None
    return bool(graph is not None and graph.__dict__.get("_native", False))


@contextmanager
def _native(data: HeteroData) -> Iterator[None]:
    """Within: ``data``'s stores answer as plain PyG stores (for PyG methods that
    :class:`PairGraph` knows keep the implicit markers right)."""
    before = data.__dict__.get("_native", False)
    data.__dict__["_native"] = True
    try:
        yield
    finally:
        data.__dict__["_native"] = before


def complete_edge_index(
    batch_src: Tensor, batch_dst: Tensor, num_graphs: int | None = None
) -> Tensor:
    """All ``(j, i)`` pairs whose source ``j`` and target ``i`` belong to the same graph.

    The graph ids need not be sorted (PyG's collation sorts them; a user's ``batch`` may
    not). Self-loops are included when source and target are the same node set.

    Args:
        batch_src: Graph id of each source node ``[N_src]``.
        batch_dst: Graph id of each target node ``[N_dst]``.
        num_graphs: Number of graphs (inferred when omitted).

    Returns:
        ``edge_index`` ``[2, sum_b N_src_b * N_dst_b]``, grouped by target node, on the device
        of ``batch_dst``.
    """
    if num_graphs is None:
        num_graphs = (
            int(
                max(
                    batch_src.max().item() if batch_src.numel() else -1,
                    batch_dst.max().item() if batch_dst.numel() else -1,
                )
            )
            + 1
        )
    dev = batch_dst.device
    batch_src = batch_src.to(dev)
    count_src = torch.bincount(batch_src, minlength=num_graphs)
    ptr_src = torch.cat([count_src.new_zeros(1), count_src.cumsum(0)])
    per_dst = count_src[batch_dst]  # sources of each target node
    dst = torch.repeat_interleave(torch.arange(batch_dst.numel(), device=dev), per_dst)
    start = torch.repeat_interleave(per_dst.cumsum(0) - per_dst, per_dst)
    rank = ptr_src[batch_dst][dst] + torch.arange(dst.numel(), device=dev) - start
    # rank: the source's position among the sources sorted by graph; the identity when sorted
    src = torch.argsort(batch_src, stable=True)[rank]
    return torch.stack([src, dst])


def _batch_of(data: HeteroData, node_type: str) -> Tensor:
    store = data[node_type]
    batch = getattr(store, "batch", None)
    if batch is not None:
        return batch
    device = next((v.device for v in store.values() if isinstance(v, Tensor)), None)
    return torch.zeros(store.num_nodes, dtype=torch.long, device=device)


def _num_graphs(data: HeteroData) -> int:
    return data.num_graphs if isinstance(data, Batch) else 1


def implicit_edge_types(data: HeteroData) -> list[tuple[str, str, str]]:
    """The edge types that carry a ``dense`` marker and no ``edge_index``."""
    return [et for et in data.edge_types
            if stored(data[et], keys_.DENSE) and not stored(data[et], keys_.EDGE_INDEX)]


def has_implicit_complete_edges(data: HeteroData) -> bool:
    """True when the complete edge types carry ``dense`` markers instead of edge indices."""
    return all(keys_.DENSE in data[et] for et in keys_.COMPLETE_EDGE_TYPES if et in data.edge_types)


def materialize_complete_edges(data: HeteroData) -> HeteroData:
    """A shallow copy of ``data`` with every implicit complete edge type (a ``dense`` marker
    and no ``edge_index``, whatever its node types are called) given an explicit
    ``edge_index``; ``data`` itself is not changed, and neither are its explicit edge types.

    Works on single graphs and on batches, on any device. Memory grows O(N^2): intended for
    sparse or pruned attention, for PyG code that needs every edge, and as the reference path
    that tests compare the dense path against.
    """
    implicit = implicit_edge_types(data)
    out = copy.copy(data)
    num_graphs = _num_graphs(data)
    for src, rel, dst in implicit:
        for nt in (src, dst):
            if nt not in data.node_types:
                raise ValueError(f"Expected node type '{nt}' of implicit edge type "
                                 f"{(src, rel, dst)} in the graph (got {data.node_types})")
        out[(src, rel, dst)].edge_index = complete_edge_index(
            _batch_of(data, src), _batch_of(data, dst), num_graphs)
        del out[(src, rel, dst)][keys_.DENSE]
    return out


def drop_legacy_cross_edges(data: HeteroData) -> HeteroData:
    """Removes the implicit ``cross`` edge types that graphs of strl-pyg 0.1.x carried beside
    the ``self`` types (the same complete edges, see :mod:`strl_pyg.data.keys`), in place.
    Explicit ``cross`` edges are the user's own cross-attention edges and are kept; so are
    implicit ones beside explicit ``self`` edges (they then mean complete cross-attention over
    different edges than the self-attention's, which the model honours)."""
    if any(stored(data[et], keys_.EDGE_INDEX) for et in keys_.SELF_EDGE_TYPES
           if et in data.edge_types):
        return data
    for et in keys_.CROSS_EDGE_TYPES:
        if et in data.edge_types and not stored(data[et], keys_.EDGE_INDEX):
            del data[et]
    return data


def edge_index_dict(data: HeteroData) -> dict[tuple[str, str, str], Tensor | CompleteEdges]:
    """``data.edge_index_dict`` with a :class:`~strl_pyg.data.CompleteEdges` marker (carrying
    the graph ids of its source and target nodes) for every implicit complete edge type: the
    edge input of a :func:`torch_geometric.nn.to_hetero` model built from
    :class:`~strl_pyg.nn.AttentionConv` layers.

    Every edge type of ``data`` is present; explicit types map to their ``edge_index``. Layers
    that take only tensors need :func:`materialize_complete_edges` instead.
    """
    implicit = set(implicit_edge_types(data))
    out: dict[tuple[str, str, str], Tensor | CompleteEdges] = {}
    for et in data.edge_types:
        if et in implicit:
            src, _, dst = et
            batched = isinstance(data, Batch)
            out[et] = CompleteEdges(_batch_of(data, src), _batch_of(data, dst)) if batched \
                else CompleteEdges()
        elif stored(data[et], keys_.EDGE_INDEX):
            out[et] = data[et].edge_index
        else:
            raise ValueError(f"Expected '{keys_.EDGE_INDEX}' or '{keys_.DENSE}' on edge type {et} "
                             "(got neither)")
    return out


def _explicit(data: HeteroData) -> HeteroData:
    """``data`` itself when nothing is implicit, else a materialised shallow copy."""
    if not implicit_edge_types(data):
        return data
    return materialize_complete_edges(copy.copy(data))


def _refuse(data: HeteroData, what: str) -> None:
    implicit = implicit_edge_types(data)
    if implicit:
        raise ImplicitEdgesError(
            f"Expected explicit edges for {what} (got implicit complete edge types "
            f"{implicit[0]} and {len(implicit) - 1} more): call "
            "materialize_complete_edges(data) first, or pass "
            "strl_pyg.data.edge_index_dict(data) to strl_pyg layers"
        )


class PairGraph(HeteroData):
    """A :class:`~torch_geometric.data.HeteroData` pair graph whose implicit complete edge
    types survive PyG's conversions, or make them refuse (see the module docstring). Returned
    by :func:`~strl_pyg.data.build_pair_graph` and :func:`~strl_pyg.data.load_graph`; a plain
    ``HeteroData`` converts with ``PairGraph.from_dict(data.to_dict())``."""

    def get_edge_store(self, src: str, rel: str, dst: str) -> EdgeStorage:
        key = (src, rel, dst)
        out = self._edge_store_dict.get(key)
        if out is None:
            self._check_type_name(rel)
            out = PairEdgeStorage(_parent=self, _key=key)
            self._edge_store_dict[key] = out
        return out

    @classmethod
    def from_dict(cls, mapping: dict[Any, Any]) -> PairGraph:
        out = super().from_dict(mapping)
        for key, store in list(out._edge_store_dict.items()):
            if type(store) is EdgeStorage:
                out._edge_store_dict[key] = PairEdgeStorage(_parent=out, _key=key,
                                                             **store.to_dict())
        return out

    def subgraph(self, subset_dict: dict[str, Tensor]) -> PairGraph:
        """As :meth:`HeteroData.subgraph`; an implicit complete edge type stays implicit (a
        subgraph of a complete graph is complete on the kept nodes)."""
        with _native(self):
            out = super().subgraph(subset_dict)
        out.__dict__["_native"] = False
        return out

    def node_type_subgraph(self, node_types: list[str]) -> PairGraph:
        with _native(self):
            out = super().node_type_subgraph(node_types)
        out.__dict__["_native"] = False
        return out

    def edge_type_subgraph(self, edge_types: list[tuple[str, str, str]]) -> PairGraph:
        with _native(self):
            out = super().edge_type_subgraph(edge_types)
        out.__dict__["_native"] = False
        return out

    def collect(self, key: str, allow_empty: bool = False) -> dict[Any, Any]:
        if key == keys_.EDGE_INDEX:
            _refuse(self, "edge_index / edge_index_dict")
        return super().collect(key, allow_empty)

    def get_all_edge_attrs(self) -> list:
        _refuse(self, "the graph-store view (PyG samplers and loaders)")
        return super().get_all_edge_attrs()

    def to_homogeneous(self, *args: Any, **kwargs: Any):
        """As :meth:`HeteroData.to_homogeneous`, with the implicit complete edges
        materialised first (on a copy): the same result as for explicit edges."""
        return HeteroData.to_homogeneous(_explicit(self), *args, **kwargs)

    def has_isolated_nodes(self) -> bool:
        return HeteroData.has_isolated_nodes(_explicit(self))

    def is_undirected(self) -> bool:
        return HeteroData.is_undirected(_explicit(self))

    def connected_components(self) -> list:
        return HeteroData.connected_components(_explicit(self))

    @property
    def num_edges(self) -> int:
        """All edges, the implicit complete ones counted as if explicit."""
        implicit = set(implicit_edge_types(self))
        total = 0
        for et, store in self.edge_items():
            if et not in implicit:
                total += store.num_edges
                continue
            n = _num_graphs(self)
            src, _, dst = et
            count_src = torch.bincount(_batch_of(self, src), minlength=n)
            count_dst = torch.bincount(_batch_of(self, dst), minlength=n)
            total += int((count_src * count_dst.to(count_src.device)).sum())
        return total

    def validate(self, raise_on_error: bool = True) -> bool:
        """:meth:`HeteroData.validate`, plus: each complete edge type carries exactly one of
        ``dense`` (a bool per graph) and explicit edges (``edge_index``, or the ``adj_t`` /
        ``adj`` that :class:`torch_geometric.transforms.ToSparseTensor` makes of it)."""
        with _native(self):  # PyG's own checks skip the edge types without 'edge_index'
            status = super().validate(raise_on_error)
        n = _num_graphs(self)
        marked = [et for et in self.edge_types if keys_.DENSE in self[et]]
        for et in dict.fromkeys((*keys_.COMPLETE_EDGE_TYPES, *marked)):
            if et not in self.edge_types:
                continue
            store = self[et]
            # explicit edges: an edge index, or the sparse adjacency PyG's ToSparseTensor
            # makes of one ('adj_t', or 'adj' with its layout options)
            has_dense = keys_.DENSE in store
            has_ei = any(stored(store, k) for k in (keys_.EDGE_INDEX, "adj_t", "adj"))
            problem = None
            if has_dense == has_ei:
                got = "both" if has_dense else "neither"
                problem = (f"Expected edge type {et} to carry either '{keys_.DENSE}' or "
                           f"'{keys_.EDGE_INDEX}' / a sparse adjacency 'adj_t' (got {got})")
            elif has_dense:
                d = store[keys_.DENSE]
                if not isinstance(d, Tensor) or d.dtype != torch.bool or d.shape != (n,):
                    got = (f"{d.dtype} {tuple(d.shape)}" if isinstance(d, Tensor)
                           else type(d).__name__)
                    problem = (f"Expected '{keys_.DENSE}' of edge type {et} as one bool per graph, "
                               f"shape ({n},) (got {got})")
            if problem is not None:
                if raise_on_error:
                    raise ValueError(problem)
                status = False
        return status
