"""One layer of the Str-L Pose dual graph: the GCG (geometric) and GGVG (visual) updates."""

from __future__ import annotations

from torch import Tensor, nn

from strl_pyg.data import CompleteEdges
from strl_pyg.nn.attention import AttentionConv
from strl_pyg.nn.layout import DenseLayout
from strl_pyg.nn.line import LineEndpointConv

__all__ = ["DualGraphLayer"]


class DualGraphLayer(nn.Module):
    r"""One layer :math:`l` of the dual graph of "Str-L Pose" (Zhang et al., Figure 1,
    middle): the Geometric Correspondence Graph (GCG) update of the geometric features
    :math:`\mathbf{g}`, then the Geometry-Guided Visual Graph (GGVG) update of the visual
    features :math:`\mathbf{v}`, over the same nodes (node :math:`i` of both streams is the
    same match), in this order:

    1. GCG self-attention over all nodes :math:`j` of the pair of node :math:`i`
       (:class:`AttentionConv` ``geo_self``):
       :math:`\mathbf{g}_i \leftarrow \mathbf{g}_i + F_g([\mathbf{g}_i \Vert \mathbf{m}_i])`,
       :math:`\mathbf{m}_i = \sum_j \operatorname{softmax}_j(\mathbf{q}(\mathbf{g}_i)^{\top}
       \mathbf{k}(\mathbf{g}_j) / \sqrt{d})\, \mathbf{v}(\mathbf{g}_j)` (multi-head);
    2. line-endpoint message passing (``line_conv``, with ``line_mp``): for the two endpoints
       of each matched line segment,
       :math:`\mathbf{g}_i \leftarrow \mathbf{g}_i + \operatorname{mean}_{j \in
       \mathcal{N}_L(i)} F_L([\mathbf{g}_i \Vert \mathbf{g}_j \Vert \mathbf{f}^0_{j,L}])`
       (:class:`LineEndpointConv`; matched points are left unchanged);
    3. GGVG self-attention (``vis_self``, with a visual graph): step 1 on :math:`\mathbf{v}`;
    4. Geometry-Guided cross-attention (``vis_cross``): **queries** from this layer's updated
       geometric features :math:`\mathbf{g}_i` (GCG), **keys and values** from the visual
       features :math:`\mathbf{v}_j` (GGVG) of the nodes of the same pair; it updates the
       visual features,
       :math:`\mathbf{v}_i \leftarrow \mathbf{v}_i + F_{guide}([\mathbf{v}_i \Vert
       \mathbf{m}^{GG}_i])`, :math:`\mathbf{m}^{GG}_i = \sum_j
       \operatorname{softmax}_j(\mathbf{q}(\mathbf{g}_i)^{\top}\mathbf{k}(\mathbf{v}_j) /
       \sqrt{d})\, \mathbf{v}(\mathbf{v}_j)` (the paper's eq. 12). The geometric features are
       not changed by it.

    Args:
        channels (int): Width :math:`C` of both streams.
        heads (int, optional): Attention heads. (default: :obj:`4`)
        mlp_ratio (int, optional): Hidden width of every update MLP, as a multiple of
            :math:`C`. (default: :obj:`2`)
        dropout (float, optional): Attention-weight dropout. (default: :obj:`0.0`)
        line_channels (int, optional): Width :math:`C_L` of the line-segment feature
            :math:`\mathbf{f}^0_L`; :obj:`None`: no line-endpoint message passing.
            (default: :obj:`None`)
        visual (bool, optional): Add the GGVG updates (steps 3 and 4). (default: :obj:`True`)

    Shapes:
        - **input:** geometric features :math:`(N, C)`, visual features :math:`(N, C)` or
          :obj:`None`; ``self_edges`` / ``cross_edges`` explicit :math:`(2, E)` (source
          :math:`j`, target :math:`i`) or a :class:`CompleteEdges` marker (complete within each
          graph of ``layout``); ``line_edges`` :math:`(2, E_L)` and ``line_feat``
          :math:`(N, C_L)` (zeros on points), or :obj:`None` (no lines in the batch: step 2 is
          skipped)
        - **output:** ``(g, v)`` of the input shapes
    """

    def __init__(self, channels: int, heads: int = 4, mlp_ratio: int = 2,
                 dropout: float = 0.0, line_channels: int | None = None,
                 visual: bool = True) -> None:
        super().__init__()
        self.channels = channels

        def attn() -> AttentionConv:
            return AttentionConv(channels, heads=heads, mlp_ratio=mlp_ratio, dropout=dropout)

        self.geo_self = attn()
        self.line_conv = (LineEndpointConv(channels, line_channels, mlp_ratio)
                          if line_channels is not None else None)
        self.vis_self = attn() if visual else None
        self.vis_cross = attn() if visual else None

    def reset_parameters(self) -> None:
        for m in (self.geo_self, self.line_conv, self.vis_self, self.vis_cross):
            if m is not None:
                m.reset_parameters()

    def forward(self, g: Tensor, v: Tensor | None, *,
                self_edges: Tensor | CompleteEdges,
                cross_edges: Tensor | CompleteEdges | None = None,
                line_edges: Tensor | None = None, line_feat: Tensor | None = None,
                layout: DenseLayout | None = None) -> tuple[Tensor, Tensor | None]:
        """Args: ``layout`` the node layout of complete attention (see
        :class:`~strl_pyg.nn.DenseLayout`; ``None`` with a marker: one graph, or the graph
        ids the marker carries)."""
        def lay(edges):
            return layout if isinstance(edges, CompleteEdges) else None

        g = self.geo_self(g, self_edges, layout=lay(self_edges))
        if self.line_conv is not None and line_edges is not None:
            assert callable(self.line_conv)
            if line_feat is None:
                raise ValueError("Expected line_feat together with line_edges (got None)")
            g = self.line_conv(g, line_edges, line_feat)
        if self.vis_self is not None:
            if v is None or cross_edges is None:
                raise ValueError("Expected visual features and cross_edges for a layer with a "
                                 f"visual graph (got v={type(v).__name__}, "
                                 f"cross_edges={type(cross_edges).__name__})")
            assert self.vis_cross is not None  # built together with vis_self
            v = self.vis_self(v, self_edges, layout=lay(self_edges))
            v = self.vis_cross((v, v), cross_edges, query=g, layout=lay(cross_edges))
        return g, v

    def __repr__(self) -> str:
        return (f"{self.__class__.__name__}({self.channels}, "
                f"line={self.line_conv is not None}, visual={self.vis_self is not None})")
