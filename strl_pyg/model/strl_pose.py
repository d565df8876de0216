"""The Str-L Pose network: encoders, dual graph (GCG + GGVG), weighted fusion, pose head.

Reads top to bottom: the model, its modules in the order of Figure 1 of the paper. Its file
I/O (save, load, metadata, the shipped weights) is the mixin of :mod:`strl_pyg.model.checkpoint`;
the configuration and output containers live in :mod:`strl_pyg.model.config`, input gathering
(validation, node ordering, edges, the dense block layout) in :mod:`strl_pyg.model.gather`;
both are importable from here.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch_geometric.data import HeteroData

from strl_pyg.data import CompleteEdges
from strl_pyg.data import keys as K
from strl_pyg.model.checkpoint import CheckpointIO
from strl_pyg.model.config import NO_INTRINSICS, GeometricOutput, PoseOutput, StrLPoseConfig
from strl_pyg.model.gather import ModelInputs, gather_inputs
from strl_pyg.model.legacy import upgrade_legacy_keys
from strl_pyg.nn import (
    DenseLayout,
    DualGraphLayer,
    ImageEncoder,
    InlierHead,
    LineSegmentEncoder,
    PixelEncoder,
    PoseHead,
    SpatialCoordinateEncoder,
    WeightedFusion,
)

__all__ = ["StrLPose"]


# ----------------------------------------------------------------------------- the model
def _in_dtype(inp, dtype: torch.dtype):
    """The gathered inputs' floating tensors in the model's dtype, so that a model moved with
    ``.to(torch.bfloat16)`` (or float64) runs on a float32 graph."""
    from dataclasses import fields, replace

    def cast(x):
        if isinstance(x, Tensor) and x.is_floating_point() and x.dtype != dtype:
            return x.to(dtype)
        if isinstance(x, tuple):
            return tuple(cast(y) for y in x)
        return x

    return replace(inp, **{f.name: cast(getattr(inp, f.name)) for f in fields(inp)
                           if f.name in ("coords", "line_feat", "visual", "images", "kpts")})


class StrLPose(CheckpointIO, nn.Module):
    r"""Str-L Pose: relative pose ``T_0to1`` from a pair graph of matched points and line
    segments (Zhang et al., "Str-L Pose: Integrating Point and Structured Line for Relative Pose
    Estimation in Dual-Graph").

    Figure 1 of the paper, left to right: encoders (``sce``, ``lse``, ``pe`` or
    ``image_encoder``); ``layers``, one :class:`~strl_pyg.nn.DualGraphLayer` per layer
    :math:`l` (GCG self-attention over all nodes of a pair, line-endpoint message passing
    with ``line_mp``, GGVG self-attention and Geometry-Guided cross-attention with
    ``visual_graph``: queries from this layer's GCG features, keys and values from the GGVG
    features); ``fusion`` (:class:`~strl_pyg.nn.WeightedFusion`, gated pooling of both
    streams per pair); ``pose_head`` (:class:`~strl_pyg.nn.PoseHead`, pose and log-variance);
    with ``geometric``, ``inlier_head`` (:class:`~strl_pyg.nn.InlierHead`) and the weighted
    essential solve.

    Complete edge types are computed on the dense path when the graph marks them implicit
    (``dense``, the default of :func:`~strl_pyg.data.build_pair_graph`), and by sparse message
    passing when they carry explicit ``edge_index`` tensors; both give the same result.

    Pose parameterisation: a unit quaternion ``(w, x, y, z)`` with canonical sign ``w >= 0``
    (the raw 4-vector is normalised) and a translation that is a unit direction
    (``translation="direction"``, scale-free data such as DeMoN) or metric (``"metric"``,
    driving data such as KITTI).

    Args:
        config: a :class:`StrLPoseConfig` (default: the full model).

    Shapes:
        - **input:** a :class:`~torch_geometric.data.HeteroData` pair graph or a batch of
          :math:`B` of them (see :mod:`strl_pyg.data.keys`).
        - **output:** :class:`PoseOutput` with ``quaternion`` :math:`(B, 4)`, ``translation``
          :math:`(B, 3)`, ``log_var`` :math:`(B, 7)`.
    """

    def __init__(self, config: StrLPoseConfig | None = None) -> None:
        super().__init__()
        cfg = self.config = config if config is not None else StrLPoseConfig()
        cfg.validate()
        C = cfg.hidden
        # Feature encoders (Figure 1, left)
        self.sce = SpatialCoordinateEncoder(C, inputs=cfg.inputs)
        self.lse = LineSegmentEncoder(cfg.line_channels) if cfg.line_mp else None
        self.pe = PixelEncoder(cfg.patch_features, C) if cfg.visual == "pixel" else None
        self.image_encoder = ImageEncoder(cfg.image_channels, C) if cfg.visual == "cnn" else None
        # Dual graph (middle): GCG + GGVG, layer by layer
        self.layers = nn.ModuleList([
            DualGraphLayer(C, heads=cfg.heads, mlp_ratio=cfg.mlp_ratio, dropout=cfg.dropout,
                           line_channels=cfg.line_channels if cfg.line_mp else None,
                           visual=cfg.visual_graph)
            for _ in range(cfg.layers)
        ])
        # Feature Weighted Fusion (right): gated pooling, then the pose/uncertainty head
        self.fusion = WeightedFusion(C, C if cfg.visual else 0, weighted=cfg.weighted)
        self.pose_head = PoseHead(self.fusion.out_channels, C, translation=cfg.translation)
        # Beyond the paper: per-node inlier logits for the weighted essential solve
        self.inlier_head = (InlierHead(self.fusion.out_channels, C) if cfg.geometric
                            else None)
        self.register_load_state_dict_pre_hook(upgrade_legacy_keys)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """Re-initialises every parameter. The modules are reset in the order of the
        version-1 layout (encoders, all GCG self-attentions, all line convolutions, all GGVG
        self-attentions, all cross-attentions, fusion gates, pose head, inlier head), so a seed
        gives the same initial weights as models of that layout did."""
        parts: list[nn.Module | None] = [self.sce, self.lse, self.pe, self.image_encoder]
        for name in ("geo_self", "line_conv", "vis_self", "vis_cross"):
            parts += [getattr(layer, name) for layer in self.layers]
        parts += [self.fusion, self.pose_head, self.inlier_head]
        for m in parts:
            if m is not None:
                m.reset_parameters()

    def forward(self, data: HeteroData, node_gate: Tensor | None = None) -> PoseOutput:
        """Validates and gathers the graph (:func:`~strl_pyg.model.gather.gather_inputs`), reads
        the padded block size of complete attention from the host (the one synchronisation;
        none for a single graph, or for explicit edges without the geometric head and the
        image encoder), then runs without touching the host.

        ``node_gate`` (``[N]`` or ``[N, 1]``, the nodes in the model's order: a single graph's
        points, then its endpoints) scales each node's encoded features: the soft node mask
        that explainers learn (:mod:`strl_pyg.explain`); ``None`` (the default) is all ones."""
        cfg = self.config
        inp = _in_dtype(gather_inputs(cfg, data), next(self.parameters()).dtype)
        gate = None
        if node_gate is not None:
            n = inp.coords.shape[0]
            if not isinstance(node_gate, Tensor) or node_gate.reshape(-1).shape[0] != n \
                    or node_gate.dim() > 2:
                got = tuple(node_gate.shape) if isinstance(node_gate, Tensor) else \
                    type(node_gate).__name__
                raise ValueError(f"Expected node_gate of shape [{n}] or [{n}, 1], one per "
                                 f"node (got {got})")
            gate = node_gate.reshape(n, 1).to(inp.coords.dtype)
        dense = (inp.self_edges is None or (cfg.visual_graph and inp.cross_edges is None)
                 or cfg.visual == "cnn" or cfg.geometric)  # what needs padded blocks
        layout = None
        if inp.block is None:  # one graph: no padding
            layout = DenseLayout.single(inp.coords.shape[0])
        elif dense:  # read here, in forward's own frame: one graph break under torch.compile
            counts, index = inp.block
            layout = DenseLayout.from_counts(inp.batch, index, counts, int(counts.max()))
        g = self.sce(inp.coords, inp.batch, layout)  # the layout: read by parallax inputs
        if gate is not None:
            g = g * gate

        line_full = None
        if self.lse is not None and inp.line_feat is not None and inp.line_edges is not None:
            f0_line = self.lse(inp.line_feat)
            line_full = f0_line.new_zeros(g.shape[0], f0_line.shape[1])
            line_full = line_full.index_copy(0, inp.endpoint_idx, f0_line)
            if gate is not None:
                line_full = line_full * gate

        v = None
        if self.pe is not None:
            v = self.pe(inp.visual)
        elif self.image_encoder is not None:
            v = self.image_encoder.encode_nodes(*inp.images, *inp.kpts, None, layout)
        if v is not None and gate is not None:
            v = v * gate

        complete = CompleteEdges()
        self_edges = complete if inp.self_edges is None else inp.self_edges
        cross_edges = complete if inp.cross_edges is None else inp.cross_edges
        for layer in self.layers:
            g, v = layer(g, v, self_edges=self_edges, cross_edges=cross_edges,
                         line_edges=inp.line_edges if line_full is not None else None,
                         line_feat=line_full, layout=layout)

        geometric = None
        if self.inlier_head is not None:
            geometric = self._geometric(data, inp, layout, g, v)
        z = self.fusion(g, v, inp.batch, inp.num_graphs)
        q, t, log_var = self.pose_head(z)
        return PoseOutput(quaternion=q, translation=t, log_var=log_var, geometric=geometric)

    def _geometric(self, data: HeteroData, inp: ModelInputs, layout: DenseLayout, g: Tensor,
                   v: Tensor | None) -> GeometricOutput:
        from strl_pyg.geometry.essential import OK, decompose_essential, weighted_essential

        cfg = self.config
        h = g if v is None else torch.cat([g, v], dim=-1)
        logits = self.inlier_head(h)
        n, B = logits.shape[0], inp.num_graphs
        batch = inp.batch if inp.batch is not None else logits.new_zeros(n, dtype=torch.long)
        coords = inp.coords
        xy = layout.to_dense(coords)  # [B, Nmax, 4], nodes in model order
        w = layout.to_dense(torch.sigmoid(logits))
        mask = layout.mask if layout.mask is not None else \
            torch.ones(1, n, dtype=torch.bool, device=logits.device)
        est = weighted_essential(xy[..., :2], xy[..., 2:], w, mask,
                                 iterations=cfg.geometric_iterations, tau=cfg.geometric_tau)
        status = est.status
        has_K = K.K0 in data and K.K1 in data
        if has_K:
            K0 = data[K.K0].reshape(-1, 3, 3)
            K1 = data[K.K1].reshape(-1, 3, 3)
            focal = 0.25 * (K0[:, 0, 0] + K0[:, 1, 1] + K1[:, 0, 0] + K1[:, 1, 1])
        else:
            focal = logits.new_ones(B)
            status = torch.full_like(status, NO_INTRINSICS)
        R, t, _ = decompose_essential(est.E.detach(), xy[..., :2].detach(),
                                      xy[..., 2:].detach(), est.weights.detach())
        ok = (status == OK)[:, None]
        R = torch.where(ok[..., None], R, torch.eye(3, dtype=R.dtype, device=R.device))
        t = torch.where(ok, t, torch.zeros_like(t))
        storage = logits if inp.inv is None else logits[inp.inv]
        n_pt = inp.sizes.get(K.POINT, 0) if inp.sizes else 0
        point_logits = storage[:n_pt] if K.POINT in (inp.sizes or {}) else None
        endpoint_logits = storage[n_pt:] if K.ENDPOINT in (inp.sizes or {}) else None
        return GeometricOutput(logits=logits, batch=batch, coords=coords,
                               point_logits=point_logits, endpoint_logits=endpoint_logits,
                               E=est.E, status=status, R=R, t=t, focal=focal.to(logits))

    def __repr__(self) -> str:
        c = self.config
        n = sum(p.numel() for p in self.parameters())
        return (f"{self.__class__.__name__}(hidden={c.hidden}, layers={c.layers}, "
                f"heads={c.heads}, lines={c.use_lines}, line_mp={c.line_mp}, "
                f"visual={c.visual!r}, visual_graph={c.visual_graph}, weighted={c.weighted}, "
                f"params={n})")
