"""The command line's readers with lens distortion: a pair whose cameras have radial or OpenCV
distortion (NeRF ``k1, k2, p1, p2``, a COLMAP camera) is undistorted before matching instead of
refused; other lens models, and a K alone for matches made elsewhere, are still refused."""

from __future__ import annotations

import argparse
import json

import cv2
import numpy as np
import pytest

from strl_pyg.cli.readers import intrinsics_from_args, read_pair
from strl_pyg.geometry import opencv_coefficients, undistort_image
from strl_pyg.utils.commandline import UsageError

H, W = 90, 120
#: K of the images in this package's pixel convention (NeRF / COLMAP store c + 0.5).
K = np.array([[100.0, 0.0, 59.5], [0.0, 100.0, 44.5], [0.0, 0.0, 1.0]])


def _images(folder, names=("0001.png", "0002.png")):
    """Two generated grey images (a smooth chequerboard, shifted between them)."""
    (folder / "images").mkdir()
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    paths = []
    for k, name in enumerate(names):
        img = 127.5 + 120 * np.sin((u + 3 * k) / 5.0) * np.sin(v / 5.0)
        cv2.imwrite(str(folder / "images" / name), img.round().astype(np.uint8))
        paths.append(str(folder / "images" / name))
    return paths


def _transforms(folder, **lens):
    pose = np.eye(4).tolist()
    (folder / "transforms.json").write_text(json.dumps({
        "fl_x": 100.0, "fl_y": 100.0, "cx": 60.0, "cy": 45.0, "w": W, "h": H, **lens,
        "frames": [{"file_path": "images/0001.png", "transform_matrix": pose},
                   {"file_path": "images/0002.png", "transform_matrix": pose}]}))
    return str(folder / "transforms.json")


def _args(paths, **flags):
    return argparse.Namespace(image0=paths[0], image1=paths[1],
                              **{"K": None, "K0": None, "K1": None, "max_side": 0, **flags})


def test_nerf_distortion_is_undistorted_before_matching(tmp_path, capsys):
    paths = _images(tmp_path)
    source = _transforms(tmp_path, k1=-0.2, k2=0.05, p1=1e-3)
    img0, img1, K0, K1 = read_pair(_args(paths, K=source))
    np.testing.assert_allclose(K0, K)
    np.testing.assert_allclose(K1, K)
    c = opencv_coefficients("OPENCV", (-0.2, 0.05, 1e-3, 0.0))
    for got, path in ((img0, paths[0]), (img1, paths[1])):
        raw = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        np.testing.assert_array_equal(got, undistort_image(raw, K, c))
        assert np.abs(got.astype(int) - raw).max() > 50  # the lens moved the pattern
    err = capsys.readouterr().err.splitlines()
    assert err == ["note: undistorted 0001.png (OPENCV k1=-0.2 k2=0.05 p1=0.001 p2=0) before "
                   "matching",
                   "note: undistorted 0002.png (OPENCV k1=-0.2 k2=0.05 p1=0.001 p2=0) before "
                   "matching"]


def test_pinhole_cameras_leave_the_images_as_read(tmp_path, capsys):
    paths = _images(tmp_path)
    source = _transforms(tmp_path, k1=0.0, p2=0.0)
    img0, _, K0, _ = read_pair(_args(paths, K=source))
    np.testing.assert_array_equal(img0, cv2.imread(paths[0], cv2.IMREAD_GRAYSCALE))
    np.testing.assert_allclose(K0, K)
    assert "undistorted" not in capsys.readouterr().err


def test_colmap_camera_file_is_undistorted_at_full_size_before_downscaling(tmp_path, capsys):
    """A COLMAP cameras.txt (SIMPLE_RADIAL) for both images: undistorted with its K, then
    downscaled for matching with the undistorted image kept as the original."""
    paths = _images(tmp_path)
    cams = tmp_path / "cameras.txt"
    cams.write_text(f"1 SIMPLE_RADIAL {W} {H} 100 60 45 -0.15\n")
    inputs = read_pair(_args(paths, K0=str(cams), max_side=60))
    raw = cv2.imread(paths[0], cv2.IMREAD_GRAYSCALE)
    full = undistort_image(raw, K, [-0.15, 0, 0, 0])
    np.testing.assert_array_equal(inputs.original[0], full)
    np.testing.assert_allclose(inputs.original[2], K)
    assert inputs[0].shape == (45, 60) and inputs.scales[0] == (0.5, 0.5)
    err = capsys.readouterr().err
    assert "note: undistorted 0001.png (SIMPLE_RADIAL k=-0.15)" in err
    assert "not applied" not in err


def test_other_lens_models_are_still_refused(tmp_path):
    paths = _images(tmp_path)
    fisheye = _transforms(tmp_path, camera_model="OPENCV_FISHEYE", k1=0.1, k2=0.01)
    with pytest.raises(UsageError, match=r"^Expected a camera model among SIMPLE_PINHOLE, "
                                         r"PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV to undistort "
                                         r"'0001.png' in '.*transforms.json' \(got "
                                         r"OPENCV_FISHEYE distortion\)"):
        read_pair(_args(paths, K=fisheye))
    k3 = _transforms(tmp_path, k1=0.1, k3=0.01)
    with pytest.raises(UsageError, match=r"\(got FULL_OPENCV distortion\)"):
        read_pair(_args(paths, K=k3))


def test_a_distorted_camera_for_k_alone_is_refused(tmp_path):
    """``predict --matches`` reads K alone (matches made elsewhere): a distorted scene camera
    cannot be described by it, so it stays refused, naming the model."""
    paths = _images(tmp_path)
    source = _transforms(tmp_path, k1=-0.2)
    with pytest.raises(UsageError, match=r"Expected pinhole images in '.*transforms.json' "
                                         r"\(got OPENCV distortion \(-0.2, 0.0, 0.0, 0.0\) for "
                                         r"'0001.png'\): undistort them first"):
        intrinsics_from_args(_args(paths, K=source))


def test_nerf_frames_record_their_lens_model(tmp_path):
    from strl_pyg.datasets.camera_files import read_nerf_transforms

    _images(tmp_path)
    im = read_nerf_transforms(_transforms(tmp_path, k1=-0.2, p2=0.003, k2=0.01, p1=0.002))[0]
    assert (im.model, im.distortion) == ("OPENCV", (-0.2, 0.01, 0.002, 0.003))
    im = read_nerf_transforms(_transforms(tmp_path))[0]
    assert (im.model, im.distortion) == ("PINHOLE", ())
    im = read_nerf_transforms(_transforms(tmp_path, camera_model="OPENCV_FISHEYE", k1=0.1,
                                          k4=0.004))[0]
    assert (im.model, im.distortion) == ("OPENCV_FISHEYE", (0.1, 0.0, 0.0, 0.004))
    with pytest.raises(ValueError, match=r"Expected k4 = 0 for a perspective camera in .* "
                                         r"frame 0 \(got 0.004\)"):
        read_nerf_transforms(_transforms(tmp_path, k1=0.1, k4=0.004))
    with pytest.raises(ValueError, match="Expected finite distortion terms"):
        read_nerf_transforms(_transforms(tmp_path, k1=float("nan")))
