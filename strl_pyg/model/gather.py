"""Input gathering of :class:`~strl_pyg.model.StrLPose`: validation of a pair graph or batch,
node ordering, edges and the dense block layout, done once per forward at the model's
boundary.

Node layout inside the model: the nodes of the active node types (points, plus line endpoints
when ``use_lines``) are concatenated and stably sorted by graph id once, so that every layer
sees graph-contiguous nodes; the geometric and the visual stream share this node set (node
``i`` of the GGVG is the same match as node ``i`` of the GCG).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor
from torch_geometric.data import Batch, HeteroData

from strl_pyg.data import keys as K
from strl_pyg.data.pair_graph import stored
from strl_pyg.model.config import StrLPoseConfig
from strl_pyg.nn import DenseLayout

__all__ = ["ModelInputs", "gather_inputs"]


@dataclass
class ModelInputs:
    """Everything the layers read, in the model's node order (see the module docstring)."""

    num_graphs: int
    batch: Tensor | None  # [N] graph ids (sorted); None for a single graph
    coords: Tensor  # [N, 4] (pos0 || pos1)
    line_feat: Tensor | None  # [N_endpoints, 8]
    endpoint_idx: Tensor | None  # [N_endpoints] positions of the endpoints among the N nodes
    visual: Tensor | None  # [N, 2P] patches, or None
    kpts: tuple[Tensor, Tensor] | None  # pixels in image 0 / 1, for visual="cnn"
    images: tuple[Tensor, Tensor] | None
    self_edges: Tensor | None  # explicit [2, E]; None = implicit complete (dense path)
    cross_edges: Tensor | None  # the self edges, or the graph's own explicit cross edges
    line_edges: Tensor | None
    inv: Tensor | None = None  # storage index -> model position (None: identity)
    sizes: dict | None = None  # nodes per type, in order
    block: tuple[Tensor, Tensor] | None = None  # DenseLayout.block_index (None: one graph)



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


def gather_inputs(cfg: StrLPoseConfig, data: HeteroData) -> ModelInputs:
    """Checks ``data`` against the model's config (one-line ``ValueError`` / ``TypeError``),
    orders its nodes by graph and collects the inputs of every layer; no host
    synchronisation (the block size of the dense layout, ``int(counts.max())`` of
    ``block``, is read by the caller)."""
    if not isinstance(data, HeteroData):
        raise TypeError(f"Expected a HeteroData pair graph or batch (got {type(data).__name__})")
    types = [K.POINT, K.ENDPOINT] if cfg.use_lines else [K.POINT]
    types = [t for t in types if t in data.node_types]
    if not types:
        raise ValueError(f"Expected node types {K.NODE_TYPES} in the graph (got {data.node_types})")
    num_graphs = data.num_graphs if isinstance(data, Batch) else 1
    nodes = _node_inputs(cfg, data, types)
    sizes = nodes["sizes"]
    n_total = sum(sizes.values())
    offsets, acc = {}, 0
    for t in types:
        offsets[t] = acc
        acc += sizes[t]
    batch = torch.cat(nodes["batches"])
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

    line_feat, endpoint_idx, line_edges = _line_inputs(cfg, data, types, sizes, offsets, batch,
                                                       remap)
    images = kpts = None
    if cfg.visual == "cnn":
        images = _cnn_images(cfg, data, num_graphs)
        kpts = (order(torch.cat(nodes["kpts0"])), order(torch.cat(nodes["kpts1"])))
    self_edges, cross_edges = _complete_inputs(cfg, data, types, offsets, remap)
    batch = order(batch) if num_graphs > 1 else None
    # The model sorted the nodes itself from PyG's batch vector: the layout needs no
    # validation, only its block size, which StrLPose.forward reads (the one host read).
    block = DenseLayout.block_index(batch, n_total, num_graphs) if batch is not None else None
    return ModelInputs(
        num_graphs=num_graphs,
        batch=batch,
        coords=order(torch.cat(nodes["coords"])),
        line_feat=line_feat,
        endpoint_idx=endpoint_idx,
        visual=order(torch.cat(nodes["visual"])) if nodes["visual"] else None,
        kpts=kpts,
        images=images,
        self_edges=self_edges,
        cross_edges=cross_edges,
        line_edges=line_edges,
        inv=inv,
        sizes=sizes,
        block=block,
    )


def _node_inputs(cfg: StrLPoseConfig, data: HeteroData, types: list[str]) -> dict:
    """Per node type, in storage order: coordinates, graph ids, visual rows, pixels."""
    out = {"coords": [], "batches": [], "visual": [], "kpts0": [], "kpts1": [], "sizes": {}}
    for t in types:
        store = data[t]
        p0 = _require(store, K.POS0, t, 2, "(normalised coordinates)")
        p1 = _require(store, K.POS1, t, 2, "(normalised coordinates)")
        if p0.shape[0] != p1.shape[0]:
            raise ValueError(f"Expected as many '{K.POS1}' as '{K.POS0}' rows on '{t}' nodes "
                             f"(got {p1.shape[0]} and {p0.shape[0]})")
        n = p0.shape[0]
        out["sizes"][t] = n
        out["coords"].append(torch.cat([p0, p1], dim=-1))
        out["batches"].append(_store_batch(store, n, p0.device))
        if cfg.visual == "pixel":
            why = "(visual='pixel' needs pixels sampled at the nodes: build the graph from " \
                  "matches with images)"
            out["visual"].append(torch.cat([
                _require(store, K.PATCH0, t, cfg.patch_features, why),
                _require(store, K.PATCH1, t, cfg.patch_features, why)], dim=-1))
        elif cfg.visual == "cnn":
            out["kpts0"].append(_require(store, K.KPTS0, t, 2, "(pixel coordinates)"))
            out["kpts1"].append(_require(store, K.KPTS1, t, 2, "(pixel coordinates)"))
    return out


def _line_inputs(cfg: StrLPoseConfig, data: HeteroData, types: list[str], sizes: dict,
                 offsets: dict, batch: Tensor, remap) -> tuple:
    """``(line_feat, endpoint_idx, line_edges)`` of the line-endpoint messages (``None`` each
    without ``line_mp`` or lines), endpoint positions and edges in model order."""
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
    return line_feat, endpoint_idx, line_edges


def _cnn_images(cfg: StrLPoseConfig, data: HeteroData, num_graphs: int) -> tuple:
    """``(image0, image1)`` of ``visual="cnn"``, checked."""
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
    return data[K.IMAGE0].float(), data[K.IMAGE1].float()


def _complete_inputs(cfg: StrLPoseConfig, data: HeteroData, types: list[str], offsets: dict,
                     remap) -> tuple[Tensor | None, Tensor | None]:
    """``(self_edges, cross_edges)``: explicit complete edges in model positions, ``None``
    where implicit (the dense path)."""

    def complete(rel: str) -> Tensor | None:
        """The explicit edges of relation ``rel`` in model positions; None when implicit
        (``dense`` markers) or absent."""
        ets = [(s, rel, d) for s in types for d in types]
        present = [et for et in ets if et in data.edge_types]
        explicit = [et for et in present if stored(data[et], K.EDGE_INDEX)]
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

    # One set of complete edges serves all three attentions (data.keys): the cross-attention
    # runs over the self edges unless the graph brings explicit cross edges of its own, or
    # the implicit cross markers of a 0.1.x graph (complete cross-attention, as then).
    self_edges = complete(K.SELF_REL)
    cross_edges = None
    if cfg.visual_graph:
        cross_edges = complete(K.CROSS_REL)
        legacy_implicit = any(K.DENSE in data[(s, K.CROSS_REL, d)] for s in types for d in types
                              if (s, K.CROSS_REL, d) in data.edge_types)
        if cross_edges is None and not legacy_implicit:
            cross_edges = self_edges
        # else: 0.1.x implicit cross markers beside explicit self edges mean dense complete
        # cross-attention, as they did then (None = dense)
    return self_edges, cross_edges
