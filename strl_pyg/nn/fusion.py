"""Feature Weighted Fusion head: gated per-graph pooling of both streams, pose and variance."""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch_geometric.utils import scatter

from strl_pyg.nn.attention import mlp, reset_mlp

__all__ = ["WeightedFusion"]


class WeightedFusion(nn.Module):
    r"""The Feature Weighted Fusion Module of "Str-L Pose" (Zhang et al.),
    with two output MLPs as in UA-Fusion (Zhuang & Chandraker, CVPR 2021):

    .. math::
        w^s_i &= \sigma\big(\mathbf{a}_s^{\top} \mathbf{f}^s_i + b_s\big), \qquad
        \mathbf{z}^s_g = \frac{1}{|\mathcal{V}_g|} \sum_{i \in \mathcal{V}_g}
        w^s_i \, \mathbf{f}^s_i \quad (s \in \{\mathrm{geo}, \mathrm{vis}\})

        \boldsymbol{\mu}_g &= \mathrm{MLP}_{\mu}([\mathbf{z}^{geo}_g \Vert \mathbf{z}^{vis}_g]),
        \qquad \log \boldsymbol{\sigma}^2_g = \mathrm{MLP}_{\sigma}([\mathbf{z}^{geo}_g \Vert
        \mathbf{z}^{vis}_g])

    With ``weighted=False`` the gates are :math:`w^s_i = 1` (plain average pooling, the
    ablation rows without ``W``). The head predicts the log-variance rather than the inverse
    variance for numerical stability (``exp(-log_var)`` is the inverse variance). A graph with
    no nodes pools to zeros.

    Args:
        geo_channels (int): Size of the geometric node features.
        vis_channels (int): Size of the visual node features; :obj:`0` when there is no visual
            stream.
        out_channels (int): Size of the pose vector (and of the log-variance).
        hidden_channels (int, optional): Hidden width of both MLPs; defaults to
            ``geo_channels``. (default: :obj:`None`)
        weighted (bool, optional): Learn the per-node sigmoid gates. (default: :obj:`True`)

    Shapes:
        - **input:** geometric features :math:`(N, C_g)`, visual features :math:`(N, C_v)` or
          :obj:`None`, graph ids :math:`(N)` or :obj:`None`, number of graphs :math:`B`
        - **output:** pose :math:`(B, O)`, log-variance :math:`(B, O)`
    """

    def __init__(
        self,
        geo_channels: int,
        vis_channels: int,
        out_channels: int,
        hidden_channels: int | None = None,
        weighted: bool = True,
    ) -> None:
        super().__init__()
        self.geo_channels = geo_channels
        self.vis_channels = vis_channels
        self.out_channels = out_channels
        self.hidden_channels = hidden = hidden_channels or geo_channels
        self.weighted = weighted
        self.gate_geo = nn.Linear(geo_channels, 1) if weighted else None
        self.gate_vis = nn.Linear(vis_channels, 1) if weighted and vis_channels > 0 else None
        in_ch = geo_channels + vis_channels
        self.pose_mlp = mlp([in_ch, hidden, hidden, out_channels])
        self.var_mlp = mlp([in_ch, hidden, out_channels])
        self.reset_parameters()

    def reset_parameters(self) -> None:
        for gate in (self.gate_geo, self.gate_vis):
            if gate is not None:
                gate.reset_parameters()
        reset_mlp(self.pose_mlp)
        reset_mlp(self.var_mlp)
        # Start near unit variance (the loss is then about a plain squared error at step 0);
        # not exactly zero weights, which would block gradients to the hidden layers.
        with torch.no_grad():
            self.var_mlp[-1].weight.mul_(0.01)
        nn.init.zeros_(self.var_mlp[-1].bias)

    def pool(self, x: Tensor, gate: nn.Module | None, batch: Tensor | None,
             num_graphs: int) -> Tensor:
        """Gated mean over the nodes of each graph, :math:`(N, C) \\to (B, C)`."""
        if gate is not None:
            x = torch.sigmoid(gate(x)) * x
        if batch is None:
            batch = x.new_zeros(x.shape[0], dtype=torch.long)
        return scatter(x, batch, dim=0, dim_size=num_graphs, reduce="mean")

    def forward(self, x_geo: Tensor, x_vis: Tensor | None, batch: Tensor | None,
                num_graphs: int) -> tuple[Tensor, Tensor]:
        z = [self.pool(x_geo, self.gate_geo, batch, num_graphs)]
        if self.vis_channels > 0:
            if x_vis is None:
                raise ValueError("Expected visual node features (got None)")
            z.append(self.pool(x_vis, self.gate_vis, batch, num_graphs))
        z = torch.cat(z, dim=-1)
        return self.pose_mlp(z), self.var_mlp(z)

    def __repr__(self) -> str:
        return (
            f"{self.__class__.__name__}(geo={self.geo_channels}, vis={self.vis_channels}, "
            f"out={self.out_channels}, weighted={self.weighted})"
        )
