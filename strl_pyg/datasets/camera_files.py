"""Camera files of posed photographs, read into one convention.

Every reader returns a list of :class:`PosedImage`: ``K`` ``[3, 3]`` in pixels of the image
file, OpenCV pixel centres (the top-left pixel's centre is ``(0, 0)``) and ``T_c2w`` ``[4, 4]``
camera-to-world with OpenCV camera axes (x right, y down, z forward). The relative pose of a
pair is then ``T_0to1 = inv(T_c2w[1]) @ T_c2w[0]`` (``X1 = R X0 + t``). The formats and their
conventions are listed in :mod:`strl_pyg.datasets.posed`.
"""

from __future__ import annotations

import json
import os
import re
import struct
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.geometry.camera import COLMAP_CAMERA_MODELS, Camera

__all__ = ["PosedImage", "posed_format", "check_pinhole", "read_real_scene", "read_colmap_model",
           "read_nerf_transforms", "read_llff_poses", "read_posed_folder"]

_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True, eq=False)
class PosedImage:
    """One photograph with its camera (OpenCV pixel centres and camera axes).

    Args:
        path: The image file.
        K: ``[3, 3]`` intrinsics in pixels of that file.
        T_c2w: ``[4, 4]`` camera-to-world pose.
        size: ``(H, W)`` of the file when the format states it, else ``None``.
        distortion: Lens distortion terms of ``model``, in COLMAP's order for it (empty:
            pinhole). ``K`` is the pinhole part; the matches of a distorted image come from
            it undistorted (:func:`strl_pyg.geometry.undistort_image` with ``K`` and
            ``opencv_coefficients(model, distortion)``, for the models in
            :data:`strl_pyg.geometry.DISTORTION_MODELS`).
        points: Ids of the 3D points the image observes (COLMAP models), else ``None``.
        model: The camera model, by COLMAP's name: the COLMAP model's own; ``"OPENCV"`` for a
            NeRF frame with ``k1, k2, p1, p2`` (``"FULL_OPENCV"`` with ``k3`` too,
            ``"OPENCV_FISHEYE"`` for a nerfstudio fisheye: ``k1 .. k4``); ``"PINHOLE"``
            otherwise.
    """

    path: str
    K: np.ndarray
    T_c2w: np.ndarray
    size: tuple[int, int] | None = None
    distortion: tuple[float, ...] = ()
    points: frozenset[int] | None = field(default=None, repr=False)
    model: str = "PINHOLE"

    @property
    def name(self) -> str:
        return Path(self.path).name


def _check_pose(T: np.ndarray, where: str) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"Expected a finite 4x4 camera pose in {where} (got shape "
                         f"{T.shape}{'' if np.isfinite(T).all() else ' with NaN or inf'})")
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-3 or np.linalg.det(R) < 0:
        raise ValueError(f"Expected a rotation in the camera pose of {where} (got R^T R off the "
                         f"identity by {err:.2g}, det {np.linalg.det(R):.3g})")
    return T


def _check_K(K: np.ndarray, where: str) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all() or not (K[0, 0] > 0 and K[1, 1] > 0):
        raise ValueError(f"Expected a 3x3 K with positive focal lengths in {where} "
                         f"(got {K.tolist() if K.size == 9 else K.shape})")
    return K


def _pinhole(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _load_json(path: Path, what: str) -> Any:
    if not path.is_file():
        raise FileNotFoundError(f"Expected {what} at '{path}' (got no such file)")
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"Expected {what} in JSON at '{path}' (got {err})") from err


# -- real_scenes ---------------------------------------------------------------------------

def read_real_scene(scene_dir: str | os.PathLike) -> list[PosedImage]:
    """The images of one ``real_scenes`` scene (``cameras.json``), in capture order."""
    scene_dir = Path(scene_dir)
    path = scene_dir / "cameras.json"
    data = _load_json(path, "a real_scenes cameras file")
    if not isinstance(data, dict) or not isinstance(data.get("images"), list):
        got = data.get("images") if isinstance(data, dict) else data
        raise ValueError(f"Expected an 'images' list in '{path}' (got "
                         f"{type(got).__name__})")
    out = []
    for n, im in enumerate(data["images"]):
        where = f"'{path}' image {n}"
        try:
            K, T = im["K"], im["T_cam_to_world"]
            file, size = im["file"], (int(im["height"]), int(im["width"]))
        except (KeyError, TypeError) as err:
            raise ValueError(f"Expected K, T_cam_to_world, file, width and height in {where} "
                             f"(got no {err})") from err
        out.append(PosedImage(str(scene_dir / file), _check_K(K, where), _check_pose(T, where),
                              size))
    return out


# -- COLMAP --------------------------------------------------------------------------------

def _colmap_camera(model: str, params: Sequence[float], where: str):
    """``(K, distortion)`` of a COLMAP camera, K in OpenCV pixel centres
    (:meth:`strl_pyg.geometry.Camera.from_colmap`)."""
    cam = Camera.from_colmap(model, params, where=where)
    return cam.K, cam.distortion


def _qvec_to_R(q: Sequence[float]) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _w2c_to_c2w(q: Sequence[float], t: Sequence[float]) -> np.ndarray:
    R = _qvec_to_R(q)
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = -R.T @ np.asarray(t, dtype=np.float64)
    return T


def _read_colmap_text(model_dir: Path):
    cams, images = {}, []
    cam_path, img_path = model_dir / "cameras.txt", model_dir / "images.txt"
    for n, line in enumerate(cam_path.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        f = line.split()
        where = f"'{cam_path}' line {n}"
        try:
            cams[int(f[0])] = (f[1], (int(f[3]), int(f[2])), *_colmap_camera(f[1], f[4:], where))
        except (IndexError, ValueError) as err:
            raise ValueError(f"Expected 'CAMERA_ID MODEL WIDTH HEIGHT PARAMS' in {where} "
                             f"(got {line[:60]!r}: {err})") from err
    lines = [ln for ln in img_path.read_text().splitlines() if not ln.startswith("#")]
    # two lines per image: the pose, then its 2D points (possibly empty)
    for k in range(0, len(lines) - 1, 2):
        f = lines[k].split()
        if not f:
            continue
        try:
            q, t = [float(v) for v in f[1:5]], [float(v) for v in f[5:8]]
            cam, name = int(f[8]), " ".join(f[9:])
            pts = lines[k + 1].split()
            ids = {int(v) for v in pts[2::3] if int(v) != -1}
        except (IndexError, ValueError) as err:
            raise ValueError(f"Expected 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME' and a "
                             f"points line in '{img_path}' (got {lines[k][:60]!r}: {err})"
                             ) from err
        images.append((name, q, t, cam, ids))
    return cams, images


class _Reader:
    def __init__(self, path: Path) -> None:
        self.path, self.buf, self.pos = path, path.read_bytes(), 0

    def take(self, fmt: str):
        size = struct.calcsize("<" + fmt)  # packed, as COLMAP writes (no native alignment)
        if self.pos + size > len(self.buf):
            raise ValueError(f"Expected a complete COLMAP binary file at '{self.path}' (got "
                             f"{len(self.buf)} bytes, cut at byte {self.pos})")
        out = struct.unpack_from("<" + fmt, self.buf, self.pos)
        self.pos += size
        return out

    def name(self) -> str:
        end = self.buf.find(b"\0", self.pos)
        if end < 0:
            raise ValueError(f"Expected a NUL-terminated image name in '{self.path}' (got the "
                             "end of the file)")
        out = self.buf[self.pos:end].decode("utf-8")
        self.pos = end + 1
        return out


def _read_colmap_binary(model_dir: Path):
    cams, images = {}, []
    r = _Reader(model_dir / "cameras.bin")
    for _ in range(r.take("Q")[0]):
        cam_id, model_id, w, h = r.take("iiQQ")
        if model_id not in COLMAP_CAMERA_MODELS:
            raise ValueError(f"Expected a COLMAP camera model id 0-{max(COLMAP_CAMERA_MODELS)} "
                             f"in '{r.path}' (got {model_id})")
        name, n, _ = COLMAP_CAMERA_MODELS[model_id]
        cams[cam_id] = (name, (int(h), int(w)),
                        *_colmap_camera(name, r.take("d" * n), f"'{r.path}'"))
    r = _Reader(model_dir / "images.bin")
    for _ in range(r.take("Q")[0]):
        f = r.take("idddddddi")
        name = r.name()
        n2d = r.take("Q")[0]
        ids = set()
        if n2d:
            pts = np.frombuffer(r.buf, dtype=np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")]),
                                count=n2d, offset=r.pos)
            r.pos += 24 * n2d
            ids = set(pts["id"][pts["id"] != -1].tolist())
        images.append((name, f[1:5], f[5:8], f[8], ids))
    return cams, images


def read_colmap_model(model_dir: str | os.PathLike,
                      image_dir: str | os.PathLike | None = None) -> list[PosedImage]:
    """The images of a COLMAP model (``.txt`` or ``.bin``, whichever is there), in capture
    order: sorted by name with the numbers in names compared as numbers (``2.jpg`` before
    ``10.jpg``).

    Each image's :attr:`PosedImage.points` holds the ids of the 3D points it sees; a model
    without point tracks (every image's points line empty, as a model written from known
    poses has) gives ``None`` there, so :func:`~strl_pyg.datasets.posed.select_pairs` has no
    co-visibility to filter on, rather than an empty set that no pair would pass.

    Args:
        model_dir: Folder with ``cameras`` and ``images`` (e.g. ``sparse/0``).
        image_dir: Where the image files are (default: ``model_dir/../../images``, COLMAP's
            project layout, else ``model_dir/images``).
    """
    model_dir = Path(model_dir)
    if (model_dir / "cameras.bin").is_file() and (model_dir / "images.bin").is_file():
        cams, images = _read_colmap_binary(model_dir)
    elif (model_dir / "cameras.txt").is_file() and (model_dir / "images.txt").is_file():
        cams, images = _read_colmap_text(model_dir)
    else:
        got = sorted(p.name for p in model_dir.iterdir()) if model_dir.is_dir() \
            else "no such folder"
        raise FileNotFoundError(f"Expected a COLMAP model (cameras and images, .txt or .bin) "
                                f"in '{model_dir}' (got {got})")
    if image_dir is None:
        image_dir = next((d for d in (model_dir.parent.parent / "images", model_dir / "images")
                          if d.is_dir()), model_dir.parent.parent / "images")
    tracks = any(ids for *_, ids in images)
    out = []
    for name, q, t, cam, ids in sorted(images, key=lambda x: _natural_key(x[0])):
        if cam not in cams:
            raise ValueError(f"Expected camera {cam} of image '{name}' in the COLMAP model at "
                             f"'{model_dir}' (got cameras {sorted(cams)})")
        model, size, K, dist = cams[cam]
        T = _check_pose(_w2c_to_c2w(q, t), f"COLMAP image '{name}'")
        out.append(PosedImage(str(Path(image_dir) / name), K, T, size, dist,
                              points=frozenset(ids) if tracks else None, model=model))
    return out


def _natural_key(name: str) -> tuple:
    """Sort key of a file name with its digit runs compared as numbers: ``frame_2.jpg``
    before ``frame_10.jpg`` (plain text order puts ``10`` first)."""
    parts = re.split(r"([0-9]+)", name)  # odd positions: the ASCII digit runs
    return (tuple((0, int(p), "") if k % 2 else (1, 0, p) for k, p in enumerate(parts)), name)


# -- NeRF / instant-ngp ----------------------------------------------------------------------

def _image_size(path: Path) -> tuple[int, int]:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileNotFoundError(f"Expected a readable image at '{path}' (got none)")
    return int(img.shape[0]), int(img.shape[1])


def _resolve_image(folder: Path, file_path: str) -> Path:
    p = folder / file_path
    if p.suffix == "" or not p.is_file():
        for ext in (".png", ".jpg", ".jpeg", ".JPG", ".PNG"):
            if p.with_name(p.name + ext).is_file():
                return p.with_name(p.name + ext)
    return p


def _nerf_lens(cam: dict, where: str) -> tuple[str, tuple[float, ...]]:
    """``(model, distortion)`` of a NeRF / nerfstudio camera as a COLMAP model
    (:attr:`PosedImage.model`): OpenCV's ``k1, k2, p1, p2`` (``k3`` makes it FULL_OPENCV's
    eight terms); nerfstudio's ``OPENCV_FISHEYE`` keeps its ``k1 .. k4``."""
    try:
        k = {n: float(cam.get(n, 0.0)) for n in ("k1", "k2", "k3", "k4", "p1", "p2")}
    except (TypeError, ValueError) as err:
        raise ValueError(f"Expected numbers as the distortion terms in {where} (got "
                         f"{err})") from None
    if not all(np.isfinite(v) for v in k.values()):
        raise ValueError(f"Expected finite distortion terms in {where} (got {k})")
    if cam.get("camera_model") == "OPENCV_FISHEYE":
        return "OPENCV_FISHEYE", (k["k1"], k["k2"], k["k3"], k["k4"])
    if k["k4"]:  # nerfstudio's perspective k4 is an r^8 term: no COLMAP model has one
        raise ValueError(f"Expected k4 = 0 for a perspective camera in {where} (got "
                         f"{k['k4']:g}): undistort the images first")
    opencv = (k["k1"], k["k2"], k["p1"], k["p2"])
    if k["k3"]:
        return "FULL_OPENCV", (*opencv, k["k3"], 0.0, 0.0, 0.0)
    return ("OPENCV", opencv) if any(opencv) else ("PINHOLE", ())


def read_nerf_transforms(path: str | os.PathLike,
                         names: Collection[str] | None = None) -> list[PosedImage]:
    """The frames of a NeRF / instant-ngp ``transforms.json``, in file order (with ``names``:
    only the frames whose image file has one of these names, e.g. ``{"0001.jpg"}``; the
    others' image sizes are not read)."""
    path = Path(path)
    data = _load_json(path, "a NeRF transforms.json")
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise ValueError(f"Expected a 'frames' list in '{path}' (got none)")
    out = []
    for n, fr in enumerate(data["frames"]):
        where = f"'{path}' frame {n}"
        cam = {**data, **fr}  # per-frame intrinsics override the file's
        if "file_path" not in fr or "transform_matrix" not in fr:
            raise ValueError(f"Expected file_path and transform_matrix in {where} "
                             f"(got {sorted(fr)})")
        file = _resolve_image(path.parent, fr["file_path"])
        if names is not None and file.name not in names:
            continue
        if "w" in cam and "h" in cam:
            size = (int(cam["h"]), int(cam["w"]))
        else:
            size = _image_size(file)
        h, w = size
        if "fl_x" in cam:
            fx = float(cam["fl_x"])
            fy = float(cam.get("fl_y", fx))
        elif "camera_angle_x" in cam:
            fx = 0.5 * w / np.tan(0.5 * float(cam["camera_angle_x"]))
            fy = (0.5 * h / np.tan(0.5 * float(cam["camera_angle_y"]))
                  if "camera_angle_y" in cam else fx)
        else:
            raise ValueError(f"Expected fl_x or camera_angle_x in {where} (got neither)")
        cx = float(cam.get("cx", w / 2)) - 0.5
        cy = float(cam.get("cy", h / 2)) - 0.5
        model, dist = _nerf_lens(cam, where)
        T = np.asarray(fr["transform_matrix"], dtype=np.float64)
        T = _check_pose(T @ _GL_TO_CV if T.shape == (4, 4) else T, where)  # else: its error
        out.append(PosedImage(str(file), _check_K(_pinhole(fx, fy, cx, cy), where), T, size,
                              dist, model=model))
    return out


# -- LLFF ------------------------------------------------------------------------------------

_IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".JPG", ".JPEG", ".PNG")


def read_llff_poses(path: str | os.PathLike,
                    image_dir: str | os.PathLike | None = None) -> list[PosedImage]:
    """The images of an LLFF ``poses_bounds.npy`` (rows in the sorted order of the image
    files, as LLFF writes them).

    Args:
        path: The ``poses_bounds.npy`` file.
        image_dir: The image folder (default: ``images`` beside the file); the focal length
            and centre are scaled from the stored full size to the files' size.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected an LLFF poses_bounds.npy at '{path}' (got no such "
                                "file)")
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as err:
        raise ValueError(f"Expected a numpy array in '{path}' (got {err})") from err
    if arr.ndim != 2 or arr.shape[1] != 17 or not np.isfinite(arr).all():
        raise ValueError(f"Expected finite [N, 17] rows in '{path}' (got shape {arr.shape})")
    image_dir = Path(image_dir) if image_dir is not None else path.parent / "images"
    files = sorted(p for p in image_dir.iterdir() if p.suffix in _IMAGE_EXTS) \
        if image_dir.is_dir() else []
    if len(files) != len(arr):
        raise ValueError(f"Expected {len(arr)} images in '{image_dir}' for the rows of '{path}' "
                         f"(got {len(files)})")
    out = []
    for n, (row, file) in enumerate(zip(arr, files, strict=True)):
        m = row[:15].reshape(3, 5)
        w_full, f_full = m[1, 4], m[2, 4]  # hwf: full-size height, width, focal
        R = np.stack([m[:, 1], m[:, 0], -m[:, 2]], axis=1)  # (down, right, back) -> OpenCV
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, m[:, 3]
        size = _image_size(file)
        s = size[1] / w_full
        K = _pinhole(f_full * s, f_full * s, (size[1] - 1) / 2, (size[0] - 1) / 2)
        where = f"'{path}' row {n}"
        out.append(PosedImage(str(file), _check_K(K, where), _check_pose(T, where), size))
    return out


def check_pinhole(image: PosedImage, where: str) -> None:
    """A ``ValueError`` for a camera with lens distortion, for callers that take the image
    files as pinhole views (the training datasets)."""
    if image.distortion and any(abs(d) > 1e-9 for d in image.distortion):
        raise ValueError(f"Expected pinhole images in {where} (got {image.model} distortion "
                         f"{image.distortion} for '{image.name}'): undistort them first, with "
                         "strl_pyg.geometry.undistort_image or colmap image_undistorter")


def _colmap_dir(folder: Path) -> Path | None:
    for sub in (folder / "sparse" / "0", folder / "sparse", folder):
        if any((sub / f"cameras.{e}").is_file() for e in ("txt", "bin")):
            return sub
    return None


def posed_format(folder: str | os.PathLike) -> str:
    """Which camera format a scene folder holds: ``"real_scenes"`` (``cameras.json``),
    ``"colmap"`` (``sparse/0``, ``sparse`` or the folder itself), ``"nerf"``
    (``transforms.json``) or ``"llff"`` (``poses_bounds.npy``), looked for in that order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"Expected a folder of posed images at '{folder}' (got no such "
                                "folder)")
    if (folder / "cameras.json").is_file():
        return "real_scenes"
    if _colmap_dir(folder) is not None:
        return "colmap"
    if (folder / "transforms.json").is_file():
        return "nerf"
    if (folder / "poses_bounds.npy").is_file():
        return "llff"
    raise FileNotFoundError(
        f"Expected cameras.json, a COLMAP model (sparse/0), transforms.json or "
        f"poses_bounds.npy in '{folder}' (got {sorted(p.name for p in folder.iterdir())[:8]})")


def read_posed_folder(folder: str | os.PathLike) -> list[PosedImage]:
    """Reads whichever format a folder holds (:func:`posed_format`)."""
    folder = Path(folder)
    kind = posed_format(folder)
    if kind == "real_scenes":
        return read_real_scene(folder)
    if kind == "colmap":
        return read_colmap_model(_colmap_dir(folder), folder / "images")
    if kind == "nerf":
        return read_nerf_transforms(folder / "transforms.json")
    return read_llff_poses(folder / "poses_bounds.npy")
