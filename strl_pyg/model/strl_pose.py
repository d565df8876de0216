"""The Str-L Pose network: encoders, dual graph (GCG + GGVG), weighted fusion, pose head.

Reads top to bottom: the model (modules in the order of Figure 1 of the paper), checkpoints;
the keys of older checkpoints are upgraded by :mod:`strl_pyg.model.legacy`. The configuration
and output containers live in
:mod:`strl_pyg.model.config`, input gathering (validation, node ordering, edges, the dense
block layout) in :mod:`strl_pyg.model.inputs`; both are importable from here.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn
from torch_geometric.data import HeteroData

from strl_pyg.data import keys as K
from strl_pyg.model.config import (
    ABLATIONS,
    NO_INTRINSICS,
    TRANSLATION_MODES,
    VISUAL_MODES,
    GeometricOutput,
    PoseOutput,
    StrLPoseConfig,
)
from strl_pyg.model.inputs import ModelInputs, gather_inputs
from strl_pyg.model.legacy import upgrade_key, upgrade_legacy_keys, what_checkpoint
from strl_pyg.nn import (
    CompleteEdges,
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
from strl_pyg.utils.io import atomic_open, safe_torch_load

__all__ = ["StrLPoseConfig", "PoseOutput", "GeometricOutput", "StrLPose", "ABLATIONS",
           "NO_INTRINSICS", "VISUAL_MODES", "TRANSLATION_MODES", "upgrade_key"]


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


class StrLPose(nn.Module):
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

    def forward(self, data: HeteroData) -> PoseOutput:
        """Validates and gathers the graph (:func:`~strl_pyg.model.inputs.gather_inputs`), reads
        the padded block size of complete attention from the host (the one synchronisation;
        none for a single graph, or for explicit edges without the geometric head and the
        image encoder), then runs without touching the host."""
        cfg = self.config
        inp = _in_dtype(gather_inputs(cfg, data), next(self.parameters()).dtype)
        dense = (inp.self_edges is None or (cfg.visual_graph and inp.cross_edges is None)
                 or cfg.visual == "cnn" or cfg.geometric)  # what needs padded blocks
        layout = None
        if inp.block is None:  # one graph: no padding
            layout = DenseLayout.single(inp.coords.shape[0])
        elif dense:  # read here, in forward's own frame: one graph break under torch.compile
            counts, index = inp.block
            layout = DenseLayout.from_counts(inp.batch, index, counts, int(counts.max()))
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
            v = self.image_encoder.encode_nodes(*inp.images, *inp.kpts, None, layout)

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

    # ------------------------------------------------------------------ checkpoints
    _FORMAT = "strl_pyg.StrLPose"
    _VERSION = 2  # 2 added "metadata"; version 1 files load with default_metadata()
    _READABLE_VERSIONS = (1, 2)
    #: Checkpoints shipped in the package (``strl_pyg/weights/``), for :meth:`from_pretrained`:
    #: ``name -> (file, metadata used when the file stores none)``.
    #: ``"geometric"`` (the default): regression + geometric head, calibrated; ``"synthetic"``:
    #: the paper's model alone (regression head), the first shipped weights.
    PRETRAINED: dict[str, tuple[str, dict[str, Any]]] = {
        "geometric": ("strl_pose_geometric.pt", {}),
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
        foreign or mismatched checkpoint. Checkpoints of the version-1 module layout load
        unchanged (:func:`upgrade_key`, applied by every ``load_state_dict`` of the model)."""
        path = Path(path)
        # weights_only=True: a file that would run code is refused (io.UnsafeFileError)
        payload = safe_torch_load(path, "StrLPose checkpoint", map_location)
        if not isinstance(payload, dict) or payload.get("format") != cls._FORMAT:
            raise ValueError(f"Expected a '{cls._FORMAT}' checkpoint at {path} (got "
                             f"{what_checkpoint(payload, path)})")
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

    def upgrade_optimizer_state(self, optimizer_state: dict[str, Any],
                                model_state: dict[str, Any]) -> dict[str, Any]:
        """Re-indexes an optimizer state saved next to ``model_state`` for this model's
        parameter order.

        An optimizer indexes its state by parameter position; the version-1 module layout
        listed the parameters in another order (all GCG self-attentions, then all line
        convolutions, ...), so the state of a version-1 training checkpoint must be permuted
        before ``optimizer.load_state_dict`` (else Adam moments land on other parameters).
        A state saved with today's layout is returned unchanged.

        Args:
            optimizer_state: ``optimizer.state_dict()`` of an optimizer over
                ``model.parameters()`` (one parameter group).
            model_state: the model state dict saved with it (its key order is the
                parameter order of that model).
        """
        keys = list(model_state)
        if all(upgrade_key(k) == k for k in keys):
            return optimizer_state
        names = [n for n, _ in self.named_parameters()]
        known = set(names)
        old_order = [upgrade_key(k) for k in keys if upgrade_key(k) in known]
        if sorted(old_order) != sorted(names):
            raise ValueError(f"Expected a model state with this model's {len(names)} "
                             f"parameters (got {len(old_order)} of them)")
        groups = optimizer_state.get("param_groups")
        if not (isinstance(groups, list) and len(groups) == 1
                and list(groups[0].get("params", [])) == list(range(len(names)))):
            raise ValueError("Expected the state of an optimizer over model.parameters() in "
                             f"one parameter group of {len(names)} (got "
                             f"{len(groups) if isinstance(groups, list) else groups!r} groups)")
        position = {n: j for j, n in enumerate(names)}
        new_index = [position[n] for n in old_order]  # old position -> new position
        group = {**groups[0], "params": list(range(len(names)))}
        if "param_names" in group:
            group["param_names"] = names
        state = {new_index[int(i)]: v for i, v in optimizer_state.get("state", {}).items()}
        return {**optimizer_state, "state": state, "param_groups": [group]}

    @classmethod
    def from_pretrained(cls, name: str = "geometric", map_location: Any = "cpu") -> StrLPose:
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
