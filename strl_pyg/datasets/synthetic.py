"""Generated two-view scenes as pair graphs: a fixed-size map-style dataset (pair ``i`` is
generated from seed ``seed + i``) and an infinite stream.

Matches are the generator's ground-truth correspondences (computed on the fly, nothing
cached), or, with ``matches="frontend"``, front-end matches on the rendered images, computed
once per pair into the match cache like the real datasets.

``scene_config`` is one :class:`~strl_pyg.synthetic.SceneConfig` for every pair, or a
:class:`~strl_pyg.synthetic.SceneDistribution` (e.g. ``scene_distribution("mixed")``) that
draws each pair's config from its seed: kinds, image sizes and intrinsics then vary within one
dataset (graphs carry normalised coordinates, their own ``K`` and image size, so mixed sizes
collate into one batch). Pair ids are ``synthetic/<kind>/<seed>`` for a fixed config and
``synthetic/<distribution>/<kind>/<seed>`` for a distribution.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterator
from dataclasses import asdict, fields, replace
from typing import Any

import numpy as np
from torch.utils.data import IterableDataset, get_worker_info
from torch_geometric.data import HeteroData

from strl_pyg.data.build import build_pair_graph
from strl_pyg.data.keys import PAIR_ID, SUBSET
from strl_pyg.data.matches import PairMatches
from strl_pyg.datasets.base import (
    CachedPairDataset,
    _check_training_frontend,
    _config_dict,
)
from strl_pyg.datasets.cache import CacheBuildReport, cache_key

__all__ = ["SyntheticPairs", "InfiniteSyntheticPairs", "MATCH_SOURCES"]

MATCH_SOURCES = ("ground_truth", "frontend")


#: SceneConfig fields that existed before the motion / intrinsics / photometry knobs: the cache
#: fingerprint lists the others only when they differ from their defaults, so caches built
#: before those knobs existed stay valid.
_LEGACY_SCENE_FIELDS = frozenset((
    "kind", "image_size", "focal_factor", "noise_px", "outlier_fraction", "low_texture",
    "repetitive_texture", "max_points", "max_lines", "min_line_length", "texels_per_metre",
    "max_texture", "image_noise", "near",
))


def _scene_config(config: Any):
    from strl_pyg.synthetic import SceneConfig, SceneDistribution

    config = SceneConfig() if config is None else config
    if not isinstance(config, (SceneConfig, SceneDistribution)):
        raise TypeError(
            f"Expected a SceneConfig or a SceneDistribution (got {type(config).__name__})"
        )
    return config


def _config_for(scene_config: Any, seed: int):
    """The SceneConfig of pair ``seed``: the fixed one, or drawn from the distribution."""
    from strl_pyg.synthetic import SceneDistribution

    if isinstance(scene_config, SceneDistribution):
        return scene_config.config(seed)
    return scene_config


def _label(scene_config: Any, kind: str) -> str:
    from strl_pyg.synthetic import SceneDistribution

    if isinstance(scene_config, SceneDistribution):
        return f"{scene_config.name}/{kind}"
    return kind


def _scene_fingerprint(scene_config: Any) -> dict[str, Any]:
    from strl_pyg.synthetic import SceneDistribution

    if isinstance(scene_config, SceneDistribution):
        return {"distribution": asdict(scene_config)}
    defaults = {f.name: f.default for f in fields(scene_config)}
    return {
        k: v for k, v in asdict(scene_config).items()
        if k in _LEGACY_SCENE_FIELDS or v != defaults[k]
    }


def _check_seed(seed: Any) -> int:
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"Expected a non-negative integer seed (got {seed!r})")
    return int(seed)


def _graph(pair_matches: PairMatches, T_0to1: Any, seed: int, kind: str, patch_size: int,
           keep_images: bool) -> HeteroData:
    data = build_pair_graph(
        pair_matches, T_0to1=T_0to1, patch_size=patch_size, keep_images=keep_images
    )
    data[PAIR_ID] = f"synthetic/{kind}/{seed}"
    data[SUBSET] = f"synthetic/{kind}"
    return data


def _match_synthetic(seed: int, scene_config: Any, frontend_config: Any) -> PairMatches:
    """Worker job: front-end matches on the rendered images of pair ``seed``."""
    from strl_pyg.frontend import match_images
    from strl_pyg.synthetic import generate_pair

    pair = generate_pair(seed, _config_for(scene_config, seed))
    matches = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K, config=frontend_config)
    info = {**matches.info, "seed": seed, "T_0to1": np.asarray(pair.T_0to1).tolist(),
            "kind": pair.kind, "motion": pair.info["motion"]}
    return replace(matches, K0=pair.K, K1=pair.K, info=info)


class SyntheticPairs(CachedPairDataset):
    """``num_pairs`` generated pairs; pair ``i`` comes from seed ``seed + i``.

    Args:
        num_pairs: Size of the dataset.
        seed: First seed (default: ``0``).
        scene_config: A :class:`~strl_pyg.synthetic.SceneConfig` (default: its defaults) or a
            :class:`~strl_pyg.synthetic.SceneDistribution` (one config per seed).
        matches: ``"ground_truth"`` (default; generated on access, no cache) or
            ``"frontend"`` (front-end matches on the rendered images; needs ``cache_dir`` and
            :meth:`build_cache`).
        cache_dir: Root of the match cache (``"frontend"`` only).
        frontend_config: ``FrontendConfig`` of the front end (``"frontend"`` only).
        patch_size, keep_images: As :func:`~strl_pyg.data.build_pair_graph`.
        transform: Applied to each graph on access.
    """

    def __init__(
        self,
        num_pairs: int,
        *,
        seed: int = 0,
        scene_config: Any = None,
        matches: str = "ground_truth",
        cache_dir: str | os.PathLike | None = None,
        frontend_config: Any = None,
        patch_size: int = 1,
        keep_images: bool = False,
        transform: Callable | None = None,
    ) -> None:
        if not isinstance(num_pairs, (int, np.integer)) or num_pairs < 0:
            raise ValueError(f"Expected a non-negative integer num_pairs (got {num_pairs!r})")
        if matches not in MATCH_SOURCES:
            raise ValueError(f"Expected matches in {MATCH_SOURCES} (got {matches!r})")
        if matches == "frontend" and cache_dir is None:
            raise ValueError("Expected a cache_dir for matches='frontend' (got None)")
        self.num_pairs_total = int(num_pairs)
        self.seed = _check_seed(seed)
        self.scene_config = _scene_config(scene_config)
        self.matches = matches
        _check_training_frontend(frontend_config)
        self.frontend_config = frontend_config
        self.patch_size = patch_size
        self.keep_images = keep_images
        self.seeds = [self.seed + i for i in range(self.num_pairs_total)]
        keys = [cache_key(f"synthetic/{s}") for s in self.seeds]
        super().__init__(keys, cache_dir or ".", self._make_fingerprint, transform)

    def _make_fingerprint(self) -> dict[str, Any]:
        return {
            "kind": "synthetic",
            "scene": _scene_fingerprint(self.scene_config),
            "frontend": _config_dict(self.frontend_config),
        }

    def _match_fn(self) -> Callable[[Any], PairMatches]:
        return functools.partial(
            _match_synthetic, scene_config=self.scene_config, frontend_config=self.frontend_config
        )

    def _skip_errors(self) -> tuple[type[BaseException], ...]:
        from strl_pyg.synthetic.pair import SceneGenerationError

        # a seed whose scene cannot be generated is recorded as failed and left out, like a
        # real pair without matches
        return (*super()._skip_errors(), SceneGenerationError)

    def _payload(self, i: int) -> int:
        return self.seeds[i]

    def _graph(self, i: int, matches: PairMatches) -> HeteroData:
        T = np.asarray(matches.info["T_0to1"], dtype=np.float64)
        seed = self.seeds[i]
        kind = matches.info.get("kind") or _config_for(self.scene_config, seed).kind
        return _graph(matches, T, seed, _label(self.scene_config, kind), self.patch_size,
                      self.keep_images)

    def build_cache(self, num_workers: int = 0, **kwargs: Any) -> CacheBuildReport:
        if self.matches != "frontend":
            raise ValueError(
                "Expected matches='frontend' to build a cache (got 'ground_truth': generated "
                "on access)"
            )
        return super().build_cache(num_workers, **kwargs)

    def len(self) -> int:
        if self.matches == "ground_truth":
            return self.num_pairs_total
        return super().len()

    def get(self, idx: int) -> HeteroData:
        if self.matches == "frontend":
            return super().get(idx)
        from strl_pyg.synthetic import generate_pair

        seed = self.seeds[idx]
        pair = generate_pair(seed, _config_for(self.scene_config, seed))
        return _graph(pair.matches, pair.T_0to1, seed, _label(self.scene_config, pair.kind),
                      self.patch_size, self.keep_images)

    def __repr__(self) -> str:
        return (
            f"{self.__class__.__name__}({self.num_pairs_total}, seed={self.seed}, "
            f"{_describe(self.scene_config)}, matches={self.matches!r})"
        )


def _describe(scene_config: Any) -> str:
    name = getattr(scene_config, "name", None)
    return f"kind={scene_config.kind!r}" if name is None else f"distribution={name!r}"


class InfiniteSyntheticPairs(IterableDataset):
    """An endless stream of generated pair graphs with ground-truth matches.

    Seeds ``seed, seed + 1, ...``; with ``DataLoader`` workers, worker ``w`` of ``n`` takes
    the seeds ``seed + w, seed + w + n, ...``, so the stream is the same for any worker count
    up to order.

    Args:
        seed: First seed (default: ``0``).
        scene_config: A :class:`~strl_pyg.synthetic.SceneConfig` or a
            :class:`~strl_pyg.synthetic.SceneDistribution`.
        patch_size, keep_images: As :func:`~strl_pyg.data.build_pair_graph`.
        transform: Applied to each graph.
    """

    def __init__(
        self,
        *,
        seed: int = 0,
        scene_config: Any = None,
        patch_size: int = 1,
        keep_images: bool = False,
        transform: Callable | None = None,
    ) -> None:
        self.seed = _check_seed(seed)
        self.scene_config = _scene_config(scene_config)
        self.patch_size = patch_size
        self.keep_images = keep_images
        self.transform = transform

    def __iter__(self) -> Iterator[HeteroData]:
        from strl_pyg.synthetic import generate_pair

        info = get_worker_info()
        offset, stride = (0, 1) if info is None else (info.id, info.num_workers)
        seed = self.seed + offset
        while True:
            pair = generate_pair(seed, _config_for(self.scene_config, seed))
            data = _graph(pair.matches, pair.T_0to1, seed, _label(self.scene_config, pair.kind),
                          self.patch_size, self.keep_images)
            yield data if self.transform is None else self.transform(data)
            seed += stride

    def __repr__(self) -> str:
        return f"{self.__class__.__name__}(seed={self.seed}, {_describe(self.scene_config)})"

