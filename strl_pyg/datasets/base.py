"""Common base of the pair datasets: pair records, image reading and resizing, and a PyG
``Dataset`` whose items are pair graphs built from cached matches.

Conventions: images are ``(H, W)`` grey or ``(H, W, 3)`` RGB uint8; intrinsics ``K`` are
``[3, 3]`` in pixels of the image they belong to, with OpenCV's pixel centres (the top-left
pixel's centre is ``(0, 0)``); ``T_0to1`` ``[4, 4]`` maps camera-0 points into camera 1,
``X1 = R X0 + t``.
"""

from __future__ import annotations

import functools
import os
import warnings
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, is_dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from torch_geometric.data import Dataset, HeteroData

from strl_pyg.data.build import build_pair_graph
from strl_pyg.data.keys import PAIR_ID, SUBSET
from strl_pyg.data.matches import PairMatches
from strl_pyg.datasets.cache import (
    CacheBuildReport,
    MatchCache,
    cache_key,
)
from strl_pyg.utils.images import decode_image

__all__ = ["ImageSource", "PairRecord", "CachedPairDataset", "PairDataset", "read_image",
           "resize_image", "scale_intrinsics", "load_pair_images"]

# Graph-level string attributes (collate to lists in a batch), for per-subset evaluation.

ON_MISSING = ("error", "skip")


@dataclass(frozen=True)
class ImageSource:
    """Where one image lives: a file (``key`` is ``None``) or, in an HDF5 file, the view
    group ``key`` whose dataset ``image`` holds the encoded bytes (DeMoN layout)."""

    path: str
    key: str | None = None

    def __str__(self) -> str:
        return self.path if self.key is None else f"{self.path}:{self.key}"


@dataclass(frozen=True, eq=False)
class PairRecord:
    """One image pair of a dataset.

    Args:
        pair_id: Unique id within the dataset, e.g. ``"kitti/06/000000-000001"``.
        subset: Name for per-subset evaluation, e.g. ``"MVS"`` or ``"KITTI/06"``.
        source0, source1: The two images.
        K0, K1: Intrinsics ``[3, 3]`` in pixels of the **original** images.
        T_0to1: Ground-truth pose ``[4, 4]``, camera 0 to camera 1.
    """

    pair_id: str
    subset: str
    source0: ImageSource
    source1: ImageSource
    K0: np.ndarray
    K1: np.ndarray
    T_0to1: np.ndarray


def read_image(source: ImageSource | str | os.PathLike, grayscale: bool = False) -> np.ndarray:
    """Reads an image as uint8 ``(H, W)`` (grey files, or ``grayscale``) or ``(H, W, 3)`` RGB,
    from a file or an HDF5 group, with the package's one decoder
    (:func:`strl_pyg.utils.images.decode_image`: 16-bit scaled to 8, alpha dropped).

    Missing files, missing HDF5 groups and undecodable data raise errors naming the file.
    """
    if not isinstance(source, ImageSource):
        source = ImageSource(str(source))
    path = Path(source.path)
    if not path.is_file():
        raise FileNotFoundError(f"Expected an image file at '{path}' (got no such file)")
    if source.key is None:
        return decode_image(np.fromfile(path, dtype=np.uint8), str(path), grayscale)
    return decode_image(_read_h5_bytes(path, source.key), str(source), grayscale)


def _read_h5_bytes(path: Path, key: str) -> np.ndarray:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if key not in f or "image" not in f[key]:
                raise KeyError(f"Expected dataset '{key}/image' in '{path}' (got none)")
            return np.frombuffer(f[key]["image"][()].tobytes(), dtype=np.uint8)
    except OSError as err:
        raise ValueError(f"Expected a readable HDF5 file at '{path}' (got {err})") from err


def scale_intrinsics(K: np.ndarray, old_size: tuple[int, int], new_size: tuple[int, int]):
    """Intrinsics of an image resized from ``old_size`` to ``new_size`` (both ``(H, W)``):
    :func:`strl_pyg.geometry.scale_intrinsics` with the sizes' ratios."""
    from strl_pyg.geometry.camera import scale_intrinsics as scale

    return scale(K, new_size[1] / old_size[1], new_size[0] / old_size[0])


def resize_image(image: np.ndarray, size: tuple[int, int] | None) -> np.ndarray:
    """Resizes to ``size`` ``(H, W)`` (area interpolation when shrinking); ``None`` keeps it."""
    if size is None or tuple(image.shape[:2]) == tuple(size):
        return image
    h, w = image.shape[:2]
    interp = cv2.INTER_AREA if size[0] <= h and size[1] <= w else cv2.INTER_LINEAR
    return cv2.resize(image, (int(size[1]), int(size[0])), interpolation=interp)


def load_pair_images(
    record: PairRecord, image_size: tuple[int, int] | None = None, grayscale: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reads, resizes and returns ``(image0, image1, K0, K1)``, K scaled to the new size."""
    out = []
    for src in (record.source0, record.source1):
        img = read_image(src, grayscale)
        out.append((resize_image(img, image_size), img.shape[:2]))
    (img0, size0), (img1, size1) = out
    K0 = record.K0 if image_size is None else scale_intrinsics(record.K0, size0, image_size)
    K1 = record.K1 if image_size is None else scale_intrinsics(record.K1, size1, image_size)
    return img0, img1, K0, K1


def _check_training_frontend(config: Any) -> None:
    """Refuses a front end whose lines' endpoints do not correspond (the descriptor matcher):
    the model reads endpoint ``k`` of a line as matching endpoint ``k``."""
    matcher = getattr(config, "line_matcher", "epipolar")
    if matcher != "epipolar":
        raise ValueError(
            f"Expected a FrontendConfig with line_matcher='epipolar' for a dataset (got "
            f"{matcher!r}): the model reads line endpoint k as matching endpoint k, which only "
            "the epipolar matcher's clipped segments satisfy")


def _config_dict(config: Any) -> Any:
    if config is None:
        from strl_pyg.frontend import FrontendConfig

        config = FrontendConfig()
    if hasattr(config, "result_fields"):  # a FrontendConfig: its speed settings aside
        return {"type": type(config).__name__, **config.result_fields()}
    if is_dataclass(config):
        return {"type": type(config).__name__, **asdict(config)}
    if isinstance(config, dict):
        return config
    raise TypeError(f"Expected a FrontendConfig dataclass or a dict (got {type(config).__name__})")


#: Images whose features a process keeps (:func:`image_features`): posed pairs (i, i + k)
#: for gaps up to 16 revisit an image within about this many pairs.
FEATURE_CACHE_IMAGES = 48
_FEATURES: OrderedDict[tuple, Any] = OrderedDict()


def image_features(source: ImageSource, image: np.ndarray, image_size: Any,
                   grayscale: bool) -> Any:
    """The front end's feature source of one image as the cache builder read it
    (:class:`~strl_pyg.frontend.features.Detect`: keypoints, descriptors and segments detected
    once per setting): an image in several pairs is detected once per process while it stays
    among the last :data:`FEATURE_CACHE_IMAGES` read."""
    from strl_pyg.frontend.features import Detect
    from strl_pyg.frontend.pipeline import check_frontend_image

    key = (str(source), None if image_size is None else tuple(image_size), bool(grayscale),
           image.shape)
    if key in _FEATURES:
        _FEATURES.move_to_end(key)
        return _FEATURES[key]
    det = Detect(check_frontend_image(image, str(source)), str(source))
    _FEATURES[key] = det
    while len(_FEATURES) > FEATURE_CACHE_IMAGES:
        _FEATURES.popitem(last=False)
    return det


def _match_record(
    record: PairRecord, image_size: tuple[int, int] | None, grayscale: bool, config: Any
) -> PairMatches:
    """Worker job: front-end matches of one pair, with K and the images as read and resized
    (colour unless ``grayscale``; the front end attaches the grey copies it matched on, which
    gave 1-channel patches for colour data such as DeMoN). Each image's features come from
    :func:`image_features` (the same matches as detecting them per pair)."""
    from strl_pyg.frontend import match_images

    img0, img1, K0, K1 = load_pair_images(record, image_size, grayscale)
    features = (image_features(record.source0, img0, image_size, grayscale),
                image_features(record.source1, img1, image_size, grayscale))
    matches = match_images(img0, img1, K0=K0, K1=K1, config=config, features=features)
    info = {**matches.info, PAIR_ID: record.pair_id, SUBSET: record.subset}
    return replace(matches, K0=K0, K1=K1, info=info, image0=img0, image1=img1)


def _no_match_errors() -> tuple[type[BaseException], ...]:
    from strl_pyg.frontend import NoMatchesError

    return (NoMatchesError,)


def check_on_missing(on_missing: str) -> str:
    if on_missing not in ON_MISSING:
        raise ValueError(f"Expected on_missing in {ON_MISSING} (got {on_missing!r})")
    return on_missing


class CachedPairDataset(Dataset):
    """A PyG dataset of pair graphs whose matches are computed once into a
    :class:`MatchCache`.

    Subclasses give the pair keys, a picklable match function with its payloads, and how to
    turn cached matches into a graph. Pairs recorded as failed (no matches), and those with
    fewer than ``min_points`` / ``min_lines`` matches, are left out of the index, with a
    warning giving their count.
    """

    def __init__(
        self,
        keys: Sequence[str],
        cache_dir: str | os.PathLike,
        fingerprint: Callable[[], dict[str, Any]],
        transform: Callable | None = None,
        root: str | os.PathLike | None = None,
        min_points: int = 0,
        min_lines: int = 0,
    ) -> None:
        for name, value in (("min_points", min_points), ("min_lines", min_lines)):
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"Expected {name} as an integer >= 0 (got {value!r})")
        self.min_points, self.min_lines = min_points, min_lines
        self._keys = list(keys)
        if len(set(self._keys)) != len(self._keys):
            raise ValueError("Expected unique pair ids (got duplicates)")
        self._cache_dir = Path(cache_dir)
        self._fingerprint = fingerprint
        self._cache: MatchCache | None = None
        super().__init__(root=None if root is None else str(root), transform=transform, log=False)
        self._index: list[int] | None = None

    # -- to be provided by subclasses
    def _match_fn(self) -> Callable[[Any], PairMatches]:
        raise NotImplementedError

    def _payload(self, i: int) -> Any:
        raise NotImplementedError

    def _graph(self, i: int, matches: PairMatches) -> HeteroData:
        raise NotImplementedError

    def _skip_errors(self) -> tuple[type[BaseException], ...]:
        return _no_match_errors()

    # -- cache
    @property
    def cache(self) -> MatchCache:
        """The match cache (its folder name hashes the front-end config and image size)."""
        if self._cache is None:
            self._cache = MatchCache(self._cache_dir, self._fingerprint())
        return self._cache

    @property
    def num_pairs(self) -> int:
        """All pairs, failed ones included."""
        return len(self._keys)

    def pair_key(self, i: int) -> str:
        """Cache key of pair ``i`` (over all pairs, failed included)."""
        return self._keys[i]

    def failed_pairs(self) -> list[str]:
        """Keys of the pairs recorded as giving no matches."""
        return [k for k in self._keys if self.cache.is_failed(k)]

    def _refresh_index(self) -> None:
        failed = set(self.failed_pairs())
        self._index = [i for i, k in enumerate(self._keys) if k not in failed]
        if failed:
            warnings.warn(
                f"{len(failed)} of {len(self._keys)} pairs gave no matches and are skipped "
                f"(markers in '{self.cache.dir}')",
                stacklevel=3,
            )
        if self.min_points or self.min_lines:
            counts = self.cache.counts([self._keys[i] for i in self._index])
            few = [i for i in self._index if self._keys[i] in counts
                   and (counts[self._keys[i]][0] < self.min_points
                        or counts[self._keys[i]][1] < self.min_lines)]
            if few:
                dropped = set(few)
                self._index = [i for i in self._index if i not in dropped]
                warnings.warn(
                    f"{len(few)} of {len(self._keys)} pairs have fewer than "
                    f"min_points={self.min_points} point or min_lines={self.min_lines} line "
                    "matches and are skipped",
                    stacklevel=3,
                )

    def build_cache(
        self,
        num_workers: int = 0,
        *,
        max_pairs: int | None = None,
        verify: bool = True,
        progress: bool = True,
        mp_context: str | None = "spawn",
    ) -> CacheBuildReport:
        """Matches every pair not yet cached (see :meth:`MatchCache.build` for the
        arguments); resumable, and safe to interrupt. Refreshes the index afterwards."""
        report = self.cache.build(
            self._keys,
            [self._payload(i) for i in range(len(self._keys))],
            self._match_fn(),
            num_workers=num_workers,
            skip_errors=self._skip_errors(),
            max_pairs=max_pairs,
            verify=verify,
            progress=progress,
            mp_context=mp_context,
            desc=type(self).__name__,
        )
        self._refresh_index()
        return report

    prepare = build_cache

    def load_matches(self, idx: int) -> PairMatches:
        """Cached matches of item ``idx``; errors name the missing or corrupt file."""
        return self.cache.load(self._keys[self._indices_all()[idx]])

    def _indices_all(self) -> list[int]:
        if self._index is None:
            self._refresh_index()
        return self._index

    # -- PyG Dataset
    def len(self) -> int:
        return len(self._indices_all())

    def get(self, idx: int) -> HeteroData:
        i = self._indices_all()[idx]
        return self._graph(i, self.cache.load(self._keys[i]))


class PairDataset(CachedPairDataset):
    """Pair graphs of real image pairs given as :class:`PairRecord` s.

    Matching runs on the images resized to ``image_size`` (K scaled to match) with
    :func:`strl_pyg.frontend.match_images`; graph items carry ``T_0to1``, ``pair_id`` and
    ``subset``.

    Args:
        records: The pairs.
        cache_dir: Root of the match cache.
        image_size: ``(H, W)`` the images are resized to before matching (``None``: keep).
        grayscale: Read colour images as grey (matching is always on grey; this decides the
            images kept with the matches, hence the channels of the graphs' patches).
        frontend_config: A ``FrontendConfig`` (default: its defaults); part of the cache key.
        patch_size: Odd patch side of the visual features (default: ``1``).
        keep_images: Store the images in each graph (:func:`build_pair_graph`).
        transform: Applied to each graph on access, e.g. ``FixedSizeResample``.
        limit: Keep only the first ``limit`` pairs (smoke runs, tests).
        kind: Dataset kind, part of the cache fingerprint.
        root: The data folder (PyG's ``root``, stored as a string).
        min_points, min_lines: Leave out the pairs with fewer cached point / line matches
            (counted once per entry from its match arrays, :meth:`MatchCache.counts`; a
            warning gives how many); not part of the cache key.
    """

    def __init__(
        self,
        records: Sequence[PairRecord],
        *,
        cache_dir: str | os.PathLike,
        image_size: tuple[int, int] | None = None,
        grayscale: bool = False,
        frontend_config: Any = None,
        patch_size: int = 1,
        keep_images: bool = False,
        transform: Callable | None = None,
        limit: int | None = None,
        kind: str = "pairs",
        root: str | os.PathLike | None = None,
        min_points: int = 0,
        min_lines: int = 0,
    ) -> None:
        if image_size is not None:
            if len(image_size) != 2 or any(int(s) != s or s <= 0 for s in image_size):
                raise ValueError(
                    f"Expected image_size as (H, W) positive integers (got {image_size!r})"
                )
            image_size = (int(image_size[0]), int(image_size[1]))
        if not isinstance(patch_size, int) or patch_size < 1 or patch_size % 2 == 0:
            raise ValueError(f"Expected an odd positive integer patch_size (got {patch_size!r})")
        if limit is not None and (not isinstance(limit, int) or limit < 0):
            raise ValueError(f"Expected limit >= 0 or None (got {limit!r})")
        self.records = list(records)[:limit]
        self.image_size = image_size
        self.grayscale = grayscale
        _check_training_frontend(frontend_config)
        self.frontend_config = frontend_config
        self.patch_size = patch_size
        self.keep_images = keep_images
        self.kind = kind
        super().__init__(
            [cache_key(r.pair_id) for r in self.records], cache_dir, self._make_fingerprint,
            transform, root, min_points=min_points, min_lines=min_lines,
        )

    def _make_fingerprint(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "image_size": self.image_size,
            "grayscale": self.grayscale,
            # caches written before the images were kept as read hold grey copies
            "images": "as_read",
            "frontend": _config_dict(self.frontend_config),
        }

    def _match_fn(self) -> Callable[[Any], PairMatches]:
        return functools.partial(
            _match_record, image_size=self.image_size, grayscale=self.grayscale,
            config=self.frontend_config,
        )

    def _payload(self, i: int) -> PairRecord:
        return self.records[i]

    def _graph(self, i: int, matches: PairMatches) -> HeteroData:
        rec = self.records[i]
        data = build_pair_graph(
            matches, T_0to1=rec.T_0to1, patch_size=self.patch_size, keep_images=self.keep_images
        )
        data[PAIR_ID] = rec.pair_id
        data[SUBSET] = rec.subset
        return data

    def record(self, idx: int) -> PairRecord:
        """The :class:`PairRecord` of item ``idx``."""
        return self.records[self._indices_all()[idx]]

    def subsets(self) -> list[str]:
        """Subset names in order of first appearance."""
        return list(dict.fromkeys(r.subset for r in self.records))

    def __repr__(self) -> str:
        return (
            f"{self.__class__.__name__}({len(self.records)} pairs, "
            f"subsets={self.subsets()}, image_size={self.image_size})"
        )
