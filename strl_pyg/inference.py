"""Inference: one call from a pair's matches (or two images and K) to a pose with a status.

:class:`PoseEstimator` runs every registered method (:data:`METHODS`, in registration order)
on the same :class:`~strl_pyg.data.PairMatches` and picks the recommended pose: the first
method of :data:`RECOMMENDED_ORDER` whose status is ``"ok"`` (PoseLib when installed, else
OpenCV, else the network's regression). All poses are ``T_0to1`` (``X1 = R X0 + t``).

Statuses (:data:`STATUSES`): ``"ok"`` (a pose), ``"degenerate"`` (the input does not
determine the pose: fewer point matches than the solvers need (:data:`MIN_POINTS`), or zero
parallax (identical images): no pose is given), ``"failed"`` (the method found no pose, e.g.
RANSAC returned no model; never replaced by an identity pose). A pose exists only with
``"ok"``.

Uncertainty: ``covariance`` ``[5, 5]`` in the tangent parameters of
:mod:`strl_pyg.pose_fusion` around the method's own pose (rotation increment ``w`` in rad,
``R = exp([w]_x) R_hat``; translation direction ``d`` in rad on the unit sphere, basis
:func:`~strl_pyg.geometry.tangent_basis` of ``t_hat``), and ``sigma``: its summary
``{"rotation_deg": sqrt(tr Cov_w), "translation_deg": sqrt(tr Cov_d)}`` (RMS angles, degrees).
The network's comes from its predicted log-variances, the classical ones from the Sampson
residuals of their inliers (first order: optimistic for RANSAC estimates), the fused one from
the information-form fusion.

The network's input follows what its checkpoint stores (:attr:`StrLPose.metadata
<strl_pyg.model.StrLPose.metadata>`): images converted to grey or RGB, patch size,
fixed-size resampling (seeded, so a pair always gets the same graph); the forward runs under
``no_grad`` in eval mode with the graph cast to the model's dtype and device.

Adding a method is one call: ``register_method("name", fn)`` with
``fn(matches, context) -> MethodResult``; ``context.results`` holds the methods run before it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
import torch

from strl_pyg.baselines import MIN_POINTS, estimate_relative_pose
from strl_pyg.data.matches import PairMatches

__all__ = [
    "STATUSES", "RECOMMENDED_ORDER", "recommended_order", "MIN_POINTS", "ZERO_PARALLAX_PX",
    "ZERO_PARALLAX_FRACTION",
    "FOCAL_RANGE", "METHODS", "MethodSpec", "MethodResult", "MethodContext", "PoseEstimate",
    "PoseEstimator", "register_method", "prepare_matches", "prepare_graph", "forward_pose",
    "input_warnings", "zero_parallax",
]

STATUSES = ("ok", "degenerate", "failed")
#: Which method fills the recommended pose: the first ``"ok"`` one (unavailable ones skipped).
RECOMMENDED_ORDER: tuple[str, ...] = ("poselib", "opencv", "regression")
#: Zero parallax: at least this fraction of the point matches moved less than this many
#: pixels (image 1 re-expressed in image 0's camera when both K are known).
ZERO_PARALLAX_PX = 0.5
ZERO_PARALLAX_FRACTION = 0.8
#: Plausible focal lengths, as multiples of the image width.
FOCAL_RANGE = (0.1, 10.0)


# ----------------------------------------------------------------------------- results
@dataclass
class MethodResult:
    """One method's pose (or the recommended one, :attr:`PoseEstimate.pose`).

    Attributes:
        method: the method's name (``None`` for a recommended pose no method could give).
        status: one of :data:`STATUSES`.
        T_0to1: float64 ``[4, 4]`` when ``status == "ok"``, else ``None``.
        covariance: ``[5, 5]`` (module docstring) or ``None`` when not available.
        warnings: human-readable reasons and caveats.
        time_ms: wall time of the method.
        num_inliers: classical methods' inlier count.
        info: JSON-ready extras (e.g. the network's ``log_var``).
        raw: the library object (``PoseOutput``, ``BaselineResult``, ``FusedPose``); not
            serialised.
    """

    method: str | None
    status: str
    T_0to1: np.ndarray | None = None
    covariance: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    time_ms: float = 0.0
    num_inliers: int | None = None
    info: dict[str, Any] = field(default_factory=dict)
    raw: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"Expected status in {STATUSES} (got {self.status!r})")
        if self.status == "ok":
            T = np.asarray(self.T_0to1, dtype=np.float64) if self.T_0to1 is not None else None
            if T is None or T.shape != (4, 4) or not np.isfinite(T).all():
                raise ValueError("Expected a finite T_0to1 [4, 4] with status 'ok' (got "
                                 f"{None if T is None else T.shape})")
            self.T_0to1 = T
        else:
            self.T_0to1 = self.covariance = None

    @property
    def sigma(self) -> dict[str, float] | None:
        """``{"rotation_deg", "translation_deg"}`` RMS angles of :attr:`covariance`."""
        if self.covariance is None:
            return None
        d = np.clip(np.diag(self.covariance), 0.0, None)
        return {"rotation_deg": math.degrees(math.sqrt(d[:3].sum())),
                "translation_deg": math.degrees(math.sqrt(d[3:].sum()))}

    def to_dict(self) -> dict[str, Any]:
        return _jsonable({"method": self.method, "status": self.status, "T_0to1": self.T_0to1,
                          "sigma": self.sigma, "covariance": self.covariance,
                          "warnings": list(self.warnings), "time_ms": self.time_ms,
                          "num_inliers": self.num_inliers, "info": self.info})


@dataclass
class PoseEstimate:
    """Result of :meth:`PoseEstimator.estimate`: the recommended :attr:`pose` (its
    ``warnings`` hold every input warning and why earlier methods were passed over), each
    method's own result in :attr:`methods`, the match counts and the matches used."""

    pose: MethodResult
    methods: dict[str, MethodResult]
    num_points: int
    num_lines: int
    matches: PairMatches | None = field(default=None, repr=False)

    @property
    def status(self) -> str:
        return self.pose.status

    @property
    def T_0to1(self) -> np.ndarray | None:
        return self.pose.T_0to1

    @property
    def warnings(self) -> list[str]:
        return self.pose.warnings

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"pose": {...}, "methods": {name: {...}}, "num_points",
        "num_lines"}``; each record has ``method``, ``status``, ``T_0to1`` (nested lists or
        ``None``), ``sigma``, ``covariance``, ``warnings``, ``time_ms``, ``num_inliers``,
        ``info``; non-finite numbers become ``None``."""
        return {"pose": self.pose.to_dict(),
                "methods": {k: v.to_dict() for k, v in self.methods.items()},
                "num_points": self.num_points, "num_lines": self.num_lines}


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, torch.Tensor):
        v = v.detach().cpu().double().numpy()
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


# ----------------------------------------------------------------------------- registry
@dataclass
class MethodContext:
    """What a method sees besides the matches: the estimator (model, seed, threshold) and
    the results of the methods run before it."""

    estimator: PoseEstimator
    results: dict[str, MethodResult]
    cache: dict[str, Any] = field(default_factory=dict)  # shared work, e.g. a forward pass

    @property
    def model(self) -> torch.nn.Module:
        return self.estimator.model


MethodFn = Callable[[PairMatches, MethodContext], MethodResult]


@dataclass(frozen=True)
class MethodSpec:
    """A registered method: ``fn``, the point matches it needs (fewer: ``"degenerate"``),
    whether it needs ``K0``/``K1`` (missing: ``"failed"``) and whether it is installed."""

    fn: MethodFn
    min_points: int = MIN_POINTS
    needs_intrinsics: bool = True
    available: Callable[[], bool] = lambda: True


#: ``name -> MethodSpec``, run in this order.
METHODS: dict[str, MethodSpec] = {}


def register_method(name: str, fn: MethodFn, *, min_points: int = MIN_POINTS,
                    needs_intrinsics: bool = True, available: Callable[[], bool] | None = None,
                    replace_existing: bool = False) -> None:
    """Adds a method to :data:`METHODS` (run after the ones registered before it)."""
    if name in METHODS and not replace_existing:
        raise ValueError(f"Expected a new method name (got {name!r}, already registered)")
    METHODS[name] = MethodSpec(fn, min_points, needs_intrinsics, available or (lambda: True))


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
    from strl_pyg.model import StrLPose

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
    from torch_geometric.data import Batch

    dtype, dev = _model_dtype(model)
    dev = torch.device(device) if device is not None else dev
    if not isinstance(data, Batch):
        data = Batch.from_data_list([data])
    data = data.to(dev)
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


# ----------------------------------------------------------------------------- input checks
def input_warnings(size0: Any, size1: Any, K0: Any, K1: Any) -> list[str]:
    """Warnings about intrinsics that do not fit the images: one K for images of different
    sizes; a principal point outside the image; a focal length outside :data:`FOCAL_RANGE`
    times the width; no intrinsics at all."""
    if K0 is None or K1 is None:
        return ["no intrinsics (K0, K1): the network's coordinates are normalised by the image "
                "size and the classical solvers cannot run"]
    out = []
    (h0, w0), (h1, w1) = (tuple(int(v) for v in s) for s in (size0, size1))
    if (h0, w0) != (h1, w1) and np.allclose(K0, K1):
        out.append(f"the images have different sizes ({w0}x{h0} and {w1}x{h1} px) but one K: "
                   "pass each image's own intrinsics (K0, K1); the pose is likely wrong")
    lo, hi = FOCAL_RANGE
    same = (h0, w0) == (h1, w1) and np.allclose(K0, K1)
    for name, K, (h, w) in ((("K" if same else "K0"), K0, (h0, w0)), ("K1", K1, (h1, w1))):
        if name == "K1" and same:
            break
        K = np.asarray(K, dtype=np.float64)
        cx, cy, fx, fy = K[0, 2], K[1, 2], K[0, 0], K[1, 1]
        if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
            out.append(f"{name}: principal point ({cx:.1f}, {cy:.1f}) lies outside the {w}x{h} "
                       "image: is K for this image, in pixels?")
        if not (lo * w <= fx <= hi * w and lo * w <= fy <= hi * w):
            out.append(f"{name}: focal length (fx={fx:.4g}, fy={fy:.4g} px) is outside "
                       f"{lo:g}-{hi:g}x the image width ({w} px): is K for this image, in "
                       "pixels?")
    return out


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


# ----------------------------------------------------------------------------- methods
def _regression(matches: PairMatches, ctx: MethodContext) -> MethodResult:
    from strl_pyg.geometry import Pose
    from strl_pyg.pose_fusion import network_covariance, tangent_basis

    est, model = ctx.estimator, ctx.model
    start = time.perf_counter()
    out = forward_pose(model, prepare_graph(matches, model, est.seed), est.device)
    ms = (time.perf_counter() - start) * 1e3
    q, t, lv = (x[0].detach().cpu().double() for x in (out.quaternion, out.translation,
                                                       out.log_var))
    if not all(bool(torch.isfinite(x).all()) for x in (q, t, lv)) or float(t.norm()) < 1e-12:
        return MethodResult("regression", "failed", time_ms=ms, raw=out,
                            warnings=["the network returned a non-finite or zero pose"])
    cov = network_covariance(q, t, lv, tangent_basis(t)).numpy()
    info = {"quaternion": q, "translation": t, "log_var": lv,
            "sigma_components": torch.exp(0.5 * lv),
            "translation_kind": model.config.translation}
    return MethodResult("regression", "ok", Pose.from_quaternion(q, t).matrix().numpy(), cov,
                        time_ms=ms, info=info, raw=out)


def _classical(name: str) -> MethodFn:
    def fn(matches: PairMatches, ctx: MethodContext) -> MethodResult:
        from strl_pyg.pose_fusion import classical_covariance

        thr = ctx.estimator.threshold_px
        res = estimate_relative_pose(matches, name, thr, seed=ctx.estimator.seed)
        if not res.success:
            return MethodResult(name, "failed", time_ms=res.time_ms, num_inliers=0, raw=res,
                                warnings=[f"{name} found no pose (no essential matrix with "
                                          "points in front of both cameras)"])
        warnings, cov = [], None
        try:
            cov = classical_covariance(res.pose, matches, res.inliers, threshold_px=thr)[1]
            cov = cov.numpy()
        except ValueError as err:
            warnings.append(f"{name}: no covariance ({err})")
        return MethodResult(name, "ok", res.pose.matrix().numpy(), cov, warnings, res.time_ms,
                            res.num_inliers, info=dict(res.info), raw=res)

    return fn


def _full_forward(matches: PairMatches, ctx: MethodContext):
    """The network on every match (no resampling: the geometric head weighs each match),
    computed once per pair and shared by ``geometric`` and ``guided``."""
    if "full_forward" not in ctx.cache:
        est, model = ctx.estimator, ctx.model
        start = time.perf_counter()
        out = forward_pose(model, prepare_graph(matches, model, est.seed, resample=None),
                           est.device)
        ctx.cache["full_forward"] = (out, (time.perf_counter() - start) * 1e3)
    return ctx.cache["full_forward"]


def _no_head(name: str, ctx: MethodContext) -> MethodResult | None:
    if not getattr(ctx.model.config, "geometric", False):
        return MethodResult(name, "failed", warnings=[
            f"{name} needs a model with the geometric head (config.geometric=True); this "
            "checkpoint has only the regression head"])
    return None


def _with_covariance(name: str, pose_T: np.ndarray, matches: PairMatches, thr: float,
                     **kw: Any) -> MethodResult:
    from strl_pyg.geometry import Pose
    from strl_pyg.guided import _normalised, _sampson
    from strl_pyg.pose_fusion import classical_covariance

    pose = Pose.from_matrix(torch.as_tensor(pose_T, dtype=torch.float64))
    x0, x1, focal = _normalised(matches)
    inl = (_sampson(pose.R, pose.t, x0, x1) < thr / focal).numpy()
    warnings = list(kw.pop("warnings", []))
    cov = None
    try:
        cov = classical_covariance(pose, matches, inl, threshold_px=thr)[1].numpy()
    except ValueError as err:
        warnings.append(f"{name}: no covariance ({err})")
    return MethodResult(name, "ok", pose_T, cov, warnings, num_inliers=int(inl.sum()), **kw)


def _geometric(matches: PairMatches, ctx: MethodContext) -> MethodResult:
    from strl_pyg.essential import DEGENERATE, refine_pose
    from strl_pyg.geometry import Pose
    from strl_pyg.guided import _normalised

    bad = _no_head("geometric", ctx)
    if bad is not None:
        return bad
    out, ms = _full_forward(matches, ctx)
    geo = out.geometric
    status = int(geo.status[0])
    if status != 0:
        why = "degenerate weighted solve (too few effective matches or rank-deficient)" \
            if status == DEGENERATE else "no intrinsics: the weighted solve needs K0, K1"
        return MethodResult("geometric", "degenerate" if status == DEGENERATE else "failed",
                            time_ms=ms, warnings=[f"geometric: {why}"], raw=out)
    start = time.perf_counter()
    w = torch.sigmoid(geo.point_logits.double().cpu())
    x0, x1, focal = _normalised(matches)
    R, t = refine_pose(geo.R[:1].cpu(), geo.t[:1].cpu(), x0[None], x1[None], w[None],
                       iterations=10, tau=ctx.estimator.threshold_px / focal)
    T = Pose(R[0], t[0]).matrix().numpy()
    ms += (time.perf_counter() - start) * 1e3
    return _with_covariance("geometric", T, matches, ctx.estimator.threshold_px, time_ms=ms,
                            info={"mean_weight": float(w.mean())}, raw=out)


def _guided(matches: PairMatches, ctx: MethodContext) -> MethodResult:
    from strl_pyg.guided import guided_estimate

    bad = _no_head("guided", ctx)
    if bad is not None:
        return bad
    base = "poselib" if _have_poselib() else "opencv"
    out, ms = _full_forward(matches, ctx)
    w = torch.sigmoid(out.geometric.point_logits.double().cpu()).numpy()
    prior = ctx.results.get(base)
    classical = prior.raw if prior is not None and prior.status == "ok" else None
    res = guided_estimate(matches, w, base, ctx.estimator.threshold_px, seed=ctx.estimator.seed,
                          classical=classical)
    ms += res.time_ms
    if not res.success:
        return MethodResult("guided", "failed", time_ms=ms, raw=res,
                            warnings=[f"guided {base}: no hypothesis found"])
    info = {"base": base, "candidate": res.info["candidate"], "refined": res.info["refined"]}
    return _with_covariance("guided", res.pose.matrix().numpy(), matches,
                            ctx.estimator.threshold_px, time_ms=ms, info=info, raw=res)


def _fused(matches: PairMatches, ctx: MethodContext) -> MethodResult:
    from strl_pyg.pose_fusion import fuse_poses

    net = ctx.results.get("regression")
    cls = next((ctx.results[c] for c in ("poselib", "opencv")
                if c in ctx.results and ctx.results[c].status == "ok"), None)
    if net is None or net.status != "ok" or cls is None:
        return MethodResult("fused", "failed", warnings=[
            "fused needs an 'ok' regression and an 'ok' classical estimate (poselib or opencv)"])
    start = time.perf_counter()
    scale = _calibration(ctx.model).get("regression", 1.0)
    f = fuse_poses(net.raw, None, cls.raw, matches, threshold_px=ctx.estimator.threshold_px,
                   network_scale=scale)
    ms = (time.perf_counter() - start) * 1e3 + net.time_ms + cls.time_ms
    if f.source == "network":
        return MethodResult("fused", "failed", time_ms=ms, raw=f, warnings=[
            f"fused: too few {cls.method} inliers for a covariance ({f.info['num_inliers']})"])
    gate = f.info.get("gate", {})
    info = {"classical": cls.method, "network_weight": f.weights,
            "sign_disagreement": f.info["sign_disagreement"], "used": f.source,
            "gate_d2": gate.get("d2")}
    warnings = [] if f.source == "fused" else [f"fused: {gate.get('reason')}"]
    return MethodResult("fused", "ok", f.pose.matrix().numpy(), f.covariance.numpy(),
                        warnings, time_ms=ms, num_inliers=f.info["num_inliers"], info=info,
                        raw=f)


def recommended_order(model: torch.nn.Module | None) -> tuple[str, ...]:
    """The order in which methods fill the recommended pose: the checkpoint's
    ``metadata["recommended_order"]`` (measured on held-out data when the checkpoint was
    calibrated, see ``benchmarks/bench_pose.py --calibrate``), else :data:`RECOMMENDED_ORDER`.
    Methods that are not installed are skipped when the estimate is made."""
    md = getattr(model, "metadata", None) if model is not None else None
    order = md.get("recommended_order") if isinstance(md, dict) else None
    if isinstance(order, (list, tuple)) and order and all(isinstance(m, str) for m in order):
        return tuple(order)
    return RECOMMENDED_ORDER


def _calibration(model: torch.nn.Module | None) -> dict[str, float]:
    """Per-method covariance scales fitted on held-out data (checkpoint metadata
    ``"calibration"``; ``{}`` when the checkpoint has none)."""
    if model is None:
        return {}
    md = getattr(model, "metadata", None)
    cal = md.get("calibration", {}) if isinstance(md, dict) else {}
    return {str(k): float(v) for k, v in cal.items()} if isinstance(cal, dict) else {}


def _have_poselib() -> bool:
    try:
        import poselib  # noqa: F401
    except ImportError:
        return False
    return True


register_method("regression", _regression, needs_intrinsics=False)
register_method("opencv", _classical("opencv"))
register_method("poselib", _classical("poselib"), available=_have_poselib)
register_method("fused", _fused)
register_method("geometric", _geometric)
register_method("guided", _guided)


# ----------------------------------------------------------------------------- estimator
def _unique(items: list[str]) -> list[str]:
    return list(dict.fromkeys(items))


class PoseEstimator:
    """Pose of one image pair by every registered method, with a recommended one.

    Args:
        model: a :class:`~strl_pyg.model.StrLPose` (any dtype or device); ``None``: the shipped
            model, :meth:`StrLPose.from_pretrained() <strl_pyg.model.StrLPose.from_pretrained>`,
            loaded on first use.
        methods: names from :data:`METHODS` to run (default: all installed ones).
        seed: resampling and RANSAC seed (same input, same result).
        threshold_px: inlier threshold of the classical solvers, pixels.
        device: where the network runs (default: the model's device).
        raise_errors: re-raise a method's exception instead of recording ``"failed"``.
    """

    def __init__(self, model: torch.nn.Module | None = None, methods: Any = None,
                 seed: int = 0, threshold_px: float = 1.0, device: Any = None,
                 raise_errors: bool = False) -> None:
        names = tuple(methods) if methods is not None else tuple(
            n for n, s in METHODS.items() if s.available())
        unknown = [n for n in names if n not in METHODS]
        if unknown or not names:
            raise ValueError(f"Expected methods from {tuple(METHODS)} (got {list(names)})")
        missing = [n for n in names if not METHODS[n].available()]
        if missing:
            raise ValueError(f"Expected installed methods (got {missing}: not importable here)")
        if not threshold_px > 0:
            raise ValueError(f"Expected threshold_px > 0 (got {threshold_px!r})")
        self.method_names = names
        self._model = model
        self.seed, self.threshold_px, self.device = int(seed), float(threshold_px), device
        self.raise_errors = raise_errors

    @property
    def model(self) -> torch.nn.Module:
        if self._model is None:
            from strl_pyg.model import StrLPose

            self._model = StrLPose.from_pretrained()
        return self._model

    def estimate(self, matches: PairMatches) -> PoseEstimate:
        """Runs the methods on ``matches`` (pixels; ``K0``/``K1`` for the classical ones)."""
        if not isinstance(matches, PairMatches):
            raise TypeError(f"Expected a PairMatches (got {type(matches).__name__})")
        warnings = input_warnings(matches.image_size0, matches.image_size1, matches.K0,
                                  matches.K1)
        n, degenerate = matches.num_points, None
        if zero_parallax(matches):
            degenerate = (f"zero parallax: most of the {n} point matches moved less than "
                          f"{ZERO_PARALLAX_PX} px (identical or near-identical images): the "
                          "translation is undefined")
            warnings.append(degenerate)
        ctx = MethodContext(self, {})
        needs_model = any(m in ("regression", "geometric", "guided", "fused")
                          for m in self.method_names)
        calibration = _calibration(self.model) if needs_model else {}
        for name in self.method_names:
            spec = METHODS[name]
            if degenerate is not None:
                res = MethodResult(name, "degenerate", warnings=[degenerate])
            elif n < spec.min_points:
                res = MethodResult(name, "degenerate", warnings=[
                    f"too few point matches for {name}: {n} (needs {spec.min_points})"])
            elif spec.needs_intrinsics and not matches.has_intrinsics:
                res = MethodResult(name, "failed",
                                   warnings=[f"{name} needs intrinsics K0, K1 (got none)"])
            else:
                try:
                    res = spec.fn(matches, ctx)
                except Exception as err:
                    if self.raise_errors:
                        raise
                    first = str(err).splitlines()[0] if str(err) else ""
                    res = MethodResult(name, "failed",
                                       warnings=[f"{name} raised {type(err).__name__}: {first}"])
            scale = calibration.get(name)
            if scale is not None and res.covariance is not None and name != "fused":
                res.covariance = res.covariance * scale
                res.info["calibration_scale"] = scale
            ctx.results[name] = res
        return self._recommend(ctx.results, warnings, matches)

    def estimate_images(self, image0: np.ndarray, image1: np.ndarray, K0: Any = None,
                        K1: Any = None, frontend_config: Any = None) -> PoseEstimate:
        """Matches two images with :func:`~strl_pyg.frontend.match_images`, then
        :meth:`estimate`. ``K1`` defaults to ``K0`` (one camera). No matches at all gives
        status ``"degenerate"``."""
        from strl_pyg.frontend import NoMatchesError, match_images

        if K0 is None and K1 is not None:
            raise ValueError("Expected K0 with K1 (got K1 only)")
        K1 = K0 if K1 is None else K1
        try:
            matches = match_images(image0, image1, K0=K0, K1=K1, config=frontend_config)
        except NoMatchesError as err:
            warnings = input_warnings(np.shape(image0)[:2], np.shape(image1)[:2], K0, K1)
            why = f"no matches: {str(err).splitlines()[0]}"
            methods = {m: MethodResult(m, "degenerate", warnings=[why])
                       for m in self.method_names}
            return PoseEstimate(MethodResult(None, "degenerate", warnings=warnings + [why]),
                                methods, 0, 0, None)
        return self.estimate(matches)

    def _recommend(self, results: dict[str, MethodResult], warnings: list[str],
                   matches: PairMatches) -> PoseEstimate:
        chosen = recommended_order(self._model)
        order = [m for m in chosen if m in results]
        notes = []
        for m in order:
            r = results[m]
            if r.status == "ok":
                pose = replace(r, warnings=_unique(warnings + notes + r.warnings))
                return PoseEstimate(pose, results, matches.num_points, matches.num_lines,
                                    matches)
            reasons = [w for w in r.warnings if w not in warnings]
            if reasons:
                notes.append(f"{m} {r.status}: {'; '.join(reasons)}")
        if not order:
            notes.append(f"none of the recommended methods {chosen} was run")
        status = "degenerate" if any(results[m].status == "degenerate" for m in order) \
            else "failed"
        pose = MethodResult(None, status, warnings=_unique(warnings + notes))
        return PoseEstimate(pose, results, matches.num_points, matches.num_lines, matches)
