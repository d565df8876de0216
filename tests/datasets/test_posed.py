"""strl_pyg.datasets.camera_files and posed: each format written from a known camera set reads back
the same
intrinsics and relative poses; pairs by overlap; clear errors on bad files."""

from __future__ import annotations

import json
import struct

import cv2
import numpy as np
import pytest

from strl_pyg.datasets.camera_files import (
    PosedImage,
    read_colmap_model,
    read_llff_poses,
    read_nerf_transforms,
    read_posed_folder,
    read_real_scene,
)
from strl_pyg.datasets.posed import (
    REAL_SCENES_SPLIT,
    PosedImagePairs,
    PosedPairOptions,
    select_pairs,
)

H, W = 48, 64


def _rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, float) / np.linalg.norm(axis) * np.radians(deg))[0]


@pytest.fixture
def cameras():
    """Four cameras (OpenCV axes, camera-to-world) looking roughly along +z, and one K."""
    rng = np.random.default_rng(3)
    out = []
    for i in range(4):
        T = np.eye(4)
        T[:3, :3] = _rot(rng.normal(size=3), 5 + 4 * i)
        T[:3, 3] = [0.3 * i, -0.1 * i, 0.05 * i]
        out.append(T)
    K = np.array([[50.0, 0, 31.5], [0, 52.0, 23.5], [0, 0, 1]])  # OpenCV pixel centres
    return out, K


def _images(folder, n):
    folder.mkdir(parents=True, exist_ok=True)
    names = [f"im{i:02d}.png" for i in range(n)]
    for name in names:
        cv2.imwrite(str(folder / name), np.zeros((H, W), np.uint8))
    return names


def _relative(images):
    return [np.linalg.inv(b.T_c2w) @ a.T_c2w for a, b in zip(images, images[1:], strict=False)]


def _assert_same(images, cameras, K):
    want = [np.linalg.inv(b) @ a for a, b in zip(cameras, cameras[1:], strict=False)]
    got = _relative(images)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g[:3, :3], w[:3, :3], atol=1e-9)
        np.testing.assert_allclose(g[:3, 3], w[:3, 3], atol=1e-9)
    for im in images:
        np.testing.assert_allclose(im.K, K, atol=1e-9)


def _quat(R):
    w = np.sqrt(max(0.0, 1 + np.trace(R))) / 2
    x = (R[2, 1] - R[1, 2]) / (4 * w)
    y = (R[0, 2] - R[2, 0]) / (4 * w)
    z = (R[1, 0] - R[0, 1]) / (4 * w)
    return [w, x, y, z]


def test_real_scenes_format_reads_back(tmp_path, cameras):
    Ts, K = cameras
    names = _images(tmp_path / "images", len(Ts))
    (tmp_path / "cameras.json").write_text(json.dumps({"images": [
        {"file": f"images/{n}", "K": K.tolist(), "T_cam_to_world": T.tolist(), "width": W,
         "height": H} for n, T in zip(names, Ts, strict=True)]}))
    ims = read_real_scene(tmp_path)
    _assert_same(ims, Ts, K)
    assert ims[0].size == (H, W) and ims[0].path.endswith("im00.png")


def _write_colmap(root, Ts, K, names, points, binary=False):
    """A PINHOLE COLMAP model of the cameras ``Ts`` in ``root/sparse/0`` (world-to-camera
    quaternions, the pixel-corner principal point), ``points[k]``: image k's observations."""
    model = root / "sparse" / "0"
    model.mkdir(parents=True)
    params = [K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5]  # PINHOLE, corner convention
    poses = []
    for T in Ts:
        Rw = T[:3, :3].T
        poses.append((_quat(Rw), -Rw @ T[:3, 3]))
    if binary:
        with open(model / "cameras.bin", "wb") as f:
            f.write(struct.pack("<Q", 1) + struct.pack("<iiQQ", 1, 1, W, H)
                    + struct.pack("<4d", *params))
        with open(model / "images.bin", "wb") as f:
            f.write(struct.pack("<Q", len(Ts)))
            for k, ((q, t), name, pts) in enumerate(zip(poses, names, points, strict=True)):
                f.write(struct.pack("<i4d3di", k + 1, *q, *t, 1) + name.encode() + b"\0")
                f.write(struct.pack("<Q", len(pts)))
                for x, y, pid in pts:
                    f.write(struct.pack("<ddq", x, y, pid))
    else:
        (model / "cameras.txt").write_text(
            "# Camera list\n1 PINHOLE {} {} {}\n".format(
                W, H, " ".join(repr(float(v)) for v in params)))
        lines = ["# Image list"]
        for k, ((q, t), name, pts) in enumerate(zip(poses, names, points, strict=True)):
            q_t = " ".join(repr(float(v)) for v in [*q, *t])
            lines.append(f"{k + 1} {q_t} 1 {name}")
            lines.append(" ".join(f"{x} {y} {pid}" for x, y, pid in pts))
        (model / "images.txt").write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("binary", [False, True])
def test_colmap_model_reads_back(tmp_path, cameras, binary):
    """COLMAP stores world-to-camera quaternions and the pixel-corner principal point."""
    Ts, K = cameras
    names = _images(tmp_path / "images", len(Ts))
    points = [[(1.0, 2.0, 7), (3.0, 4.0, -1)], [(1.0, 2.0, 7)], [(5.0, 5.0, 9)], []]
    _write_colmap(tmp_path, Ts, K, names, points, binary)
    ims = read_posed_folder(tmp_path)
    _assert_same(ims, Ts, K)
    assert ims[0].points == frozenset({7}) and ims[3].points == frozenset()
    # the binary reader skipped 4 bytes of every name (a native-aligned record size): the
    # images of a .bin model were not found
    assert [im.path for im in ims] == [str(tmp_path / "images" / n) for n in names]


@pytest.mark.parametrize("binary", [False, True])
def test_colmap_images_in_capture_order_and_a_model_without_tracks(tmp_path, cameras, binary):
    """Images named 1.png ... 12.png came back as 1, 10, 11, 12, 2, ... (text order), so the
    gap-1 pairs joined frames 9 apart; a model written from known poses (no point tracks)
    gave every image an empty point set, and no pair passed the co-visibility filter."""
    Ts, K = cameras
    Ts = [Ts[k % 4] @ np.diag([1.0, 1.0, 1.0, 1.0]) for k in range(12)]
    for k, T in enumerate(Ts):
        T[:3, 3] = [0.05 * k, 0.0, 0.0]  # a slow pan: every neighbour overlaps
        T[:3, :3] = _rot([0, 1, 0], 2 * k)
    names = [f"{k + 1}.png" for k in range(12)]
    (tmp_path / "images").mkdir()
    for n in names:
        cv2.imwrite(str(tmp_path / "images" / n), np.zeros((H, W), np.uint8))
    _write_colmap(tmp_path, Ts, K, names, [[] for _ in names], binary)
    ims = read_posed_folder(tmp_path)
    assert [im.path.rsplit("/", 1)[1] for im in ims] == names
    _assert_same(ims, Ts, K)
    assert all(im.points is None for im in ims)  # no co-visibility to filter on
    pairs = select_pairs(ims, PosedPairOptions(gaps=(1,)))
    assert pairs == [(k, k + 1) for k in range(11)]
    # a pair's id holds positions: a COLMAP scene's cache is apart from text-order entries
    ds = PosedImagePairs([tmp_path], cache_dir=tmp_path / "cache", pairs=PosedPairOptions(
        gaps=(1,)))
    assert ds._make_fingerprint()["colmap_order"] == "natural"


def test_colmap_distortion_is_kept_and_refused_for_pairs(tmp_path, cameras):
    Ts, K = cameras
    names = _images(tmp_path / "images", 2)
    model = tmp_path / "sparse"
    model.mkdir()
    (model / "cameras.txt").write_text(f"1 SIMPLE_RADIAL {W} {H} 50 32 24 -0.1\n")
    rows = []
    for k, name in enumerate(names):
        rows += [f"{k + 1} 1 0 0 0 {k} 0 0 1 {name}", ""]
    (model / "images.txt").write_text("\n".join(rows) + "\n")
    ims = read_colmap_model(model, tmp_path / "images")
    assert ims[0].distortion == (-0.1,)
    np.testing.assert_allclose(ims[0].K, [[50, 0, 31.5], [0, 50, 23.5], [0, 0, 1]])
    with pytest.raises(ValueError, match="Expected pinhole images .* undistort"):
        PosedImagePairs([("s", ims)], cache_dir=tmp_path / "c")


def test_nerf_transforms_reads_back(tmp_path, cameras):
    """transforms.json: OpenGL camera axes, corner-convention centre, extension optional."""
    Ts, K = cameras
    names = _images(tmp_path / "images", len(Ts))
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    (tmp_path / "transforms.json").write_text(json.dumps({
        "fl_x": K[0, 0], "fl_y": K[1, 1], "cx": K[0, 2] + 0.5, "cy": K[1, 2] + 0.5,
        "w": W, "h": H,
        "frames": [{"file_path": f"images/{n[:-4]}", "transform_matrix": (T @ flip).tolist()}
                   for n, T in zip(names, Ts, strict=True)]}))
    ims = read_nerf_transforms(tmp_path / "transforms.json")
    _assert_same(ims, Ts, K)
    assert ims[1].path.endswith("im01.png")


def test_llff_poses_bounds_reads_back(tmp_path, cameras):
    """poses_bounds.npy: 3x5 [R|t|hwf] with columns (down, right, back), full-size hwf."""
    Ts, _ = cameras
    _images(tmp_path / "images", len(Ts))
    f_full, s = 100.0, 0.5  # the stored full size is twice the files'
    rows = []
    for T in Ts:
        R = T[:3, :3]
        llff = np.stack([R[:, 1], R[:, 0], -R[:, 2]], axis=1)  # (right, down, fwd) -> LLFF
        m = np.concatenate([llff, T[:3, 3:4], [[H / s], [W / s], [f_full]]], axis=1)
        rows.append(np.concatenate([m.ravel(), [0.1, 10.0]]))
    np.save(tmp_path / "poses_bounds.npy", np.array(rows))
    ims = read_llff_poses(tmp_path / "poses_bounds.npy")
    K = np.array([[f_full * s, 0, (W - 1) / 2], [0, f_full * s, (H - 1) / 2], [0, 0, 1]])
    _assert_same(ims, Ts, K)


@pytest.mark.parametrize("write, match", [
    (lambda d: None, "Expected cameras.json, a COLMAP model"),
    (lambda d: (d / "cameras.json").write_text("{"), "Expected a real_scenes cameras file in "
     "JSON"),
    (lambda d: (d / "cameras.json").write_text(json.dumps({"images": [
        {"file": "a.png", "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
         "T_cam_to_world": np.diag([1.0, 1.0, 2.0, 1.0]).tolist(), "width": 4,
         "height": 4}]})), "Expected a rotation in the camera pose"),
    (lambda d: np.save(d / "poses_bounds.npy", np.zeros((2, 15))), r"Expected finite \[N, 17\]"),
])
def test_bad_files_are_one_line_errors(tmp_path, write, match):
    write(tmp_path)
    with pytest.raises((ValueError, FileNotFoundError), match=match) as exc:
        read_posed_folder(tmp_path)
    assert "\n" not in str(exc.value)


def test_a_cut_colmap_binary_names_the_file(tmp_path):
    (tmp_path / "cameras.bin").write_bytes(struct.pack("<Q", 1) + b"\0\0")
    (tmp_path / "images.bin").write_bytes(struct.pack("<Q", 0))
    with pytest.raises(ValueError, match="Expected a complete COLMAP binary file at .*cameras"):
        read_colmap_model(tmp_path)


def test_pairs_follow_gaps_rotation_axes_and_covisibility():
    def cam(deg, points=None):
        T = np.eye(4)
        T[:3, :3] = _rot([0, 1, 0], deg)
        return PosedImage("x.png", np.eye(3), T, points=points)

    ims = [cam(0), cam(10), cam(20), cam(100)]
    assert select_pairs(ims, PosedPairOptions(gaps=(1,))) == [(0, 1), (1, 2)]
    assert select_pairs(ims, PosedPairOptions(gaps=(1, 2), max_rotation_deg=15)) == [
        (0, 1), (1, 2)]
    assert select_pairs(ims, PosedPairOptions(gaps=(1,), min_rotation_deg=15)) == []
    assert select_pairs(ims, PosedPairOptions(gaps=(1, 3), max_rotation_deg=180,
                                              max_axis_angle_deg=90)) == [(0, 1), (1, 2),
                                                                          (2, 3)]
    seen = [cam(0, frozenset({1, 2, 3})), cam(5, frozenset({3, 4, 5})), cam(9, frozenset({3}))]
    assert select_pairs(seen, PosedPairOptions(gaps=(1,), min_covisible=0.5)) == [(1, 2)]
    with pytest.raises(ValueError, match="Expected gaps as positive integers"):
        PosedPairOptions(gaps=(0,))


def test_real_scenes_split_is_the_readme_split(shared_data):
    root = shared_data / "real_scenes"
    if not root.is_dir():
        pytest.skip("real_scenes not found")
    on_disk = {p.name for p in root.iterdir() if p.is_dir()}
    assert set(REAL_SCENES_SPLIT["train"]) | set(REAL_SCENES_SPLIT["val"]) == on_disk
    assert not set(REAL_SCENES_SPLIT["train"]) & set(REAL_SCENES_SPLIT["val"])
    ims = read_posed_folder(root / "fruit")
    assert len(ims) == 80 and ims[0].size == (640, 480)
    # the README's check: consecutive stored poses give the same relative pose as T_0to1
    T = np.linalg.inv(ims[1].T_c2w) @ ims[0].T_c2w
    assert 5 < np.degrees(np.arccos((np.trace(T[:3, :3]) - 1) / 2)) < 15
