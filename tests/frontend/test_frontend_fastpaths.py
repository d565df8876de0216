"""The front end's fast paths against their reference paths."""

from __future__ import annotations

import cv2
import numpy as np

from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.points import _knn2, _top2_l2, match_points


def _grey(img: np.ndarray) -> np.ndarray:
    return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)


def test_top2_matrix_product_equals_opencv_knn():
    rng = np.random.default_rng(0)
    d0 = rng.integers(0, 120, (300, 128)).astype(np.float32)
    d1 = np.concatenate([d0[:200] + rng.normal(0, 3, (200, 128)).astype(np.float32),
                         rng.integers(0, 120, (150, 128)).astype(np.float32)])
    nn01, ratio01, nn10 = _top2_l2(d0, d1)
    ref01, rratio = _knn2(d0, d1, cv2.NORM_L2)
    ref10, _ = _knn2(d1, d0, cv2.NORM_L2)
    np.testing.assert_array_equal(nn01, ref01)
    np.testing.assert_array_equal(nn10, ref10)
    np.testing.assert_allclose(ratio01, rratio, atol=1e-5)
    assert (ratio01[:200] < 0.5).all() and (ratio01[200:] > 0.7).all()  # the planted matches


def test_match_points_fast_equals_reference_on_a_pair(generated_pair):
    pair = generated_pair(3)
    g0, g1 = _grey(pair.image0), _grey(pair.image1)
    fast = match_points(g0, g1, FrontendConfig())
    ref = match_points(g0, g1, FrontendConfig(), reference=True)
    assert len(fast[0]) > 50
    # same matches in the same order (ties of equal ratio could swap: none here)
    np.testing.assert_array_equal(fast[0], ref[0])
    np.testing.assert_array_equal(fast[1], ref[1])
    np.testing.assert_allclose(fast[2], ref[2], atol=1e-5)


def test_top2_reverse_direction_takes_the_first_of_tied_rows():
    # duplicated query descriptors tie exactly in the reverse direction: the fast path must pick
    # the first row, as the column-wise argmin of the same float32 distances does
    rng = np.random.default_rng(1)
    base = rng.integers(0, 120, (40, 128)).astype(np.float32)
    d0 = np.concatenate([base, base[::-1], base[:7]])  # every row appears 2-3 times
    # integer descriptors: every product and distance is exact in float32, so ties are exact
    d1 = base[rng.permutation(40)] + rng.integers(-2, 3, (40, 128)).astype(np.float32)
    nn01, ratio01, nn10 = _top2_l2(d0, d1)
    sq = ((d0 * d0).sum(1)[:, None] + (d1 * d1).sum(1)[None, :]) - 2.0 * (d0 @ d1.T)
    np.testing.assert_array_equal(nn10, sq.argmin(axis=0))
    assert nn10.max() < 40  # the first copy of each row
    np.testing.assert_array_equal(nn01, sq.argmin(axis=1))
    np.testing.assert_allclose(ratio01[:40], ratio01[40:80][::-1], rtol=1e-12)


def test_single_train_descriptor():
    d0 = np.ones((3, 128), np.float32)
    d1 = np.ones((1, 128), np.float32)
    nn01, ratio, nn10 = _top2_l2(d0, d1)
    ref, rratio = _knn2(d0, d1, cv2.NORM_L2)
    np.testing.assert_array_equal(nn01, ref)
    np.testing.assert_allclose(ratio, rratio)
    assert nn10.shape == (1,)


def test_concurrent_detection_gives_the_same_matches(generated_pair):
    from strl_pyg.frontend import match_images

    pair = generated_pair(4)
    for detector in ("sift", "orb"):
        a = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                         config=FrontendConfig(detector=detector))
        b = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                         config=FrontendConfig(detector=detector, concurrent=False))
        assert a.num_points > 20 and a.num_lines > 0
        np.testing.assert_array_equal(a.points0, b.points0)
        np.testing.assert_array_equal(a.points1, b.points1)
        np.testing.assert_array_equal(a.lines0, b.lines0)
        np.testing.assert_array_equal(a.lines1, b.lines1)


def test_k_nearest_by_partition_equals_the_stable_sort():
    # the line guidance's k nearest point matches: a partition instead of a full sort, the same
    # set as the stable argsort (ties by the lower column), also with many exact ties
    from strl_pyg.frontend.lines import _k_nearest

    rng = np.random.default_rng(0)
    for _ in range(200):
        n, m = int(rng.integers(1, 30)), int(rng.integers(1, 40))
        k = int(rng.integers(1, m + 1))
        d2 = rng.integers(0, 6, (n, m)).astype(float)
        ref = np.sort(np.argsort(d2, axis=1, kind="stable")[:, :k], axis=1)
        np.testing.assert_array_equal(_k_nearest(d2, k), ref)
    d2 = rng.normal(size=(50, 80))  # no ties at all
    ref = np.sort(np.argsort(d2, axis=1, kind="stable")[:, :7], axis=1)
    np.testing.assert_array_equal(_k_nearest(d2, 7), ref)


def test_guided_midpoints_equal_the_straightforward_version():
    # the distances as two planes: the same float64 values as the [N, M, 2] sum, so the same
    # nearest points and the same predicted midpoints, bit for bit (half-pixel grids: ties)
    from strl_pyg.frontend.lines import _guided_midpoints

    rng = np.random.default_rng(1)
    lines0 = rng.integers(0, 200, (60, 2, 2)) / 2.0
    p0 = rng.integers(0, 200, (90, 2)) / 2.0
    p1 = p0 + rng.normal(0, 3, p0.shape)
    mid = lines0.mean(1)
    d2 = ((mid[:, None, :] - p0[None, :, :]) ** 2).sum(-1)
    nearest = np.argsort(d2, axis=1, kind="stable")[:, :8]
    ref = mid + np.median((p1 - p0)[nearest], axis=1)
    np.testing.assert_array_equal(_guided_midpoints(lines0, p0, p1, 8), ref)


def test_products_through_torch_equal_numpys():
    import pytest

    from strl_pyg.utils.products import matmul

    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(300, 3)), rng.normal(size=(3, 250))
    np.testing.assert_allclose(matmul(a, b), a @ b, rtol=1e-12, atol=1e-12)
    assert matmul(a, b).dtype == np.float64
    # integer-valued float32 (SIFT descriptors): every partial sum is exact, so equal bit for bit
    d0 = rng.integers(0, 256, (200, 128)).astype(np.float32)
    d1 = rng.integers(0, 256, (180, 128)).astype(np.float32)
    ref = (d0.astype(np.int64) @ d1.T.astype(np.int64)).astype(np.float32)
    np.testing.assert_array_equal(matmul(d0, d1.T), ref)
    ro = np.broadcast_to(d0[:1], (4, 128))  # read-only view: copied, not refused
    np.testing.assert_array_equal(matmul(ro, d1.T), ref[[0, 0, 0, 0]])
    assert matmul(np.zeros((0, 3)), b).shape == (0, 250)
    with pytest.raises(ValueError, match=r"Expected a \[N, K\] and b \[K, M\] \(got \(300, 3\) "
                                         r"and \(2, 250\)\)"):
        matmul(a, b[:2])
    with pytest.raises(ValueError, match=r"Expected a and b of one dtype \(got float32 and "
                                         r"float64\)"):
        matmul(a.astype(np.float32), b)
    with pytest.raises(ValueError, match=r"Expected a as a float32 or float64 array \(got int64"):
        matmul(a.astype(np.int64), b)
    # views torch.from_numpy refuses (negative strides) and foreign byte order: handled
    np.testing.assert_allclose(matmul(a[::-1], b[:, ::-1]), (a[::-1] @ b[:, ::-1]), rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(matmul(a.astype(">f8"), b), a @ b, rtol=1e-12, atol=1e-12)


def test_line_candidates_through_torch_equal_numpys_products(monkeypatch, generated_pair):
    from strl_pyg.frontend import lines as fl
    from strl_pyg.frontend.lines import candidate_pairs, detect_lines
    from strl_pyg.frontend.points import fit_fundamental

    pair = generated_pair(5)
    cfg = FrontendConfig()
    g0, g1 = _grey(pair.image0), _grey(pair.image1)
    p0, p1, _, _ = match_points(g0, g1, cfg)
    F, inl = fit_fundamental(p0, p1, cfg)
    s0, s1 = detect_lines(g0, cfg), detect_lines(g1, cfg)
    fast = candidate_pairs(s0, s1, F, g1.shape, cfg, (p0[inl], p1[inl]))
    monkeypatch.setattr(fl, "matmul", lambda a, b: a @ b)  # the reference: NumPy's BLAS
    ref = candidate_pairs(s0, s1, F, g1.shape, cfg, (p0[inl], p1[inl]))
    assert len(fast[0]) > 20
    for x, y in zip(fast, ref, strict=True):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)
    # float32 segments (what cv2's LSD returns) give the same candidates, not a dtype error
    f32 = candidate_pairs(s0.astype(np.float32), s1.astype(np.float32), F, g1.shape, cfg,
                          (p0[inl], p1[inl]))
    np.testing.assert_array_equal(f32[0], fast[0])
    np.testing.assert_array_equal(f32[1], fast[1])
    np.testing.assert_allclose(f32[2], fast[2], atol=1e-3)


def test_near_prediction_equals_the_einsum_version():
    # the distance to each supporting line as two planes: the same values as the einsum over
    # [N0, N1, 2] temporaries, so the same mask
    from strl_pyg.frontend.lines import _near_prediction

    rng = np.random.default_rng(2)
    cfg = FrontendConfig()
    pred = rng.uniform(0, 640, (120, 2))
    lines1 = rng.uniform(0, 640, (150, 2, 2))
    P1, D1 = lines1[:, 0], lines1[:, 1] - lines1[:, 0]
    n1 = np.stack([-D1[:, 1], D1[:, 0]], axis=1) / np.linalg.norm(D1, axis=1)[:, None]
    dist = np.abs(np.einsum("ijk,jk->ij", pred[:, None, :] - P1[None], n1))
    ref = dist <= cfg.line_guide_tol * float(np.hypot(480, 640))
    got = _near_prediction(pred, lines1, (480, 640), cfg)
    assert 0 < got.sum() < got.size
    np.testing.assert_array_equal(got, ref)
