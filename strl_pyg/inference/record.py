"""The pose record of :mod:`strl_pyg.inference.estimator`: one method's result
(:class:`MethodResult`)
and a pair's estimate (:class:`PoseEstimate`: the recommended pose and every method's), both
JSON-ready through ``to_dict``. All poses are ``T_0to1`` (``X1 = R X0 + t``).

Statuses (:data:`STATUSES`): ``"ok"`` (a pose), ``"rotation_only"`` (the matches have no
parallax: a pure rotation, or a translation too small to see; the rotation is in
:attr:`MethodResult.rotation` with its ``sigma["rotation_deg"]``, there is no translation
direction, and ``T_0to1`` is ``None``), ``"unreliable"`` (a pose was computed but must
not be used: the intrinsics fail the input checks, or many of the matches that fit its epipolar
geometry lie behind a camera; the reasons are in ``warnings`` and ``info["unreliable"]``, the
computed pose, for inspection only, in ``info["unreliable_T_0to1"]``), ``"degenerate"`` (the
input does not determine the pose: fewer point matches than the solvers need, or zero parallax
(identical images): no pose is given), ``"failed"`` (the method found no pose, e.g. RANSAC
returned no model, or the matches do not support it; never replaced by an identity pose),
``"skipped"`` (a method's record only: the input lacks what it reads, e.g. images for a model
that reads pixels, or the method it starts from was skipped; the recommended pose is never
``"skipped"``). A pose (``T_0to1``, ``covariance``, ``sigma``) exists only with ``"ok"``: a
script that reads ``T_0to1`` or ``sigma`` without the status gets ``None`` for any other.

Uncertainty: ``covariance`` ``[5, 5]`` in the tangent parameters of
:mod:`strl_pyg.estimation.pose_fusion` around the method's own pose (rotation increment ``w`` in
rad, ``R = exp([w]_x) R_hat``; translation direction ``d`` in rad on the unit sphere, basis
:func:`~strl_pyg.geometry.tangent_basis` of ``t_hat``), and ``sigma``: its summary
``{"rotation_deg": sqrt(tr Cov_w), "translation_deg": sqrt(tr Cov_d)}`` (RMS angles, degrees).
PoseLib's, OpenCV's and the guided one are first order plus a bootstrap of the classical solve
(:mod:`strl_pyg.estimation.uncertainty`), the fused one the information-form fusion plus the
classical bootstrap, the network's come from its predicted log-variances
(``info["covariance"]`` names which); each is scaled by the checkpoint's calibration
(``info["calibration_scale"]``) where one applies.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches
from strl_pyg.geometry.pose import Pose
from strl_pyg.inference.status import Action, Status, Verdict

__all__ = ["MethodResult", "PoseEstimate"]


@dataclass
class MethodResult:
    """One method's pose (or the recommended one, :attr:`PoseEstimate.pose`).

    Attributes:
        method: the method's name (``None`` for a recommended pose no method could give).
        status: a :class:`~strl_pyg.inference.status.Status` (its string is taken too).
        T_0to1: float64 ``[4, 4]`` when ``status == "ok"``, else ``None`` (given as a ``[4, 4]``
            array or as a :class:`~strl_pyg.geometry.Pose`, kept for :meth:`as_pose`).
        covariance: ``[5, 5]`` (module docstring) or ``None`` when not available.
        warnings: human-readable reasons and caveats.
        time_ms: wall time of the method.
        num_inliers: classical methods' inlier count.
        info: JSON-ready extras (e.g. the network's ``log_var``).
        raw: the library object (``PoseOutput``, ``BaselineResult``, ``FusedPose``); not
            serialised.
        inliers: bool ``[Np]`` per point match of the input (repeated rows share their
            correspondence's value): within the support band of the pose and in front of
            both cameras; ``None`` for methods the support check does not read.
        rotation: the rotation ``[3, 3]`` of an ``"ok"`` or ``"rotation_only"`` record.
        calibrated: whether :attr:`covariance` was scaled by a measured calibration
            (``False``: a warning says why not; ``None``: not decided, or no covariance).
        bad_intrinsics: the pose was computed with intrinsics that fail the input checks
            (:func:`~strl_pyg.inference.checks.intrinsics_problems`).
        unsupported: the support check refused the pose (its matches do not support it:
            :func:`~strl_pyg.inference.support.check_support`); ``info["unsupported"]`` in
            the JSON record.
        support_checked: whether the matches' support decides this pose
            (:func:`~strl_pyg.inference.support.check_support`'s default; ``False`` for the
            regression, whose pose is learned, not fitted to the matches).
        raised: the exception's type name where the method raised (``status == "failed"``);
            ``info["raised"]`` in the JSON record.
        verdicts: every rule's :class:`~strl_pyg.inference.status.Verdict` on this pose, in
            the order they spoke (refusals, widened sigmas, reports); :attr:`rule` is the one
            that gave it its status.
        covariance_with_focal: the covariance with the focal length's effect added (the
            ``focal`` rule: solves with both focal lengths scaled by its range, where the
            matches do not verify the focal length); ``None`` where it was not measured.
            :attr:`covariance` is the pose's uncertainty for the intrinsics given.
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
    inliers: np.ndarray | None = field(default=None, repr=False)
    rotation: np.ndarray | None = None
    calibrated: bool | None = None
    bad_intrinsics: bool = False
    unsupported: bool = False
    raised: str | None = None
    support_checked: bool = True
    verdicts: list[Verdict] = field(default_factory=list)
    covariance_with_focal: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.status = Status.of(self.status)
        if self.status is Status.ROTATION_ONLY:
            R = None if self.rotation is None else np.asarray(self.rotation, dtype=np.float64)
            if R is None or R.shape != (3, 3) or not np.isfinite(R).all():
                raise ValueError("Expected a finite rotation [3, 3] with status "
                                 f"'rotation_only' (got {None if R is None else R.shape})")
            cov = self.covariance
            if cov is not None and np.asarray(cov).shape != (3, 3):
                raise ValueError(f"Expected a [3, 3] rotation covariance with status "
                                 f"'rotation_only' (got {np.asarray(cov).shape})")
            self.rotation, self.T_0to1 = R, None
            self._pose = self._pose_of = None
            return
        pose = self.T_0to1 if isinstance(self.T_0to1, Pose) else None
        if pose is not None:  # a method's own Pose: kept for as_pose(), the matrix from it
            if pose.R.shape != (3, 3):
                raise ValueError(f"Expected one pose (got a batch of shape "
                                 f"{tuple(pose.R.shape[:-2])})")
            # its own copy: the caller's tensors may change later, the record must not
            pose = Pose(pose.R.detach().cpu().double().clone(),
                        pose.t.detach().cpu().double().clone())
            self.T_0to1 = pose.matrix().numpy()
        self._pose = self._pose_of = None
        if self.status is Status.OK:
            T = np.asarray(self.T_0to1, dtype=np.float64) if self.T_0to1 is not None else None
            if T is None or T.shape != (4, 4) or not np.isfinite(T).all():
                raise ValueError("Expected a finite T_0to1 [4, 4] with status 'ok' (got "
                                 f"{None if T is None else T.shape})")
            self.T_0to1 = T
            if pose is not None:
                self._pose, self._pose_of = pose, T.copy()
            self.rotation = T[:3, :3].copy()
        else:
            self.T_0to1 = self.covariance = self.rotation = None
            self.covariance_with_focal = None

    def as_pose(self) -> Pose | None:
        """``T_0to1`` as a float64 :class:`~strl_pyg.geometry.Pose` (``None`` unless
        ``"ok"``): the method's own when it built the record from one (no round trip through
        the 4x4 matrix), else made once from ``T_0to1``."""
        if self.T_0to1 is None:
            return None
        T = np.asarray(self.T_0to1, dtype=np.float64)
        if self._pose is None or not np.array_equal(self._pose_of, T):  # T_0to1 changed
            self._pose = Pose.from_matrix(torch.as_tensor(T.copy()))
            self._pose_of = T.copy()
        return self._pose

    def unreliable(self, reasons: list[str], rule: str,
                   evidence: dict[str, Any] | None = None) -> MethodResult:
        """This record refused by ``rule`` as ``"unreliable"`` (from ``"ok"`` or
        ``"rotation_only"``; an ``"unreliable"`` one gets the further reasons; any other is
        returned unchanged): no ``T_0to1`` nor covariance, the pose moved to
        ``info["unreliable_T_0to1"]``, ``reasons`` added to ``warnings`` and to
        ``info["unreliable"]``, and a :class:`~strl_pyg.inference.status.Verdict` of ``rule``
        (with ``evidence``) to :attr:`verdicts`."""
        if self.status not in (Status.OK, Status.ROTATION_ONLY, Status.UNRELIABLE) \
                or not reasons:
            return self
        info = {**self.info, "unreliable": list(self.info.get("unreliable", [])) + reasons}
        if self.status is Status.OK:
            info["unreliable_T_0to1"] = self.T_0to1
        if self.status is Status.ROTATION_ONLY:
            info["unreliable_rotation"] = self.rotation
        verdict = Verdict(rule, Action.REFUSED, Status.UNRELIABLE, "; ".join(reasons),
                          dict(evidence or {}))
        return MethodResult(self.method, Status.UNRELIABLE, None, None,
                            self.warnings + reasons, self.time_ms, self.num_inliers, info,
                            self.raw, self.inliers, calibrated=self.calibrated,
                            bad_intrinsics=self.bad_intrinsics,
                            verdicts=[*self.verdicts, verdict])

    def with_verdict(self, verdict: Verdict, warn: bool = True) -> MethodResult:
        """This record with ``verdict`` added to :attr:`verdicts` (and its reason to the
        warnings with ``warn``); the caller has made the change it describes."""
        warnings = self.warnings + [verdict.reason] if warn and verdict.reason and \
            verdict.reason not in self.warnings else self.warnings
        return replace(self, verdicts=[*self.verdicts, verdict], warnings=warnings)

    @property
    def rule(self) -> str | None:
        """The rule that gave this record its status: the last refusing verdict's (``None``
        for an ``"ok"`` pose, or where no rule was named)."""
        if self.status is Status.OK:
            return None
        for v in reversed(self.verdicts):
            if v.status is self.status:
                return v.rule
        return None

    @property
    def sigma_with_focal(self) -> dict[str, float] | None:
        """:attr:`sigma` of :attr:`covariance_with_focal` (``None`` where it was not
        measured)."""
        return None if self.covariance_with_focal is None else _sigma_of(
            self.covariance_with_focal)

    @property
    def sigma(self) -> dict[str, float] | None:
        """``{"rotation_deg", "translation_deg"}`` RMS angles of :attr:`covariance`."""
        return None if self.covariance is None else _sigma_of(self.covariance)

    def to_dict(self) -> dict[str, Any]:
        return _jsonable({"method": self.method, "status": self.status.value,
                          "rule": self.rule, "T_0to1": self.T_0to1,
                          "rotation": self.rotation, "sigma": self.sigma,
                          "sigma_with_focal": self.sigma_with_focal,
                          "covariance": self.covariance,
                          "warnings": list(self.warnings), "time_ms": self.time_ms,
                          "num_inliers": self.num_inliers, "info": {
                              **self.info, **({"unsupported": True} if self.unsupported else {}),
                              **({"raised": self.raised} if self.raised else {})},
                          "verdicts": [v.to_dict() for v in self.verdicts],
                          "inliers": self.inliers})


@dataclass
class PoseEstimate:
    """Result of :meth:`PoseEstimator.estimate`: the recommended :attr:`pose` (its
    ``warnings`` hold every input warning and why earlier methods were passed over), each
    method's own result in :attr:`methods`, the match counts and the matches used."""

    pose: MethodResult
    methods: dict[str, MethodResult]
    num_points: int
    num_lines: int
    #: The matches the methods ran on: the input's with each repeated match once
    #: (:meth:`PairMatches.deduplicated`); :attr:`point_rows` maps the input's rows to them.
    matches: PairMatches | None = field(default=None, repr=False)
    #: For every input point row, its row in :attr:`matches` (``None`` when unknown).
    point_rows: np.ndarray | None = field(default=None, repr=False)
    #: The pair's two-view configuration and focal check
    #: (:class:`~strl_pyg.estimation.two_view.TwoViewGeometry`; ``None`` without intrinsics).
    geometry: Any = field(default=None, repr=False)

    @property
    def configuration(self) -> str | None:
        """``"general"``, ``"planar"``, ``"rotation"`` or ``"degenerate"`` (``None``: not
        decided, e.g. without intrinsics)."""
        return None if self.geometry is None else self.geometry.configuration

    def inliers_of_matches(self, record: MethodResult | None = None) -> np.ndarray | None:
        """The inlier mask of ``record`` (default: the recommended pose), whose
        :attr:`MethodResult.inliers` follow the input's rows, over the rows of
        :attr:`matches` instead: what ``draw_matches(est.matches, point_inliers=...)``
        takes. ``None`` without a mask."""
        rec = self.pose if record is None else record
        if rec.inliers is None or self.matches is None:
            return None
        if self.point_rows is None:
            return np.asarray(rec.inliers, dtype=bool)
        out = np.zeros(self.matches.num_points, dtype=bool)
        out[self.point_rows] = rec.inliers
        return out

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
        "num_lines", "two_view"}`` (the configuration, :attr:`geometry`); each record has
        ``method``, ``status``, ``T_0to1`` (nested lists or
        ``None``), ``sigma``, ``covariance``, ``warnings``, ``time_ms``, ``num_inliers``,
        ``info``; non-finite numbers become ``None``."""
        return {"pose": self.pose.to_dict(),
                "methods": {k: v.to_dict() for k, v in self.methods.items()},
                "num_points": self.num_points, "num_lines": self.num_lines,
                "two_view": None if self.geometry is None else _jsonable(
                    self.geometry.to_dict())}


def _sigma_of(cov: Any) -> dict[str, float | None]:
    """``{"rotation_deg", "translation_deg"}`` RMS angles of a ``[5, 5]`` (or a rotation's
    ``[3, 3]``) covariance."""
    d = np.clip(np.diag(np.asarray(cov, dtype=np.float64)), 0.0, None)
    return {"rotation_deg": math.degrees(math.sqrt(d[:3].sum())),
            "translation_deg": math.degrees(math.sqrt(d[3:].sum())) if len(d) > 3
            else None}  # a rotation alone has no translation direction


def _jsonable(v: Any) -> Any:
    if isinstance(v, enum.Enum):
        return v.value
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
