import math

import numpy as np
import pytest
import torch

from strl_pyg.geometry import Pose, quaternion_to_rotation, relative_pose_from_c2w
from strl_pyg.metrics import (
    KITTI_SEGMENT_LENGTHS,
    absolute_trajectory_error,
    integrate_relative_poses,
    kitti_odometry_errors,
    kitti_odometry_summary,
    pose_auc,
    relative_pose_error,
    relative_translation_norms,
    rotation_error_deg,
    translation_angle_error_deg,
    umeyama_alignment,
)

F64 = torch.float64


def rot_y(rad: float) -> np.ndarray:
    c, s = math.cos(rad), math.sin(rad)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def random_rotations(n, seed=0):
    g = torch.Generator().manual_seed(seed)
    return quaternion_to_rotation(torch.randn(n, 4, generator=g, dtype=F64))


# ------------------------------------------------------------------ two-view errors
def test_rotation_error_known_answers():
    R = random_rotations(5)
    torch.testing.assert_close(rotation_error_deg(R, R), torch.zeros(5, dtype=F64),
                               atol=1e-6, rtol=0)
    d = torch.from_numpy(rot_y(math.radians(10.0)))
    torch.testing.assert_close(rotation_error_deg(R @ d, R), torch.full((5,), 10.0, dtype=F64))
    torch.testing.assert_close(rotation_error_deg(d @ R, R), torch.full((5,), 10.0, dtype=F64))
    # numpy and Pose at the boundary, broadcasting one GT against a batch
    e = rotation_error_deg(Pose(d.numpy(), np.zeros(3)), np.eye(3)[None].repeat(2, 0))
    torch.testing.assert_close(e, torch.full((2,), 10.0, dtype=F64))


def test_rotation_error_gradcheck():
    R_gt = random_rotations(3, seed=1)
    q = torch.tensor([[0.9, 0.1, 0.3, -0.2]] * 3, dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda q: rotation_error_deg(quaternion_to_rotation(q), R_gt), (q,))


def test_translation_error_sign_convention():
    t = torch.tensor([[1.0, 0, 0], [1.0, 0, 0], [0, 0, 2.0], [0, 1, 1]], dtype=F64)
    g = torch.tensor([[3.0, 0, 0], [-1.0, 0, 0], [1.0, 0, 0], [0, 0, 5.0]], dtype=F64)
    torch.testing.assert_close(translation_angle_error_deg(t, g),
                               torch.tensor([0.0, 180.0, 90.0, 45.0], dtype=F64))
    torch.testing.assert_close(translation_angle_error_deg(t, g, fold_sign=True),
                               torch.tensor([0.0, 0.0, 90.0, 45.0], dtype=F64))
    e = translation_angle_error_deg([0.0, 0, 0], [1.0, 0, 0])
    assert torch.isnan(e)


def test_relative_pose_error_identity_and_known():
    T = Pose(torch.from_numpy(rot_y(math.radians(10.0))), [0.0, 0.0, 1.0])
    er, et = relative_pose_error(T, T.matrix())
    assert float(er) == pytest.approx(0.0, abs=1e-6) and float(et) == pytest.approx(0.0, abs=1e-6)
    er, et = relative_pose_error(Pose(np.eye(3), [0.0, 0, -1.0]), T, fold_sign=False)
    assert float(er) == pytest.approx(10.0) and float(et) == pytest.approx(180.0)
    _, et = relative_pose_error(Pose(np.eye(3), [0.0, 0, -1.0]), T, fold_sign=True)
    assert float(et) == pytest.approx(0.0)


# ------------------------------------------------------------------ AUC
def reference_auc(errors, thr):
    """Independent reference: sample the recall polyline densely and integrate."""
    e = np.sort(np.where(np.isfinite(errors), errors, np.inf))
    y = np.arange(1, len(e) + 1) / len(e)
    keep = e < thr
    xs = np.linspace(0.0, thr, 200001)
    curve = np.interp(xs, np.r_[0.0, e[keep]], np.r_[0.0, y[keep]])
    return np.trapezoid(curve, xs) / thr


def test_pose_auc_known_answers():
    assert pose_auc(np.zeros(10)) == pytest.approx([1.0, 1.0, 1.0])
    # one pair with error e: area = e / 2 + (t - e), so AUC = 1 - e / (2 t)
    assert pose_auc([2.0]) == pytest.approx([0.8, 0.9, 0.95])
    assert pose_auc([30.0, np.nan, np.inf]) == pytest.approx([0.0, 0.0, 0.0])
    assert pose_auc([1.0, float("nan")], thresholds=(10,)) == pytest.approx([0.5 * 0.95])
    rng = np.random.default_rng(0)
    errs = np.abs(rng.normal(0, 8, 200))
    errs[::17] = np.nan
    for thr, auc in zip((5, 10, 20), pose_auc(errs), strict=True):
        assert auc == pytest.approx(reference_auc(errs, thr), abs=1e-6)


def test_pose_auc_bad_input():
    with pytest.raises(ValueError, match="at least one"):
        pose_auc([])
    with pytest.raises(ValueError, match="non-negative"):
        pose_auc([-1.0])
    with pytest.raises(ValueError, match="positive thresholds"):
        pose_auc([1.0], thresholds=(0,))


# ------------------------------------------------------------------ KITTI odometry measure
@pytest.fixture(scope="module")
def kitti_gt(kitti_root):
    rows = np.loadtxt(kitti_root / "poses" / "06.txt")
    assert rows.shape == (1101, 12)
    return rows.reshape(-1, 3, 4)


def reference_segments(T, lengths, step):
    """Brute-force segment ends, written as the devkit's loops."""
    dist = [0.0]
    for i in range(1, len(T)):
        dist.append(dist[-1] + float(np.linalg.norm(T[i, :3, 3] - T[i - 1, :3, 3])))
    out = []
    for f in range(0, len(T), step):
        for L in lengths:
            last = next((i for i in range(f, len(T)) if dist[i] > dist[f] + L), -1)
            if last != -1:
                out.append((f, last, L))
    return out


def test_kitti_gt_against_itself_is_zero(kitti_gt):
    seg = kitti_odometry_errors(kitti_gt, kitti_gt)
    ref = reference_segments(kitti_gt, KITTI_SEGMENT_LENGTHS, 10)
    assert len(seg) == len(ref) > 500
    np.testing.assert_array_equal(seg.first_frame, [r[0] for r in ref])
    np.testing.assert_array_equal(seg.last_frame, [r[1] for r in ref])
    s = kitti_odometry_summary(seg)
    assert s["t_err_pct"] < 1e-6 and s["r_err_deg_per_100m"] < 1e-4
    assert sorted(s["per_length"]) == [float(L) for L in KITTI_SEGMENT_LENGTHS]


def test_kitti_constant_yaw_drift(kitti_gt):
    # Estimate i = Ry(i * delta) @ GT_i (a yaw about the world's vertical axis growing by
    # delta per frame). Then inv(D_est) @ D_gt = inv(G_l) Ry(-(l - f) delta) G_l, a conjugate
    # of a rotation by (l - f) delta: the segment's rotation error is exactly
    # (l - f) * delta / L radians per metre.
    delta = math.radians(0.01)
    est = kitti_gt.copy()
    for i in range(len(est)):
        A = rot_y(i * delta)
        est[i, :, :3] = A @ kitti_gt[i, :, :3]
        est[i, :, 3] = A @ kitti_gt[i, :, 3]
    seg = kitti_odometry_errors(kitti_gt, est)
    expected = (seg.last_frame - seg.first_frame) * delta / seg.length
    np.testing.assert_allclose(seg.r_err, expected, rtol=1e-4, atol=1e-8)
    s = kitti_odometry_summary({"06": seg})
    expected_deg_100m = np.degrees(expected.mean()) * 100
    assert s["r_err_deg_per_100m"] == pytest.approx(expected_deg_100m, rel=1e-4)
    assert s["per_sequence"]["06"]["r_err_deg_per_100m"] == pytest.approx(expected_deg_100m,
                                                                          rel=1e-4)
    # sanity of magnitude: 0.01 deg per frame at roughly 1 m per frame is ~1 deg per 100 m
    assert 0.5 < s["r_err_deg_per_100m"] < 2.0


def test_kitti_scaled_translation(kitti_gt):
    # Positions scaled by (1 + s) about the origin, rotations kept: the error pose is a pure
    # translation of length s * |t_l - t_f|, so t_err = s * chord / L.
    s = 0.05
    est = kitti_gt.copy()
    est[:, :, 3] *= 1 + s
    seg = kitti_odometry_errors(kitti_gt, est, lengths=(100, 400))
    chord = np.linalg.norm(kitti_gt[seg.last_frame, :, 3] - kitti_gt[seg.first_frame, :, 3], axis=1)
    np.testing.assert_allclose(seg.t_err, s * chord / seg.length, rtol=1e-4)
    assert seg.r_err.max() < 1e-8


def test_kitti_bad_input(kitti_gt):
    with pytest.raises(ValueError, match="as many estimated"):
        kitti_odometry_errors(kitti_gt, kitti_gt[:-1])
    with pytest.raises(ValueError, match=r"\[N, 4, 4\]"):
        kitti_odometry_errors(kitti_gt[:, :, :3], kitti_gt[:, :, :3])


# ------------------------------------------------------------------ Umeyama / ATE
def test_umeyama_recovers_similarity():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(40, 3))
    R = random_rotations(1, seed=2)[0].numpy()
    t, s = np.array([1.0, -2.0, 0.5]), 2.5
    Y = s * X @ R.T + t
    R2, t2, s2 = umeyama_alignment(X, Y, with_scale=True)
    np.testing.assert_allclose(R2, R, atol=1e-10)
    np.testing.assert_allclose(t2, t, atol=1e-10)
    assert s2 == pytest.approx(s)
    R3, t3, s3 = umeyama_alignment(X, X @ R.T + t)
    assert s3 == 1.0
    np.testing.assert_allclose(R3, R, atol=1e-10)
    # a reflection in the data still gives a proper rotation
    R4, _, _ = umeyama_alignment(X, X * np.array([1.0, 1.0, -1.0]))
    assert np.linalg.det(R4) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="at least 3"):
        umeyama_alignment(X[:2], X[:2])


def test_ate(kitti_gt):
    G = kitti_gt[:200]
    R = random_rotations(1, seed=3)[0].numpy()
    P = 0.3 * G[:, :, 3] @ R.T + np.array([5.0, 1.0, -2.0])
    assert absolute_trajectory_error(P, G, align="sim3").rmse < 1e-8
    assert absolute_trajectory_error(P, G, align="rigid").rmse > 1.0
    rigid = absolute_trajectory_error(Pose.from_matrix(G), G, align="none")
    assert rigid.rmse == 0.0 and rigid.max == 0.0
    noisy = G[:, :, 3] + np.random.default_rng(0).normal(0, 0.1, (200, 3))
    r = absolute_trajectory_error(noisy, G, align="none")
    assert r.rmse == pytest.approx(0.1 * math.sqrt(3), rel=0.15)
    with pytest.raises(ValueError, match="align in"):
        absolute_trajectory_error(P, G, align="se3")


# ------------------------------------------------------------------ trajectory integration
def test_integrate_recovers_gt(kitti_gt):
    G = Pose.from_matrix(kitti_gt[:60])
    rel = relative_pose_from_c2w(G[:-1], G[1:])
    out = integrate_relative_poses(rel, T_w_c0=G[0])
    assert out.shape == (60,)
    np.testing.assert_allclose(out.numpy(), G.numpy(), atol=1e-5)
    # unit-translation predictions with ground-truth scale per pair give the same trajectory
    unit = Pose(rel.R, rel.t / rel.t.norm(dim=-1, keepdim=True))
    scales = relative_translation_norms(G)
    out = integrate_relative_poses(unit.matrix(), T_w_c0=G[0], scales=scales)
    np.testing.assert_allclose(out.numpy(), G.numpy(), atol=1e-5)
    # without scale, every step of a unit-translation chain has length 1
    out = integrate_relative_poses(unit)
    # (KITTI's rotations are orthonormal to ~1e-7 only, which the chain carries along)
    np.testing.assert_allclose(relative_translation_norms(out).numpy(), 1.0, atol=1e-6)
    with pytest.raises(ValueError, match="'scales' of shape"):
        integrate_relative_poses(unit, scales=np.ones(3))
