"""Output heads: the paper's pose and uncertainty regression, and the per-node inlier head of
the geometric (weighted essential-matrix) output."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from strl_pyg.nn.mlp import mlp, reset_mlp

__all__ = ["PoseHead", "InlierHead", "TRANSLATION_MODES"]

TRANSLATION_MODES = ("direction", "metric")


class PoseHead(nn.Module):
    r"""The two output MLPs of the Feature Weighted Fusion Module of "Str-L Pose" (as in
    UA-Fusion, Zhuang & Chandraker, CVPR 2021): from the pooled pair feature
    :math:`\mathbf{z}_g` (:class:`~strl_pyg.nn.WeightedFusion`),

    .. math::
        [\tilde{\mathbf{q}} \Vert \tilde{\mathbf{t}}] = \mathrm{MLP}_{\mu}(\mathbf{z}_g),
        \qquad \log \boldsymbol{\sigma}^2 = \mathrm{MLP}_{\sigma}(\mathbf{z}_g),

    :math:`\mathbf{q} = \pm\tilde{\mathbf{q}} / \lVert\tilde{\mathbf{q}}\rVert` a unit
    quaternion ``(w, x, y, z)`` with the canonical sign :math:`w \ge 0`, and
    :math:`\mathbf{t} = \tilde{\mathbf{t}} / \lVert\tilde{\mathbf{t}}\rVert` (``"direction"``,
    scale-free data) or :math:`\tilde{\mathbf{t}}` (``"metric"``). The head predicts the
    log-variance of the 7 components rather than the paper's inverse variance, for numerical
    stability (``exp(-log_var)`` is the inverse variance).

    Initialisation (:meth:`reset_parameters`): the last layer of :math:`\mathrm{MLP}_{\mu}`
    gets ``+1`` on the bias of :math:`\tilde{q}_w` (the network starts near the identity
    rotation); the last layer of :math:`\mathrm{MLP}_{\sigma}` is scaled by 0.01 with a zero
    bias (near unit variance, so the loss starts close to a squared error; not exactly zero
    weights, which would block gradients to the hidden layers).

    Args:
        in_channels (int): Size of :math:`\mathbf{z}_g`.
        hidden_channels (int): Hidden width of both MLPs.
        translation (str, optional): ``"direction"`` or ``"metric"``.
            (default: :obj:`"direction"`)

    Shapes:
        - **input:** :math:`(B, C_{in})`
        - **output:** quaternion :math:`(B, 4)`, translation :math:`(B, 3)`, log-variance
          :math:`(B, 7)` (quaternion components first)
    """

    def __init__(self, in_channels: int, hidden_channels: int,
                 translation: str = "direction") -> None:
        super().__init__()
        if translation not in TRANSLATION_MODES:
            raise ValueError(f"Expected translation in {TRANSLATION_MODES} "
                             f"(got {translation!r})")
        self.in_channels = in_channels
        self.hidden_channels = hidden_channels
        self.translation = translation
        self.pose_mlp = mlp([in_channels, hidden_channels, hidden_channels, 7])
        self.var_mlp = mlp([in_channels, hidden_channels, 7])
        self.reset_parameters()

    def reset_parameters(self) -> None:
        reset_mlp(self.pose_mlp)
        reset_mlp(self.var_mlp)
        var_out, pose_out = self.var_mlp[-1], self.pose_mlp[-1]
        assert isinstance(var_out, nn.Linear) and isinstance(pose_out, nn.Linear)
        with torch.no_grad():
            var_out.weight.mul_(0.01)
            var_out.bias.zero_()
            pose_out.bias[0] += 1.0  # start at the identity rotation

    def forward(self, z: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        raw = self.pose_mlp(z)
        q = raw[:, :4]
        q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-8)
        q = torch.where(q[:, :1] < 0, -q, q)
        t = raw[:, 4:]
        if self.translation == "direction":
            t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-8)
        return q, t, self.var_mlp(z)

    def __repr__(self) -> str:
        return (f"{self.__class__.__name__}({self.in_channels}, hidden={self.hidden_channels}, "
                f"translation={self.translation!r})")


class InlierHead(nn.Sequential):
    r"""Per-node inlier logits of the geometric head (``StrLPoseConfig.geometric``):
    ``Linear(C_in, C) -> ReLU -> Linear(C, C/2) -> ReLU -> Linear(C/2, 1)`` on the
    concatenated final node features of both streams; the sigmoid of a logit is the node's
    weight in the weighted essential-matrix solve (:mod:`strl_pyg.geometry.essential`).

    Args:
        in_channels (int): :math:`C_{in}` (geometric plus visual feature size).
        hidden_channels (int): :math:`C`.

    Shapes:
        - **input:** :math:`(N, C_{in})`
        - **output:** logits :math:`(N)`
    """

    def __init__(self, in_channels: int, hidden_channels: int) -> None:
        super().__init__(nn.Linear(in_channels, hidden_channels), nn.ReLU(),
                         nn.Linear(hidden_channels, hidden_channels // 2), nn.ReLU(),
                         nn.Linear(hidden_channels // 2, 1))
        self.in_channels = in_channels
        self.hidden_channels = hidden_channels

    def reset_parameters(self) -> None:
        reset_mlp(self)

    def forward(self, x: Tensor) -> Tensor:
        return super().forward(x).squeeze(-1)
