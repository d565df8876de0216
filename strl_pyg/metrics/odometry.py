"""Trajectory metrics of visual odometry built from two-view poses, re-exported by
:mod:`strl_pyg.metrics.two_view` (import them from there or from here).

* :func:`kitti_odometry_errors`: the KITTI odometry benchmark's drift measure, written after
  the official devkit's definition (``evaluate_odometry.cpp``), and
  :func:`kitti_odometry_summary`, its averages as the benchmark reports them.
* :func:`absolute_trajectory_error` with Umeyama alignment (:func:`umeyama_alignment`).
* :func:`integrate_relative_poses` to chain ``T_0to1`` predictions into camera-to-world poses,
  and :func:`relative_translation_norms`, the ground-truth step lengths that scale them.

Trajectories are **camera-to-world** poses ``T_w_c`` (as KITTI's ``poses/NN.txt``); the
trajectory files are written by :mod:`strl_pyg.metrics.trajectory`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from strl_pyg.geometry import Pose, as_pose, as_tensor, rotation_angle_deg
from strl_pyg.metrics.trajectory import project_to_so3

__all__ = [
    "KITTI_SEGMENT_LENGTHS",
    "KittiSegmentErrors",
    "kitti_odometry_errors",
    "kitti_odometry_summary",
    "umeyama_alignment",
    "ATEResult",
    "absolute_trajectory_error",
    "relative_translation_norms",
    "integrate_relative_poses",
]


# ----------------------------------------------------------------------------- KITTI odometry
#: Segment lengths of the KITTI odometry benchmark, metres.
KITTI_SEGMENT_LENGTHS = (100, 200, 300, 400, 500, 600, 700, 800)


@dataclass
class KittiSegmentErrors:
    """Per-segment drift of one sequence, as the KITTI devkit computes it (numpy arrays ``[S]``).

    ``t_err`` is translation error per metre (fraction, multiply by 100 for percent);
    ``r_err`` is rotation error in **radians per metre** (devkit units). Use
    :func:`kitti_odometry_summary` for percent and degrees per 100 m.
    """

    first_frame: np.ndarray
    last_frame: np.ndarray
    length: np.ndarray
    t_err: np.ndarray
    r_err: np.ndarray
    speed: np.ndarray

    def __len__(self) -> int:
        return len(self.first_frame)


def _trajectory_matrices(poses: Any, name: str) -> np.ndarray:
    if isinstance(poses, Pose):
        T = poses.numpy()
    else:
        T = as_tensor(poses, name).detach().cpu().double().numpy()
        if T.ndim == 2 and T.shape[1] == 12:
            T = T.reshape(-1, 3, 4)
    if T.ndim != 3 or T.shape[1:] not in ((3, 4), (4, 4)):
        raise ValueError(
            f"Expected '{name}' as a Pose [N] or of shape [N, 4, 4], [N, 3, 4] or [N, 12] "
            f"(got {tuple(T.shape)})"
        )
    if T.shape[1] == 3:
        T = np.concatenate([T, np.tile([[[0.0, 0.0, 0.0, 1.0]]], (len(T), 1, 1))], axis=1)
    if not np.isfinite(T).all():
        raise ValueError(f"Expected finite poses in '{name}' (got NaN or inf)")
    return T


def kitti_odometry_errors(
    T_w_c_gt: Any,
    T_w_c_est: Any,
    lengths: Sequence[float] = KITTI_SEGMENT_LENGTHS,
    step: int = 10,
    frame_time_s: float = 0.1,
) -> KittiSegmentErrors:
    """The KITTI odometry benchmark's segment errors of one sequence.

    Following the devkit: distances are accumulated along the **ground-truth** positions;
    for every start frame ``f`` in ``0, step, 2 step, ...`` and every length ``L``, the segment
    ends at the first frame ``l`` whose distance exceeds ``dist[f] + L`` (segments that run off
    the end are skipped); with ``D_gt = inv(T_gt[f]) T_gt[l]`` and likewise ``D_est``, the error
    pose is ``inv(D_est) D_gt``; its rotation angle over ``L`` and its translation norm over
    ``L`` are the segment's ``r_err`` and ``t_err``. One deliberate difference: the angle is
    computed with :func:`~strl_pyg.geometry.rotation_angle_deg` (atan2) instead of the devkit's
    ``acos``, equal for rotations but accurate for errors below ~0.01 degrees.

    Args:
        T_w_c_gt, T_w_c_est: **camera-to-world** poses of the same frames: a :class:`Pose`
            ``[N]`` or matrices ``[N, 4, 4]``, ``[N, 3, 4]``, or KITTI rows ``[N, 12]``.
        lengths: segment lengths in metres (default 100, ..., 800).
        step: start-frame spacing (default 10, as the devkit).
        frame_time_s: seconds between frames, only for ``speed`` (KITTI: 0.1).

    Returns:
        :class:`KittiSegmentErrors`, segments ordered by start frame then length.
    """
    gt = _trajectory_matrices(T_w_c_gt, "T_w_c_gt")
    est = _trajectory_matrices(T_w_c_est, "T_w_c_est")
    if len(gt) != len(est):
        raise ValueError(
            f"Expected as many estimated as ground-truth poses (got {len(est)} and {len(gt)})"
        )
    if step < 1:
        raise ValueError(f"Expected step >= 1 (got {step})")
    steps = np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1)
    dist = np.concatenate([[0.0], np.cumsum(steps)])
    firsts, lasts, lens = [], [], []
    for f in range(0, len(gt), step):
        for L in lengths:
            # first frame with dist > dist[f] + L; dist is non-decreasing
            l = int(np.searchsorted(dist, dist[f] + L, side="right"))
            if l >= len(gt):
                continue
            firsts.append(f)
            lasts.append(l)
            lens.append(float(L))
    f_idx, l_idx = np.asarray(firsts, dtype=np.int64), np.asarray(lasts, dtype=np.int64)
    length = np.asarray(lens, dtype=np.float64)
    # A general 4x4 inverse, as the devkit: pose files hold rotations orthonormal to ~1e-7 only,
    # and the rigid inverse would turn that into a spurious error of the ground truth itself.
    d_gt = np.linalg.inv(gt[f_idx]) @ gt[l_idx]
    d_est = np.linalg.inv(est[f_idx]) @ est[l_idx]
    err = np.linalg.inv(d_est) @ d_gt
    # The devkit takes acos((trace - 1) / 2); the atan2 form gives the same angle for a
    # rotation and stays accurate near 0, where acos loses half the digits.
    angle = np.radians(rotation_angle_deg(torch.from_numpy(err[:, :3, :3])).numpy())
    r_err = angle / length if len(err) else np.zeros(0)
    t_err = np.linalg.norm(err[:, :3, 3], axis=1) / length if len(err) else np.zeros(0)
    speed = length / (frame_time_s * (l_idx - f_idx + 1)) if len(err) else np.zeros(0)
    return KittiSegmentErrors(f_idx, l_idx, length, t_err, r_err, speed)


def kitti_odometry_summary(
    segments: KittiSegmentErrors | Sequence[KittiSegmentErrors] | dict[Any, KittiSegmentErrors],
) -> dict[str, Any]:
    """Averages segment errors as the benchmark reports them.

    Args:
        segments: one sequence's :class:`KittiSegmentErrors`, a list of them, or a dict
            ``{sequence name: segments}``.

    Returns:
        ``{"t_err_pct", "r_err_deg_per_100m", "num_segments", "per_length": {L: (t_err_pct,
        r_err_deg_per_100m, count)}, "per_sequence": {name: {...same keys...}}}``; the overall
        figures average over **all** segments of all sequences (as the devkit does), not over
        sequence means. Values are ``NaN`` where no segment exists.
    """
    if isinstance(segments, KittiSegmentErrors):
        seqs = {"0": segments}
    elif isinstance(segments, dict):
        seqs = dict(segments)
    else:
        seqs = {str(i): s for i, s in enumerate(segments)}
    if not seqs:
        raise ValueError("Expected at least one sequence of segment errors (got none)")

    def _summ(parts: list[KittiSegmentErrors]) -> dict[str, Any]:
        t = np.concatenate([p.t_err for p in parts])
        r = np.concatenate([p.r_err for p in parts])
        ln = np.concatenate([p.length for p in parts])
        per_len = {}
        for L in np.unique(ln):
            m = ln == L
            per_len[float(L)] = (
                float(t[m].mean() * 100.0),
                float(np.degrees(r[m].mean()) * 100.0),
                int(m.sum()),
            )
        n = len(t)
        return {
            "t_err_pct": float(t.mean() * 100.0) if n else float("nan"),
            "r_err_deg_per_100m": float(np.degrees(r.mean()) * 100.0) if n else float("nan"),
            "num_segments": n,
            "per_length": per_len,
        }

    out = _summ(list(seqs.values()))
    out["per_sequence"] = {k: _summ([v]) for k, v in seqs.items()}
    return out


# ----------------------------------------------------------------------------- ATE
def umeyama_alignment(
    src: Any, dst: Any, with_scale: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares similarity (or rigid) transform with ``dst ~ s R src + t`` (Umeyama 1991).

    Args:
        src, dst: corresponding points ``[N, 3]`` (N >= 3, not all collinear for a unique R).
        with_scale: estimate ``s`` (Sim(3)); otherwise ``s = 1`` (SE(3)).

    Returns:
        ``(R [3, 3], t [3], s)`` as numpy float64.
    """
    X = as_tensor(src, "src").detach().cpu().double().numpy()
    Y = as_tensor(dst, "dst").detach().cpu().double().numpy()
    if X.ndim != 2 or X.shape[1] != 3 or X.shape != Y.shape:
        raise ValueError(
            f"Expected 'src' and 'dst' of one shape [N, 3] (got {X.shape} and {Y.shape})"
        )
    if len(X) < 3:
        raise ValueError(f"Expected at least 3 points to align (got {len(X)})")
    mx, my = X.mean(0), Y.mean(0)
    Xc, Yc = X - mx, Y - my
    cov = Yc.T @ Xc / len(X)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0  # keep a proper rotation
    R = U @ S @ Vt
    var_x = (Xc**2).sum() / len(X)
    s = float(np.trace(np.diag(D) @ S) / var_x) if with_scale and var_x > 0 else 1.0
    t = my - s * R @ mx
    return R, t, s


@dataclass
class ATEResult:
    """Absolute trajectory error after alignment; distances in the ground truth's units."""

    rmse: float
    mean: float
    median: float
    max: float
    errors: np.ndarray = field(repr=False)
    R: np.ndarray = field(repr=False)
    t: np.ndarray = field(repr=False)
    scale: float = 1.0
    aligned: np.ndarray = field(default=None, repr=False)  # estimated positions after alignment


def _positions(x: Any, name: str) -> np.ndarray:
    if isinstance(x, Pose):
        return x.t.detach().cpu().double().numpy().reshape(-1, 3)
    a = as_tensor(x, name).detach().cpu().double().numpy()
    if a.ndim == 2 and a.shape[1] == 3:
        return a
    return _trajectory_matrices(a, name)[:, :3, 3]


def absolute_trajectory_error(
    est: Any, gt: Any, align: str = "rigid"
) -> ATEResult:
    """Position error of an estimated trajectory after aligning it to the ground truth.

    Args:
        est, gt: camera positions ``[N, 3]``, or camera-to-world poses (:class:`Pose` ``[N]``,
            ``[N, 4, 4]``, ``[N, 3, 4]``, ``[N, 12]``), whose translations are the positions.
        align: ``"rigid"`` (SE(3), default), ``"sim3"`` (with scale, for monocular or
            unit-translation estimates) or ``"none"``.

    Returns:
        :class:`ATEResult` with RMSE, mean, median and max of the per-frame distances.
    """
    P = _positions(est, "est")
    G = _positions(gt, "gt")
    if P.shape != G.shape:
        raise ValueError(f"Expected as many estimated as GT positions (got {len(P)} and {len(G)})")
    if align not in ("rigid", "sim3", "none"):
        raise ValueError(f"Expected align in ('rigid', 'sim3', 'none') (got {align!r})")
    if align == "none":
        R, t, s = np.eye(3), np.zeros(3), 1.0
    else:
        R, t, s = umeyama_alignment(P, G, with_scale=align == "sim3")
    A = s * P @ R.T + t
    e = np.linalg.norm(A - G, axis=1)
    return ATEResult(
        rmse=float(np.sqrt(np.mean(e**2))),
        mean=float(e.mean()),
        median=float(np.median(e)),
        max=float(e.max()),
        errors=e,
        R=R,
        t=t,
        scale=s,
        aligned=A,
    )


# ----------------------------------------------------------------------------- integration
def relative_translation_norms(T_w_c: Any) -> torch.Tensor:
    """Distances between consecutive camera centres, ``[N] poses -> [N - 1]``.

    These are the ground-truth scales to give :func:`integrate_relative_poses` for
    unit-translation predictions. Accepts what :func:`kitti_odometry_errors` accepts.
    """
    T = _trajectory_matrices(T_w_c, "T_w_c")
    return torch.from_numpy(np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1))


def integrate_relative_poses(
    T_0to1: Any, T_w_c0: Any = None, scales: Any = None, eps: float = 1e-12
) -> Pose:
    """Chains per-pair ``T_0to1`` (frame ``i`` to ``i + 1``) into camera-to-world poses.

    ``T_w_c[i + 1] = T_w_c[i] @ inv(T_{i to i+1})``, in float64 on rotations projected onto
    SO(3) before and after (:func:`project_to_so3`; inputs must be rotations up to rounding,
    ``|RR^T - I| <= 1e-4``): a float32 chain drifts past evo's 1e-6 orthonormality check
    after ~1000 steps. Files: :func:`write_kitti_trajectory`, :func:`write_tum_trajectory`.

    Scale: with ``scales=None`` translations are used as given (metric predictions, or a
    trajectory whose every step has length 1 for unit-translation predictions). With
    ``scales`` ``[M]`` (e.g. :func:`relative_translation_norms` of the ground truth, the usual
    protocol for two-view methods that only predict a direction) each translation is first
    normalised to unit length, then multiplied by its scale.

    Args:
        T_0to1: :class:`Pose` ``[M]`` or matrices ``[M, 4, 4]`` / ``[M, 3, 4]``.
        T_w_c0: camera-to-world pose of the first frame (default identity).
        scales: optional per-pair lengths, shape ``[M]``.

    Returns:
        float64 :class:`Pose` ``[M + 1]`` of camera-to-world poses.
    """
    rel = as_pose(T_0to1, "T_0to1")
    if len(rel.shape) != 1:
        raise ValueError(f"Expected 'T_0to1' with one batch dimension [M] (got {tuple(rel.shape)})")
    t = rel.t.double()
    if scales is not None:
        s = as_tensor(scales, "scales").to(t)
        if s.shape != (len(rel),):
            raise ValueError(f"Expected 'scales' of shape ({len(rel)},) (got {tuple(s.shape)})")
        norm = t.norm(dim=-1, keepdim=True)
        if bool((norm < eps).any()):
            raise ValueError("Expected non-zero translations to rescale (got a zero translation)")
        t = t / norm * s[:, None]
    rel = Pose(project_to_so3(rel.R, "T_0to1"), t)
    if T_w_c0 is None:
        start = Pose.identity(dtype=torch.float64, device=rel.device)
    else:
        start = as_pose(T_w_c0, "T_w_c0").to(device=rel.device)
        start = Pose(project_to_so3(start.R, "T_w_c0"), start.t.double())
    out = [start]
    inv_rel = rel.inv()
    for i in range(len(rel)):
        out.append(out[-1] @ inv_rel[i])
    chain = Pose.stack(out)
    return Pose(project_to_so3(chain.R, "T_w_c", tol=None), chain.t)
