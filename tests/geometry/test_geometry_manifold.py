"""SO(3) / sphere maps and the one signed Sampson residual (strl_pyg.geometry), the
deprecated aliases of moved modules, and the one image reader (strl_pyg.utils.images)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from strl_pyg.geometry import (
    essential_from_pose,
    quaternion_to_rotation,
    sampson_error,
    signed_sampson,
    so3_exp,
    tangent_basis,
)

F64 = torch.float64


def _old_batched_basis(t):  # the former strl_pyg.geometry.essential._basis, as a reference
    helper = torch.zeros_like(t)
    helper[torch.arange(t.shape[0]), t.abs().argmin(-1)] = 1.0
    b1 = torch.linalg.cross(t, helper)
    b1 = b1 / b1.norm(dim=-1, keepdim=True)
    return torch.stack([b1, torch.linalg.cross(t, b1)], dim=-1)


def test_tangent_basis_batched_equals_rows_and_the_former_solver_basis():
    t = torch.randn(6, 3, generator=torch.Generator().manual_seed(1), dtype=F64)
    t = t / t.norm(dim=-1, keepdim=True)
    B = tangent_basis(t)
    assert B.shape == (6, 3, 2)
    for i in range(6):
        torch.testing.assert_close(B[i], tangent_basis(t[i]), rtol=0, atol=0)
    torch.testing.assert_close(B, _old_batched_basis(t), rtol=0, atol=1e-15)
    gram = B.transpose(-1, -2) @ B
    torch.testing.assert_close(gram, torch.eye(2, dtype=F64).expand(6, 2, 2))
    with pytest.raises(ValueError, match="non-zero translation"):
        tangent_basis(torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]))
    with pytest.raises(ValueError, match=r"\(\*, 3\)"):
        tangent_basis(torch.ones(2))


def test_so3_exp_matches_the_quaternion_of_the_axis_angle():
    w = torch.tensor([[0.3, -0.2, 0.5], [0.0, 0.0, 0.0], [1e-8, 0.0, 0.0]], dtype=F64)
    theta = w.norm(dim=-1, keepdim=True)
    axis = torch.where(theta > 0, w / theta.clamp_min(1e-300), torch.zeros_like(w))
    q = torch.cat([torch.cos(theta / 2), torch.sin(theta / 2) * axis], dim=-1)
    torch.testing.assert_close(so3_exp(w), quaternion_to_rotation(q), rtol=0, atol=1e-12)


def test_signed_sampson_is_the_signed_root_of_sampson_error():
    g = torch.Generator().manual_seed(0)
    R = so3_exp(torch.tensor([0.05, -0.1, 0.02], dtype=F64))
    E = essential_from_pose(R, torch.tensor([1.0, 0.2, 0.1], dtype=F64))
    x0 = torch.rand(50, 2, generator=g, dtype=F64) - 0.5
    x1 = torch.rand(50, 2, generator=g, dtype=F64) - 0.5
    r = signed_sampson(E, x0, x1)
    torch.testing.assert_close(r.square(), sampson_error(E, x0, x1), rtol=1e-12, atol=1e-30)
    torch.testing.assert_close(signed_sampson(-E, x0, x1), -r)  # the sign is kept
    assert (r > 0).any() and (r < 0).any()
    # batched, as the weighted solver calls it
    rb = signed_sampson(torch.stack([E, 2 * E]), torch.stack([x0, x0]), torch.stack([x1, x1]))
    torch.testing.assert_close(rb, torch.stack([r, r]))


def test_one_image_reader_for_the_cli_and_the_datasets(tmp_path):
    cv2 = pytest.importorskip("cv2")
    from strl_pyg.cli.readers import read_image_file
    from strl_pyg.datasets import read_image
    from strl_pyg.utils import UsageError

    rgb = np.random.default_rng(0).integers(0, 256, (20, 30, 3), dtype=np.uint8)
    path = tmp_path / "a.png"
    cv2.imwrite(str(path), rgb[..., ::-1])  # OpenCV writes BGR
    np.testing.assert_array_equal(read_image_file(path), rgb)
    np.testing.assert_array_equal(read_image(path), rgb)
    # 16-bit with alpha: scaled to 8 bits, alpha dropped, by both
    deep = np.concatenate([rgb.astype(np.uint16) * 257, np.full((20, 30, 1), 65535, np.uint16)],
                          axis=-1)
    path16 = tmp_path / "b.png"
    cv2.imwrite(str(path16), deep[..., [2, 1, 0, 3]])
    np.testing.assert_array_equal(read_image_file(path16), rgb)
    np.testing.assert_array_equal(read_image(path16), rgb)
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    with pytest.raises(UsageError, match="empty file"):
        read_image_file(empty)
    with pytest.raises(UsageError, match="got a folder"):
        read_image_file(tmp_path)
