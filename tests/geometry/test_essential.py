"""Weighted essential-matrix solve, pose recovery and refinement (strl_pyg.geometry.essential)."""

import pytest
import torch
from torch.autograd import gradcheck

from strl_pyg.geometry import essential_from_pose
from strl_pyg.geometry import so3_exp as _so3_exp
from strl_pyg.geometry.essential import (
    DEGENERATE,
    OK,
    decompose_essential,
    refine_pose,
    sampson_sq,
    smallest_eigenvector,
    weighted_essential,
)
from strl_pyg.metrics.two_view import rotation_error_deg, translation_angle_error_deg


def _scene(B=3, N=100, seed=0):
    g = torch.Generator().manual_seed(seed)
    X = torch.randn(B, N, 3, generator=g, dtype=torch.float64) * torch.tensor(
        [2.0, 2.0, 1.0], dtype=torch.float64) + torch.tensor([0.0, 0.0, 5.0],
                                                              dtype=torch.float64)
    R = _so3_exp(0.3 * torch.randn(B, 3, generator=g, dtype=torch.float64))
    t = torch.randn(B, 3, generator=g, dtype=torch.float64)
    t = t / t.norm(dim=-1, keepdim=True)
    X1 = X @ R.transpose(-1, -2) + t[:, None]
    return R, t, X[..., :2] / X[..., 2:], X1[..., :2] / X1[..., 2:], g


def test_exact_pose_from_noise_free_matches_with_uniform_weights():
    R, t, x0, x1, _ = _scene()
    est = weighted_essential(x0, x1, torch.ones(x0.shape[:2], dtype=torch.float64))
    assert est.E.shape == (3, 3, 3) and torch.equal(est.status, torch.full((3,), OK))
    assert sampson_sq(est.E, x0, x1).max() < 1e-20
    Rh, th, front = decompose_essential(est.E, x0, x1)
    assert torch.allclose(Rh, R, atol=1e-9) and torch.allclose(th, t, atol=1e-9)
    assert torch.allclose(front, torch.ones(3, dtype=torch.float64))
    # agrees with E = [t]_x R up to sign and scale
    E_gt = essential_from_pose(R, t)
    E_gt = E_gt / E_gt.flatten(-2).norm(dim=-1)[:, None, None]
    s = torch.sign((E_gt * est.E).flatten(-2).sum(-1))[:, None, None]
    assert torch.allclose(s * est.E, E_gt, atol=1e-9)


def test_zero_weighted_outliers_are_ignored():
    R, t, x0, x1, g = _scene()
    x1 = x1.clone()
    x1[:, :40] = torch.rand(3, 40, 2, generator=g, dtype=torch.float64) - 0.5
    w = torch.ones(x0.shape[:2], dtype=torch.float64)
    w[:, :40] = 0.0
    est = weighted_essential(x0, x1, w, iterations=0)
    Rh, th, _ = decompose_essential(est.E, x0, x1, w)
    assert torch.allclose(Rh, R, atol=1e-9) and torch.allclose(th, t, atol=1e-9)
    # the same outliers with uniform weights do corrupt the plain eight-point solve
    bad = weighted_essential(x0, x1, torch.ones_like(w), iterations=0)
    Rb, _, _ = decompose_essential(bad.E, x0, x1)
    assert rotation_error_deg(Rb, R).max() > 1.0


def test_padding_mask_equals_dropping_the_rows():
    R, t, x0, x1, g = _scene(B=1, N=60)
    noisy1 = x1 + 1e-3 * torch.randn(x1.shape, generator=g, dtype=torch.float64)
    w = torch.rand(1, 60, generator=g, dtype=torch.float64)
    mask = torch.ones(1, 60, dtype=torch.bool)
    mask[:, 45:] = False
    a = weighted_essential(x0, noisy1, w, mask)
    b = weighted_essential(x0[:, :45], noisy1[:, :45], w[:, :45])
    s = torch.sign((a.E * b.E).sum())
    assert torch.allclose(a.E, s * b.E, atol=1e-10)


def test_irls_reduces_the_error_under_outliers():
    R, t, x0, x1, g = _scene(B=4, N=300, seed=1)
    x0n = x0 + 1e-3 * torch.randn(x0.shape, generator=g, dtype=torch.float64)
    x1n = x1 + 1e-3 * torch.randn(x1.shape, generator=g, dtype=torch.float64)
    x1n[:, :30] += 0.05 * torch.randn(4, 30, 2, generator=g, dtype=torch.float64)  # 10 %
    w = torch.ones(x0.shape[:2], dtype=torch.float64)
    plain = weighted_essential(x0n, x1n, w, iterations=0)
    irls = weighted_essential(x0n, x1n, w, iterations=5, tau=2e-3)
    Rp, tp, _ = decompose_essential(plain.E, x0n, x1n)
    Ri, ti, _ = decompose_essential(irls.E, x0n, x1n)
    err_p = rotation_error_deg(Rp, R) + translation_angle_error_deg(tp, t)
    err_i = rotation_error_deg(Ri, R) + translation_angle_error_deg(ti, t)
    assert err_i.mean() < 0.8 * err_p.mean()


def test_refinement_lowers_the_weighted_cost_and_the_error():
    R, t, x0, x1, g = _scene(B=4, N=300, seed=2)
    x0n = x0 + 1e-3 * torch.randn(x0.shape, generator=g, dtype=torch.float64)
    x1n = x1 + 1e-3 * torch.randn(x1.shape, generator=g, dtype=torch.float64)
    w = torch.rand(4, 300, generator=g, dtype=torch.float64)
    est = weighted_essential(x0n, x1n, w, iterations=0)
    Ri, ti, _ = decompose_essential(est.E, x0n, x1n)
    Rr, tr = refine_pose(Ri, ti, x0n, x1n, w, iterations=10)

    def cost(Rc, tc):
        E = essential_from_pose(Rc, tc)
        return (w * sampson_sq(E, x0n, x1n)).sum(1)

    assert (cost(Rr, tr) <= cost(Ri, ti) + 1e-15).all()
    err_i = rotation_error_deg(Ri, R) + translation_angle_error_deg(ti, t)
    err_r = rotation_error_deg(Rr, R) + translation_angle_error_deg(tr, t)
    assert err_r.mean() < err_i.mean()
    # starting 2 degrees off, refinement goes back to the noise floor
    R_off = _so3_exp(torch.full((4, 3), 0.02, dtype=torch.float64)) @ R
    Rr2, tr2 = refine_pose(R_off, t, x0n, x1n, torch.ones_like(w), iterations=15)
    assert rotation_error_deg(Rr2, R).max() < 0.3


@pytest.mark.parametrize("case", ["few", "zero_weights", "identical", "nan"])
def test_degenerate_inputs_get_a_status_and_no_nan(case):
    R, t, x0, x1, _ = _scene(B=2, N=50)
    w = torch.ones(2, 50, dtype=torch.float64, requires_grad=True)
    if case == "few":
        x0, x1, w = x0[:, :6], x1[:, :6], w[:, :6].detach().requires_grad_()
    elif case == "zero_weights":
        w = torch.zeros(2, 50, dtype=torch.float64, requires_grad=True)
    elif case == "identical":
        x1 = x0.clone()
    elif case == "nan":
        x0 = x0.clone()
        x0[:, 5:] = float("nan")  # only 5 finite rows left
    est = weighted_essential(x0, x1, w)
    assert torch.equal(est.status, torch.full((2,), DEGENERATE))
    assert torch.isfinite(est.E).all()
    est.E.sum().backward()
    assert torch.isfinite(w.grad).all()


def test_gradcheck_float64():
    R, t, x0, x1, g = _scene(B=2, N=14, seed=3)
    x1 = x1 + 1e-3 * torch.randn(x1.shape, generator=g, dtype=torch.float64)
    w = (0.2 + torch.rand(2, 14, generator=g, dtype=torch.float64)).requires_grad_()
    a = x0.clone().requires_grad_()
    assert gradcheck(lambda w, a: weighted_essential(a, x1, w, iterations=2, tau=1e-2).E,
                     (w, a))


def _eigvec_grad(M, g, fn):
    M = M.clone().requires_grad_()
    v = fn(M)
    v = v * torch.sign(v[..., :1])  # the sign of an eigenvector is arbitrary: fix it
    (v * g).sum().backward()
    return M.grad


def test_smallest_eigenvector_has_eigh_gradient_on_separated_spectra():
    g = torch.Generator().manual_seed(0)
    A = torch.randn(3, 20, 9, generator=g, dtype=torch.float64)
    M = A.transpose(-1, -2) @ A
    up = torch.randn(3, 9, generator=g, dtype=torch.float64)
    ours = _eigvec_grad(M, up, smallest_eigenvector)
    ref = _eigvec_grad(M, up, lambda m: torch.linalg.eigh(m)[1][..., 0])
    # eigh's gradient, symmetrised (it is symmetric already; only that part reaches a symmetric M)
    torch.testing.assert_close(ours, 0.5 * (ref + ref.transpose(-1, -2)), rtol=1e-9,
                               atol=1e-12)
    torch.testing.assert_close(smallest_eigenvector(M), torch.linalg.eigh(M)[1][..., 0])
    assert gradcheck(lambda m: smallest_eigenvector(0.5 * (m + m.transpose(-1, -2))) *
                     torch.sign(smallest_eigenvector(0.5 * (m + m.transpose(-1, -2)))[..., :1]),
                     (M[:1].clone().requires_grad_(),))


def test_smallest_eigenvector_gradient_is_finite_with_tied_upper_eigenvalues():
    """torch.linalg.eigh's backward divides by every pair's gap: two equal eigenvalues that the
    smallest eigenvector does not depend on give a NaN gradient (the weighted eight-point reads
    only that eigenvector)."""
    Q = torch.linalg.qr(torch.randn(9, 9, generator=torch.Generator().manual_seed(1),
                                    dtype=torch.float64))[0]
    lam = torch.tensor([0.01, 1.0, 2.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0], dtype=torch.float64)
    M = (Q * lam) @ Q.T
    M = (0.5 * (M + M.T))[None]
    up = torch.randn(1, 9, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    D = torch.diag(lam)[None]  # the same spectrum, diagonal: the ties are exact there
    # (torch 2.13's eigh gives NaN here: its backward divides by the gap of every pair)
    grad = _eigvec_grad(D, up, smallest_eigenvector)
    assert torch.isfinite(grad).all()
    # dv0 = sum_j v_j v_j^T dM v0 / (l0 - lj): for a diagonal M, v0 = e0 and the gradient is
    # (up_j / (l0 - lj)) at (j, 0), symmetrised
    expect = torch.zeros(9, 9, dtype=torch.float64)
    expect[1:, 0] = up[0, 1:] / (lam[0] - lam[1:])
    expect = 0.5 * (expect + expect.T)
    torch.testing.assert_close(grad[0], expect)
    # a rotated copy of the same spectrum: the finite-difference derivative agrees (v0 is
    # a smooth function of M there; only eigh's backward was not)
    def fixed_sign(m):
        v = smallest_eigenvector(0.5 * (m + m.transpose(-1, -2)))
        return v * torch.sign(v[..., :1])

    assert gradcheck(fixed_sign, (M.clone().requires_grad_(),))


def test_smallest_eigenvector_gradient_stays_finite_at_a_repeated_smallest_eigenvalue():
    M = torch.diag(torch.tensor([1.0, 1.0, 2.0], dtype=torch.float64))[None]
    grad = _eigvec_grad(M, torch.ones(1, 3, dtype=torch.float64),
                        lambda m: smallest_eigenvector(m, gap_tol=1e-6))
    assert torch.isfinite(grad).all() and grad.abs().max() <= 1e6


def test_bad_shapes_raise_one_line_errors():
    with pytest.raises(ValueError, match="Expected x0, x1 of shape"):
        weighted_essential(torch.zeros(5, 3), torch.zeros(5, 3), torch.ones(5))
    with pytest.raises(ValueError, match="Expected weights of shape"):
        weighted_essential(torch.zeros(5, 2), torch.zeros(5, 2), torch.ones(4))
