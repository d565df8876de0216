"""The network's side of :mod:`strl_pyg.inference.estimator`: its input graph and forward pass.

The network's input follows what its checkpoint stores (:attr:`StrLPose.metadata
<strl_pyg.model.strl_pose.StrLPose.metadata>`): images converted to grey or RGB, patch size,
fixed-size resampling (seeded, so a pair always gets the same graph); the forward runs under
``no_grad`` in eval mode with the graph cast to the model's dtype and device.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from strl_pyg.data.matches import PairMatches

__all__ = ["prepare_matches", "prepare_graph", "forward_pose", "network_pose", "network_poses",
           "NetworkPoses", "resampled_rows"]


def _convert_image(image: np.ndarray | None, channels: int | None) -> np.ndarray | None:
    if image is None or channels is None:
        return image
    if channels == 1 and image.ndim == 3:
        return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    if channels == 3 and image.ndim == 2:
        return np.repeat(image[..., None], 3, axis=2)
    return image


def _metadata(model: torch.nn.Module) -> dict[str, Any]:
    from strl_pyg.model.strl_pose import StrLPose

    md = getattr(model, "metadata", None)
    return md if isinstance(md, dict) else StrLPose.default_metadata(model.config)


def prepare_matches(matches: PairMatches, model: torch.nn.Module) -> tuple[PairMatches, int]:
    """``(matches, patch_size)``: the matches with images converted to the channels the
    model's checkpoint stores (grey or RGB), and the patch size to sample."""
    cfg = model.config
    if cfg.visual is None:
        return matches, 1
    if not matches.has_images:
        raise ValueError(f"Expected images in the matches for a model with visual={cfg.visual!r} "
                         "(got none)")
    md = _metadata(model)
    channels = md["patch_channels"]
    return matches._derived(image0=_convert_image(matches.image0, channels),
                            image1=_convert_image(matches.image1, channels)), \
        md["patch_size"] or 1


def prepare_graph(matches: PairMatches, model: torch.nn.Module, seed: int | None = 0,
                  resample: Any = "model", reference: bool = False):
    """The model's input graph of one pair: :func:`prepare_matches`, then
    :func:`~strl_pyg.data.build_pair_graph`, then :class:`~strl_pyg.data.FixedSizeResample`
    to ``resample`` (``(points, lines)``, ``None`` = none, ``"model"`` = the checkpoint's).

    The graph is built on the resampled rows only (the same indices, drawn from the same
    generator, so the same graph as building every match and resampling the graph: every node
    feature is the node's own); ``reference=True`` takes that longer way."""
    from strl_pyg.data.build import build_pair_graph
    from strl_pyg.data.transforms import FixedSizeResample

    # every network method (regression, the geometric head, guided, fused through regression)
    # comes through here, so this one check is what refuses descriptor-matched lines
    if matches.num_lines and not matches.line_endpoints_correspond:
        raise ValueError(
            "Expected lines whose endpoint k matches endpoint k (got lines from the descriptor "
            "matcher, info['line_endpoints'] == 'as detected'): the network reads endpoints as "
            "correspondences; match with FrontendConfig(line_matcher='epipolar') or use the "
            "line solvers (vp, vp_checked)")
    m, p = prepare_matches(matches, model)
    keep_images = model.config.visual == "cnn"
    if isinstance(resample, str) and resample == "model":
        resample = _metadata(model)["resample"]
    if resample is None:
        return build_pair_graph(m, patch_size=p, keep_images=keep_images)
    n_points, n_lines = int(resample[0]), int(resample[1])
    if not reference:
        pi, li = resampled_rows(m, (n_points, n_lines), seed)
        if pi.numel() or li.numel():
            return build_pair_graph(m._derived(pi.numpy(), li.numpy()), patch_size=p,
                                    keep_images=keep_images)
    data = build_pair_graph(m, patch_size=p, keep_images=keep_images)
    if not reference:  # nothing drawn (targets 0, or nothing to draw): the empty graph, no redraw
        return FixedSizeResample(n_points, n_lines, seed=0)(data)
    return FixedSizeResample(n_points, n_lines, seed=seed)(data)


def resampled_rows(matches: PairMatches, resample: tuple[int, int],
                   seed: int | None) -> tuple[torch.Tensor, torch.Tensor]:
    """The rows of ``matches`` the model's graph holds at ``resample = (points, lines)``:
    FixedSizeResample's draws, in its order (points, then lines), with ``seed``."""
    from strl_pyg.data.transforms import resample_indices

    generator = None if seed is None else torch.Generator().manual_seed(seed)
    pi = resample_indices(matches.num_points, int(resample[0]), generator)
    li = resample_indices(matches.num_lines, int(resample[1]), generator)
    return pi, li


@dataclass
class NetworkPoses:
    """The network on several pairs at once (:func:`network_poses`); row ``i`` is pair ``i``.

    Attributes:
        output: the model's :class:`~strl_pyg.model.PoseOutput` of the batch.
        T_0to1: ``[B, 4, 4]`` float64, ``X1 = R X0 + t`` (unit translation direction).
        sigma_deg: ``[B, 2]`` the network's own RMS rotation and translation-direction angles
            (:attr:`PoseOutput.sigma_deg <strl_pyg.model.PoseOutput.sigma_deg>`: uncalibrated;
            :class:`~strl_pyg.inference.PoseEstimator`'s ``regression`` record scales them by
            the checkpoint's calibration and widens them by the swap and data checks).
        point_weights: per pair, the geometric head's inlier weight (sigmoid of its logit) of
            each point node of the pair's graph (``None`` without a geometric head).
        point_rows: per pair, the input row of each of those point nodes (the graph holds
            the model's resampled rows: ``resample="model"``).
    """

    output: Any
    T_0to1: np.ndarray
    sigma_deg: np.ndarray
    point_weights: list[np.ndarray] | None
    point_rows: list[np.ndarray]


def network_poses(model: torch.nn.Module, pairs: Sequence[PairMatches], seed: int | None = 0,
                  resample: Any = "model", device: Any = None) -> NetworkPoses:
    """The model on a batch of pairs: each pair's graph as :func:`prepare_graph` builds it (the
    same graph as one pair at a time: the same poses, to float precision), one
    ``Batch.from_data_list``, one forward (:func:`forward_pose`). A model that reads pixels
    (the shipped one: ``visual="pixel"``) needs each pair's images in its matches."""
    from torch_geometric.data import Batch

    from strl_pyg.data import keys as K

    pairs = list(pairs)
    if not pairs or not all(isinstance(m, PairMatches) for m in pairs):
        raise TypeError(f"Expected a non-empty list of PairMatches (got "
                        f"{[type(m).__name__ for m in pairs][:3] or 'an empty list'})")
    graphs = [prepare_graph(m, model, seed, resample) for m in pairs]
    out = forward_pose(model, Batch.from_data_list(graphs), device)
    T = out.T_0to1.detach().double().cpu().numpy()
    if isinstance(resample, str) and resample == "model":
        resample = _metadata(model)["resample"]
    rows = [resampled_rows(m, resample, seed)[0].numpy() if resample is not None
            else np.arange(m.num_points) for m in pairs]
    weights = None
    geo = out.geometric
    if geo is not None and geo.point_logits is not None:
        counts = [int(g[K.POINT].num_nodes) for g in graphs]
        w = torch.sigmoid(geo.point_logits.detach().double()).cpu().numpy()
        weights = list(np.split(w, np.cumsum(counts)[:-1]))
    return NetworkPoses(out, T, out.sigma_deg.detach().double().cpu().numpy(), weights, rows)


def _model_dtype(model: torch.nn.Module) -> tuple[torch.dtype, torch.device]:
    tensors = [t for t in list(model.parameters()) + list(model.buffers())
               if t.is_floating_point()]
    dtypes = sorted({str(t.dtype) for t in tensors})
    if len(dtypes) > 1:
        raise TypeError(f"Expected model parameters of one floating dtype (got {dtypes})")
    if not tensors:
        return torch.float32, torch.device("cpu")
    return tensors[0].dtype, tensors[0].device


@torch.no_grad()
def forward_pose(model: torch.nn.Module, data: Any, device: Any = None):
    """The model's ``PoseOutput`` on a pair graph or batch: eval mode (restored afterwards),
    ``no_grad``, the graph's floating tensors cast to the model's dtype (float32 outputs for
    half-precision models, float64 for float64 ones) and moved to its device (or
    ``device``)."""
    dtype, dev = _model_dtype(model)
    dev = torch.device(device) if device is not None else dev
    # one graph goes in as it is (the model reads a graph without batch vectors as one pair;
    # Batch.from_data_list cost 2.6 ms of a 37 ms forward); a shallow copy, so that the move
    # and the casts below replace tensors of the copy, never of the caller's graph or batch
    data = copy.copy(data).to(dev)
    for store in data.stores:
        for key, value in list(store.items()):
            if isinstance(value, torch.Tensor) and value.is_floating_point():
                store[key] = value.to(dtype)
    was_training = model.training
    model.eval()
    try:
        out = model(data)
    except RuntimeError as err:
        if "dtype" not in str(err) and "Half" not in str(err) and "BFloat16" not in str(err):
            raise
        raise TypeError(f"Expected a forward pass in the model's dtype {dtype} on this device "
                        f"(got {str(err).splitlines()[0]})") from err
    finally:
        model.train(was_training)
    out_dtype = torch.float64 if dtype == torch.float64 else torch.float32
    out.quaternion, out.translation, out.log_var = (
        x.to(out_dtype) for x in (out.quaternion, out.translation, out.log_var))
    return out


def network_pose(model: torch.nn.Module, matches: PairMatches, seed: int = 0,
                 resample: Any = "model", device: Any = None):
    """The model's ``PoseOutput`` on one pair's matches: :func:`prepare_graph` then
    :func:`forward_pose`. The one place that turns a :class:`~strl_pyg.model.StrLPose` and a
    pair into a pose (the ``regression`` method, the geometric head's full forward,
    ``strl-pose predict`` and ``evaluate`` all call it)."""
    return forward_pose(model, prepare_graph(matches, model, seed, resample), device)

