"""Input readers of the ``strl-pose`` command line: images, intrinsics, the downscaling of
large pairs for matching (``--max-side``), and input-file checks. Every problem raises
:class:`UsageError` with a one-line ``Expected ... (got ...)`` message (printed by
:func:`strl_pyg.cli.main` with exit code 2). Imports only numpy at module level; OpenCV when an
image is read.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from strl_pyg.utils.commandline import UsageError

__all__ = ["MAX_SIDE", "read_image_file", "read_intrinsics", "downscale_for_matching",
           "PairInputs", "read_pair", "non_negative_int", "bootstrap_count", "DEMO_SEED",
           "load_model", "check_input_file", "intrinsics_from_args"]

#: Default longest image side for matching (``--max-side``); larger images are downscaled.
#: A 6000x4000 pair at full resolution took 5.6 GB and 48 s in `strl-pose match`; 0.5 GB and
#: 2.4 s at 1600 (2 CPU cores).
MAX_SIDE = 1600
#: ``--matcher``'s choices: the names of :data:`strl_pyg.frontend.config.PRESETS`, spelled
#: here so that building the parser imports neither OpenCV nor torch (a test holds them equal)
MATCHER_PRESETS = ("fast", "thorough", "adaptive", "legacy")


def read_image_file(path: str | os.PathLike) -> np.ndarray:
    """Reads an image file as uint8 ``(H, W)`` or ``(H, W, 3)`` RGB with the package's one
    reader (:func:`strl_pyg.utils.read_image_file`); its errors become :class:`UsageError`."""
    from strl_pyg.utils import images

    try:
        return images.read_image_file(path)
    except (OSError, ValueError) as err:
        raise UsageError(str(err)) from None


def _K_from_numbers(values: list[float], source: str) -> np.ndarray:
    if len(values) == 4:
        fx, fy, cx, cy = values
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    if len(values) == 9:
        return np.asarray(values, dtype=np.float64).reshape(3, 3)
    if len(values) == 12:  # a 3x4 projection matrix (KITTI P0)
        return np.asarray(values, dtype=np.float64).reshape(3, 4)[:, :3]
    raise UsageError(f"Expected 4 (fx,fy,cx,cy), 9 (3x3) or 12 (3x4) numbers for intrinsics in "
                     f"{source} (got {len(values)})")


def _colmap_camera(text: str, source: str):
    """The one camera of a COLMAP ``cameras.txt`` (``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``)
    as a :class:`~strl_pyg.geometry.Camera`, in this package's pixel convention: COLMAP puts
    the centre of the top-left pixel at (0.5, 0.5), OpenCV and this package at (0, 0), so
    ``c = c_colmap - 0.5``."""
    cams = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    distinct = {tuple(c[1:]) for c in cams}
    if len(distinct) != 1:
        raise UsageError(f"Expected one camera in the COLMAP cameras file {source} (got "
                         f"{len(distinct)}: give each image's with --K0 / --K1 as fx,fy,cx,cy)")
    from strl_pyg.geometry.camera import Camera

    try:
        return Camera.from_colmap(cams[0][1], cams[0][4:], where=source)
    except ValueError as err:
        raise UsageError(str(err)) from None


class _Lens(NamedTuple):
    """An image's camera as a flag gives it: ``K`` ``[3, 3]`` (pixels of the image as read),
    its COLMAP ``model`` and ``distortion`` terms (pinhole: ``"PINHOLE"``, ``()``) and where
    it was read (for messages)."""

    K: np.ndarray
    model: str = "PINHOLE"
    distortion: tuple[float, ...] = ()
    source: str = "the flag"

    @property
    def distorted(self) -> bool:
        return any(abs(d) > 1e-9 for d in self.distortion)


def read_intrinsics(text_or_path: str) -> np.ndarray:
    """Intrinsics from ``"fx,fy,cx,cy"``, nine comma-separated numbers, or a file holding a
    3x3 matrix (DeMoN ``cam.txt``), a 3x4 projection, KITTI ``calib.txt`` (``P0:`` row), a
    COLMAP ``cameras.txt`` (one camera) or a Strecha ``.camera`` file (K, then distortion,
    R, centre and size: the first nine numbers). A COLMAP camera's distortion is not applied
    here (a note says so; :func:`read_pair` undistorts the images it reads)."""
    lens = _read_lens(text_or_path)
    if lens.distorted:
        print(f"note: {lens.model} distortion parameters in {lens.source} are not applied: the "
              "matches must come from undistorted images", file=sys.stderr)
    return lens.K


def _read_lens(text_or_path: str) -> _Lens:
    """:func:`read_intrinsics` with a COLMAP camera's model and distortion terms."""
    path = Path(text_or_path)
    if path.is_dir():
        raise UsageError(f"Expected an intrinsics file or 'fx,fy,cx,cy' (got the folder "
                         f"'{path}')")
    if path.is_file():
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as err:
            raise UsageError(f"Expected a text intrinsics file at '{path}' (got "
                             f"{type(err).__name__})") from None
        first = next((ln.split() for ln in text.splitlines()
                      if ln.strip() and not ln.startswith("#")), [])
        if len(first) >= 5 and first[0].isdigit() and first[1].replace("_", "").isalpha():
            cam = _colmap_camera(text, f"'{path}'")
            return _Lens(_checked_K(cam.K), cam.model, cam.distortion, f"'{path}'")
        if path.suffix == ".camera":  # Strecha: K (3 rows), distortion, R, centre, W H
            nums = text.split()
            if len(nums) < 9:
                raise UsageError(f"Expected a Strecha .camera file starting with a 3x3 K in "
                                 f"'{path}' (got {len(nums)} numbers)")
            text = " ".join(nums[:9])
        rows = {ln.split(":", 1)[0].strip(): ln.split(":", 1)[1] for ln in text.splitlines()
                if ":" in ln}
        bare = [ln.split() for ln in text.splitlines() if ln.strip()]
        if not rows and len(bare) >= 2 and all(len(r) == 12 for r in bare):
            # KITTI's calib.txt without its 'P0:' labels: rows of 3x4 projections, P0 first
            text = " ".join(bare[0])
        body = rows.get("P0", rows.get("P2", text if not rows else None))
        if body is None:
            raise UsageError(f"Expected a 'P0:' row or bare numbers in '{path}' "
                             f"(got keys {sorted(rows)})")
        source = f"'{path}'"
    else:
        if not any(c.isdigit() for c in text_or_path) or os.sep in text_or_path:
            raise UsageError(f"Expected an intrinsics file or 'fx,fy,cx,cy' (got '{text_or_path}'"
                             ", which is neither an existing file nor numbers)")
        body, source = text_or_path.replace(",", " "), "the flag"
    try:
        values = [float(v) for v in body.split()]
    except ValueError as err:
        raise UsageError(f"Expected numbers for intrinsics in {source} (got {err})") from err
    if not all(np.isfinite(values)):
        raise UsageError(f"Expected finite numbers for intrinsics in {source} (got {values})")
    return _Lens(_checked_K(_K_from_numbers(values, source)), source=source)


def _checked_K(K: np.ndarray) -> np.ndarray:
    from strl_pyg.data.checks import check_K

    try:
        return check_K(K, "K")
    except ValueError as err:
        raise UsageError(str(err)) from err


def is_scene_cameras(text_or_path: str) -> bool:
    """Whether an intrinsics flag names a posed scene's cameras (a ``.json`` file: NeRF
    ``transforms.json`` or real_scenes ``cameras.json``; or a folder: a COLMAP model or a scene
    folder) rather than one K for every image."""
    path = Path(text_or_path)
    return path.is_dir() or (path.suffix.lower() == ".json" and path.is_file())


def _source_state(path: Path) -> tuple:
    """What identifies a cameras source's content within one process: the file's path, inode,
    size and change times; for a folder, those of each entry of it and of its ``sparse`` /
    ``sparse/0`` model (a subfolder such as ``images`` by its own times, which change with
    its listing)."""
    def one(p: Path) -> tuple:
        st = p.stat()
        return str(p.resolve()), st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns

    if not path.is_dir():
        return (one(path),)
    entries = [p for sub in (path, path / "sparse", path / "sparse" / "0") if sub.is_dir()
               for p in sorted(sub.iterdir())]
    return (one(path),) + tuple(one(p) for p in entries)


#: Cameras read from a source, by :func:`_source_state` and, for a NeRF file (read one frame
#: at a time), the frame's name: ``predict --pairs`` looks up two images a pair in one
#: scene's cameras.
_CAMERAS_READ: dict[tuple, tuple[list, list[str]]] = {}


def _scene_cameras(path: Path, name: str) -> tuple[list, list[str]]:
    """The posed images of a cameras source (with ``name``: a NeRF file reads that frame
    only) and the image names it lists, read once per source (and NeRF frame) and process."""
    state = _source_state(path)
    for key in ((state, None), (state, name)):
        if key in _CAMERAS_READ:
            return _CAMERAS_READ[key]
    images, listed, per_frame = _read_scene_cameras(path, name)
    if len(_CAMERAS_READ) >= 64:
        _CAMERAS_READ.clear()
    _CAMERAS_READ[(state, name if per_frame else None)] = images, listed
    return images, listed


def _read_scene_cameras(path: Path, name: str) -> tuple[list, list[str], bool]:
    """:func:`_scene_cameras` without the memo; and whether only the frame ``name`` was read
    (a NeRF file)."""
    import json

    from strl_pyg.datasets import camera_files as cf

    if path.is_dir():
        images = cf.read_posed_folder(path)
        return images, [Path(im.path).name for im in images], False
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise UsageError(f"Expected a JSON camera file at '{path}' (got {type(err).__name__}: "
                         f"{err})") from None
    if isinstance(data, dict) and "frames" in data:
        listed = [Path(str(fr.get("file_path", "?"))).name for fr in data["frames"]
                  if isinstance(fr, dict)]
        return cf.read_nerf_transforms(path, names={name}), listed, True
    if isinstance(data, dict) and "images" in data and path.name == "cameras.json":
        images = cf.read_real_scene(path.parent)
        return images, [Path(im.path).name for im in images], False
    got = sorted(data)[:8] if isinstance(data, dict) else type(data).__name__
    raise UsageError(f"Expected a NeRF transforms.json ('frames') or a real_scenes "
                     f"cameras.json ('images') at '{path}' (got {got} in '{path.name}')")


def scene_intrinsics(source: str, image: str | os.PathLike,
                     size: tuple[int, int] | None = None) -> np.ndarray:
    """The K of ``image`` in a posed scene's cameras (:func:`is_scene_cameras`; the formats
    of :mod:`strl_pyg.datasets.camera_files`, in their documented conventions): the camera
    whose image is this file, else the one camera whose image has this file name (two with
    the name are refused). With ``size`` ``(H, W)`` of the image as read, a K stored for
    another resolution of the same aspect is scaled to it (e.g. LLFF's ``images_4``).
    A camera with lens distortion is refused: K alone would not describe the image
    (:func:`read_pair` undistorts the images it reads instead)."""
    lens = _scene_lens(source, image, size)
    if lens.distorted:
        raise UsageError(f"Expected pinhole images in {lens.source} (got {lens.model} "
                         f"distortion {lens.distortion} for '{Path(image).name}'): undistort "
                         "them first, with strl_pyg.geometry.undistort_image or colmap "
                         "image_undistorter, or give strl-pose the images to undistort")
    return lens.K


def _scene_lens(source: str, image: str | os.PathLike, size: tuple[int, int] | None = None
                ) -> _Lens:
    """:func:`scene_intrinsics` with the camera's model and distortion terms (unchanged by
    the scaling: they act on normalised coordinates)."""
    path, image = Path(source), Path(image)
    try:
        images, listed = _scene_cameras(path, image.name)
    except (OSError, ValueError) as err:  # the readers' one-line errors
        raise UsageError(str(err)) from None
    same = [im for im in images if Path(im.path).resolve() == image.resolve()]
    found = same or [im for im in images if Path(im.path).name == image.name]
    if not found:
        seen = ", ".join(sorted(listed)[:5])
        raise UsageError(f"Expected the image '{image.name}' among the cameras of '{path}' "
                         f"(got {len(listed)} others: {seen}"
                         f"{', ...' if len(listed) > 5 else ''})")
    if len(found) > 1:
        raise UsageError(f"Expected one camera for '{image.name}' in '{path}' (got "
                         f"{len(found)}: {', '.join(im.path for im in found[:3])}); give the "
                         "image's path as the cameras list it")
    im = found[0]
    K = np.array(im.K, dtype=np.float64)
    if size is not None and tuple(size) != tuple(im.size):
        sy, sx = size[0] / im.size[0], size[1] / im.size[1]
        if abs(sx - sy) > 0.01 * max(sx, sy):
            raise UsageError(f"Expected '{image.name}' at the size its camera in '{path}' was "
                             f"stored for, or a scaled copy ({im.size[0]}x{im.size[1]} px, H x W) "
                             f"(got {size[0]}x{size[1]} px)")
        # pixel centres: x' + 0.5 = s (x + 0.5)
        K[0, 0], K[0, 2] = K[0, 0] * sx, (K[0, 2] + 0.5) * sx - 0.5
        K[1, 1], K[1, 2] = K[1, 1] * sy, (K[1, 2] + 0.5) * sy - 0.5
    return _Lens(K, im.model, tuple(im.distortion), f"'{path}'")


def intrinsics_from_args(args, sizes: tuple | None = None
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """K0 and K1 of ``--K`` / ``--K0`` / ``--K1``: one K each, or a posed scene's cameras
    (:func:`is_scene_cameras`) read for ``args.image0`` / ``args.image1``
    (:func:`scene_intrinsics`, ``sizes``: the images' ``(H, W)`` as read). For K alone: a
    scene camera with distortion is refused, a COLMAP file's is noted as not applied."""
    return _per_image(args, sizes, scene_intrinsics, read_intrinsics)


def _per_image(args, sizes: tuple | None, scene, single) -> tuple:
    """``(of image 0, of image 1)`` from ``--K`` / ``--K0`` / ``--K1``: ``scene(source, image,
    size)`` for a posed scene's cameras, ``single(value)`` for one camera; ``None`` where no
    flag gives one."""
    images = (getattr(args, "image0", None), getattr(args, "image1", None))

    def one(flag: str, value: str, k: int):
        if is_scene_cameras(value):
            if images[k] is None:
                raise UsageError(f"Expected images to look up in the cameras of {flag} "
                                 f"'{value}' (got none)")
            return scene(value, images[k], None if sizes is None else sizes[k])
        return single(value)

    if args.K:
        return one("--K", args.K, 0), one("--K", args.K, 1)
    first = one("--K0", args.K0, 0) if args.K0 else None
    second = one("--K1", args.K1, 1) if args.K1 else (
        one("--K0", args.K0, 1) if args.K0 and is_scene_cameras(args.K0) else first)
    return first, second


def _undistorted(image: np.ndarray, lens: _Lens | None, name: str
                 ) -> tuple[np.ndarray, np.ndarray | None]:
    """``(image, K)`` as a pinhole camera of ``K`` sees it: a distorted image undistorted
    (:func:`strl_pyg.geometry.undistort_image`, same K and size; one line on stderr); a model
    outside :data:`~strl_pyg.geometry.DISTORTION_MODELS` is refused."""
    if lens is None or not lens.distorted:
        return image, None if lens is None else lens.K
    from strl_pyg.geometry.distortion import (
        DISTORTION_MODELS,
        opencv_coefficients,
        undistort_image,
    )

    if lens.model not in DISTORTION_MODELS:
        raise UsageError(f"Expected a camera model among {', '.join(DISTORTION_MODELS)} to "
                         f"undistort '{Path(name).name}' in {lens.source} (got {lens.model} "
                         "distortion): undistort the images first, e.g. with colmap "
                         "image_undistorter")
    try:
        coeffs = opencv_coefficients(lens.model, lens.distortion)
        out = undistort_image(image, lens.K, coeffs)
    except ValueError as err:
        raise UsageError(f"{err} for '{Path(name).name}' in {lens.source}") from None
    terms = " ".join(f"{t}={v:g}" for t, v in zip(DISTORTION_MODELS[lens.model],
                                                   lens.distortion, strict=True))
    print(f"note: undistorted {Path(name).name} ({lens.model} {terms}) before matching",
          file=sys.stderr)
    return out, lens.K


def downscale_for_matching(image: np.ndarray, K: np.ndarray | None, max_side: int
                           ) -> tuple[np.ndarray, np.ndarray | None, tuple[float, float]]:
    """Shrinks ``image`` (area interpolation) so its longer side is at most ``max_side``
    pixels (``0``: unchanged) and scales ``K`` to match.

    With pixel centres at integer coordinates (OpenCV), a resize by ``(s_x, s_y)`` maps
    ``x' = (x + 0.5) s_x - 0.5``: ``fx' = s_x fx``, ``cx' = (cx + 0.5) s_x - 0.5`` (likewise
    y). Returns the image, ``K`` and the factors ``(s_x, s_y)`` (``(1, 1)`` when unchanged).
    """
    h, w = image.shape[:2]
    if max_side <= 0 or max(h, w) <= max_side:
        return image, K, (1.0, 1.0)
    import cv2

    s = max_side / max(h, w)
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    small = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA)
    sx, sy = nw / w, nh / h
    if K is not None:
        from strl_pyg.geometry.camera import scale_intrinsics

        K = scale_intrinsics(K, sx, sy)
    return small, K, (sx, sy)


class PairInputs(tuple):
    """``(image0, image1, K0, K1)`` as matched (downscaled to ``--max-side``), unpacking like
    a 4-tuple, with the originals: ``original`` (the same 4-tuple at full resolution) and
    ``scales`` (``((s_x, s_y)`` of image 0, of image 1)``)."""

    original: tuple
    scales: tuple[tuple[float, float], tuple[float, float]]

    @property
    def downscaled(self) -> bool:
        return self.scales != ((1.0, 1.0), (1.0, 1.0))

    @property
    def original_frame(self) -> dict | None:
        """The sizes and intrinsics the user gave (``estimate_images(..., original=)``) where
        the images were downscaled; ``None`` where they were not."""
        if not self.downscaled:
            return None
        o0, o1, K0, K1 = self.original
        return {"size0": tuple(np.shape(o0)[:2]), "size1": tuple(np.shape(o1)[:2]),
                "K0": K0, "K1": K1}

    def to_original_frame(self, matches):
        """``matches`` of the downscaled images expressed in the original pixel frame
        (coordinates ``x = (x' + 0.5) / s - 0.5``, original sizes, intrinsics and images)."""
        if not self.downscaled:
            return matches
        from strl_pyg.data.matches import PairMatches

        def back(xy: np.ndarray, s: tuple[float, float]) -> np.ndarray:
            return (np.asarray(xy, dtype=np.float64) + 0.5) / np.asarray(s) - 0.5

        imgs = []
        for small, full in ((matches.image0, self.original[0]), (matches.image1, self.original[1])):
            if small is not None and small.ndim == 2 and full.ndim == 3:
                import cv2

                full = cv2.cvtColor(full, cv2.COLOR_RGB2GRAY)
            imgs.append(None if small is None else full)
        (s0, s1), info = self.scales, dict(matches.info)
        info["downscaled_for_matching"] = {"scale0": list(s0), "scale1": list(s1)}
        return PairMatches(
            points0=back(matches.points0, s0), points1=back(matches.points1, s1),
            lines0=back(matches.lines0, s0), lines1=back(matches.lines1, s1),
            point_scores=matches.point_scores, line_scores=matches.line_scores,
            image_size0=self.original[0].shape[:2], image_size1=self.original[1].shape[:2],
            K0=self.original[2], K1=self.original[3], image0=imgs[0], image1=imgs[1],
            info=info)


def check_input_file(path: str | os.PathLike, what: str) -> None:
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"Expected a {what} at '{path}' (got a folder)")
    if not path.is_file():
        raise UsageError(f"Expected a {what} at '{path}' (got no such file)")


def read_pair(args) -> PairInputs:
    """Reads the pair's images and intrinsics, undistorts an image whose camera has lens
    distortion (a COLMAP model or NeRF ``k1, k2, p1, p2``: the pinhole image of the same K
    and size, :func:`_undistorted`) and downscales them to ``--max-side``."""
    img0, img1 = read_image_file(args.image0), read_image_file(args.image1)
    lens0, lens1 = _per_image(args, (img0.shape[:2], img1.shape[:2]), _scene_lens, _read_lens)
    img0, K0 = _undistorted(img0, lens0, args.image0)
    img1, K1 = _undistorted(img1, lens1, args.image1)
    max_side = getattr(args, "max_side", MAX_SIDE)
    small0, sK0, s0 = downscale_for_matching(img0, K0, max_side)
    small1, sK1, s1 = downscale_for_matching(img1, K1, max_side)
    inputs = PairInputs((small0, small1, sK0, sK1))
    inputs.original, inputs.scales = (img0, img1, K0, K1), (s0, s1)
    if inputs.downscaled:
        print(f"note: images downscaled for matching to at most {max_side} px "
              f"({img0.shape[0]}x{img0.shape[1]} -> {small0.shape[0]}x{small0.shape[1]} px, "
              "H x W); "
              "--max-side 0 keeps the full resolution", file=sys.stderr)
    return inputs


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0, one-line error otherwise."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"Expected an integer >= 0 (got {text!r})") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"Expected an integer >= 0 (got {text!r})")
    return value


def bootstrap_count(text: str) -> int:
    """argparse type of ``--bootstrap``: 0 (off) or an integer >= 3 (``MIN_BOOTSTRAP`` of
    :mod:`strl_pyg.estimation.uncertainty`, written out here so that parsing stays torch-free;
    a test keeps the two equal)."""
    value = non_negative_int(text)
    if value in (1, 2):
        raise argparse.ArgumentTypeError(f"Expected 0 or an integer >= 3 (got {text!r})")
    return value


#: The demo's pair: held out (training uses seeds < 2,000,000).
DEMO_SEED = 2_000_017


def load_model(path: str | os.PathLike | None):
    """The model of ``--checkpoint`` (default: the shipped weights), one-line errors."""
    from strl_pyg.model.strl_pose import StrLPose
    from strl_pyg.training.checkpoints import default_checkpoint

    path = Path(path) if path else default_checkpoint()
    if path.is_dir():
        raise UsageError(f"Expected a model checkpoint file at '{path}' (got a folder)")
    if not path.is_file():
        raise UsageError(f"Expected a model checkpoint at '{path}' (got no such file); train one "
                         "with 'strl-pose train' or pass --checkpoint")
    return StrLPose.load(path).eval()


def frontend_config(args):
    """The :class:`~strl_pyg.frontend.FrontendConfig` of ``--matcher`` and ``--detector``:
    the named preset, or the defaults where no ``--matcher`` is given."""
    from strl_pyg.frontend.config import FrontendConfig

    preset = getattr(args, "matcher", None)
    if preset:
        return FrontendConfig.preset(preset, detector=args.detector)
    return FrontendConfig(detector=args.detector)
