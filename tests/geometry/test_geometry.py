import math

import numpy as np
import pytest
import torch

from strl_pyg.geometry import (
    Pose,
    essential_from_pose,
    fundamental_from_essential,
    normalize_points,
    project_points,
    quaternion_to_rotation,
    relative_pose_from_c2w,
    relative_pose_from_w2c,
    rotation_angle_deg,
    rotation_to_quaternion,
    sampson_error,
    skew,
    symmetric_epipolar_error,
)

F64 = torch.float64


def rot_axis(axis: str, deg: float) -> torch.Tensor:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    m = {
        "x": [[1, 0, 0], [0, c, -s], [0, s, c]],
        "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
        "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]],
    }[axis]
    return torch.tensor(m, dtype=F64)


def random_pose(*shape, seed=0) -> Pose:
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(*shape, 4, generator=g, dtype=F64)
    return Pose(quaternion_to_rotation(q), torch.randn(*shape, 3, generator=g, dtype=F64))


# ------------------------------------------------------------------ quaternions
def test_quaternion_known_values():
    q = rotation_to_quaternion(rot_axis("x", 90.0))
    h = math.sqrt(0.5)
    torch.testing.assert_close(q, torch.tensor([h, h, 0.0, 0.0], dtype=F64))
    torch.testing.assert_close(rotation_to_quaternion(torch.eye(3, dtype=F64)),
                               torch.tensor([1.0, 0, 0, 0], dtype=F64))
    # a non-unit quaternion is normalised; the negated one is the same rotation
    R = quaternion_to_rotation(torch.tensor([2.0, 0.0, 0.0, 2.0], dtype=F64))
    torch.testing.assert_close(R, rot_axis("z", 90.0))
    torch.testing.assert_close(quaternion_to_rotation(-torch.tensor([1.0, 0, 0, 1.0])),
                               rot_axis("z", 90.0).float())


@pytest.mark.parametrize("shape", [(), (1,), (7,), (2, 3)])
def test_quaternion_roundtrip_canonical(shape):
    g = torch.Generator().manual_seed(1)
    q = torch.randn(*shape, 4, generator=g, dtype=F64)
    q = q / q.norm(dim=-1, keepdim=True)
    q = torch.where(q[..., :1] < 0, -q, q)
    R = quaternion_to_rotation(q)
    assert R.shape == (*shape, 3, 3)
    torch.testing.assert_close(R @ R.transpose(-1, -2), torch.eye(3, dtype=F64).expand_as(R))
    q2 = rotation_to_quaternion(R)
    assert q2.shape == (*shape, 4)
    assert bool((q2[..., 0] >= 0).all())
    torch.testing.assert_close(q2, q)


def test_quaternion_numpy_boundary_and_errors():
    R = rotation_to_quaternion(np.eye(3))
    assert isinstance(R, torch.Tensor) and R.dtype == F64
    with pytest.raises(ValueError, match=r"Expected 'R' of shape \(\*, 3, 3\)"):
        rotation_to_quaternion(np.eye(4))
    with pytest.raises(ValueError, match="non-zero norm"):
        quaternion_to_rotation(np.zeros(4))
    with pytest.raises(TypeError, match="numeric"):
        quaternion_to_rotation(np.array(["a", "b", "c", "d"]))


def test_quaternion_gradcheck():
    q = torch.tensor([[0.9, 0.2, -0.3, 0.1], [0.3, -0.5, 0.6, 0.4]], dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(quaternion_to_rotation, (q,))
    R = quaternion_to_rotation(q.detach()).requires_grad_(True)
    assert torch.autograd.gradcheck(rotation_to_quaternion, (R,))


# ------------------------------------------------------------------ rotation angle
@pytest.mark.parametrize("deg", [0.0, 1e-6, 10.0, 90.0, 179.9999, 180.0])
def test_rotation_angle(deg):
    for axis in "xyz":
        torch.testing.assert_close(rotation_angle_deg(rot_axis(axis, deg)),
                                   torch.tensor(deg, dtype=F64), atol=1e-9, rtol=0)


# ------------------------------------------------------------------ Pose
def test_pose_identities():
    a, b, c = random_pose(4, seed=1), random_pose(4, seed=2), random_pose(4, seed=3)
    eye = torch.eye(4, dtype=F64).expand(4, 4, 4)
    torch.testing.assert_close((a @ a.inv()).matrix(), eye)
    torch.testing.assert_close((a.inv() @ a).matrix(), eye)
    torch.testing.assert_close(((a @ b) @ c).matrix(), (a @ (b @ c)).matrix())
    torch.testing.assert_close((a @ b).inv().matrix(), (b.inv() @ a.inv()).matrix())
    # (a @ b) applies b first
    X = torch.randn(4, 10, 3, dtype=F64)
    torch.testing.assert_close((a @ b).transform(X), a.transform(b.transform(X)))
    torch.testing.assert_close((a @ b).matrix(), a.matrix() @ b.matrix())
    torch.testing.assert_close(a.compose(b).matrix(), (a @ b).matrix())


def test_pose_transform_known():
    p = Pose(rot_axis("z", 90.0), [1.0, 2.0, 3.0])
    out = p.transform(torch.tensor([[1.0, 0.0, 0.0]], dtype=F64))
    torch.testing.assert_close(out, torch.tensor([[1.0, 3.0, 3.0]], dtype=F64))
    torch.testing.assert_close(p.angle_deg(), torch.tensor(90.0, dtype=F64))


def test_pose_conversions_roundtrip():
    p = random_pose(3, seed=4)
    for q in (Pose.from_matrix(p.matrix()), Pose.from_matrix(p.matrix()[:, :3]),
              Pose.from_kitti_row(p.to_kitti_row()), Pose.from_quaternion(p.quaternion(), p.t),
              Pose.from_matrix(p.numpy()), Pose.from_Rt(p.R.numpy(), p.t.numpy())):
        torch.testing.assert_close(q.matrix(), p.matrix())
    assert p.to_kitti_row().shape == (3, 12)
    assert p.numpy().shape == (3, 4, 4) and isinstance(p.numpy(), np.ndarray)
    # the KITTI row is row-major [R | t]
    row = p[0].to_kitti_row()
    torch.testing.assert_close(row[[3, 7, 11]], p.t[0])
    torch.testing.assert_close(row[[0, 1, 2]], p.R[0, 0])


def test_pose_batching_indexing_dtype():
    p = random_pose(5, seed=5)
    assert len(p) == 5 and p.shape == (5,)
    assert p[2].shape == () and p[1:3].shape == (2,)
    torch.testing.assert_close(p[2].matrix(), p.matrix()[2])
    with pytest.raises(TypeError):
        len(p[0])
    assert p.to(torch.float32).dtype == torch.float32
    # broadcasting: one pose composed with a batch
    torch.testing.assert_close((p[0] @ p).matrix(), p[0].matrix() @ p.matrix())
    s = Pose.stack([p[0], p[1]])
    torch.testing.assert_close(s.matrix(), p.matrix()[:2])
    ident = Pose.identity((2,))
    torch.testing.assert_close(ident.matrix(), torch.eye(4, dtype=F64).expand(2, 4, 4))


def test_pose_bad_input():
    with pytest.raises(ValueError, match=r"Expected 'R' of shape \(\*, 3, 3\) \(got \(2, 2\)\)"):
        Pose(np.eye(2), np.zeros(3))
    with pytest.raises(ValueError, match="broadcast"):
        Pose(np.eye(3)[None].repeat(2, 0), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"\(\*, 4, 4\) or \(\*, 3, 4\)"):
        Pose.from_matrix(np.eye(3))
    with pytest.raises(ValueError, match=r"\(\*, 12\)"):
        Pose.from_kitti_row(np.zeros(11))
    with pytest.raises(TypeError, match="Expected a Pose"):
        Pose.identity().compose(np.eye(4))


# ------------------------------------------------------------------ relative poses
def test_relative_pose_c2w_w2c_agree():
    T_w_c0, T_w_c1 = random_pose(6, seed=6), random_pose(6, seed=7)
    a = relative_pose_from_c2w(T_w_c0, T_w_c1)
    b = relative_pose_from_w2c(T_w_c0.inv(), T_w_c1.inv())
    c = relative_pose_from_c2w(T_w_c0.matrix().numpy(), T_w_c1.matrix()[:, :3].numpy())
    torch.testing.assert_close(a.matrix(), b.matrix())
    torch.testing.assert_close(a.matrix(), c.matrix())
    # definition: a world point seen in camera 0 maps to the same point seen in camera 1
    Xw = torch.randn(6, 20, 3, dtype=F64)
    X0, X1 = T_w_c0.inv().transform(Xw), T_w_c1.inv().transform(Xw)
    torch.testing.assert_close(a.transform(X0), X1)


def test_relative_pose_kitti_rows(kitti_root):
    rows = np.loadtxt(kitti_root / "poses" / "06.txt")[:3]
    P = Pose.from_kitti_row(rows)
    T = relative_pose_from_c2w(P[0], P[2])
    # T_0to1 = inv(P_B) @ P_A with 4x4 matrices
    M = np.linalg.inv(P[2].numpy()) @ P[0].numpy()
    # the file's rotations are orthonormal to ~1e-7 only, so the rigid inverse differs slightly
    np.testing.assert_allclose(T.numpy(), M, atol=1e-5)
    # the car drives forward (+z of camera 0), so camera 0's centre lies behind camera 2
    assert T.t[2] < -1.0


# ------------------------------------------------------------------ epipolar
def two_view_scene(n=50, seed=0):
    g = torch.Generator().manual_seed(seed)
    X0 = torch.rand(n, 3, generator=g, dtype=F64) * torch.tensor([8.0, 6.0, 10.0]) + torch.tensor(
        [-4.0, -3.0, 4.0], dtype=F64)
    T = Pose(rot_axis("y", 8.0) @ rot_axis("x", -3.0), torch.tensor([0.5, 0.1, -0.2], dtype=F64))
    K0 = torch.tensor([[500.0, 0, 320], [0, 510, 240], [0, 0, 1]], dtype=F64)
    K1 = torch.tensor([[450.0, 0, 300], [0, 455, 250], [0, 0, 1]], dtype=F64)
    return T, K0, K1, project_points(X0, K0), project_points(T.transform(X0), K1)


def test_skew_and_essential_constraint():
    v, w = torch.randn(4, 3, dtype=F64), torch.randn(4, 3, dtype=F64)
    torch.testing.assert_close((skew(v) @ w[..., None])[..., 0], torch.linalg.cross(v, w))
    T, K0, K1, p0, p1 = two_view_scene()
    E = essential_from_pose(T.R, T.t)
    torch.testing.assert_close(E, essential_from_pose(T))
    x0, x1 = normalize_points(p0, K0), normalize_points(p1, K1)
    for err in (sampson_error, symmetric_epipolar_error):
        assert err(E, x0, x1).abs().max() < 1e-20
        F = fundamental_from_essential(E, K0, K1)
        assert err(F, p0, p1).abs().max() < 1e-18


def test_normalize_points_matches_inverse_K():
    K = torch.tensor([[500.0, 2.0, 320], [0, 510, 240], [0, 0, 1]], dtype=F64)
    x = torch.rand(2, 10, 2, dtype=F64) * 600
    h = torch.cat([x, torch.ones_like(x[..., :1])], -1) @ torch.linalg.inv(K).T
    torch.testing.assert_close(normalize_points(x, K), h[..., :2])
    torch.testing.assert_close(project_points(torch.cat([h[..., :2], h[..., 2:]], -1), K), x)


def test_sampson_known_value_pixels():
    # Pure x-translation, identity K: epipolar lines are horizontal, so the symmetric
    # distance of a point displaced by dy vertically is dy in each image, and Sampson's
    # first-order distance is dy / sqrt(2) (the minimal correction splits it over both).
    E = essential_from_pose(torch.eye(3, dtype=F64), torch.tensor([1.0, 0.0, 0.0], dtype=F64))
    x0 = torch.tensor([[0.3, 0.2], [-0.5, 0.1]], dtype=F64)
    x1 = x0 + torch.tensor([[0.7, 0.01], [0.2, -0.03]], dtype=F64)
    dy = torch.tensor([0.01, 0.03], dtype=F64)
    torch.testing.assert_close(sampson_error(E, x0, x1, squared=False), dy / math.sqrt(2))
    torch.testing.assert_close(sampson_error(E, x0, x1), dy**2 / 2)
    torch.testing.assert_close(symmetric_epipolar_error(E, x0, x1), 2 * dy**2)


def test_sampson_gradcheck_and_batch():
    T, K0, K1, p0, p1 = two_view_scene(n=6)
    g = torch.Generator().manual_seed(3)
    # residuals well away from 0, where the unsquared distance has a kink
    x0 = normalize_points(p0, K0) + 2e-2 * torch.randn(6, 2, generator=g, dtype=F64)
    x1 = normalize_points(p1, K1)
    E = essential_from_pose(T).requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda E, a, b: sampson_error(E, a, b), (E, x0.requires_grad_(True), x1))
    assert torch.autograd.gradcheck(
        lambda E, a, b: symmetric_epipolar_error(E, a, b, squared=False), (E, x0, x1))
    # batched equals per-item
    Eb = torch.stack([E.detach(), 2 * E.detach()])
    xb0, xb1 = torch.stack([x0.detach()] * 2), torch.stack([x1] * 2)
    out = sampson_error(Eb, xb0, xb1)
    assert out.shape == (2, 6)
    torch.testing.assert_close(out[1], sampson_error(2 * E.detach(), x0.detach(), x1))
    torch.testing.assert_close(out[0], out[1])  # scale invariant


def test_epipolar_bad_input():
    with pytest.raises(ValueError, match="same N"):
        sampson_error(np.eye(3), np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"'x0' of shape \(\*, 2\)"):
        sampson_error(np.eye(3), np.zeros((3, 3)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="Expected 't'"):
        essential_from_pose(np.eye(3))


def test_epipolar_terms_equal_the_matrix_products_batched():
    """The broadcast sums of ``_epipolar_terms`` (its fast path: no intra-op thread pool)
    against the plain matrix products, batched, with gradients."""
    from strl_pyg.geometry.epipolar import _epipolar_terms

    g = torch.Generator().manual_seed(0)
    M = torch.randn(4, 3, 3, dtype=torch.float64, generator=g, requires_grad=True)
    x0 = torch.randn(4, 50, 2, dtype=torch.float64, generator=g)
    x1 = torch.randn(4, 50, 2, dtype=torch.float64, generator=g)
    r, Mx0, Mtx1 = _epipolar_terms(M, x0, x1)
    h0 = torch.cat([x0, torch.ones_like(x0[..., :1])], -1)
    h1 = torch.cat([x1, torch.ones_like(x1[..., :1])], -1)
    ref0, ref1 = h0 @ M.transpose(-1, -2), h1 @ M
    torch.testing.assert_close(Mx0, ref0, rtol=0, atol=1e-12)
    torch.testing.assert_close(Mtx1, ref1, rtol=0, atol=1e-12)
    torch.testing.assert_close(r, (h1 * ref0).sum(-1), rtol=0, atol=1e-12)
    (g1,) = torch.autograd.grad((r.sum() + Mx0.sum() + Mtx1.sum()), M)
    (g2,) = torch.autograd.grad(((h1 * ref0).sum() + ref0.sum() + ref1.sum()), M)
    torch.testing.assert_close(g1, g2, rtol=0, atol=1e-10)
