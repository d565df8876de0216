"""From a :class:`~strl_pyg.data.PairMatches` to a heterogeneous PyG pair graph.

The layout is documented once, in :mod:`strl_pyg.data.keys`.

Complete edge types (the ``self`` types: every node of a pair to every node of it, the edges of
all three attentions of the dual graph) are **implicit** by default: each such edge type
carries only a ``dense`` marker and layers run dense attention over per-graph blocks, so a
graph's memory grows O(N), not O(N^2) (a 576-node graph would otherwise hold 331,776 edges per
edge family). :func:`materialize_complete_edges` turns the markers into explicit
``edge_index`` tensors for users who want sparse or pruned attention. The graphs are
:class:`~strl_pyg.data.pair_graph.PairGraph` objects, whose PyG conversions keep or refuse the
implicit edges instead of dropping them (see :mod:`strl_pyg.data.pair_graph`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch_geometric.data import HeteroData

from strl_pyg.data import keys as keys_
from strl_pyg.data.matches import PairMatches
from strl_pyg.data.pair_graph import PairGraph, drop_legacy_cross_edges, materialize_complete_edges
from strl_pyg.geometry import check_rotation, normalize_points
from strl_pyg.utils.io import atomic_open

__all__ = ["build_pair_graph", "normalize_coords", "sample_patches", "image_to_tensor",
           "line_edge_index", "save_graph", "load_graph"]

COMPLETE_EDGE_MODES = ("implicit", "explicit")
NORMALIZATIONS = ("auto", "intrinsics", "image_size")


def normalize_coords(
    xy: Tensor, image_size: tuple[int, int], K_mat: Tensor | None = None
) -> Tensor:
    """Normalises pixel coordinates.

    With intrinsics ``K``: ideal camera coordinates ``K^{-1} [x, y, 1]^T`` (first two entries).
    Without: centred on the image and divided by half its longer side, so the longer axis spans
    ``[-1, 1]`` and the aspect ratio is kept: ``(x - (W - 1) / 2) / (max(H, W) / 2)``.

    Args:
        xy: Pixel coordinates ``(*, 2)``.
        image_size: ``(H, W)``.
        K_mat: Optional intrinsics ``(3, 3)``.

    Returns:
        Normalised coordinates ``(*, 2)``, same dtype as ``xy``.
    """
    if K_mat is not None:  # one implementation of K^-1: strl_pyg.geometry.normalize_points
        flat = xy.reshape(-1, 2)
        return normalize_points(flat, K_mat.to(xy.device)).to(xy.dtype).reshape(xy.shape)
    h, w = image_size
    centre = xy.new_tensor([(w - 1) / 2.0, (h - 1) / 2.0])
    return (xy - centre) / (max(h, w) / 2.0)


def image_to_tensor(image: np.ndarray) -> Tensor:
    """``(H, W)`` or ``(H, W, 3)`` uint8/float image -> ``(C, H, W)`` float32 in ``[0, 1]``."""
    t = torch.from_numpy(np.ascontiguousarray(image))
    t = t.float().div_(255.0) if t.dtype == torch.uint8 else t.float()
    return t.unsqueeze(0) if t.dim() == 2 else t.permute(2, 0, 1)


def _to_grey(t: Tensor) -> Tensor:
    if t.shape[0] == 1:
        return t
    w = t.new_tensor([0.299, 0.587, 0.114]).view(3, 1, 1)
    return (t * w).sum(0, keepdim=True)


def sample_patches(image: Tensor, xy: Tensor, patch_size: int = 1) -> Tensor:
    """Samples ``patch_size x patch_size`` pixel patches bilinearly around each coordinate.

    Pixel centres are at integer coordinates (OpenCV convention); samples outside the image
    take the value of the nearest border pixel.

    Args:
        image: ``(C, H, W)`` float image.
        xy: Pixel coordinates ``(N, 2)``.
        patch_size: Odd side length; 1 samples the single (interpolated) pixel, as the paper.

    Returns:
        ``(N, C * patch_size**2)``, channel-major (all offsets of channel 0 first).
    """
    from strl_pyg.data.sampling import sample_bilinear  # the package's one sampler

    c = image.shape[0]
    n = xy.shape[0]
    if n == 0:
        return image.new_zeros(0, c * patch_size * patch_size)
    if patch_size == 1:
        pts = xy[:, None, :]  # [N, 1, 2]
    else:
        r = patch_size // 2
        off = torch.arange(-r, r + 1, dtype=xy.dtype, device=xy.device)
        oy, ox = torch.meshgrid(off, off, indexing="ij")
        pts = xy[:, None, :] + torch.stack([ox, oy], dim=-1).reshape(1, -1, 2)  # [N, p*p, 2]
    out = sample_bilinear(image.unsqueeze(0), pts.reshape(1, -1, 2), padding="border")
    return out[0].view(c, n, -1).permute(1, 0, 2).reshape(n, c * patch_size * patch_size)


def line_edge_index(num_lines: int) -> Tensor:
    """Endpoint ``2i <-> 2i+1`` for every line, both directions: ``[2, 2 * num_lines]``."""
    src = torch.arange(2 * num_lines)
    return torch.stack([src, src ^ 1])


def _checked_pose_matrix(T_0to1: Any) -> Tensor:
    if hasattr(T_0to1, "matrix") and callable(T_0to1.matrix):  # strl_pyg.geometry.Pose
        T_0to1 = T_0to1.matrix()
    if hasattr(T_0to1, "detach"):
        T_0to1 = T_0to1.detach().cpu().numpy()
    T = np.asarray(T_0to1, dtype=np.float64)
    if T.shape == (3, 4):
        T = np.vstack([T, [0.0, 0.0, 0.0, 1.0]])
    if T.shape != (4, 4):
        raise ValueError(f"Expected T_0to1 of shape (4, 4) or (3, 4) (got {T.shape})")
    if not np.isfinite(T).all():
        raise ValueError("Expected a finite T_0to1 (got NaN or inf)")
    check_rotation(T[:3, :3], "the rotation of T_0to1", tol=1e-4)
    return torch.from_numpy(T).float()


def build_pair_graph(
    matches: PairMatches,
    *,
    T_0to1: Any = None,
    patch_size: int = 1,
    complete_edges: str = "implicit",
    normalization: str = "auto",
    keep_images: bool = False,
) -> PairGraph:
    """Builds the Str-L Pose pair graph of one image pair.

    Node features (all float32):

    * ``kpts0``/``kpts1`` ``[N, 2]``: pixel coordinates in image 0/1;
    * ``pos0``/``pos1`` ``[N, 2]``: normalised coordinates (:func:`normalize_coords`: by the
      intrinsics when ``normalization`` is ``"intrinsics"``, or ``"auto"`` and both K are
      known; else by the image size);
    * ``patch0``/``patch1`` ``[N, C * p * p]``: pixels sampled bilinearly around each node in
      both images, when the matches carry images (greyscale when the two images differ in
      channels);
    * endpoints only, ``line_feat`` ``[2 Nl, 8]``: the paper's line-segment features
      ``(x0, y0, dx0, dy0, x1, y1, dx1, dy1)`` of each endpoint, normalised, where ``d`` is the
      other endpoint of the same segment minus this one;
    * ``score`` ``[N]`` when the matches carry scores.

    Args:
        matches: Validated matches of the pair.
        T_0to1: Optional ground-truth pose ``(4, 4)`` or ``(3, 4)`` (or a ``Pose``) mapping
            camera-0 points into camera 1; stored as graph attribute ``T_0to1`` ``[1, 4, 4]``.
        patch_size: Odd patch side (default: ``1``, the paper's single pixel).
        complete_edges: ``"implicit"`` (default, O(N) memory, dense layers) or ``"explicit"``
            (``edge_index`` tensors, O(N^2)).
        normalization: ``"auto"`` (default), ``"intrinsics"`` or ``"image_size"``.
        keep_images: Also store both images as ``image0``/``image1`` ``[1, C, H, W]`` (needed
            by the ``+R`` image-encoder ablation).

    Returns:
        A :class:`~strl_pyg.data.pair_graph.PairGraph` (a ``HeteroData``) with node types
        ``point`` and ``endpoint``; see :mod:`strl_pyg.data.keys` for the full layout.
    """
    if not isinstance(matches, PairMatches):
        raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
    if not isinstance(patch_size, int) or patch_size < 1 or patch_size % 2 == 0:
        raise ValueError(f"Expected an odd positive integer patch_size (got {patch_size!r})")
    if complete_edges not in COMPLETE_EDGE_MODES:
        raise ValueError(
            f"Expected complete_edges in {COMPLETE_EDGE_MODES} (got {complete_edges!r})"
        )
    if normalization not in NORMALIZATIONS:
        raise ValueError(f"Expected normalization in {NORMALIZATIONS} (got {normalization!r})")
    if normalization == "intrinsics" and not matches.has_intrinsics:
        raise ValueError(
            "Expected K0 and K1 in the matches for normalization='intrinsics' (got none)"
        )
    if keep_images and not matches.has_images:
        raise ValueError("Expected images in the matches for keep_images=True (got none)")
    pose = None if T_0to1 is None else _checked_pose_matrix(T_0to1)

    use_K = matches.has_intrinsics and normalization != "image_size"
    Ks = (
        (torch.from_numpy(matches.K0).float(), torch.from_numpy(matches.K1).float())
        if matches.has_intrinsics
        else (None, None)
    )
    sizes = (matches.image_size0, matches.image_size1)
    images = None
    if matches.has_images:
        images = [image_to_tensor(matches.image0), image_to_tensor(matches.image1)]
        if images[0].shape[0] != images[1].shape[0]:
            images = [_to_grey(t) for t in images]

    nl = matches.num_lines
    lines = [torch.from_numpy(matches.lines0).float(), torch.from_numpy(matches.lines1).float()]
    coords = {keys_.POINT: [torch.from_numpy(matches.points0).float(),
                            torch.from_numpy(matches.points1).float()],
              keys_.ENDPOINT: [ln.reshape(-1, 2) for ln in lines]}
    data = PairGraph()
    point, endpoint = data[keys_.POINT], data[keys_.ENDPOINT]
    n_points = matches.num_points
    for i, (pos_key, patch_key) in enumerate(((keys_.POS0, keys_.PATCH0),
                                              (keys_.POS1, keys_.PATCH1))):
        # both node types in one call per image (every feature is the node's own)
        xy = torch.cat([coords[keys_.POINT][i], coords[keys_.ENDPOINT][i]])
        pos = normalize_coords(xy, sizes[i], Ks[i] if use_K else None)
        point[pos_key], endpoint[pos_key] = pos[:n_points], pos[n_points:]
        if images is not None:
            patch = sample_patches(images[i], xy, patch_size)
            point[patch_key], endpoint[patch_key] = patch[:n_points], patch[n_points:]
    for node_type, (xy0, xy1) in coords.items():
        store = data[node_type]
        store.num_nodes = xy0.shape[0]
        store[keys_.KPTS0], store[keys_.KPTS1] = xy0, xy1
    if matches.point_scores is not None:
        data[keys_.POINT][keys_.SCORE] = torch.from_numpy(matches.point_scores).float()
    if matches.line_scores is not None:
        data[keys_.ENDPOINT][keys_.SCORE] = (
            torch.from_numpy(matches.line_scores).float().repeat_interleave(2)
        )

    ep = data[keys_.ENDPOINT]
    other = torch.arange(2 * nl) ^ 1
    p0, p1 = ep[keys_.POS0], ep[keys_.POS1]
    ep[keys_.LINE_FEAT] = torch.cat([p0, p0[other] - p0, p1, p1[other] - p1], dim=-1)
    data[keys_.LINE_EDGE].edge_index = line_edge_index(nl)

    for et in keys_.COMPLETE_EDGE_TYPES:
        data[et][keys_.DENSE] = torch.ones(1, dtype=torch.bool)
    if complete_edges == "explicit":
        data = materialize_complete_edges(data)

    data[keys_.IMAGE_SIZE0] = torch.tensor([sizes[0]], dtype=torch.long)
    data[keys_.IMAGE_SIZE1] = torch.tensor([sizes[1]], dtype=torch.long)
    K0, K1 = Ks
    if K0 is not None and K1 is not None:
        data[keys_.K0], data[keys_.K1] = K0.unsqueeze(0), K1.unsqueeze(0)
    if pose is not None:
        data[keys_.T_0TO1] = pose.unsqueeze(0)
    if keep_images and images is not None:  # (keep_images without images: refused above)
        data[keys_.IMAGE0], data[keys_.IMAGE1] = images[0].unsqueeze(0), images[1].unsqueeze(0)
    return data


def save_graph(data: HeteroData, path: str | os.PathLike) -> Path:
    """Saves a pair graph atomically as a dict of tensors (loadable with ``weights_only``)."""
    path = Path(path)
    with atomic_open(path) as f:
        torch.save(data.to_dict(), f)
    return path


def load_graph(path: str | os.PathLike) -> PairGraph:
    """Loads a graph written by :func:`save_graph` as a :class:`PairGraph`, with clear errors
    for bad files."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected a graph file at '{path}' (got no such file)")
    try:
        raw = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:
        raise ValueError(
            f"Expected a graph file written by save_graph at '{path}' (got {err})"
        ) from err
    if not isinstance(raw, dict) or keys_.POINT not in raw:
        raise ValueError(f"Expected a pair-graph dict in '{path}' (got {type(raw).__name__})")
    return drop_legacy_cross_edges(PairGraph.from_dict(raw))
