"""The images of a photo collection and their cameras.

A :class:`CollectionImage` is one photograph: its name (relative to the image folder, the name
COLMAP and hloc use), its file and its :class:`~strl_pyg.geometry.camera.Camera` (pinhole
intrinsics in OpenCV's pixel convention, the COLMAP model and its distortion terms). Images with
lens distortion are undistorted to a pinhole camera with the same ``K`` and size before
detection (:func:`load_gray`), so every keypoint, segment, solver and graph sees pinhole
pixels; the COLMAP database gets the keypoints distorted back into the file's pixels, with the
original camera.

Cameras come from (:func:`read_collection`): one ``K`` for every image; a COLMAP model
(``cameras.txt``/``.bin`` with ``images``), a COLMAP database, a NeRF ``transforms.json`` (with
``k1, k2, p1, p2``) or a real_scenes ``cameras.json``; or a ``K`` per pair from a SuperGlue
pairs file (:mod:`strl_pyg.collection.pairs`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.geometry.camera import Camera

__all__ = ["CollectionImage", "read_collection", "list_images", "load_gray", "IMAGE_EXTENSIONS"]

#: The image files a folder lists (case-insensitive).
IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


@dataclass(frozen=True)
class CollectionImage:
    """One photograph of a collection.

    Args:
        name: Its name relative to the image folder (``/`` separated).
        path: The file.
        camera: Its camera (``None`` where unknown: the pairs then carry no intrinsics).
    """

    name: str
    path: str
    camera: Camera | None = None


def list_images(image_dir: str | os.PathLike) -> list[str]:
    """The image names under ``image_dir`` (recursively, sorted, ``/`` separated)."""
    root = Path(image_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"Expected an image folder at '{root}' (got no such folder)")
    names = sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                   if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS)
    if not names:
        raise FileNotFoundError(f"Expected images ({', '.join(IMAGE_EXTENSIONS)}) under "
                                f"'{root}' (got none)")
    return names


def _camera_of_posed(im: Any) -> Camera:
    model = getattr(im, "model", "PINHOLE") or "PINHOLE"
    K = np.asarray(im.K, dtype=np.float64)
    return Camera(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), im.size,
                  model if im.distortion else "PINHOLE", tuple(im.distortion))


def _cameras_of_database(path: Path) -> dict[str, Camera]:
    import pycolmap

    out = {}
    with pycolmap.Database.open(str(path)) as db:
        cams = {c.camera_id: c for c in db.read_all_cameras()}
        for im in db.read_all_images():
            c = cams[im.camera_id]
            out[im.name] = Camera.from_colmap(c.model.name, list(c.params),
                                              (int(c.height), int(c.width)),
                                              where=f"'{path}' camera {c.camera_id}")
    return out


def _cameras_of(source: str | os.PathLike) -> dict[str, Camera]:
    """Image name -> camera, from a COLMAP database file or a posed folder / file."""
    from strl_pyg.datasets.camera_files import read_posed_folder

    path = Path(source)
    if path.is_file() and path.suffix == ".db":
        return _cameras_of_database(path)
    folder = path.parent if path.is_file() else path
    images = read_posed_folder(folder)
    return {Path(im.path).name: _camera_of_posed(im) for im in images} | {
        os.path.relpath(im.path, folder / "images"): _camera_of_posed(im) for im in images}


def read_collection(image_dir: str | os.PathLike, names: list[str] | None = None,
                    K: Any = None, cameras: str | os.PathLike | None = None
                    ) -> list[CollectionImage]:
    """The images of a collection with their cameras.

    Args:
        image_dir: The image folder.
        names: The image names to take (default: every image under the folder).
        K: One ``[3, 3]`` pinhole ``K`` (pixels, OpenCV's convention) for every image.
        cameras: A COLMAP database (``.db``), or a folder (or a file in it) holding a COLMAP
            model, ``transforms.json`` or ``cameras.json`` (:func:`~strl_pyg.datasets.
            camera_files.read_posed_folder`); its images are matched by name.

    Raises:
        ValueError: both ``K`` and ``cameras``; an image the cameras do not list.
    """
    from strl_pyg.data.checks import check_K

    names = list_images(image_dir) if names is None else list(names)
    if K is not None and cameras is not None:
        raise ValueError(f"Expected one K or a cameras source (got both: K and '{cameras}')")
    by_name: dict[str, Camera] = {}
    if cameras is not None:
        by_name = _cameras_of(cameras)
    one = None if K is None else Camera.from_K(np.asarray(check_K(K, "K"), dtype=np.float64))
    out = []
    for name in names:
        path = Path(image_dir) / name
        if not path.is_file():
            raise FileNotFoundError(f"Expected the image '{name}' under '{image_dir}' (got no "
                                    "such file)")
        cam = one
        if cameras is not None:
            cam = by_name.get(name, by_name.get(Path(name).name))
            if cam is None:
                raise ValueError(f"Expected a camera for '{name}' in '{cameras}' (got "
                                 f"{len(by_name)} others)")
        out.append(CollectionImage(name, str(path), cam))
    return out


@lru_cache(maxsize=8)
def _read(path: str) -> np.ndarray:
    from strl_pyg.utils.images import read_image_file

    return read_image_file(path, grayscale=True)


def load_gray(image: CollectionImage) -> np.ndarray:
    """The image as grey uint8 ``[H, W]``, undistorted to its camera's pinhole ``K`` (same
    size) where the camera has lens distortion. The last 8 files read are kept in memory
    (consecutive pairs share images)."""
    gray = _read(image.path)
    cam = image.camera
    if cam is not None and cam.size is not None and tuple(cam.size) != gray.shape[:2]:
        raise ValueError(f"Expected '{image.name}' at its camera's size {cam.size[0]}x"
                         f"{cam.size[1]} (H x W) (got {gray.shape[0]}x{gray.shape[1]})")
    if cam is not None and cam.distorted:
        from strl_pyg.geometry.distortion import undistort_image

        gray = undistort_image(gray, cam.K, cam.opencv_distortion)
    return gray
