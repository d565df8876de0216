"""Transforms on pair graphs (PyG ``BaseTransform`` style)."""

from __future__ import annotations

import copy
import math

import torch
from torch import Tensor
from torch_geometric.data import Batch, HeteroData
from torch_geometric.transforms import BaseTransform

from strl_pyg.data import has_implicit_complete_edges, materialize_complete_edges
from strl_pyg.data import keys as keys_
from strl_pyg.data.build import line_edge_index
from strl_pyg.data.pair_graph import stored
from strl_pyg.geometry.manifold import so3_exp

__all__ = [
    "FixedSizeResample",
    "MaterializeCompleteEdges",
    "RandomRoll",
    "RandomSwap",
    "resample_indices",
    "roll_cameras",
    "roll_pose",
    "swap_images",
]


def resample_indices(n: int, target: int, generator: torch.Generator | None = None) -> Tensor:
    """Indices that bring ``n`` items to exactly ``target`` by random deletion or repetition.

    With ``n >= target``, a random subset of ``target`` distinct items (random deletion); with
    ``0 < n < target``, every item once plus ``target - n`` items drawn with replacement
    (random repetition), in random order. With ``n == 0`` nothing can be repeated: returns an
    empty index.
    """
    if n == 0:
        return torch.zeros(0, dtype=torch.long)
    if n >= target:
        return torch.randperm(n, generator=generator)[:target]
    extra = torch.randint(n, (target - n,), generator=generator)
    idx = torch.cat([torch.arange(n), extra])
    return idx[torch.randperm(target, generator=generator)]


class FixedSizeResample(BaseTransform):
    """Brings every pair graph to a fixed number of points and lines, as the paper does
    (following UA-Fusion: random repetition and deletion, 384 points and 192 lines).

    Line endpoints move in pairs, so a line is kept, repeated or deleted whole. A pair with no
    lines stays without lines (and likewise for points): there is nothing to repeat.

    Args:
        num_points: Target number of points (default: ``384``).
        num_lines: Target number of line segments (default: ``192``).
        seed: Seed of the transform's own generator; successive calls draw successive
            samples, so the same seed gives the same sequence of graphs. With ``None``
            (default), torch's global generator is used (seeded per DataLoader worker).
    """

    def __init__(self, num_points: int = 384, num_lines: int = 192, seed: int | None = None):
        if num_points < 0 or num_lines < 0:
            raise ValueError(
                "Expected non-negative targets "
                f"(got num_points={num_points}, num_lines={num_lines})"
            )
        self.num_points = num_points
        self.num_lines = num_lines
        self.seed = seed
        self.generator = None
        if seed is not None:
            self.generator = torch.Generator().manual_seed(seed)

    def forward(self, data: HeteroData) -> HeteroData:
        if isinstance(data, Batch):
            raise TypeError("Expected a single pair graph (got a batch): resample before batching")
        explicit = not has_implicit_complete_edges(data)
        data = copy.copy(data)  # attributes are reassigned below, never modified in place
        pi = resample_indices(data[keys_.POINT].num_nodes, self.num_points, self.generator)
        nl = data[keys_.ENDPOINT].num_nodes // 2
        li = resample_indices(nl, self.num_lines, self.generator)
        ei = torch.stack([2 * li, 2 * li + 1], dim=1).reshape(-1)
        for node_type, idx in ((keys_.POINT, pi), (keys_.ENDPOINT, ei)):
            store = data[node_type]
            n = store.num_nodes
            for key, value in list(store.items()):
                if isinstance(value, Tensor) and value.dim() > 0 and value.size(0) == n:
                    store[key] = value[idx]
            store.num_nodes = idx.numel()
        data[keys_.LINE_EDGE].edge_index = line_edge_index(li.numel())
        if explicit:  # the complete edges of the kept nodes, rebuilt
            for et in keys_.COMPLETE_EDGE_TYPES:
                if et in data.edge_types:
                    if stored(data[et], keys_.EDGE_INDEX):
                        del data[et][keys_.EDGE_INDEX]
                    data[et][keys_.DENSE] = torch.ones(1, dtype=torch.bool)
            data = materialize_complete_edges(data)
        return data

    def __repr__(self) -> str:
        return (
            f"{self.__class__.__name__}(num_points={self.num_points}, "
            f"num_lines={self.num_lines}, seed={self.seed})"
        )


class MaterializeCompleteEdges(BaseTransform):
    """Transform form of :func:`~strl_pyg.data.build.materialize_complete_edges`."""

    def forward(self, data: HeteroData) -> HeteroData:
        return materialize_complete_edges(data)


_SWAPPED_NODE_KEYS = ((keys_.KPTS0, keys_.KPTS1), (keys_.POS0, keys_.POS1),
                      (keys_.PATCH0, keys_.PATCH1))
_SWAPPED_GRAPH_KEYS = ((keys_.IMAGE_SIZE0, keys_.IMAGE_SIZE1), (keys_.K0, keys_.K1),
                       (keys_.IMAGE0, keys_.IMAGE1))


def swap_images(data: HeteroData) -> HeteroData:
    """The pair graph with image 0 and image 1 exchanged (a new object; works on batches).

    Every per-image attribute trades places, the line features swap their two halves, and
    ``T_0to1`` becomes its inverse. Building the graph from matches whose images were swapped
    gives the same graph. The graph attribute ``swapped`` records the exchange (toggled, so
    swapping twice restores it).
    """
    data = copy.copy(data)  # attributes are reassigned below, never modified in place
    for node_type in keys_.NODE_TYPES:
        store = data[node_type]
        for a, b in _SWAPPED_NODE_KEYS:
            if a in store:
                store[a], store[b] = store[b], store[a]
    lf = data[keys_.ENDPOINT][keys_.LINE_FEAT]
    data[keys_.ENDPOINT][keys_.LINE_FEAT] = torch.cat([lf[:, 4:], lf[:, :4]], dim=1)
    for a, b in _SWAPPED_GRAPH_KEYS:
        if a in data:
            data[a], data[b] = data[b], data[a]
    n = data.num_graphs if isinstance(data, Batch) else 1
    prev = data[keys_.SWAPPED] if keys_.SWAPPED in data else torch.zeros(n, dtype=torch.bool)
    data[keys_.SWAPPED] = ~prev
    if keys_.T_0TO1 in data:
        T = data[keys_.T_0TO1]
        R_t = T[..., :3, :3].transpose(-1, -2)
        inv = T.clone()
        inv[..., :3, :3] = R_t
        inv[..., :3, 3] = -(R_t @ T[..., :3, 3:4]).squeeze(-1)
        data[keys_.T_0TO1] = inv
    return data


class RandomSwap(BaseTransform):
    """Exchanges the two images of a pair with probability ``p`` (:func:`swap_images`): a
    training augmentation that makes the data symmetric under reversing the motion (driving
    data only ever moves forward).

    Args:
        p: Probability of a swap (default: ``0.5``).
        seed: Seed of the transform's own generator (``None``: torch's global generator).
    """

    def __init__(self, p: float = 0.5, seed: int | None = None) -> None:
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"Expected a probability p in [0, 1] (got {p!r})")
        self.p = p
        self.seed = seed
        self.generator = None if seed is None else torch.Generator().manual_seed(seed)

    def forward(self, data: HeteroData) -> HeteroData:
        if float(torch.rand(1, generator=self.generator)) < self.p:
            return swap_images(data)
        if keys_.SWAPPED not in data:  # every graph carries the flag, so batches collate
            data = copy.copy(data)
            data[keys_.SWAPPED] = torch.zeros(1, dtype=torch.bool)
        return data

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}(p={self.p}, seed={self.seed})"


def _rotate_pairs(x: Tensor, c: float, s: float) -> Tensor:
    """Rotates the consecutive coordinate pairs ``(x, y)`` of the last dimension by the angle
    whose cosine and sine are ``c`` and ``s``."""
    xy = x.reshape(*x.shape[:-1], x.shape[-1] // 2, 2)  # also for 0 nodes
    out = torch.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)
    return out.reshape(x.shape).to(x.dtype)


def roll_pose(T: Tensor, angle: float | Tensor) -> Tensor:
    """``T_0to1`` of two cameras both rolled by ``angle`` (radians) about their optical axes:
    :math:`(R_z R R_z^\\top, R_z t)`. ``T`` is ``[..., 4, 4]``; ``angle`` a number (one roll
    for all) or ``[B]`` (one per pose of a ``[B, 4, 4]`` batch); ``-angle`` undoes it."""
    a = torch.as_tensor(angle, dtype=torch.float64, device=T.device)
    Rz = so3_exp(torch.stack([torch.zeros_like(a), torch.zeros_like(a), a], dim=-1))
    Td = T.double()
    out = T.clone()
    out[..., :3, :3] = (Rz @ Td[..., :3, :3] @ Rz.transpose(-1, -2)).to(T.dtype)
    out[..., :3, 3] = (Rz @ Td[..., :3, 3:4]).squeeze(-1).to(T.dtype)
    return out


def roll_cameras(data: HeteroData, angle: float) -> HeteroData:
    """The pair graph of both cameras rolled by ``angle`` (radians) about their optical axes
    (a new object): a training augmentation that is exact in the intrinsics-normalised
    coordinates.

    A roll :math:`R_z` maps a normalised ray :math:`(x, y, 1)` to :math:`(R_z (x, y), 1)`, so
    ``pos0`` / ``pos1`` of every node and the four 2-vectors of ``line_feat`` rotate by
    ``angle``, and ``T_0to1`` becomes :math:`(R_z R R_z^\\top, R_z t)`. The appearance
    (``patch*``, ``kpts*``, ``image*``) and ``K`` stay: they describe the same points.

    Raises ``ValueError`` for a graph without ``K0`` and ``K1`` (its coordinates are
    normalised by the image size, where a roll is not a rotation of the coordinates), and for
    a batch (roll each graph before collating).
    """
    if isinstance(data, Batch):
        raise ValueError("Expected one pair graph (got a Batch): roll each graph before "
                         "collating")
    if keys_.K0 not in data or keys_.K1 not in data:
        raise ValueError("Expected a graph with intrinsics K0 and K1 (coordinates normalised "
                         "by K) to roll its cameras (got a graph without them)")
    angle = float(angle)
    if not math.isfinite(angle):
        raise ValueError(f"Expected a finite roll angle (got {angle!r})")
    c, s = math.cos(angle), math.sin(angle)
    data = copy.copy(data)  # attributes are reassigned below, never modified in place
    for node_type in keys_.NODE_TYPES:
        if node_type not in data.node_types:
            continue
        store = data[node_type]
        for key in (keys_.POS0, keys_.POS1, keys_.LINE_FEAT):
            if key in store:
                store[key] = _rotate_pairs(store[key], c, s)
    if keys_.T_0TO1 in data:
        data[keys_.T_0TO1] = roll_pose(data[keys_.T_0TO1], angle)
    prev = data[keys_.ROLL] if keys_.ROLL in data else torch.zeros(1, dtype=torch.float64)
    data[keys_.ROLL] = prev + angle
    return data


class RandomRoll(BaseTransform):
    """Rolls both cameras of a pair by an angle drawn uniformly from
    ``[-max_degrees, max_degrees]`` (:func:`roll_cameras`): a training augmentation for
    data whose cameras are always upright (generated scenes, driving), so that a network does
    not learn "an orbit moves sideways" and fail on a pair filmed with the camera on its side
    (the Middlebury dino's views are rolled by 90 degrees).

    Args:
        max_degrees: The largest roll, in ``[0, 180]`` (``180``: every orientation).
        seed: Seed of the transform's own generator (``None``: torch's global generator).
    """

    def __init__(self, max_degrees: float = 180.0, seed: int | None = None) -> None:
        if not 0.0 <= max_degrees <= 180.0:
            raise ValueError(f"Expected max_degrees in [0, 180] (got {max_degrees!r})")
        self.max_degrees = float(max_degrees)
        self.seed = seed
        self.generator = None if seed is None else torch.Generator().manual_seed(seed)

    def forward(self, data: HeteroData) -> HeteroData:
        u = float(torch.rand(1, generator=self.generator, dtype=torch.float64))
        angle = (2.0 * u - 1.0) * self.max_degrees
        return roll_cameras(data, angle * torch.pi / 180.0)

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}(max_degrees={self.max_degrees}, seed={self.seed})"
