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
    project_to_so3,
    relative_translation_norms,
    umeyama_alignment,
    write_kitti_trajectory,
    write_tum_trajectory,
)
from strl_pyg.metrics.two_view import (
    pose_auc,
    relative_pose_error,
    rotation_error_deg,
    translation_angle_error_deg,
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


# ------------------------------------------------------------- SO(3) drift and trajectory files
def float32_chain(n=2000, seed=0) -> Pose:
    """``n`` random small float32 relative poses (a driving-like chain)."""
    g = torch.Generator().manual_seed(seed)
    q = torch.cat([torch.ones(n, 1), 0.05 * torch.randn(n, 3, generator=g)], dim=1)
    R = quaternion_to_rotation(q.float())
    t = torch.randn(n, 3, generator=g) * torch.tensor([0.1, 0.05, 1.0])
    return Pose(R, t.float())


def so3_error(R) -> float:
    R = np.asarray(R, dtype=np.float64)
    return float(np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max())


def test_integrated_rotations_stay_on_so3():
    """The reproduced bug: 1600 float32 steps drifted to |RR^T - I| ~ 8e-6 (evo rejects
    1e-6). Composition now runs in float64 on projected rotations."""
    rel = float32_chain(2000)
    out = integrate_relative_poses(rel)
    assert out.dtype == F64 and out.shape == (2001,)
    assert so3_error(out.R.numpy()) < 1e-12
    assert np.linalg.det(out.R.numpy()).min() == pytest.approx(1.0, abs=1e-12)
    # the projection only removes rounding: a float64 reference chain agrees to float32 level
    ref = [np.eye(4)]
    for T in rel.matrix().double().numpy():
        ref.append(ref[-1] @ np.linalg.inv(T))
    np.testing.assert_allclose(out.numpy(), np.stack(ref), atol=1e-3)
    with pytest.raises(ValueError, match="Expected rotations in 'T_0to1'"):
        reflection = torch.diag(torch.tensor([1.0, 1, -1]))[None]
        integrate_relative_poses(Pose(reflection, torch.zeros(1, 3)))


def test_project_to_so3_known_answers():
    R = quaternion_to_rotation(torch.tensor([[0.9, 0.1, -0.3, 0.2]], dtype=F64))
    torch.testing.assert_close(project_to_so3(R * (1 + 1e-6)), R, atol=1e-12, rtol=0)
    noisy = R + 1e-6 * torch.randn(1, 3, 3, dtype=F64, generator=torch.Generator().manual_seed(0))
    assert so3_error(project_to_so3(noisy).numpy()) < 1e-14
    with pytest.raises(ValueError, match="orthonormal"):
        project_to_so3(2 * R)
    with pytest.raises(ValueError, match="det"):
        project_to_so3(-R)
    with pytest.raises(ValueError, match=r"\(\*, 3, 3\)"):
        project_to_so3(torch.zeros(3, 4))


def read_like_evo(path, fields: int) -> np.ndarray:
    """evo's ``csv_read_matrix(delim=" ", comment_str="#")`` and its field-count check."""
    import csv

    with open(path) as f:
        rows = list(csv.reader((ln for ln in f if not ln.startswith("#")), delimiter=" "))
    assert rows and all(len(r) == fields for r in rows), "evo: wrong entries per row"
    return np.array(rows).astype(float)


def quaternion_matrix_like_evo(q_wxyz: np.ndarray) -> np.ndarray:
    """``transformations.quaternion_matrix`` (used by evo): normalise, then the Hamilton matrix."""
    q = q_wxyz / np.linalg.norm(q_wxyz, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def test_trajectory_files_read_back_as_evo_and_the_devkit_read_them(tmp_path):
    traj = integrate_relative_poses(float32_chain(2000))
    T = traj.numpy()

    kitti = write_kitti_trajectory(tmp_path / "out" / "06.txt", traj)
    text = kitti.read_text()
    assert text.count("\n") == 2001 and not any(ln != ln.strip() for ln in text.splitlines())
    rows = read_like_evo(kitti, 12)
    # the KITTI devkit: fscanf("%lf" x 12) per pose, whitespace-separated
    devkit = np.array(text.split(), dtype=np.float64).reshape(-1, 12)
    np.testing.assert_array_equal(rows, devkit)
    P = rows.reshape(-1, 3, 4)
    np.testing.assert_allclose(P, T[:, :3], rtol=0, atol=1e-12)
    assert so3_error(P[:, :, :3]) < 1e-9
    assert np.abs(np.linalg.det(P[:, :, :3]) - 1).max() < 1e-9

    stamps = np.linspace(0.0, 207.5, 2001)
    tum = write_tum_trajectory(tmp_path / "06.tum", traj, timestamps=stamps)
    m = read_like_evo(tum, 8)
    np.testing.assert_allclose(m[:, 0], stamps, rtol=0, atol=1e-12)
    assert (np.diff(m[:, 0]) > 0).all()
    np.testing.assert_allclose(m[:, 1:4], T[:, :3, 3], rtol=0, atol=1e-12)
    q_wxyz = np.roll(m[:, 4:], 1, axis=1)  # evo: qx qy qz qw -> w first
    assert np.abs(np.linalg.norm(q_wxyz, axis=1) - 1).max() < 1e-12
    R = quaternion_matrix_like_evo(q_wxyz)
    assert so3_error(R) < 1e-9
    np.testing.assert_allclose(R, T[:, :3, :3], rtol=0, atol=1e-9)
    # default timestamps: the frame index
    m = read_like_evo(write_tum_trajectory(tmp_path / "i.tum", traj[:5]), 8)
    np.testing.assert_array_equal(m[:, 0], np.arange(5.0))


def test_trajectory_writers_are_atomic_and_check_their_input(tmp_path, monkeypatch):
    import strl_pyg.metrics.trajectory as tj

    traj = integrate_relative_poses(float32_chain(20))
    path = write_kitti_trajectory(tmp_path / "t.txt", traj)
    before = path.read_text()
    calls = {"n": 0}
    real = tj._line

    def failing(values):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("disk full")
        return real(values)

    monkeypatch.setattr(tj, "_line", failing)
    with pytest.raises(RuntimeError, match="disk full"):
        write_kitti_trajectory(path, integrate_relative_poses(float32_chain(20, seed=1)))
    monkeypatch.undo()
    assert path.read_text() == before and [p.name for p in tmp_path.iterdir()] == ["t.txt"]

    bad = traj.matrix().clone()
    bad[3, :3, :3] *= -1
    with pytest.raises(ValueError, match="Expected rotations in 'T_w_c'"):
        write_kitti_trajectory(tmp_path / "bad.txt", bad)
    bad = traj.matrix().clone()
    bad[2, 0, 3] = float("nan")
    with pytest.raises(ValueError, match="finite"):
        write_tum_trajectory(tmp_path / "bad.tum", bad)
    with pytest.raises(ValueError, match="strictly increasing"):
        write_tum_trajectory(tmp_path / "bad.tum", traj, timestamps=np.zeros(21))
    with pytest.raises(ValueError, match=r"'timestamps' of shape \(21,\)"):
        write_tum_trajectory(tmp_path / "bad.tum", traj, timestamps=np.arange(3.0))
    with pytest.raises(ValueError, match="Expected 'T_w_c'"):
        write_kitti_trajectory(tmp_path / "bad.txt", np.zeros((4, 5)))
    assert not any(p.name.startswith("bad") for p in tmp_path.iterdir())
