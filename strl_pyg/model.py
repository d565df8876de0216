"""The Str-L Pose network: encoders, dual graph (GCG + GGVG), weighted fusion, pose head.

Reads top to bottom: configuration, output container, input gathering (validation, node
ordering, edges), the model.

Node layout inside the model: the nodes of the active node types (points, plus line endpoints
when ``use_lines``) are concatenated and stably sorted by graph id once, so that every layer
sees graph-contiguous nodes; the geometric and the visual stream share this node set (node
``i`` of the GGVG is the same match as node ``i`` of the GCG).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn
from torch_geometric.data import Batch, HeteroData

from strl_pyg.data import keys as K
from strl_pyg.geometry import Pose, quaternion_to_rotation
from strl_pyg.io import atomic_open, safe_torch_load
from strl_pyg.nn import (
    AttentionConv,
    ImageEncoder,
    LineEndpointConv,
    LineSegmentEncoder,
    PixelEncoder,
    SpatialCoordinateEncoder,
    WeightedFusion,
)

__all__ = ["StrLPoseConfig", "PoseOutput", "GeometricOutput", "StrLPose", "ABLATIONS",
           "NO_INTRINSICS"]

#: Rows of the paper's ablation table (Table 3) and the switches that reproduce them.
ABLATIONS: dict[str, dict[str, Any]] = {
    "baseline": dict(use_lines=False, line_mp=False, visual=None, visual_graph=False,
                     weighted=False),
    "L": dict(use_lines=True, line_mp=False, visual=None, visual_graph=False, weighted=False),
    "LP": dict(use_lines=True, line_mp=True, visual=None, visual_graph=False, weighted=False),
    "R": dict(use_lines=False, line_mp=False, visual="cnn", visual_graph=False, weighted=False),
    "V": dict(use_lines=False, line_mp=False, visual="pixel", visual_graph=True,
              weighted=False),
    "LP+R": dict(use_lines=True, line_mp=True, visual="cnn", visual_graph=False,
                 weighted=False),
    "LP+V": dict(use_lines=True, line_mp=True, visual="pixel", visual_graph=True,
                 weighted=False),
    "V+W": dict(use_lines=False, line_mp=False, visual="pixel", visual_graph=True,
                weighted=True),
    "full": dict(use_lines=True, line_mp=True, visual="pixel", visual_graph=True,
                 weighted=True),
}

VISUAL_MODES = (None, "pixel", "cnn")
TRANSLATION_MODES = ("direction", "metric")


@dataclass
class StrLPoseConfig:
    """Configuration of :class:`StrLPose`. The defaults are the full model (``"full"``).

    The paper leaves width, depth and heads open; the defaults follow its closest relative,
    UA-Fusion (Zhuang & Chandraker, CVPR 2021): width 128, four attention layers, four heads.
    """

    hidden: int = 128  # node feature width C of both streams
    layers: int = 4  # dual-graph layers; each is GCG self-attn (+ line MP) (+ GGVG self + cross)
    heads: int = 4  # attention heads; must divide `hidden`
    mlp_ratio: int = 2  # hidden width of every residual update MLP, as a multiple of `hidden`
    line_channels: int = 64  # width of the LSE line-segment feature f0_L
    use_lines: bool = True  # "+L": line endpoints become nodes (SCE-encoded like points)
    line_mp: bool = True  # "+LP": line-endpoint message passing with LSE features
    visual: str | None = "pixel"  # None | "pixel" (PE on patch0/1, "+V") | "cnn" (image0/1, "+R")
    visual_graph: bool = True  # GGVG layers (visual self-attn + geometry-guided cross-attn)
    weighted: bool = True  # "+W": sigmoid-gated pooling in the fusion head (else mean pooling)
    patch_features: int = 3  # per-image features of patch0/patch1 (C * p * p; RGB, p = 1)
    image_channels: int = 3  # channels of image0/image1 for visual="cnn"
    translation: str = "direction"  # "direction" (unit vector, scale-free data) | "metric"
    dropout: float = 0.0  # attention-weight dropout
    # Beyond the paper: the geometric head (per-node inlier logits -> weighted essential solve,
    # strl_pyg.essential). The paper's regression head is always present; this adds a second
    # output, trained jointly (strl_pyg.loss.GeometricLoss).
    geometric: bool = False
    geometric_iterations: int = 2  # IRLS rounds after the weighted eight-point solve
    geometric_tau: float = 2e-3  # Cauchy scale of the IRLS kernel, normalised units

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        for name in ("hidden", "layers", "heads", "mlp_ratio", "line_channels",
                     "patch_features", "image_channels"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Expected a positive integer '{name}' (got {value!r})")
        if self.hidden % self.heads:
            raise ValueError(
                f"Expected heads to divide hidden (got hidden={self.hidden}, heads={self.heads})"
            )
        if self.visual not in VISUAL_MODES:
            raise ValueError(f"Expected visual in {VISUAL_MODES} (got {self.visual!r})")
        if self.visual_graph and self.visual is None:
            raise ValueError("Expected a visual encoder for visual_graph=True (got visual=None)")
        if self.line_mp and not self.use_lines:
            raise ValueError("Expected use_lines=True for line_mp=True (got use_lines=False)")
        if self.translation not in TRANSLATION_MODES:
            raise ValueError(
                f"Expected translation in {TRANSLATION_MODES} (got {self.translation!r})"
            )
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"Expected dropout in [0, 1) (got {self.dropout!r})")
        if not isinstance(self.geometric, bool):
            raise ValueError(f"Expected a bool 'geometric' (got {self.geometric!r})")
        if not isinstance(self.geometric_iterations, int) or self.geometric_iterations < 0:
            raise ValueError(f"Expected geometric_iterations >= 0 (got "
                             f"{self.geometric_iterations!r})")
        if not self.geometric_tau > 0:
            raise ValueError(f"Expected geometric_tau > 0 (got {self.geometric_tau!r})")

    @classmethod
    def ablation(cls, name: str, **overrides: Any) -> StrLPoseConfig:
        """The configuration of one row of the paper's ablation table.

        Args:
            name: one of ``"baseline"``, ``"L"``, ``"LP"``, ``"R"``, ``"V"``, ``"LP+R"``,
                ``"LP+V"``, ``"V+W"``, ``"full"``.
            **overrides: other fields (width, depth, translation mode, ...).
        """
        if name not in ABLATIONS:
            raise ValueError(f"Expected an ablation in {tuple(ABLATIONS)} (got {name!r})")
        return cls(**{**ABLATIONS[name], **overrides})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> StrLPoseConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"Expected StrLPoseConfig fields (got unknown keys {unknown})")
        return cls(**d)


@dataclass
class PoseOutput:
    """Predicted relative pose ``T_0to1`` (maps camera-0 points into camera 1,
    ``X1 = R X0 + t``) of ``B`` pairs.

    Attributes:
        quaternion: unit quaternions ``(w, x, y, z)`` with ``w >= 0``, ``[B, 4]``.
        translation: ``[B, 3]``; a unit direction when the model's ``translation`` is
            ``"direction"``, metric otherwise.
        log_var: predicted log-variance ``log sigma^2`` of the 7 pose components (quaternion
            first), ``[B, 7]``; ``exp(-log_var)`` is the inverse variance of the paper.
    """

    quaternion: Tensor
    translation: Tensor
    log_var: Tensor
    geometric: GeometricOutput | None = None

    @property
    def R(self) -> Tensor:
        """Rotation matrices ``[B, 3, 3]``."""
        return quaternion_to_rotation(self.quaternion)

    @property
    def pose(self) -> Pose:
        return Pose(self.R, self.translation)

    @property
    def T_0to1(self) -> Tensor:
        """Homogeneous ``[B, 4, 4]`` matrices."""
        return self.pose.matrix()


#: ``GeometricOutput.status`` codes: the solve's own (``strl_pyg.essential.OK`` /
#: ``DEGENERATE``) plus this one: the graph was normalised by image size, not by intrinsics, so
#: the weighted solve would give a fundamental matrix and no metric pose.
NO_INTRINSICS = 2


@dataclass
class GeometricOutput:
    """Output of the geometric head (``StrLPoseConfig.geometric``), per node and per pair.

    Node tensors are in the model's node order (``batch`` sorted; within a pair, points first,
    then line endpoints); ``point_logits`` / ``endpoint_logits`` are the same logits in the
    graph's own storage order of each node type (index ``i`` is ``data['point']`` row ``i``).

    Attributes:
        logits: ``[N]`` inlier logits (sigmoid = weight of the node in the solve).
        batch: ``[N]`` pair index of every node.
        coords: ``[N, 4]`` normalised ``(x0, y0, x1, y1)`` of every node.
        point_logits, endpoint_logits: ``[N_point]``, ``[N_endpoint]`` (or ``None``).
        E: ``[B, 3, 3]`` algebraic essential matrices of the weighted solve (unit norm).
        status: ``[B]`` long: 0 ok, 1 degenerate (too few effective matches, rank-deficient),
            :data:`NO_INTRINSICS`.
        R, t: ``[B, 3, 3]``, ``[B, 3]`` pose decomposed from ``E`` (cheirality), float64,
            not differentiable; identity / zero where ``status`` is not 0.
        focal: ``[B]`` mean focal length in pixels of the pair (1 without intrinsics), used to
            express pixel thresholds in normalised units.
    """

    logits: Tensor
    batch: Tensor
    coords: Tensor
    point_logits: Tensor | None
    endpoint_logits: Tensor | None
    E: Tensor
    status: Tensor
    R: Tensor
    t: Tensor
    focal: Tensor

    @property
    def T_0to1(self) -> Tensor:
        return Pose(self.R, self.t).matrix()


# ----------------------------------------------------------------------------- input gathering
@dataclass
class _Inputs:
    num_graphs: int
    batch: Tensor | None  # [N] graph ids (sorted); None for a single graph
    coords: Tensor  # [N, 4] (pos0 || pos1)
    line_feat: Tensor | None  # [N_endpoints, 8]
    endpoint_idx: Tensor | None  # [N_endpoints] positions of the endpoints among the N nodes
    visual: Tensor | None  # [N, 2P] patches, or None
    kpts: tuple[Tensor, Tensor] | None  # pixels in image 0 / 1, for visual="cnn"
    images: tuple[Tensor, Tensor] | None
    self_edges: Tensor | None  # explicit [2, E]; None = implicit complete (dense path)
    cross_edges: Tensor | None
    line_edges: Tensor | None
    inv: Tensor | None = None  # storage index -> model position (None: identity)
    sizes: dict | None = None  # nodes per type, in order


def _store_batch(store, n: int, device) -> Tensor:
    batch = getattr(store, "batch", None)
    return batch if batch is not None else torch.zeros(n, dtype=torch.long, device=device)


def _require(store, key: str, node_type: str, cols: int, why: str) -> Tensor:
    if key not in store:
        raise ValueError(f"Expected '{key}' on '{node_type}' nodes {why} (got none)")
    x = store[key]
    if not isinstance(x, Tensor) or x.dim() != 2 or x.shape[1] != cols:
        shape = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
        raise ValueError(f"Expected '{node_type}.{key}' of shape [N, {cols}] (got {shape})")
    return x


def _gather(cfg: StrLPoseConfig, data: HeteroData) -> _Inputs:
    if not isinstance(data, HeteroData):
        raise TypeError(f"Expected a HeteroData pair graph or batch (got {type(data).__name__})")
    types = [K.POINT, K.ENDPOINT] if cfg.use_lines else [K.POINT]
    types = [t for t in types if t in data.node_types]
    if not types:
        raise ValueError(f"Expected node types {K.NODE_TYPES} in the graph (got {data.node_types})")
    num_graphs = data.num_graphs if isinstance(data, Batch) else 1

    coords, batches, visual, kpts0, kpts1, sizes = [], [], [], [], [], {}
    for t in types:
        store = data[t]
        p0 = _require(store, K.POS0, t, 2, "(normalised coordinates)")
        p1 = _require(store, K.POS1, t, 2, "(normalised coordinates)")
        if p0.shape[0] != p1.shape[0]:
            raise ValueError(f"Expected as many '{K.POS1}' as '{K.POS0}' rows on '{t}' nodes "
                             f"(got {p1.shape[0]} and {p0.shape[0]})")
        n = p0.shape[0]
        sizes[t] = n
        coords.append(torch.cat([p0, p1], dim=-1))
        batches.append(_store_batch(store, n, p0.device))
        if cfg.visual == "pixel":
            why = "(visual='pixel' needs pixels sampled at the nodes: build the graph from " \
                  "matches with images)"
            visual.append(torch.cat([
                _require(store, K.PATCH0, t, cfg.patch_features, why),
                _require(store, K.PATCH1, t, cfg.patch_features, why)], dim=-1))
        elif cfg.visual == "cnn":
            kpts0.append(_require(store, K.KPTS0, t, 2, "(pixel coordinates)"))
            kpts1.append(_require(store, K.KPTS1, t, 2, "(pixel coordinates)"))

    n_total = sum(sizes.values())
    offsets = {}
    acc = 0
    for t in types:
        offsets[t] = acc
        acc += sizes[t]
    batch = torch.cat(batches)
    if num_graphs > 1 and n_total:
        perm = torch.argsort(batch, stable=True)
        inv = torch.empty_like(perm)
        inv[perm] = torch.arange(n_total, device=perm.device)
    else:
        perm = inv = None

    def order(x: Tensor) -> Tensor:
        return x if perm is None else x[perm]

    def remap(ei: Tensor) -> Tensor:
        return ei if inv is None else inv[ei]

    line_feat = endpoint_idx = None
    has_lines = K.ENDPOINT in types and sizes[K.ENDPOINT] > 0
    if cfg.line_mp and K.ENDPOINT in types:
        ep = data[K.ENDPOINT]
        line_feat = _require(ep, K.LINE_FEAT, K.ENDPOINT, 8, "(line_mp=True)")
        if line_feat.shape[0] != sizes[K.ENDPOINT]:
            raise ValueError(f"Expected one '{K.LINE_FEAT}' row per endpoint "
                             f"(got {line_feat.shape[0]} and {sizes[K.ENDPOINT]})")
        idx = torch.arange(sizes[K.ENDPOINT], device=batch.device) + offsets[K.ENDPOINT]
        endpoint_idx = remap(idx)

    line_edges = None
    if cfg.line_mp and has_lines:
        if K.LINE_EDGE not in data.edge_types or K.EDGE_INDEX not in data[K.LINE_EDGE]:
            raise ValueError(f"Expected '{K.EDGE_INDEX}' on edge type {K.LINE_EDGE} "
                             "(line_mp=True) (got none)")
        line_edges = remap(data[K.LINE_EDGE].edge_index + offsets[K.ENDPOINT])

    def complete(rel: str) -> Tensor | None:
        ets = [(s, rel, d) for s in types for d in types]
        present = [et for et in ets if et in data.edge_types]
        explicit = [et for et in present if K.EDGE_INDEX in data[et]]
        if not explicit:
            return None
        if len(explicit) != len(present):
            raise ValueError(
                f"Expected the '{rel}' edge types all implicit ('{K.DENSE}') or all explicit "
                f"('{K.EDGE_INDEX}') (got explicit {explicit} and implicit "
                f"{[et for et in present if et not in explicit]})"
            )
        parts = []
        for s, _, d in explicit:
            ei = data[(s, rel, d)].edge_index
            parts.append(torch.stack([ei[0] + offsets[s], ei[1] + offsets[d]]))
        return remap(torch.cat(parts, dim=1))

    images = kpts = None
    if cfg.visual == "cnn":
        for key in (K.IMAGE0, K.IMAGE1):
            img = data[key] if key in data else None
            ok = isinstance(img, Tensor) and img.dim() == 4 and img.shape[0] == num_graphs \
                and img.shape[1] == cfg.image_channels
            if not ok:
                got = tuple(img.shape) if isinstance(img, Tensor) else "none"
                raise ValueError(
                    f"Expected graph attribute '{key}' of shape [{num_graphs}, "
                    f"{cfg.image_channels}, H, W] for visual='cnn' (build the graph with "
                    f"keep_images=True) (got {got})"
                )
        images = (data[K.IMAGE0].float(), data[K.IMAGE1].float())
        kpts = (order(torch.cat(kpts0)), order(torch.cat(kpts1)))

    return _Inputs(
        num_graphs=num_graphs,
        batch=order(batch) if num_graphs > 1 else None,
        coords=order(torch.cat(coords)),
        line_feat=line_feat,
        endpoint_idx=endpoint_idx,
        visual=order(torch.cat(visual)) if visual else None,
        kpts=kpts,
        images=images,
        self_edges=complete(K.SELF_REL),
        cross_edges=complete(K.CROSS_REL) if cfg.visual_graph else None,
        line_edges=line_edges,
        inv=inv,
        sizes=sizes,
    )


# ----------------------------------------------------------------------------- the model
class StrLPose(nn.Module):
    r"""Str-L Pose: relative pose ``T_0to1`` from a pair graph of matched points and line
    segments (Zhang et al., "Str-L Pose: Integrating Point and Structured Line for Relative Pose
    Estimation in Dual-Graph").

    Per layer :math:`l`: GCG self-attention over all nodes of a pair; line-endpoint message
    passing (``line_mp``); GGVG self-attention (``visual_graph``); Geometry-Guided
    cross-attention whose queries are this layer's GCG features and whose keys and values are
    the GGVG features. Then :class:`~strl_pyg.nn.WeightedFusion` pools both streams per pair
    and regresses the pose and its log-variance.

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
        self.sce = SpatialCoordinateEncoder(C)
        self.lse = LineSegmentEncoder(cfg.line_channels) if cfg.line_mp else None
        self.pe = PixelEncoder(cfg.patch_features, C) if cfg.visual == "pixel" else None
        self.image_encoder = ImageEncoder(cfg.image_channels, C) if cfg.visual == "cnn" else None

        def attn() -> AttentionConv:
            return AttentionConv(C, heads=cfg.heads, mlp_ratio=cfg.mlp_ratio,
                                 dropout=cfg.dropout)

        L = cfg.layers
        self.geo_self = nn.ModuleList([attn() for _ in range(L)])
        self.line_convs = (
            nn.ModuleList([LineEndpointConv(C, cfg.line_channels, cfg.mlp_ratio)
                           for _ in range(L)]) if cfg.line_mp else None
        )
        self.vis_self = nn.ModuleList([attn() for _ in range(L)]) if cfg.visual_graph else None
        self.vis_cross = nn.ModuleList([attn() for _ in range(L)]) if cfg.visual_graph else None
        self.fusion = WeightedFusion(C, C if cfg.visual else 0, 7, C, weighted=cfg.weighted)
        cin = C + (C if cfg.visual else 0)
        self.inlier_head = nn.Sequential(
            nn.Linear(cin, C), nn.ReLU(), nn.Linear(C, C // 2), nn.ReLU(), nn.Linear(C // 2, 1)
        ) if cfg.geometric else None
        self.reset_parameters()

    def reset_parameters(self) -> None:
        for child in self.children():
            if hasattr(child, "reset_parameters"):
                child.reset_parameters()
            elif isinstance(child, (nn.ModuleList, nn.Sequential)):
                for m in child:
                    if hasattr(m, "reset_parameters"):
                        m.reset_parameters()
        with torch.no_grad():  # start at the identity rotation
            self.fusion.pose_mlp[-1].bias[0] += 1.0

    def forward(self, data: HeteroData) -> PoseOutput:
        cfg = self.config
        inp = _gather(cfg, data)
        batch = inp.batch
        g = self.sce(inp.coords)

        line_full = None
        if self.lse is not None and inp.line_feat is not None and inp.line_edges is not None:
            f0_line = self.lse(inp.line_feat)
            line_full = f0_line.new_zeros(g.shape[0], f0_line.shape[1])
            line_full = line_full.index_copy(0, inp.endpoint_idx, f0_line)

        v = None
        if self.pe is not None:
            v = self.pe(inp.visual)
        elif self.image_encoder is not None:
            v = self.image_encoder.encode_nodes(*inp.images, *inp.kpts, batch)

        for layer in range(cfg.layers):
            g = self.geo_self[layer](g, inp.self_edges, batch,
                                     complete=inp.self_edges is None)
            if line_full is not None:
                g = self.line_convs[layer](g, inp.line_edges, line_full)
            if self.vis_self is not None:
                v = self.vis_self[layer](v, inp.self_edges, batch,
                                         complete=inp.self_edges is None)
                v = self.vis_cross[layer]((v, v), inp.cross_edges, batch, query=g,
                                          complete=inp.cross_edges is None)

        geometric = None
        if self.inlier_head is not None:
            geometric = self._geometric(data, inp, g, v)
        raw, log_var = self.fusion(g, v, batch, inp.num_graphs)
        q = raw[:, :4]
        q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-8)
        q = torch.where(q[:, :1] < 0, -q, q)
        t = raw[:, 4:]
        if cfg.translation == "direction":
            t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-8)
        return PoseOutput(quaternion=q, translation=t, log_var=log_var, geometric=geometric)

    def _geometric(self, data: HeteroData, inp: _Inputs, g: Tensor,
                   v: Tensor | None) -> GeometricOutput:
        from torch_geometric.utils import to_dense_batch

        from strl_pyg.essential import OK, decompose_essential, weighted_essential

        cfg = self.config
        h = g if v is None else torch.cat([g, v], dim=-1)
        logits = self.inlier_head(h).squeeze(-1)
        n, B = logits.shape[0], inp.num_graphs
        batch = inp.batch if inp.batch is not None else logits.new_zeros(n, dtype=torch.long)
        coords = inp.coords
        xy, mask = to_dense_batch(coords, batch, batch_size=B)  # [B, Nmax, 4]
        w, _ = to_dense_batch(torch.sigmoid(logits), batch, batch_size=B)
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

    # ------------------------------------------------------------------ checkpoints
    _FORMAT = "strl_pyg.StrLPose"
    _VERSION = 2  # 2 added "metadata"; version 1 files load with default_metadata()
    _READABLE_VERSIONS = (1, 2)
    #: Checkpoints shipped in the package (``strl_pyg/weights/``), for :meth:`from_pretrained`:
    #: ``name -> (file, metadata used when the file stores none)``.
    PRETRAINED: dict[str, tuple[str, dict[str, Any]]] = {
        "synthetic": ("strl_pose_synthetic.pt", {"training_data": (
            "generated street/indoor/boxes scenes only: 3000 pairs, ground-truth matches with "
            "0.7 px noise and 10% outliers, 4000 steps of batch 16, swap augmentation")}),
    }

    @staticmethod
    def default_metadata(config: StrLPoseConfig) -> dict[str, Any]:
        """What a checkpoint without metadata (version 1) is assumed to be trained with:
        ``resample`` ``[384, 192]`` (points, lines of :class:`~strl_pyg.data.FixedSizeResample`,
        ``None`` = not resampled); ``patch_channels`` the channels images are converted to
        before sampling (1 grey, 3 RGB; ``image_channels`` for ``visual="cnn"``, ``None``
        without visual input) and ``patch_size`` (odd ``p`` with ``patch_features =
        channels * p * p``; ``None`` unless ``visual="pixel"``), both from the config;
        ``training_data`` ``None`` (unknown)."""
        channels = size = None
        if config.visual == "cnn":
            channels = config.image_channels
        elif config.visual == "pixel":
            for c in (1, 3):
                p = math.isqrt(config.patch_features // c)
                if c * p * p == config.patch_features and p % 2:
                    channels, size = c, p
                    break
            else:
                raise ValueError(f"Expected patch_features = C * p * p with C in (1, 3) and odd "
                                 f"p (got {config.patch_features})")
        return {"resample": [384, 192], "patch_channels": channels, "patch_size": size,
                "training_data": None}

    @staticmethod
    def _check_metadata(md: Any, config: StrLPoseConfig) -> dict[str, Any]:
        if not isinstance(md, dict) or not all(isinstance(k, str) for k in md):
            raise ValueError(f"Expected metadata as a dict with str keys (got {type(md).__name__})")
        out = {**StrLPose.default_metadata(config), **md}
        rs = out["resample"]
        if rs is not None:
            rs = list(rs) if isinstance(rs, (list, tuple)) else rs
            if not (isinstance(rs, list) and len(rs) == 2 and all(
                    isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in rs)):
                raise ValueError(f"Expected metadata 'resample' as [points, lines] >= 0 or None "
                                 f"(got {out['resample']!r})")
            out["resample"] = rs
        default = StrLPose.default_metadata(config)
        for key in ("patch_channels", "patch_size"):
            if out[key] != default[key]:
                raise ValueError(f"Expected metadata '{key}' {default[key]!r} for this config "
                                 f"(visual={config.visual!r}, patch_features="
                                 f"{config.patch_features}) (got {out[key]!r})")
        if out["training_data"] is not None and not isinstance(out["training_data"], str):
            raise ValueError(f"Expected metadata 'training_data' as a str or None "
                             f"(got {type(out['training_data']).__name__})")
        return out

    @property
    def metadata(self) -> dict[str, Any]:
        """Training metadata (:meth:`default_metadata` keys plus any free-form ones) stored in
        the checkpoint; the defaults when none was stored or set."""
        md = self.__dict__.get("_metadata")
        return dict(md) if md is not None else self.default_metadata(self.config)

    @metadata.setter
    def metadata(self, value: dict[str, Any]) -> None:
        self._metadata = self._check_metadata(value, self.config)

    def save(self, path: str | os.PathLike, metadata: dict[str, Any] | None = None) -> Path:
        """Writes the config, the weights and the training metadata (:attr:`metadata` updated
        with ``metadata``; plain str/int/float/bool/None/list/dict values) to ``path``
        atomically (temp file + rename)."""
        path = Path(path)
        md = self._check_metadata({**self.metadata, **(metadata or {})}, self.config)
        payload = {
            "format": self._FORMAT,
            "version": self._VERSION,
            "config": self.config.to_dict(),
            "metadata": md,
            "state_dict": {k: v.detach().cpu() for k, v in self.state_dict().items()},
        }
        with atomic_open(path) as f:
            torch.save(payload, f)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, map_location: Any = "cpu") -> StrLPose:
        """Rebuilds a model saved with :meth:`save`; raises ``ValueError`` on a corrupt,
        foreign or mismatched checkpoint."""
        path = Path(path)
        # weights_only=True: a file that would run code is refused (io.UnsafeFileError)
        payload = safe_torch_load(path, "StrLPose checkpoint", map_location)
        if not isinstance(payload, dict) or payload.get("format") != cls._FORMAT:
            got = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
            raise ValueError(f"Expected a '{cls._FORMAT}' checkpoint at {path} (got {got!r})")
        if payload.get("version") not in cls._READABLE_VERSIONS:
            raise ValueError(f"Expected checkpoint version in {cls._READABLE_VERSIONS} "
                             f"(got {payload.get('version')!r})")
        model = cls(StrLPoseConfig.from_dict(payload["config"]))
        try:
            model.load_state_dict(payload["state_dict"], strict=True)
        except RuntimeError as err:
            raise ValueError(
                f"Expected weights matching the checkpoint's config at {path} (got {err})"
            ) from err
        if payload.get("metadata") is not None:
            model.metadata = payload["metadata"]
        return model

    @classmethod
    def from_pretrained(cls, name: str = "synthetic", map_location: Any = "cpu") -> StrLPose:
        """A shipped checkpoint (:attr:`PRETRAINED`), read from the installed package (not the
        working directory), in eval mode."""
        if name not in cls.PRETRAINED:
            raise ValueError(f"Expected a pretrained name in {tuple(cls.PRETRAINED)} "
                             f"(got {name!r})")
        from importlib.resources import as_file, files

        file, fallback = cls.PRETRAINED[name]
        with as_file(files("strl_pyg") / "weights" / file) as path:
            if not Path(path).is_file():
                raise FileNotFoundError(f"Expected the shipped checkpoint '{file}' in the "
                                        f"strl_pyg package at {path} (got none)")
            model = cls.load(path, map_location)
        if "_metadata" not in model.__dict__:
            model.metadata = fallback
        return model.eval()

    def __repr__(self) -> str:
        c = self.config
        n = sum(p.numel() for p in self.parameters())
        return (f"{self.__class__.__name__}(hidden={c.hidden}, layers={c.layers}, "
                f"heads={c.heads}, lines={c.use_lines}, line_mp={c.line_mp}, "
                f"visual={c.visual!r}, visual_graph={c.visual_graph}, weighted={c.weighted}, "
                f"params={n})")
