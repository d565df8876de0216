"""What goes into :mod:`strl_pyg.inference.estimator`: the network's input graph and forward
pass, and
the checks of a pair's matches and intrinsics that turn into warnings, ``"unreliable"`` or
``"degenerate"``.

The network's input follows what its checkpoint stores (:attr:`StrLPose.metadata
<strl_pyg.model.strl_pose.StrLPose.metadata>`): images converted to grey or RGB, patch size,
fixed-size resampling (seeded, so a pair always gets the same graph); the forward runs under
``no_grad`` in eval mode with the graph cast to the model's dtype and device.
"""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import Any

import cv2
import numpy as np
import torch

from strl_pyg.data.matches import PairMatches

__all__ = [
    "ZERO_PARALLAX_PX", "ZERO_PARALLAX_FRACTION", "FOCAL_RANGE", "NORMALISED_K_MAX",
    "prepare_matches", "prepare_graph", "forward_pose", "input_warnings",
    "intrinsics_problems", "zero_parallax", "network_pose", "check_device"]

#: Zero parallax: at least this fraction of the point matches moved less than this many
#: pixels (image 1 re-expressed in image 0's camera when both K are known).
ZERO_PARALLAX_PX = 0.5
ZERO_PARALLAX_FRACTION = 0.8
#: Plausible focal lengths, as multiples of the image width.
FOCAL_RANGE = (0.1, 10.0)


# ----------------------------------------------------------------------------- network input
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
    return replace(matches, image0=_convert_image(matches.image0, channels),
                   image1=_convert_image(matches.image1, channels)), md["patch_size"] or 1


def prepare_graph(matches: PairMatches, model: torch.nn.Module, seed: int = 0,
                  resample: Any = "model"):
    """The model's input graph of one pair: :func:`prepare_matches`, then
    :func:`~strl_pyg.data.build_pair_graph`, then :class:`~strl_pyg.data.FixedSizeResample`
    to ``resample`` (``(points, lines)``, ``None`` = none, ``"model"`` = the checkpoint's)."""
    from strl_pyg.data.graph import build_pair_graph
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
    data = build_pair_graph(m, patch_size=p, keep_images=model.config.visual == "cnn")
    if isinstance(resample, str) and resample == "model":
        resample = _metadata(model)["resample"]
    if resample is not None:
        data = FixedSizeResample(int(resample[0]), int(resample[1]), seed=seed)(data)
    return data


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


# ----------------------------------------------------------------------------- input checks
#: A K whose focal lengths are at most this and whose principal point lies within this of
#: the origin looks normalised (by the image width or size) rather than in pixels.
NORMALISED_K_MAX = 10.0


def intrinsics_problems(size0: Any, size1: Any, K0: Any, K1: Any) -> list[str]:
    """Why the intrinsics do not fit the images (``[]`` when they do, or when there are
    none): one K for images of different sizes; a principal point outside the image (with a
    hint when ``cx`` and ``cy`` look swapped); a normalised K (focal lengths and principal
    point of at most :data:`NORMALISED_K_MAX`) with pixel coordinates; a focal length outside
    :data:`FOCAL_RANGE` times the width. Sizes are ``(H, W)``; every pose computed with such
    intrinsics is ``"unreliable"`` (:class:`~strl_pyg.inference.estimator.PoseEstimator`)."""
    if K0 is None or K1 is None:
        return []
    out = []
    (h0, w0), (h1, w1) = (tuple(int(v) for v in s) for s in (size0, size1))
    if (h0, w0) != (h1, w1) and np.allclose(K0, K1):
        out.append(f"the images have different sizes ({h0}x{w0} and {h1}x{w1} px, H x W) but "
                   "one K: pass each image's own intrinsics (K0, K1); the pose is likely wrong")
    lo, hi = FOCAL_RANGE
    same = (h0, w0) == (h1, w1) and np.allclose(K0, K1)
    for name, K, (h, w) in ((("K" if same else "K0"), K0, (h0, w0)), ("K1", K1, (h1, w1))):
        if name == "K1" and same:
            break
        K = np.asarray(K, dtype=np.float64)
        cx, cy, fx, fy = K[0, 2], K[1, 2], K[0, 0], K[1, 1]
        size = f"{h}x{w} px (H x W)"
        if max(abs(fx), abs(fy), abs(cx), abs(cy)) <= NORMALISED_K_MAX and w > 4 * \
                NORMALISED_K_MAX:
            out.append(f"{name} looks normalised (fx={fx:.4g}, fy={fy:.4g}, cx={cx:.4g}, "
                       f"cy={cy:.4g}) but the points are pixels of a {size} image: pass K in "
                       "pixels (a K normalised by the image size: multiply row 0 by W and row 1 "
                       "by H)")
            continue
        if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
            swapped = -0.5 <= cy <= w - 0.5 and -0.5 <= cx <= h - 0.5
            hint = (f": cx and cy look swapped (cx is the column, at most {w - 0.5:g} here)"
                    if swapped else ": is K for this image, in pixels?")
            out.append(f"{name}: principal point (cx={cx:.1f}, cy={cy:.1f}) lies outside the "
                       f"{size} image{hint}")
        if not (lo * w <= fx <= hi * w and lo * w <= fy <= hi * w):
            out.append(f"{name}: focal length (fx={fx:.4g}, fy={fy:.4g} px) is outside "
                       f"{lo:g}-{hi:g}x the image width ({w} px): is K for this image, in "
                       "pixels?")
    return out


def input_warnings(size0: Any, size1: Any, K0: Any, K1: Any) -> list[str]:
    """Warnings about the intrinsics: none at all (the classical solvers cannot run), or
    :func:`intrinsics_problems`."""
    if K0 is None or K1 is None:
        return ["no intrinsics (K0, K1): the network's coordinates are normalised by the image "
                "size and the classical solvers cannot run"]
    return intrinsics_problems(size0, size1, K0, K1)


def zero_parallax(matches: PairMatches) -> bool:
    """Whether at least :data:`ZERO_PARALLAX_FRACTION` of the point matches moved less than
    :data:`ZERO_PARALLAX_PX` pixels (identical or near-identical images)."""
    if matches.num_points == 0:
        return False
    p0, p1 = matches.points0, matches.points1
    if matches.has_intrinsics:
        K0, K1 = matches.K0, matches.K1
        x1 = np.c_[p1, np.ones(len(p1))] @ np.linalg.inv(K1).T
        p1 = (x1 @ K0.T)[:, :2] / (x1 @ K0.T)[:, 2:]
    moved = np.linalg.norm(p1 - p0, axis=1)
    return float(np.mean(moved < ZERO_PARALLAX_PX)) >= ZERO_PARALLAX_FRACTION


def check_device(device: Any) -> torch.device | None:
    """``device`` as a ``torch.device`` (``None`` stays ``None``); ``ValueError`` for a name
    torch does not know or a device this machine does not have."""
    if device is None:
        return None
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(f"Expected a torch device such as 'cpu' or 'cuda' (got {device!r})"
                         ) from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(f"Expected a device this machine has (got {device!r}: CUDA is not "
                             "available here); use device='cpu', or None for the model's own")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ValueError(f"Expected a CUDA device index below {torch.cuda.device_count()} "
                             f"(got {device!r})")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"Expected a device this machine has (got {device!r}: MPS is not "
                         "available here); use device='cpu', or None for the model's own")
    elif dev.type == "meta":
        raise ValueError(f"Expected a device that holds data (got {device!r})")
    return dev
