"""The work of a scene run, one image or one pair at a time, in any process.

These functions hold no file open and write nothing: a worker (a process of the pool or a rank
of ``torchrun``) computes, and the process that owns the outputs writes
(:mod:`strl_pyg.collection.scene`). A worker builds its :class:`~strl_pyg.inference.
PoseEstimator` once (:func:`init_worker`).
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np

from strl_pyg.collection.images import CollectionImage, load_gray
from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.features import (
    POINTS,
    Detect,
    MissingFeatures,
    Precomputed,
    settings_key,
)

__all__ = ["init_worker", "features_task", "pair_task", "compact_record", "keypoint_indices"]

_STATE: dict[str, Any] = {}


def init_worker(methods: Any = None, model: Any = None, threads: int = 1) -> None:
    """Sets up this process: ``threads`` torch / OpenCV threads, and the estimator's
    arguments (it is built on the first pair)."""
    import cv2
    import torch

    torch.set_num_threads(max(1, int(threads)))
    cv2.setNumThreads(max(1, int(threads)))
    _STATE.clear()
    _STATE.update(methods=methods, model=model)


def _estimator():
    if "estimator" not in _STATE:
        from strl_pyg.inference import PoseEstimator
        from strl_pyg.inference.registry import RECOMMENDED

        methods = _STATE.get("methods")
        _STATE["estimator"] = PoseEstimator(_STATE.get("model"),
                                            RECOMMENDED if methods is None else methods)
    return _STATE["estimator"]


def features_task(image: CollectionImage, configs: list[tuple[str, dict]]
                  ) -> tuple[str, tuple[int, int], dict[str, Any]]:
    """One image's features for each ``(kind, FrontendConfig fields)``: ``(name, (H, W),
    {settings_key: PointFeatures or segments})``."""
    gray = load_gray(image)
    det = Detect(gray, image.name)
    out: dict[str, Any] = {}
    for kind, fields in configs:
        cfg = FrontendConfig(**fields)
        out[settings_key(kind, cfg)] = det.points(cfg) if kind == POINTS else det.lines(cfg)
    return image.name, gray.shape[:2], out


def keypoint_indices(points: np.ndarray, keypoints: np.ndarray) -> np.ndarray:
    """For each match coordinate ``[M, 2]``, the index of the keypoint ``[K, 2]`` at exactly
    that position (the front end copies keypoints' coordinates; keypoints at one position,
    SIFT's orientations, give the first); ``-1`` where none is."""
    lookup: dict[tuple[float, float], int] = {}
    for k, xy in enumerate(map(tuple, np.asarray(keypoints, dtype=np.float64))):
        lookup.setdefault(xy, k)
    return np.array([lookup.get(tuple(p), -1) for p in np.asarray(points, dtype=np.float64)],
                    dtype=np.int64).reshape(-1)


def compact_record(est: Any) -> dict[str, Any]:
    """The table's fields of a :class:`~strl_pyg.inference.PoseEstimate`: status, rule,
    method, configuration, ``T_0to1``, sigma (degrees), counts, warnings, time."""
    pose = est.pose
    T = pose.T_0to1
    return {
        "status": str(pose.status), "rule": pose.rule, "method": pose.method,
        "configuration": est.configuration,
        "T_0to1": None if T is None else np.asarray(T, dtype=float).tolist(),
        "sigma": pose.sigma, "num_points": est.num_points, "num_lines": est.num_lines,
        "num_inliers": pose.num_inliers, "warnings": list(pose.warnings),
        "time_ms": pose.time_ms,
    }


def pair_task(task: dict[str, Any]) -> dict[str, Any]:
    """One pair: ``task`` holds ``i, j``, both :class:`CollectionImage` (``image0/1``), ``K0/1``
    (or ``None``), their stored features (``arrays0/1``, by :func:`settings_key`) and the
    :class:`FrontendConfig` fields. Returns ``{"i", "j", "record", "points_key", "matches"
    [M, 2] keypoint indices, "inliers" [M]}``, or ``{"i", "j", "missing": [(image side,
    kind, config fields)]}`` when a feature the pair needs is not stored yet (the adaptive
    second pass), or ``{"i", "j", "error"}`` for a one-line input error."""
    from strl_pyg.frontend.pipeline import thorough_points

    cfg = FrontendConfig(**task["config"])
    im0, im1 = task["image0"], task["image1"]
    sources = (Precomputed(task["arrays0"], im0.name), Precomputed(task["arrays1"], im1.name))
    base = {"i": task["i"], "j": task["j"]}
    try:
        g0, g1 = load_gray(im0), load_gray(im1)
        est = _estimator().estimate_images(g0, g1, task["K0"], task["K1"], cfg,
                                           features=sources)
    except MissingFeatures as err:
        side = 0 if err.name == im0.name else 1
        other = task["arrays1" if side == 0 else "arrays0"]
        missing = [(side, err.kind, asdict(err.config))]
        if settings_key(err.kind, err.config) not in other:
            missing.append((1 - side, err.kind, asdict(err.config)))
        return {**base, "missing": missing}
    except (OSError, ValueError, TypeError) as err:
        return {**base, "error": str(err).splitlines()[0]}
    out = {**base, "record": compact_record(est)}
    m = est.matches
    if m is None or m.num_points == 0:
        return {**out, "points_key": None, "matches": np.zeros((0, 2), np.int64),
                "inliers": np.zeros(0, bool)}
    used = thorough_points(cfg) if m.info.get("second_pass") else cfg
    key = settings_key(POINTS, used)
    idx = np.stack([keypoint_indices(m.points0, sources[0].points(used).keypoints),
                    keypoint_indices(m.points1, sources[1].points(used).keypoints)], axis=1)
    inl = est.inliers_of_matches()
    inl = np.zeros(len(idx), bool) if inl is None else np.asarray(inl, bool)
    keep = (idx >= 0).all(axis=1)
    return {**out, "points_key": key, "matches": idx[keep], "inliers": inl[keep]}

