"""Per-image features on disk: one HDF5 file per setting, hloc's layout.

A :class:`FeatureStore` is a folder holding one file per :func:`~strl_pyg.frontend.features.
settings_key`: ``points-<hash>.h5`` and ``lines-<hash>.h5``. Each file has one group per image
name (a name with ``/`` nests, as in hloc) and the setting's fields as JSON in its ``settings``
attribute. A points group holds hloc's datasets: ``keypoints [K, 2]`` (float64 pixels, OpenCV's
convention: the top-left pixel's centre at ``(0, 0)``, as hloc stores them), ``descriptors
[D, K]`` (transposed, as hloc) and ``image_size [2]`` (``W, H``, as hloc); a lines group holds
``lines [S, 2, 2]`` (pixels) and ``image_size``. A points file is therefore a features file
hloc's matchers read.

A group is complete once written: the file is flushed after each image, and a group that lacks
a dataset (the process was killed while writing it) is dropped when the store opens it again,
so a rerun computes that image again and nothing else. A file HDF5 cannot open at all is moved
aside to ``<file>.corrupt`` with a warning (one-line, naming it) and started afresh.

One process writes a store at a time; readers in other processes open it read-only while no
one writes (the scene runner's phases: :mod:`strl_pyg.collection.scene`).
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.features import (
    LINES,
    POINTS,
    PointFeatures,
    lines_settings,
    points_settings,
    settings_key,
)

__all__ = ["FeatureStore"]


class FeatureStore:
    """A folder of per-image features, one HDF5 file per setting (module docstring).

    Args:
        root: The folder (created when writable).
        writable: Open the files for appending (default) or read-only.

    ``computed`` counts the images this object wrote, per kind: what tests and the scene
    summary read to check that each image's features were computed once.
    """

    def __init__(self, root: str | os.PathLike, writable: bool = True) -> None:
        self.root = Path(root)
        self.writable = writable
        if writable:
            self.root.mkdir(parents=True, exist_ok=True)
        elif not self.root.is_dir():
            raise FileNotFoundError(f"Expected a feature store folder at '{self.root}' (got no "
                                    "such folder)")
        self._files: dict[str, Any] = {}
        self.computed = {POINTS: 0, LINES: 0}

    # -- files --------------------------------------------------------------------------
    def path(self, key: str) -> Path:
        return self.root / f"{key}.h5"

    def _file(self, kind: str, cfg: FrontendConfig, create: bool):
        import h5py

        key = settings_key(kind, cfg)
        if key in self._files:
            return self._files[key]
        path = self.path(key)
        if not path.exists() and not (create and self.writable):
            return None
        try:
            f = h5py.File(path, "a" if self.writable else "r")
        except OSError as err:
            if not self.writable:
                raise ValueError(f"Expected an HDF5 feature file at '{path}' (got {err})") \
                    from None
            aside = path.with_suffix(".h5.corrupt")
            warnings.warn(f"Expected an HDF5 feature file at '{path}' (got {err}); moved to "
                          f"'{aside}', its images' features are computed again", stacklevel=3)
            os.replace(path, aside)
            f = h5py.File(path, "a")
        if self.writable:
            settings = points_settings(cfg) if kind == POINTS else lines_settings(cfg)
            f.attrs["settings"] = json.dumps({"kind": kind, **settings}, sort_keys=True)
            _drop_incomplete(f, kind)
        self._files[key] = f
        return f

    def close(self) -> None:
        for f in self._files.values():
            f.close()
        self._files.clear()

    def __enter__(self) -> FeatureStore:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- reading ------------------------------------------------------------------------
    def has(self, kind: str, name: str, cfg: FrontendConfig) -> bool:
        """Whether the image's features of this kind and setting are stored."""
        f = self._file(kind, cfg, create=False)
        return f is not None and name in f and _complete(f[name], kind)

    def names(self, kind: str, cfg: FrontendConfig) -> list[str]:
        """The images whose features of this kind and setting are stored."""
        f = self._file(kind, cfg, create=False)
        if f is None:
            return []
        out: list[str] = []
        f.visititems(lambda n, obj: out.append(n) if _complete(obj, kind) else None)
        return out

    def points(self, name: str, cfg: FrontendConfig) -> PointFeatures:
        """The stored keypoints and descriptors of ``name`` (``KeyError`` when absent)."""
        g = self._group(POINTS, name, cfg)
        desc = np.asarray(g["descriptors"]).T
        return PointFeatures(np.asarray(g["keypoints"], dtype=np.float64),
                             desc if desc.size or len(g["keypoints"]) else None)

    def lines(self, name: str, cfg: FrontendConfig) -> np.ndarray:
        """The stored segments ``[S, 2, 2]`` of ``name`` (``KeyError`` when absent)."""
        return np.asarray(self._group(LINES, name, cfg)["lines"], dtype=np.float64)

    def _group(self, kind: str, name: str, cfg: FrontendConfig):
        f = self._file(kind, cfg, create=False)
        if f is None or name not in f or not _complete(f[name], kind):
            raise KeyError(f"Expected {kind} features {settings_key(kind, cfg)} of '{name}' in "
                           f"'{self.root}' (got none)")
        return f[name]

    def image_size(self, name: str, cfg: FrontendConfig) -> tuple[int, int]:
        """The ``(H, W)`` of the image whose point features of ``cfg`` are stored (``KeyError``
        when absent)."""
        w, h = (int(v) for v in self._group(POINTS, name, cfg)["image_size"])
        return h, w

    def arrays(self, name: str, configs: list[FrontendConfig]) -> dict[str, Any]:
        """Every stored feature of ``name`` among the settings of ``configs``, by
        :func:`settings_key`: what :class:`~strl_pyg.frontend.features.Precomputed` takes."""
        out: dict[str, Any] = {}
        for cfg in configs:
            for kind in (POINTS, LINES) if cfg.lines else (POINTS,):
                key = settings_key(kind, cfg)
                if key not in out and self.has(kind, name, cfg):
                    out[key] = (self.points(name, cfg) if kind == POINTS
                                else self.lines(name, cfg))
        return out

    # -- writing ------------------------------------------------------------------------
    def put(self, kind: str, name: str, cfg: FrontendConfig, value: Any,
            image_size: tuple[int, int]) -> None:
        """Stores one image's features (:class:`PointFeatures` or segments ``[S, 2, 2]``)
        of an image of ``image_size`` ``(H, W)``, replacing what was there; flushed."""
        if not self.writable:
            raise ValueError(f"Expected a writable feature store (got '{self.root}' opened "
                             "read-only)")
        f = self._file(kind, cfg, create=True)
        if name in f:
            del f[name]
        g = f.create_group(name)
        g.create_dataset("image_size", data=np.array([image_size[1], image_size[0]]))
        if kind == POINTS:
            g.create_dataset("keypoints", data=np.asarray(value.keypoints, np.float64))
            desc = value.descriptors
            if desc is None:
                desc = np.zeros((0, 128), np.float32)
            g.create_dataset("descriptors", data=np.ascontiguousarray(np.asarray(desc).T))
        else:
            g.create_dataset("lines", data=np.asarray(value, np.float64).reshape(-1, 2, 2))
        f.flush()
        self.computed[kind] += 1


_NEEDS = {POINTS: ("image_size", "keypoints", "descriptors"), LINES: ("image_size", "lines")}


def _complete(obj: Any, kind: str) -> bool:
    import h5py

    return isinstance(obj, h5py.Group) and all(k in obj for k in _NEEDS[kind])


def _drop_incomplete(f: Any, kind: str) -> None:
    """Deletes the groups a killed writer left without all their datasets."""
    import h5py

    partial: list[str] = []

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Group) and any(isinstance(v, h5py.Dataset)
                                               for v in obj.values()) \
                and not _complete(obj, kind):
            partial.append(name)

    f.visititems(visit)
    for name in partial:
        del f[name]
    if partial:
        f.flush()
