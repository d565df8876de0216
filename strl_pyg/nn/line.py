"""Line-segment endpoint message passing (Line Segment Structural Integration)."""

from __future__ import annotations

import torch
from torch import Tensor
from torch_geometric.nn import MessagePassing

from strl_pyg.nn.mlp import as_index, as_pair, mlp, reset_mlp

__all__ = ["LineEndpointConv"]


class LineEndpointConv(MessagePassing):
    r"""The line-segment endpoint update of "Str-L Pose: Integrating Point and Structured Line
    for Relative Pose Estimation in Dual-Graph" (Zhang et al.; "Line Segment Endpoint Edge"):

    .. math::
        \mathbf{f}_i' = \mathbf{f}_i + \frac{1}{|\mathcal{N}(i)|}
        \sum_{j \in \mathcal{N}(i)} F_L\big([\,\mathbf{f}_i \,\Vert\, \mathbf{f}_j
        \,\Vert\, \mathbf{f}^0_{j,L}\,]\big)

    where the edges join the two endpoints of each matched line segment,
    :math:`\mathbf{f}^0_{j,L}` is the Line Segment Encoder feature of endpoint :math:`j` and
    :math:`F_L` is a two-layer MLP. Nodes without incoming edges (matched points) are returned
    unchanged.

    Args:
        channels (int or tuple): Size of each source and target node feature; a tuple
            ``(src_channels, dst_channels)`` for bipartite inputs. The output has the target
            size. Widths are fixed at construction (no lazy ``-1``).
        line_channels (int): Size of the line-segment feature :math:`\mathbf{f}^0_{L}`.
        mlp_ratio (int, optional): Hidden width of :math:`F_L` as a multiple of the target
            channels. (default: :obj:`2`)
        **kwargs (optional): Additional arguments of
            :class:`torch_geometric.nn.conv.MessagePassing`.

    Shapes:
        - **input:**
          node features :math:`(|\mathcal{V}|, C)` or
          :math:`((|\mathcal{V_s}|, C_s), (|\mathcal{V_t}|, C_t))`,
          edge indices :math:`(2, |\mathcal{E}|)`,
          line features of the source nodes :math:`(|\mathcal{V}_s|, C_L)`, or the
          ``(source, target)`` pair of them that :func:`~torch_geometric.nn.to_hetero` and
          :class:`~torch_geometric.nn.HeteroConv` pass for an edge type whose source and
          target node types differ (the source's are read)
        - **output:** node features :math:`(|\mathcal{V}_t|, C_t)`
    """

    def __init__(
        self, channels: int | tuple[int, int], line_channels: int, mlp_ratio: int = 2, **kwargs
    ) -> None:
        kwargs.setdefault("aggr", "mean")
        src_channels, dst_channels = as_pair(channels)
        for name, value in (("source channels", src_channels),
                            ("target channels", dst_channels),
                            ("line_channels", line_channels), ("mlp_ratio", mlp_ratio)):
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Expected {name} as a positive int (no lazy -1: the MLP "
                                 f"reads the widths together) (got channels={channels!r}, "
                                 f"line_channels={line_channels!r}, mlp_ratio={mlp_ratio!r})")
        super().__init__(**kwargs)
        self.channels = channels
        self.line_channels = line_channels
        self.mlp_ratio = mlp_ratio
        self.mlp = mlp(
            [dst_channels + src_channels + line_channels, mlp_ratio * dst_channels, dst_channels]
        )
        self.reset_parameters()

    def reset_parameters(self) -> None:
        super().reset_parameters()
        reset_mlp(self.mlp)

    def forward(self, x: Tensor | tuple[Tensor, Tensor], edge_index: Tensor,
                line_feat: Tensor | tuple[Tensor | None, Tensor | None]) -> Tensor:
        if isinstance(line_feat, (tuple, list)):  # PyG's hetero machinery: (src, dst)
            first = line_feat[0]
            if first is None:
                raise ValueError("Expected line features of the source node type (got None "
                                 "in the (source, target) pair)")
            line_feat = first
        assert isinstance(line_feat, Tensor)
        x_src, x_dst = as_pair(x)
        src_channels, dst_channels = as_pair(self.channels)
        for what, t, c in (("source", x_src, src_channels), ("target", x_dst, dst_channels),
                           ("line", line_feat, self.line_channels)):
            if t.dim() != 2 or t.shape[-1] != c:
                raise ValueError(f"Expected {what} features of shape [N, {c}] (got "
                                 f"{tuple(t.shape)})")
        if line_feat.shape[0] != x_src.shape[0]:
            raise ValueError(
                "Expected one line feature per source node "
                f"(got {line_feat.shape[0]} and {x_src.shape[0]})"
            )
        size = (x_src.shape[0], x_dst.shape[0])
        agg = self.propagate(as_index(edge_index), x=(x_src, x_dst), line=line_feat,
                             size=size)
        return x_dst + agg

    def message(self, x_i: Tensor, x_j: Tensor, line_j: Tensor) -> Tensor:
        return self.mlp(torch.cat([x_i, x_j, line_j], dim=-1))

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}({self.channels}, line_channels={self.line_channels})"
