"""One Camera for the command line and the datasets: COLMAP's models read once (the datasets'
reader took FOV's fy for cx), the pixel-centre shift, and one rescale of K."""

from __future__ import annotations

import numpy as np
import pytest

from strl_pyg.geometry import COLMAP_CAMERA_MODELS, Camera, scale_intrinsics


@pytest.mark.parametrize("model_id", sorted(COLMAP_CAMERA_MODELS))
def test_every_colmap_model_reads_its_focal_lengths_and_centre(model_id):
    name, n, focals = COLMAP_CAMERA_MODELS[model_id]
    params = (
        [500.0, 320.5, 240.5] if focals == 1 else [500.0, 510.0, 320.5, 240.5])
    params += [0.01] * (n - len(params))
    cam = Camera.from_colmap(name, [str(p) for p in params], (480, 640))
    fy = 500.0 if focals == 1 else 510.0
    np.testing.assert_allclose(cam.K, [[500, 0, 320], [0, fy, 240], [0, 0, 1]])
    assert cam.distorted == (len(cam.distortion) > 0)
    assert len(cam.distortion) == n - (3 if focals == 1 else 4)


def test_fov_has_two_focal_lengths_in_the_dataset_reader(tmp_path):
    """COLMAP's FOV is fx, fy, cx, cy, omega: the datasets' own parser read it as f, cx, cy."""
    from strl_pyg.datasets.camera_files import _colmap_camera

    K, dist = _colmap_camera("FOV", [500, 510, 320.5, 240.5, 0.9], "test")
    np.testing.assert_allclose(K, [[500, 0, 320], [0, 510, 240], [0, 0, 1]])
    assert dist == (0.9,)


def test_bad_colmap_cameras_refuse_in_one_line():
    with pytest.raises(ValueError, match="Expected a COLMAP camera model among"):
        Camera.from_colmap("KANNALA", [1, 2, 3], where="cams.txt")
    with pytest.raises(ValueError, match="Expected 4 parameters for COLMAP model PINHOLE in x"):
        Camera.from_colmap("PINHOLE", [1, 2, 3], where="x")
    with pytest.raises(ValueError, match="Expected numbers"):
        Camera.from_colmap("PINHOLE", [1, 2, 3, "a"], where="x")


def test_rescale_maps_pixel_centres():
    K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])  # centred on 640x480
    half = scale_intrinsics(K, 0.5, 0.5)
    np.testing.assert_allclose(half, [[250, 0, 159.5], [0, 250, 119.5], [0, 0, 1]])  # 320x240
    cam = Camera.from_K(K, (480, 640)).scaled(0.5, 0.5)
    np.testing.assert_allclose(cam.K, half)
    assert cam.size == (240, 320)
    from strl_pyg.datasets.base import scale_intrinsics as by_size

    np.testing.assert_allclose(by_size(K, (480, 640), (240, 320)), half)
