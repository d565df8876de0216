"""Lens distortion (``strl_pyg.geometry.distortion``): the forward model against known answers
and OpenCV's projection, its inverse, COLMAP's models as OpenCV coefficients, and images
undistorted back to the pinhole rendering."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from strl_pyg.geometry import (
    COLMAP_CAMERA_MODELS,
    DISTORTION_MODELS,
    Camera,
    distort_points,
    opencv_coefficients,
    undistort_image,
    undistort_points,
    undistortion_maps,
)

#: A 1280x960 camera of about 77 deg horizontal field of view.
K = np.array([[800.0, 0.0, 639.5], [0.0, 800.0, 479.5], [0.0, 0.0, 1.0]])
SIZE = (960, 1280)
#: A strong real lens's terms (barrel), as COLMAP reports for a phone or GoPro-like camera.
OPENCV = (-0.25, 0.08, 1e-3, -5e-4)


def _grid(size=SIZE, n=(31, 41)) -> np.ndarray:
    """``[N, 2]`` pixels over the whole image, its corners included."""
    h, w = size
    u, v = np.meshgrid(np.linspace(0, w - 1, n[1]), np.linspace(0, h - 1, n[0]))
    return np.stack([u.ravel(), v.ravel()], axis=1)


@pytest.mark.parametrize("model,terms", [("SIMPLE_RADIAL", (-0.1,)), ("RADIAL", (-0.25, 0.08)),
                                         ("OPENCV", OPENCV)])
def test_undistort_inverts_distort_over_the_image(model, terms):
    c = opencv_coefficients(model, terms)
    xy = _grid()
    back = distort_points(undistort_points(xy, K, c), K, c)
    np.testing.assert_allclose(back, xy, atol=1e-6, rtol=0)
    # the other way round over the pinhole image's central part (its corners leave the lens's
    # image and fold back where the barrel model stops being monotonic)
    inner = xy[np.abs(xy - K[:2, 2]).max(axis=1) < 400]
    np.testing.assert_allclose(undistort_points(distort_points(inner, K, c), K, c), inner,
                               atol=1e-6, rtol=0)
    assert np.abs(back - undistort_points(xy, K, c)).max() > 50  # a lens that moves points


def test_radial_terms_scale_the_normalised_radius():
    k1, k2 = -0.21, 0.07
    c = opencv_coefficients("RADIAL", (k1, k2))
    r = np.array([0.0, 0.1, 0.4, 0.8])
    theta = np.array([0.0, 1.0, 2.5, -2.0])
    xn = np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1)
    pix = xn * [K[0, 0], K[1, 1]] + K[:2, 2]
    out = (distort_points(pix, K, c) - K[:2, 2]) / [K[0, 0], K[1, 1]]
    expected = xn * (1 + k1 * r**2 + k2 * r**4)[:, None]
    np.testing.assert_allclose(out, expected, atol=1e-12)


def test_tangential_terms_agree_with_opencv_projection():
    """distort_points of a pinhole projection is cv2.projectPoints with the coefficients."""
    rng = np.random.default_rng(3)
    X = np.column_stack([rng.uniform(-0.7, 0.7, (200, 2)), np.ones(200)]) * rng.uniform(
        1, 5, (200, 1))
    c = opencv_coefficients("OPENCV", (0.05, -0.02, 4e-3, -3e-3))
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, c)
    pinhole = X[:, :2] / X[:, 2:] * [K[0, 0], K[1, 1]] + K[:2, 2]
    np.testing.assert_allclose(distort_points(pinhole, K, c), ref.reshape(-1, 2), atol=1e-9)
    # the tangential part matters: without it the points are off by pixels
    no_tangential = distort_points(pinhole, K, [0.05, -0.02, 0, 0])
    assert np.abs(no_tangential - ref.reshape(-1, 2)).max() > 1.0


@pytest.mark.parametrize("model,terms,expected", [
    ("SIMPLE_PINHOLE", (), [0, 0, 0, 0]),
    ("PINHOLE", [], [0, 0, 0, 0]),
    ("SIMPLE_RADIAL", (-0.1,), [-0.1, 0, 0, 0]),
    ("RADIAL", (-0.1, 0.02), [-0.1, 0.02, 0, 0]),
    ("OPENCV", (-0.1, 0.02, 0.003, -0.004), [-0.1, 0.02, 0.003, -0.004]),
])
def test_each_model_gives_opencv_coefficients(model, terms, expected):
    np.testing.assert_array_equal(opencv_coefficients(model, terms), expected)


def test_distortion_models_hold_colmap_parameter_counts():
    by_name = {name: (n, focals) for name, n, focals in COLMAP_CAMERA_MODELS.values()}
    for model, terms in DISTORTION_MODELS.items():
        n, focals = by_name[model]
        assert len(terms) == n - focals - 2, model


def test_camera_gives_its_opencv_distortion():
    cam = Camera.from_colmap("OPENCV", [500, 510, 320.5, 240.5, -0.1, 0.02, 1e-3, 2e-3])
    np.testing.assert_array_equal(cam.opencv_distortion, [-0.1, 0.02, 1e-3, 2e-3])
    cam = Camera.from_colmap("SIMPLE_RADIAL", [500, 320.5, 240.5, -0.1])
    np.testing.assert_array_equal(cam.opencv_distortion, [-0.1, 0, 0, 0])
    np.testing.assert_array_equal(Camera.from_K(K).opencv_distortion, np.zeros(4))
    with pytest.raises(ValueError, match=r"among SIMPLE_PINHOLE, .*OPENCV to undistort \(got "
                                         r"'OPENCV_FISHEYE'\)"):
        _ = Camera.from_colmap("OPENCV_FISHEYE", [500, 510, 320, 240, 0.1, 0, 0, 0]
                               ).opencv_distortion


def test_bad_models_terms_and_inputs_refuse_in_one_line():
    for model in ("OPENCV_FISHEYE", "FULL_OPENCV", "opencv"):
        with pytest.raises(ValueError, match=r"^Expected a camera model among SIMPLE_PINHOLE, "
                                             r"PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV to "
                                             rf"undistort \(got '{model}'\)$"):
            opencv_coefficients(model, (0.1,) * 4)
    with pytest.raises(ValueError, match=r"Expected 2 distortion terms for RADIAL \(k1, k2\) "
                                         r"\(got shape \(1,\)\)"):
        opencv_coefficients("RADIAL", (0.1,))
    with pytest.raises(ValueError, match=r"Expected 0 distortion terms for PINHOLE \(none\)"):
        opencv_coefficients("PINHOLE", (0.1,))
    with pytest.raises(ValueError, match="Expected finite distortion terms for OPENCV"):
        opencv_coefficients("OPENCV", (0.1, np.nan, 0, 0))
    with pytest.raises(ValueError, match="Expected numbers as the distortion terms of RADIAL"):
        opencv_coefficients("RADIAL", ("a", 0))
    c = np.zeros(4)
    bad_calls = [
        (lambda: distort_points([[1.0, np.nan]], K, c), "Expected finite pixel points"),
        (lambda: undistort_points(np.zeros((3, 3)), K, c), r"of shape \(N, 2\) \(got shape"),
        (lambda: distort_points(np.zeros((1, 2)), K, [0.1, np.nan, 0, 0]),
         r"Expected 4 finite OpenCV coefficients"),
        (lambda: distort_points(np.zeros((1, 2)), K, [0.1, 0, 0]), r"\[k1, k2, p1, p2\]"),
        (lambda: distort_points(np.zeros((1, 2)), K[:2], c), r"finite \(3, 3\) matrix"),
        (lambda: distort_points(np.zeros((1, 2)), K * [[1], [1], [2]], c), "fx, fy > 0"),
        (lambda: distort_points(np.zeros((1, 2)), K + [[0, 1, 0], [0, 0, 0], [0, 0, 0]], c),
         r"without skew .* \(got K\[0, 1\] = 1\)"),
        (lambda: undistortion_maps(K, c, (0, 10)), r"between 1 and 32767 px \(got \(0, 10\)\)"),
        (lambda: undistort_image(np.zeros((4, 4, 5), np.uint8), K, c), r"C <= 4"),
        (lambda: undistort_image(np.full((4, 4), np.nan), K, c), "finite values"),
    ]
    for call, message in bad_calls:
        with pytest.raises(ValueError, match=message) as info:
            call()
        assert "\n" not in str(info.value)
    with pytest.raises(TypeError, match=r"dtype uint8, uint16, float32 or float64 \(got int64"):
        undistort_image(np.zeros((4, 4), np.int64), K, c)


# ------------------------------------------------------------------------------- images
def _pattern(xy: np.ndarray) -> np.ndarray:
    """A smooth chequerboard of straight lines in pinhole pixels (period 24 px): zero on the
    lines u, v = 12 k, +-1 between."""
    return np.sin(np.pi * xy[..., 0] / 12.0) * np.sin(np.pi * xy[..., 1] / 12.0)


def _rendered(size, K, c):
    """``(pinhole, distorted)`` renderings of :func:`_pattern`: the distorted image samples
    the pattern at the pinhole pixel the lens images at each of its pixels."""
    h, w = size
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    grid = np.stack([u, v], axis=-1)
    pinhole = _pattern(grid)
    distorted = _pattern(undistort_points(grid.reshape(-1, 2), K, c)).reshape(h, w)
    return pinhole, distorted


def test_undistort_image_gives_back_the_pinhole_rendering():
    size = (180, 240)
    Ks = np.array([[150.0, 0, 119.5], [0, 150.0, 89.5], [0, 0, 1]])
    c = opencv_coefficients("OPENCV", OPENCV)
    pinhole, distorted = _rendered(size, Ks, c)
    out = undistort_image(distorted, Ks, c)
    assert out.shape == distorted.shape and out.dtype == np.float64
    # where the source is inside the distorted image (the corners sample outside: zeros)
    map_x, map_y = undistortion_maps(Ks, c, size)
    inside = (map_x > 1) & (map_x < size[1] - 2) & (map_y > 1) & (map_y < size[0] - 2)
    assert inside.mean() > 0.9
    err = np.abs(out - pinhole)[inside]
    assert err.max() < 0.05  # bilinear sampling of a 24 px period: a few hundredths
    assert np.abs(distorted - pinhole)[inside].max() > 0.9  # the lens moved the lines
    # straight lines come back straight: along rows through the middles of chequer rows the
    # vertical lines cross at u = 12 k, the same columns in every row
    for v in (42, 90, 138):
        row = out[v, 20:-20]
        i = np.nonzero((row[:-1] > 0) != (row[1:] > 0))[0]
        u = 20 + i + row[i] / (row[i] - row[i + 1])  # sub-pixel crossings
        assert len(u) == 17  # u = 24 .. 216
        np.testing.assert_allclose(u, 12 * np.round(u / 12), atol=0.1)
    # the opposite lens does not give it back (the test can fail)
    wrong = undistort_image(distorted, Ks, -c)
    assert np.abs(wrong - pinhole)[inside].max() > 0.5


def test_undistortion_maps_are_the_forward_model_and_cached():
    c = opencv_coefficients("RADIAL", (-0.2, 0.05))
    size = (48, 64)
    Ks = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
    map_x, map_y = undistortion_maps(Ks, c, size)
    assert map_x.shape == size and map_x.dtype == np.float32 and not map_x.flags.writeable
    v, u = np.mgrid[0:size[0], 0:size[1]]
    ref = distort_points(np.stack([u.ravel(), v.ravel()], axis=1), Ks, c)
    np.testing.assert_allclose(map_x.ravel(), ref[:, 0], atol=1e-3)
    np.testing.assert_allclose(map_y.ravel(), ref[:, 1], atol=1e-3)
    again = undistortion_maps(Ks.tolist(), list(c), list(size))
    assert again[0] is map_x and again[1] is map_y


@pytest.mark.parametrize("shape,dtype", [((30, 40), np.uint8), ((30, 40, 3), np.uint8),
                                         ((30, 40, 1), np.uint16), ((30, 40), np.float32)])
def test_undistort_image_keeps_shape_and_dtype(shape, dtype):
    img = (np.random.default_rng(0).uniform(0, 1, shape) * (255 if dtype == np.uint8 else 1)
           ).astype(dtype)
    Ks = np.array([[40.0, 0, 19.5], [0, 40.0, 14.5], [0, 0, 1]])
    out = undistort_image(img, Ks, [-0.1, 0, 0, 0])
    assert out.shape == img.shape and out.dtype == img.dtype
    # the centre pixel does not move
    assert np.allclose(out[14:16, 19:21].astype(float), img[14:16, 19:21].astype(float),
                       atol=1e-3 if dtype == np.float32 else 1)
    same = undistort_image(img, Ks, np.zeros(4))  # a pinhole camera: a copy
    np.testing.assert_array_equal(same, img)
    assert same is not img


def test_empty_and_pinhole_points_pass_through():
    assert undistort_points(np.zeros((0, 2)), K, OPENCV).shape == (0, 2)
    assert distort_points(np.zeros((0, 2)), K, OPENCV).shape == (0, 2)
    xy = _grid(n=(3, 3))
    np.testing.assert_array_equal(undistort_points(xy, K, np.zeros(4)), xy)
    np.testing.assert_array_equal(distort_points(xy, K, np.zeros(4)), xy)
