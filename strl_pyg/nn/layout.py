"""Where the nodes of a batch sit in padded per-graph blocks, computed once per forward."""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["DenseLayout"]


class DenseLayout:
    r"""The padded block layout of the nodes of :math:`B` graphs: node :math:`n` of graph
    ``batch[n]`` goes to row ``index[n]`` of block ``batch[n]`` of a :math:`(B, L, \dots)`
    tensor, :math:`L` the largest graph, ``index[n]`` the node's rank among the nodes of its
    graph in storage order (nodes need not be sorted by graph).

    Dense (complete) attention pads per-graph blocks to :math:`L`. Working out :math:`L`
    needs the node counts on the host, so a layout is built **once**, at a public boundary
    (:meth:`from_batch`, one host synchronisation), and every layer then scatters and gathers
    with it without touching the host again (what makes a ``torch.compile``\ d forward one
    graph).

    Build it with :meth:`from_batch` (or :meth:`single` for one graph, :meth:`from_counts` from
    :meth:`block_index` and a block size read by the caller); the constructor takes
    precomputed parts and trusts them.

    Attributes:
        batch: ``[N]`` graph id of every node, or ``None``: one graph, no padding.
        index: ``[N]`` row of every node inside its graph's block (``None`` with ``batch``).
        mask: ``[B, L]`` bool, ``True`` where a block row holds a node (``None`` with
            ``batch``).
        counts: ``[B]`` nodes per graph (``None`` with ``batch``).
        num_nodes, num_graphs, max_nodes: :math:`N`, :math:`B`, :math:`L` as Python ints.
    """

    __slots__ = ("batch", "index", "mask", "counts", "num_nodes", "num_graphs", "max_nodes")

    def __init__(self, batch: Tensor | None, index: Tensor | None, mask: Tensor | None,
                 counts: Tensor | None, num_nodes: int, num_graphs: int,
                 max_nodes: int) -> None:
        self.batch = batch
        self.index = index
        self.mask = mask
        self.counts = counts
        self.num_nodes = num_nodes
        self.num_graphs = num_graphs
        self.max_nodes = max_nodes

    @classmethod
    def single(cls, num_nodes: int) -> DenseLayout:
        """All ``num_nodes`` nodes form one graph."""
        return cls(None, None, None, None, num_nodes, 1, num_nodes)

    @classmethod
    def from_batch(cls, batch: Tensor | None, num_nodes: int, num_graphs: int | None = None,
                   *, validate: bool = True) -> DenseLayout:
        """The layout of nodes with graph ids ``batch`` ``[N]`` (any order; ``None``: one graph).

        Args:
            batch: 1-D long graph ids, or ``None``.
            num_nodes: :math:`N`.
            num_graphs: :math:`B` (default: the largest id + 1). Graphs without nodes are
                allowed (their block is all padding).
            validate: check shape, dtype and id range (a host synchronisation); a caller that
                built ``batch`` itself (the model from a PyG batch) may skip it.

        Reads the host once for :math:`L`, and once more for the id range when validating
        or when ``num_graphs`` is not given.
        """
        if batch is None:
            return cls.single(num_nodes)
        if validate and (not isinstance(batch, Tensor) or batch.dim() != 1
                         or batch.dtype != torch.long):
            got = (f"{batch.dtype} {tuple(batch.shape)}" if isinstance(batch, Tensor)
                   else type(batch).__name__)
            raise TypeError(f"Expected graph ids as a 1-D long tensor (got {got})")
        if batch.numel() != num_nodes:
            raise ValueError(f"Expected one graph id per node (got {batch.numel()} ids for "
                             f"{num_nodes} nodes)")
        if num_graphs is not None and (isinstance(num_graphs, bool)
                                       or not isinstance(num_graphs, int) or num_graphs < 1):
            raise ValueError(f"Expected num_graphs as a positive int (got {num_graphs!r})")
        if num_nodes == 0:
            B = 1 if num_graphs is None else num_graphs
            counts = batch.new_zeros(B)
            return cls(batch, batch, torch.zeros(B, 0, dtype=torch.bool, device=batch.device),
                       counts, 0, B, 0)
        if num_graphs is None or validate:
            lo, hi = torch.stack([batch.min(), batch.max()]).tolist()
            if lo < 0 or (num_graphs is not None and hi >= num_graphs):
                raise ValueError(f"Expected graph ids in [0, {num_graphs}) (got ids in "
                                 f"[{lo}, {hi}])")
            num_graphs = hi + 1 if num_graphs is None else num_graphs
        counts, index = cls.block_index(batch, num_nodes, num_graphs)
        return cls.from_counts(batch, index, counts, int(counts.max()))  # the one host read

    @staticmethod
    def block_index(batch: Tensor, num_nodes: int, num_graphs: int) -> tuple[Tensor, Tensor]:
        """``counts`` ``[B]`` (nodes per graph) and ``index`` ``[N]`` (row of each node in its
        graph's block) of valid graph ids, without a host synchronisation."""
        counts = batch.new_zeros(num_graphs).index_add_(0, batch, torch.ones_like(batch))
        start = counts.cumsum(0) - counts
        perm = torch.argsort(batch, stable=True)
        rank = torch.arange(num_nodes, device=batch.device) - start[batch[perm]]
        return counts, torch.empty_like(rank).index_copy_(0, perm, rank)

    @classmethod
    def from_counts(cls, batch: Tensor, index: Tensor, counts: Tensor,
                    max_nodes: int) -> DenseLayout:
        """The layout from :meth:`block_index`'s parts and the block size
        ``max_nodes = int(counts.max())``, read by the caller (a compiled caller
        reads it in its own frame: one graph break, not one per nested call)."""
        mask = torch.arange(max_nodes, device=batch.device)[None, :] < counts[:, None]
        return cls(batch, index, mask, counts, batch.numel(), counts.numel(), max_nodes)

    def to_dense(self, x: Tensor) -> Tensor:
        """``[N, *F]`` node rows -> ``[B, L, *F]`` blocks, zeros in the padding."""
        if x.shape[0] != self.num_nodes:
            raise ValueError(f"Expected {self.num_nodes} node rows for this layout "
                             f"(got {x.shape[0]})")
        if self.batch is None:
            return x.unsqueeze(0)
        out = x.new_zeros((self.num_graphs, self.max_nodes, *x.shape[1:]))
        return out.index_put((self.batch, self.index), x)

    def from_dense(self, x: Tensor) -> Tensor:
        """``[B, L, *F]`` blocks -> ``[N, *F]`` node rows, in storage order."""
        if self.batch is None:
            return x[0]
        return x[self.batch, self.index]

    def __repr__(self) -> str:
        return (f"{self.__class__.__name__}(num_nodes={self.num_nodes}, "
                f"num_graphs={self.num_graphs}, max_nodes={self.max_nodes})")
