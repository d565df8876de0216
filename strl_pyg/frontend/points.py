"""Points of the front end: SIFT/ORB keypoints, Lowe's ratio test with a mutual nearest-neighbour
check, and the MAGSAC fundamental matrix that guides the line matcher."""

from __future__ import annotations

import time
from typing import Any

import cv2
import numpy as np

from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.utils.products import matmul
from strl_pyg.utils.threads import shared_pool

__all__ = ["match_points", "fit_fundamental", "on_both", "detect_points", "root_sift"]


def on_both(fn, a, b, concurrent: bool = True):
    """``(fn(a), fn(b))``, in two threads when ``concurrent`` (OpenCV's detectors release the
    GIL: measured 1.2x for SIFT and 1.7x for LSD on a KITTI pair with the second core busy)."""
    if not concurrent:
        return fn(a), fn(b)
    fb = shared_pool("frontend", 2).submit(fn, b)
    return fn(a), fb.result()


def _detector(cfg: FrontendConfig):
    if cfg.detector == "sift":
        return (cv2.SIFT_create(nfeatures=int(cfg.max_keypoints),
                                contrastThreshold=float(cfg.contrast_threshold)), cv2.NORM_L2)
    return cv2.ORB_create(nfeatures=int(cfg.max_keypoints)), cv2.NORM_HAMMING


def root_sift(desc: np.ndarray) -> np.ndarray:
    """RootSIFT (Arandjelovic & Zisserman 2012: the square root of the L1-normalised
    descriptor, whose L2 distance is the Hellinger kernel of the originals), quantised as
    COLMAP stores it: ``round(512 * v)`` clipped to 255. Integer-valued like OpenCV's SIFT
    descriptors, so the matcher's products stay exact (:func:`_top2_l2`)."""
    d = np.asarray(desc, dtype=np.float64)
    d = np.sqrt(d / np.maximum(d.sum(axis=1, keepdims=True), 1e-12))
    return np.minimum(np.round(512.0 * d), 255.0).astype(np.float32)


def upsample_factor(shape: tuple, cfg: FrontendConfig) -> int:
    """2 where the image's longer side is at most ``cfg.upsample_below`` (detection then runs
    on the image upsampled 2x: smaller features, as COLMAP's ``first_octave=-1`` finds them
    on small photographs), else 1."""
    return 2 if max(shape[:2]) <= int(cfg.upsample_below) else 1


def detect_points(gray: np.ndarray, cfg: FrontendConfig):
    """Keypoints ``[K, 2]`` (pixels of ``gray``, OpenCV's convention), descriptors ``[K, D]``
    (RootSIFT where ``cfg.rootsift`` and SIFT) or ``None`` where nothing was found."""
    s = upsample_factor(gray.shape, cfg)
    img = gray if s == 1 else cv2.resize(gray, (gray.shape[1] * s, gray.shape[0] * s),
                                          interpolation=cv2.INTER_LINEAR)
    kp, desc = _detector(cfg)[0].detectAndCompute(img, None)
    xy = np.array([k.pt for k in kp], dtype=np.float64).reshape(-1, 2)
    if s != 1:  # pixel centres: x in the image is (x_up + 0.5) / s - 0.5
        xy = (xy + 0.5) / s - 0.5
    if desc is not None and cfg.detector == "sift" and cfg.rootsift:
        desc = root_sift(desc)
    return xy, desc


def _knn2(d_query: np.ndarray, d_train: np.ndarray, norm: int):
    """Nearest index and distance ratio (nearest / second nearest) per query row."""
    matcher = cv2.BFMatcher(norm, crossCheck=False)
    knn = matcher.knnMatch(d_query, d_train, k=2)
    nn = np.full(len(d_query), -1, np.int64)
    ratio = np.ones(len(d_query))
    for q, m in enumerate(knn):
        if len(m) == 2:
            nn[q] = m[0].trainIdx
            ratio[q] = m[0].distance / max(m[1].distance, 1e-12)
        elif len(m) == 1:
            nn[q] = m[0].trainIdx
            ratio[q] = 0.0 if m[0].distance == 0 else 1.0
    return nn, ratio


def _top2_l2(d0: np.ndarray, d1: np.ndarray):
    """Both directions' nearest index and ratio (nearest / second nearest L2 distance) from one
    matrix product: ``(nn01, ratio01, nn10)`` as :func:`_knn2` gives them. The product (float32)
    only ranks the candidates; the two distances of each ratio are recomputed exactly from the
    descriptors (float64), so a ratio differs from OpenCV's by rounding only.

    Costs one ``[N0, N1]`` float32 matrix beside the product (built in place) and row-wise
    (contiguous) reductions only: the two nearest by two ``argmin`` passes, the reverse
    direction's nearest from the column minima (a column-wise ``argmin`` and ``argpartition``
    were 70 % of the time on a 2048 x 2048 KITTI pair).

    Identical to the straightforward ``argpartition`` / ``argmin(axis=0)`` version: OpenCV's SIFT
    descriptors are integer-valued (norm about 512), so every product and squared distance is
    an exact integer in float32 whatever the BLAS or thread count, and ties are exact ties in
    both (both take the lowest index). Descriptors must be finite: one NaN row would leave
    every row's minimum undefined."""
    a = np.ascontiguousarray(d0, dtype=np.float32)
    b = np.ascontiguousarray(d1, dtype=np.float32)
    prod = matmul(a, b.T)  # [N0, N1]; not NumPy's BLAS (see strl_pyg.utils.products)
    prod *= 2.0  # exact: the same float32 values as (|a|^2 + |b|^2) - 2 a.b computed apart
    sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :]
    sq -= prod
    del prod
    # the reverse direction: each column's minimum (a row-wise pass), then the first row that
    # reaches it (flat hits are in row order), as ``sq.argmin(axis=0)`` without its slow strided
    # reduction
    col_min = sq.min(axis=0)
    hit_row, hit_col = np.divmod(np.flatnonzero(sq == col_min[None, :]), sq.shape[1])
    cols, first_hit = np.unique(hit_col, return_index=True)
    nn10 = np.zeros(sq.shape[1], np.int64)
    nn10[cols] = hit_row[first_hit]
    rows = np.arange(len(a))
    if sq.shape[1] == 1:
        nn01 = np.zeros(len(a), np.int64)
        dist = np.linalg.norm(a.astype(np.float64) - b[0].astype(np.float64), axis=1)
        return nn01, np.where(dist == 0, 0.0, 1.0), nn10.astype(np.int64)
    first = sq.argmin(axis=1)
    sq[rows, first] = np.inf  # the second nearest: the nearest of the others
    second = sq.argmin(axis=1)
    two = np.stack([first, second], axis=1)
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    dist = np.linalg.norm(a64[:, None, :] - b64[two], axis=2)  # [N0, 2] exact
    pick = dist.argmin(axis=1)
    nn01 = two[rows, pick]
    ratio = dist[rows, pick] / np.maximum(dist[rows, 1 - pick], 1e-12)
    return nn01.astype(np.int64), ratio, nn10.astype(np.int64)


def match_points(
    gray0: np.ndarray, gray1: np.ndarray, cfg: FrontendConfig | None = None,
    reference: bool = False, features: tuple[Any, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Detects and matches keypoints.

    Args:
        gray0, gray1: grey uint8 images ``[H0, W0]``, ``[H1, W1]``.
        cfg: :class:`FrontendConfig`.
        reference: match SIFT descriptors with OpenCV's brute-force k-NN (twice, one per
            direction) instead of one matrix product with top-2 (:func:`_top2_l2`); the two
            agree up to float rounding of near ties.
        features: the two images' feature sources (:mod:`strl_pyg.frontend.features`)
            whose keypoints and descriptors for ``cfg`` are used instead of detecting them.

    Returns:
        ``points0 [M, 2]``, ``points1 [M, 2]`` pixels, ``scores [M]`` (``1 - ratio``, higher is
        better), sorted by score, and a dict of counts and timings in ms.
    """
    cfg = cfg or FrontendConfig()
    t0 = time.perf_counter()
    norm = _detector(cfg)[1]
    if features is not None:
        f0, f1 = (f.points(cfg) for f in features)
        (kp0, d0), (kp1, d1) = (f0.keypoints, f0.descriptors), (f1.keypoints, f1.descriptors)
    else:  # one detector per image: an OpenCV feature object is not shared between threads
        (kp0, d0), (kp1, d1) = on_both(lambda g: detect_points(g, cfg), gray0, gray1,
                                       cfg.concurrent)
    t1 = time.perf_counter()
    stats = {"keypoints0": len(kp0), "keypoints1": len(kp1)}
    empty = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    if d0 is None or d1 is None or len(kp0) < 2 or len(kp1) < 2:
        stats["timings_ms"] = {"points_detect": 1e3 * (t1 - t0), "points_match": 0.0}
        return (*empty, stats)
    if norm == cv2.NORM_L2 and not reference:  # one matrix product for both directions
        nn01, ratio01, nn10 = _top2_l2(d0, d1)
    else:  # OpenCV's brute-force k-NN, twice (the reference path; ORB's Hamming distance)
        nn01, ratio01 = _knn2(d0, d1, norm)
        nn10 = _knn2(d1, d0, norm)[0] if cfg.mutual else None
    keep = (nn01 >= 0) & (ratio01 < cfg.ratio)
    if cfg.mutual:
        idx = np.flatnonzero(keep)
        keep[idx] = nn10[nn01[idx]] == idx
    idx0 = np.flatnonzero(keep)
    idx1 = nn01[idx0]
    order = np.lexsort((idx0, ratio01[idx0]))[: int(cfg.max_points)]  # ties: by index
    idx0, idx1 = idx0[order], idx1[order]
    p0, p1 = kp0[idx0].reshape(-1, 2), kp1[idx1].reshape(-1, 2)
    t2 = time.perf_counter()
    stats["timings_ms"] = {"points_detect": 1e3 * (t1 - t0), "points_match": 1e3 * (t2 - t1)}
    return p0, p1, 1.0 - ratio01[idx0], stats


def fit_fundamental(p0: np.ndarray, p1: np.ndarray, cfg: FrontendConfig
                    ) -> tuple[np.ndarray | None, np.ndarray]:
    """Fundamental matrix ``F [3, 3]`` (``x1^T F x0 = 0``, pixels) of point matches ``[M, 2]``
    by OpenCV's USAC-MAGSAC (seeded with ``cfg.seed``), and the inlier mask ``[M]``; ``F`` is
    ``None`` (mask all ``False``) with fewer than 8 matches or when no model is found."""
    if len(p0) < 8:
        return None, np.zeros(len(p0), bool)
    cv2.setRNGSeed(int(cfg.seed))
    try:
        F, mask = cv2.findFundamentalMat(
            p0, p1, cv2.USAC_MAGSAC, cfg.ransac_threshold, cfg.ransac_confidence,
            int(cfg.ransac_max_iters),
        )
    except cv2.error:  # OpenCV 5's USAC asserts on some degenerate samples: no model found
        return None, np.zeros(len(p0), bool)
    if F is None or F.shape != (3, 3) or mask is None:
        return None, np.zeros(len(p0), bool)
    return F, mask.reshape(-1).astype(bool)


_fit_fundamental = fit_fundamental  # the name before the split
