"""A scene run as a COLMAP database, for COLMAP's and GLOMAP's mappers (pycolmap).

:func:`write_database` writes, with ``pycolmap.Database``:

- **cameras**: one per distinct camera (model, parameters, size) in COLMAP's convention (the
  top-left pixel's corner at ``(0, 0)``: ``c_colmap = c + 0.5``), with its distortion terms;
  an image without a camera gets a ``SIMPLE_RADIAL`` guess (focal 1.2 x the longer side, as
  COLMAP's own extractor guesses without EXIF), which the mappers refine;
- **rigs and frames**: one single-camera rig per camera and one frame per image, as COLMAP's
  feature extractor writes them;
- **images** of the pairs (names relative to the image folder) and **keypoints**: the stored
  keypoints of every pass the image took part in (first pass, then the adaptive second), in
  the file's pixels (distorted back where the camera has distortion) and COLMAP's convention;
- **matches**: every point match of each pair;
- **two-view geometries**: for pairs whose recommended pose has a status in ``verified``, its
  inlier matches, ``cam2_from_cam1`` (our ``T_0to1``, unit translation), ``E``, ``F`` and the
  configuration (``general`` -> ``CALIBRATED``, ``planar`` -> ``PLANAR``, ``rotation`` ->
  ``PANORAMIC``; without intrinsics ``UNCALIBRATED``); other pairs ``DEGENERATE`` with no
  inliers, as COLMAP's verification writes a pair it rejects.

The file is written under a temporary name and renamed when complete.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from strl_pyg.collection.files import STATUS_TO_VERIFY, pair_key
from strl_pyg.collection.images import CollectionImage
from strl_pyg.collection.pairs import Pair
from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.features import POINTS, settings_key
from strl_pyg.frontend.pipeline import thorough_points
from strl_pyg.frontend.store import FeatureStore
from strl_pyg.geometry.camera import Camera

__all__ = ["write_database", "colmap_camera", "CONFIGURATIONS"]

#: Our two-view configurations -> COLMAP's ``TwoViewGeometryConfiguration`` names.
CONFIGURATIONS = {"general": "CALIBRATED", "planar": "PLANAR", "rotation": "PANORAMIC"}


def colmap_camera(camera: Camera | None, size: tuple[int, int]) -> tuple[str, list[float]]:
    """``(model, params)`` of a camera in COLMAP's convention (module docstring); ``size``
    ``(H, W)`` of the image."""
    if camera is None:
        f = 1.2 * max(size)
        return "SIMPLE_RADIAL", [f, size[1] / 2.0, size[0] / 2.0, 0.0]
    cx, cy = camera.cx + 0.5, camera.cy + 0.5
    d = list(camera.distortion)
    if not camera.distorted:
        return "PINHOLE", [camera.fx, camera.fy, cx, cy]
    if camera.model in ("SIMPLE_RADIAL", "RADIAL"):
        return camera.model, [camera.fx, cx, cy, *d]
    return "OPENCV", [camera.fx, camera.fy, cx, cy, *camera.opencv_distortion.tolist()]


def _keypoints(store: FeatureStore, image: CollectionImage, cfg: FrontendConfig
               ) -> tuple[np.ndarray, dict[str, int]]:
    """The image's keypoints for the database ``[K, 2]`` (float32, file pixels, COLMAP's
    convention) and the offset of each pass's keypoints in them, by settings key."""
    parts, offsets, n = [], {}, 0
    for c in [cfg, thorough_points(cfg)] if cfg.thorough_below > 0 else [cfg]:
        if store.has(POINTS, image.name, c):
            xy = store.points(image.name, c).keypoints
            offsets[settings_key(POINTS, c)] = n
            parts.append(xy)
            n += len(xy)
    xy = np.concatenate(parts) if parts else np.zeros((0, 2))
    cam = image.camera
    if cam is not None and cam.distorted and len(xy):
        from strl_pyg.geometry.distortion import distort_points

        xy = distort_points(xy, cam.K, cam.opencv_distortion)
    return (xy + 0.5).astype(np.float32), offsets


def _skew(t: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


def _geometry(rec: dict, inlier_matches: np.ndarray, K0: np.ndarray | None,
              K1: np.ndarray | None, verified: tuple[str, ...]):
    import pycolmap

    C = pycolmap.TwoViewGeometryConfiguration
    if rec.get("status") not in verified or rec.get("T_0to1") is None or not len(inlier_matches):
        return pycolmap.TwoViewGeometry(config=C.DEGENERATE)
    T = np.asarray(rec["T_0to1"], dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3] / max(np.linalg.norm(T[:3, 3]), 1e-12)
    E = _skew(t) @ R
    geo = pycolmap.TwoViewGeometry()
    if K0 is None or K1 is None:
        geo.config = C.UNCALIBRATED
    else:
        Kc0, Kc1 = K0.copy(), K1.copy()
        Kc0[:2, 2] += 0.5
        Kc1[:2, 2] += 0.5
        geo.config = getattr(C, CONFIGURATIONS.get(rec.get("configuration") or "general",
                                                   "CALIBRATED"))
        geo.F = np.linalg.inv(Kc1).T @ E @ np.linalg.inv(Kc0)
    geo.E = E
    geo.cam2_from_cam1 = pycolmap.Rigid3d(np.concatenate([R, t[:, None]], axis=1))
    geo.inlier_matches = inlier_matches.astype(np.uint32)
    return geo


def write_database(path: str | os.PathLike, images: list[CollectionImage], pairs: list[Pair],
                   records: dict[tuple[str, str], dict], store: FeatureStore,
                   matches_path: str | os.PathLike, cfg: FrontendConfig,
                   verified: tuple[str, ...] = STATUS_TO_VERIFY) -> Path:
    """Writes the COLMAP database of a scene run (module docstring) and returns its path.

    Args:
        path: The database file (replaced).
        images, pairs: The run's collection and pairs.
        records: The finished pairs' records by ``(image0, image1)`` names.
        store: The run's features; ``matches_path``: its ``matches.h5``.
        cfg: The run's front-end settings.
        verified: The statuses written as verified geometries.
    """
    import h5py
    import pycolmap

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    if tmp.exists():
        tmp.unlink()
    ids: dict[str, int] = {}
    offsets: dict[str, dict[str, int]] = {}
    cams: dict[tuple, int] = {}
    with pycolmap.Database.open(str(tmp)) as db, h5py.File(matches_path, "r") as mh5:
        used = {k for p in pairs for k in (p.i, p.j)}
        for im in (images[k] for k in sorted(used)):  # the images of the pairs
            xy, offsets[im.name] = _keypoints(store, im, cfg)
            size = _size(store, im, cfg)
            model, params = colmap_camera(im.camera, size)
            ckey = (model, tuple(np.round(params, 9)), size)
            if ckey not in cams:
                cam = pycolmap.Camera(model=model, width=size[1], height=size[0], params=params)
                cam.camera_id = db.write_camera(cam)
                rig = pycolmap.Rig()
                rig.add_ref_sensor(cam.sensor_id)
                rig_id = db.write_rig(rig)
                cams[ckey] = cam.camera_id
                cams[("rig", cam.camera_id)] = rig_id
            cam_id = cams[ckey]
            image = pycolmap.Image(name=im.name, camera_id=cam_id)
            image_id = db.write_image(image)
            frame = pycolmap.Frame()
            frame.rig_id = cams[("rig", cam_id)]
            frame.add_data_id(pycolmap.data_t(pycolmap.sensor_t(pycolmap.SensorType.CAMERA,
                                                                cam_id), image_id))
            db.write_frame(frame)
            db.write_keypoints(image_id, xy)
            ids[im.name] = image_id
        for p in pairs:
            a, b = images[p.i], images[p.j]
            rec = records.get((a.name, b.name))
            key = pair_key(a.name, b.name)
            if rec is None or "error" in rec or key not in mh5:
                continue
            g = mh5[key]
            pk = str(g.attrs["points_key"])
            m = np.asarray(g["matches"], dtype=np.int64).reshape(-1, 2)
            if not pk or not len(m):
                continue
            m = m + np.array([offsets[a.name][pk], offsets[b.name][pk]])
            inl = np.asarray(g["inliers"], dtype=bool)
            db.write_matches(ids[a.name], ids[b.name], m.astype(np.uint32))
            K0 = np.asarray(p.K0) if p.K0 is not None else (
                None if a.camera is None else a.camera.K)
            K1 = np.asarray(p.K1) if p.K1 is not None else (
                None if b.camera is None else b.camera.K)
            db.write_two_view_geometry(ids[a.name], ids[b.name],
                                       _geometry(rec, m[inl], K0, K1, verified))
    os.replace(tmp, path)
    return path


def _size(store: FeatureStore, image: CollectionImage, cfg: FrontendConfig) -> tuple[int, int]:
    """The image's ``(H, W)``: its camera's, else the stored features'."""
    if image.camera is not None and image.camera.size is not None:
        return (int(image.camera.size[0]), int(image.camera.size[1]))
    return store.image_size(image.name, cfg)
