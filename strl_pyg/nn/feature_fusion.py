"""Feature Weighted Fusion: sigmoid-gated per-graph pooling of both streams."""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch_geometric.utils import scatter

__all__ = ["WeightedFusion"]


class WeightedFusion(nn.Module):
    r"""The pooling half of the Feature Weighted Fusion Module of "Str-L Pose" (Zhang et
    al.): a sigmoid weight per node and stream, then the mean over the nodes of each graph,
    both streams concatenated:

    .. math::
        w^s_i = \sigma\big(\mathbf{a}_s^{\top} \mathbf{f}^s_i + b_s\big), \qquad
        \mathbf{z}^s_g = \frac{1}{|\mathcal{V}_g|} \sum_{i \in \mathcal{V}_g}
        w^s_i \, \mathbf{f}^s_i \quad (s \in \{\mathrm{geo}, \mathrm{vis}\}), \qquad
        \mathbf{z}_g = [\mathbf{z}^{geo}_g \Vert \mathbf{z}^{vis}_g]

    The paper's module then feeds :math:`\mathbf{z}_g` to two MLPs (pose and uncertainty):
    :class:`~strl_pyg.nn.PoseHead`. With ``weighted=False`` the gates are :math:`w^s_i = 1`
    (plain average pooling, the ablation rows without ``W``). A graph with no nodes pools to
    zeros.

    Args:
        geo_channels (int): Size of the geometric node features.
        vis_channels (int): Size of the visual node features; :obj:`0` when there is no visual
            stream.
        weighted (bool, optional): Learn the per-node sigmoid gates. (default: :obj:`True`)

    Shapes:
        - **input:** geometric features :math:`(N, C_g)`, visual features :math:`(N, C_v)` or
          :obj:`None`, graph ids :math:`(N)` or :obj:`None`, number of graphs :math:`B`
        - **output:** :math:`(B, C_g + C_v)` (:attr:`out_channels`)
    """

    def __init__(self, geo_channels: int, vis_channels: int, weighted: bool = True) -> None:
        super().__init__()
        self.geo_channels = geo_channels
        self.vis_channels = vis_channels
        self.weighted = weighted
        self.gate_geo = nn.Linear(geo_channels, 1) if weighted else None
        self.gate_vis = nn.Linear(vis_channels, 1) if weighted and vis_channels > 0 else None
        self.reset_parameters()

    @property
    def out_channels(self) -> int:
        return self.geo_channels + self.vis_channels

    def reset_parameters(self) -> None:
        for gate in (self.gate_geo, self.gate_vis):
            if gate is not None:
                gate.reset_parameters()

    def pool(self, x: Tensor, gate: nn.Module | None, batch: Tensor | None,
             num_graphs: int) -> Tensor:
        """Gated mean over the nodes of each graph, :math:`(N, C) \\to (B, C)`."""
        if gate is not None:
            x = torch.sigmoid(gate(x)) * x
        if batch is None:
            batch = x.new_zeros(x.shape[0], dtype=torch.long)
        return scatter(x, batch, dim=0, dim_size=num_graphs, reduce="mean")

    def forward(self, x_geo: Tensor, x_vis: Tensor | None, batch: Tensor | None,
                num_graphs: int) -> Tensor:
        z = [self.pool(x_geo, self.gate_geo, batch, num_graphs)]
        if self.vis_channels > 0:
            if x_vis is None:
                raise ValueError("Expected visual node features (got None)")
            z.append(self.pool(x_vis, self.gate_vis, batch, num_graphs))
        return torch.cat(z, dim=-1)

    def __repr__(self) -> str:
        return (f"{self.__class__.__name__}(geo={self.geo_channels}, vis={self.vis_channels}, "
                f"weighted={self.weighted})")
