"""Evaluation pairs: matches with their ground-truth relative pose, from held-out generated
scenes, a DeMoN DeepSfM folder or KITTI odometry sequences.

An :class:`EvalPair` holds one pair's :class:`~strl_pyg.data.PairMatches` (with ``K0``,
``K1``), its ground truth ``T_0to1`` (``X1 = R X0 + t``), the subset it is grouped under in
the tables, a unique id and, for KITTI, the frame indices that chain pairs into trajectories.
:func:`strl_pyg.evaluation.run.evaluate_pairs` runs the methods on them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from strl_pyg.data.matches import PairMatches
from strl_pyg.synthetic.config import LINE_SCENE_KINDS

__all__ = ["EvalPair", "synthetic_eval_pairs", "demon_eval_pairs", "kitti_eval_pairs",
           "posed_eval_pairs"]


@dataclass
class EvalPair:
    """One pair to evaluate.

    Args:
        matches: :class:`~strl_pyg.data.PairMatches` with ``K0``, ``K1`` (pixels).
        T_0to1: ground truth ``[4, 4]``, camera 0 to camera 1.
        subset: name to group results by (e.g. ``"MVS"``, ``"KITTI/06"``).
        pair_id: unique id.
        frames: ``(i, j)`` frame indices within the subset's sequence, for trajectories.
    """

    matches: PairMatches
    T_0to1: np.ndarray
    subset: str
    pair_id: str
    frames: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.matches, PairMatches):
            raise TypeError(f"Expected a PairMatches (got {type(self.matches).__name__})")
        if not self.matches.has_intrinsics:
            raise ValueError(f"Expected intrinsics in the matches of '{self.pair_id}' (got none)")
        T = np.asarray(self.T_0to1, dtype=np.float64)
        if T.shape == (3, 4):
            T = np.vstack([T, [0.0, 0.0, 0.0, 1.0]])
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise ValueError(f"Expected a finite T_0to1 of shape (4, 4) (got {T.shape})")
        self.T_0to1 = T


def synthetic_eval_pairs(
    num_pairs: int,
    seed: int = 2_000_000,
    kinds: Sequence[str] = LINE_SCENE_KINDS,
    matches: str = "ground_truth",
    scene: dict[str, Any] | None = None,
    frontend_config: Any = None,
    progress: bool = False,
) -> list[EvalPair]:
    """Held-out generated pairs (training uses seeds below 2,000,000): pair ``i`` is kind
    ``kinds[i % len(kinds)]`` from seed ``seed + i``.

    Args:
        matches: ``"ground_truth"`` (the generator's matches, after ``scene``'s noise and
            outliers) or ``"frontend"`` (:func:`~strl_pyg.frontend.match_images` on the
            rendered images).
        scene: other :class:`~strl_pyg.synthetic.SceneConfig` fields, e.g.
            ``{"noise_px": 1.0, "outlier_fraction": 0.3}``.
    """
    from strl_pyg.synthetic import SceneConfig, generate_pair

    if matches not in ("ground_truth", "frontend"):
        raise ValueError(f"Expected matches in ('ground_truth', 'frontend') (got {matches!r})")
    if not isinstance(num_pairs, int) or num_pairs < 1:
        raise ValueError(f"Expected a positive integer num_pairs (got {num_pairs!r})")
    if not kinds:
        raise ValueError("Expected at least one scene kind (got none)")
    out = []
    for i in tqdm(range(num_pairs), desc="generate", disable=not progress, leave=False):
        kind = kinds[i % len(kinds)]
        pair = generate_pair(seed + i, SceneConfig(**{**(scene or {}), "kind": kind}))
        m = pair.matches
        if matches == "frontend":
            from strl_pyg.frontend import match_images

            m = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                             config=frontend_config)
            m = replace(m, K0=pair.K, K1=pair.K)
        out.append(EvalPair(m, pair.T_0to1, f"synthetic/{kind}", f"synthetic/{kind}/{seed + i}"))
    return out


def _dataset_pairs(ds: Any, num_workers: int, progress: bool,
                   frames: bool = False) -> list[EvalPair]:
    ds.build_cache(num_workers=num_workers, progress=progress)
    out = []
    for i in range(len(ds)):
        rec = ds.record(i)
        fr = None
        if frames:
            a, b = rec.pair_id.rsplit("/", 1)[-1].split("-")
            fr = (int(a), int(b))
        out.append(EvalPair(ds.load_matches(i), rec.T_0to1, rec.subset, rec.pair_id, fr))
    return out


def demon_eval_pairs(root: str | os.PathLike, cache_dir: str | os.PathLike, split: str = "test",
                     limit: int | None = None, num_workers: int = 0, progress: bool = False,
                     **kwargs: Any) -> list[EvalPair]:
    """DeMoN pairs of a DeepSfM folder root (front-end matches, cached in ``cache_dir``);
    ``kwargs`` go to :class:`~strl_pyg.datasets.DeMoNFolder`."""
    from strl_pyg.datasets import DeMoNFolder

    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"Expected a DeMoN DeepSfM folder at '{root}' (got none)")
    ds = DeMoNFolder(root, cache_dir=cache_dir, split=split, limit=limit, **kwargs)
    return _dataset_pairs(ds, num_workers, progress)


def kitti_eval_pairs(root: str | os.PathLike, cache_dir: str | os.PathLike,
                     sequences: Sequence[str] = ("09", "10"), frame_gap: int = 1,
                     limit: int | None = None, num_workers: int = 0, progress: bool = False,
                     **kwargs: Any) -> list[EvalPair]:
    """KITTI odometry pairs ``(i, i + frame_gap)`` (front-end matches, cached in
    ``cache_dir``) with their frame indices; ``kwargs`` go to
    :class:`~strl_pyg.datasets.KITTIOdometry`."""
    from strl_pyg.datasets import KITTIOdometry

    root = Path(root)
    if not (root / "sequences").is_dir():
        raise FileNotFoundError(f"Expected a KITTI odometry root with 'sequences/' at '{root}' "
                                "(got none)")
    ds = KITTIOdometry(root, cache_dir=cache_dir, sequences=list(sequences),
                       frame_gap=frame_gap, limit=limit, **kwargs)
    return _dataset_pairs(ds, num_workers, progress, frames=True)


def posed_eval_pairs(root: str | os.PathLike, cache_dir: str | os.PathLike,
                     scenes: Sequence[str] | None = None, frame_gap: int = 2, stride: int = 4,
                     limit: int | None = None, num_workers: int = 0, progress: bool = False,
                     **kwargs: Any) -> list[EvalPair]:
    """Posed-photograph pairs ``(i, i + frame_gap)`` for every ``stride``-th ``i`` of the
    scene folders ``scenes`` under ``root`` (any format of :mod:`strl_pyg.datasets.posed`;
    default: the real_scenes split's validation scenes where ``root`` holds them, else every
    scene folder), front-end matches cached in ``cache_dir``; ``kwargs`` go to
    :class:`~strl_pyg.datasets.posed.PosedImagePairs`."""
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT, PosedImagePairs, PosedPairOptions

    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"Expected a folder of posed scenes at '{root}' (got none)")
    on_disk = sorted(p.name for p in root.iterdir() if p.is_dir())
    if not scenes:
        val = list(REAL_SCENES_SPLIT["val"])
        scenes = val if set(val) <= set(on_disk) else on_disk
    missing = [s for s in scenes if s not in on_disk]
    if missing or not scenes:
        raise FileNotFoundError(f"Expected scene folders under '{root}' (got "
                                f"{', '.join(missing) or 'none'} not there; on disk: "
                                f"{', '.join(on_disk[:12]) or 'nothing'})")
    ds = PosedImagePairs([root / s for s in scenes], cache_dir=cache_dir, limit=limit,
                         pairs=PosedPairOptions(gaps=(int(frame_gap),), stride=int(stride)),
                         **kwargs)
    return _dataset_pairs(ds, num_workers, progress)
