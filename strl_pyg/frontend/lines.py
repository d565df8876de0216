"""Lines of the front end: LSD detection and the epipolar line matcher.

1. A fundamental matrix ``F`` is fitted to the point matches (:func:`fit_fundamental
   <strl_pyg.frontend.points.fit_fundamental>`).
2. :func:`candidate_pairs`: for every pair of segments, the epipolar lines of the two endpoints
   of segment ``i`` in image 0 cut the supporting line of segment ``j`` in image 1; pairs whose
   cut interval overlaps segment ``j`` too little, that meet the epipolar lines at a grazing
   angle, or whose contrast polarity differs (LSD orients segments by their gradient) are
   discarded; so are pairs far from where the nearby point matches predict the segment in
   image 1. The two segments are clipped to their common part, so endpoint ``k`` of the clipped
   segment in image 0 lies on the epipolar line of endpoint ``k`` in image 1 (the same 3D point
   under ``F``).
3. :func:`~strl_pyg.frontend.line_descriptors.line_descriptor_scores` scores each candidate by
   the normalised cross-correlation of grey-level profiles sampled along the clipped segments.
4. Mutual best pairs above a threshold are kept (greedy in decreasing score).

Pixels: OpenCV's convention (centre of the top-left pixel is ``(0, 0)``).
"""

from __future__ import annotations

import cv2
import numpy as np

from strl_pyg.frontend.config import FrontendConfig
from strl_pyg.frontend.line_descriptors import band_descriptors, line_descriptor_scores
from strl_pyg.utils.products import matmul

__all__ = ["detect_lines", "candidate_pairs", "match_lines", "match_lines_by_descriptor"]


def detect_lines(gray: np.ndarray, cfg: FrontendConfig | None = None) -> np.ndarray:
    """LSD segments ``[N, 2, 2]`` pixels, longest first, at least ``min_line_length`` long.

    LSD orients every segment by its gradient (the brighter side is on the same hand when one
    walks from endpoint 0 to endpoint 1), which :func:`match_lines` uses as contrast polarity.
    """
    cfg = cfg or FrontendConfig()
    lsd = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD, cfg.lsd_scale)
    lines = lsd.detect(gray)[0]
    if lines is None:
        return np.zeros((0, 2, 2))
    lines = lines.reshape(-1, 2, 2).astype(np.float64)
    length = np.linalg.norm(lines[:, 1] - lines[:, 0], axis=1)
    keep = length >= cfg.min_line_length
    lines, length = lines[keep], length[keep]
    order = np.lexsort((lines[:, 0, 1], lines[:, 0, 0], -length))
    lines = lines[order][: int(cfg.max_detected_lines)]
    h, w = gray.shape
    return np.clip(lines, 0.0, [w - 1.0, h - 1.0])


def _hom(x: np.ndarray) -> np.ndarray:
    return np.concatenate([x, np.ones((*x.shape[:-1], 1))], axis=-1)


def _guided_midpoints(lines0, p0, p1, k: int):
    """Predicted image-1 midpoints of ``lines0`` from the median displacement of the ``k``
    nearest point matches; ``None`` without enough matches."""
    if k <= 0 or len(p0) < k:
        return None
    mid = lines0.mean(1)
    # dx^2 + dy^2 as two [N, M] planes: the same float64 values as the sum over a trailing
    # axis of 2 ([N, M, 2] temporaries and a strided reduction cost 3x as much)
    d2 = np.subtract.outer(mid[:, 0], p0[:, 0])
    d2 *= d2
    dy = np.subtract.outer(mid[:, 1], p0[:, 1])
    dy *= dy
    d2 += dy
    nearest = _k_nearest(d2, k)
    shift = np.median((p1 - p0)[nearest], axis=1)
    return mid + shift


def _near_prediction(pred: np.ndarray, lines1: np.ndarray, image_size1: tuple[int, int],
                     cfg: FrontendConfig) -> np.ndarray:
    """``[N0, N1]``: whether segment ``j``'s supporting line passes within
    ``cfg.line_guide_tol`` of image 1's diagonal of the predicted midpoint ``pred[i]``."""
    P1, D1 = lines1[:, 0], lines1[:, 1] - lines1[:, 0]
    n1 = np.stack([-D1[:, 1], D1[:, 0]], axis=1) / np.linalg.norm(D1, axis=1)[:, None]
    # (pred - P1) . n1 as two [N0, N1] planes (no [N0, N1, 2] temporaries)
    dist = np.subtract.outer(pred[:, 0], P1[:, 0])
    dist *= n1[:, 0]
    dy = np.subtract.outer(pred[:, 1], P1[:, 1])
    dy *= n1[:, 1]
    dist += dy
    return np.abs(dist) <= cfg.line_guide_tol * float(np.hypot(*image_size1))


def _k_nearest(d2: np.ndarray, k: int) -> np.ndarray:
    """Per row of ``d2 [N, M]``, the columns of its ``k`` smallest values, ties broken by the
    lower column (the set ``np.argsort(d2, kind="stable")[:, :k]`` gives, in column order),
    ``[N, k]``, by a partition instead of a full sort."""
    if k >= d2.shape[1]:
        return np.broadcast_to(np.arange(d2.shape[1]), d2.shape).copy()
    kth = np.partition(d2, k - 1, axis=1)[:, k - 1 : k]  # the k-th smallest value per row
    take = d2 <= kth
    # rows with ties at the k-th value: of the values equal to it, the lowest columns that
    # complete k (only those rows pay for the cumulative count)
    tied = np.flatnonzero(take.sum(axis=1) > k)
    if len(tied):
        sub = d2[tied]
        equal = sub == kth[tied]
        need = k - (sub < kth[tied]).sum(axis=1, keepdims=True)
        take[tied] = (sub < kth[tied]) | (equal & (np.cumsum(equal, axis=1) <= need))
    return np.nonzero(take)[1].reshape(len(d2), k)


def candidate_pairs(
    lines0: np.ndarray,
    lines1: np.ndarray,
    F: np.ndarray,
    image_size1: tuple[int, int],
    cfg: FrontendConfig,
    guide: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Segment pairs consistent with ``F`` and their clipped endpoints (module docstring, 2).

    Args:
        lines0, lines1: detected segments ``[N0, 2, 2]``, ``[N1, 2, 2]`` pixels.
        F: ``[3, 3]`` with ``x1^T F x0 = 0`` (pixels).
        image_size1: ``(H, W)`` of image 1 (the guidance tolerance is a fraction of its
            diagonal).
        cfg: :class:`~strl_pyg.frontend.FrontendConfig`.
        guide: point matches ``(points0 [M, 2], points1 [M, 2])`` consistent with ``F``.

    Returns:
        ``i0 [C]``, ``i1 [C]`` (indices into ``lines0``, ``lines1``), clipped ``c0 [C, 2, 2]``,
        ``c1 [C, 2, 2]`` (endpoint ``k`` matches endpoint ``k``) and ``flip [C]`` (segment 1
        runs against segment 0's endpoint order), row-major in ``(i0, i1)``.
    """
    # float64 whatever the caller's (LSD returns float32): the products below take one dtype
    lines0 = np.asarray(lines0, dtype=np.float64).reshape(-1, 2, 2)
    lines1 = np.asarray(lines1, dtype=np.float64).reshape(-1, 2, 2)
    F = np.asarray(F, dtype=np.float64)
    P0, D0 = lines0[:, 0], lines0[:, 1] - lines0[:, 0]
    P1, D1 = lines1[:, 0], lines1[:, 1] - lines1[:, 0]
    len1 = np.linalg.norm(D1, axis=1)
    # Epipolar lines in image 1 of both endpoints of every segment 0: [N0, 3].
    ea, eb = _hom(lines0[:, 0]) @ F.T, _hom(lines0[:, 1]) @ F.T
    with np.errstate(divide="ignore", invalid="ignore"):
        # [N0, N1] products through PyTorch, not NumPy's BLAS (see strl_pyg.utils.products)
        den_a, den_b = matmul(ea[:, :2], D1.T), matmul(eb[:, :2], D1.T)
        h1 = _hom(P1).T
        sa = -matmul(ea, h1) / den_a  # parameter on segment 1 where epipolar line a cuts it
        sb = -matmul(eb, h1) / den_b
        sin_a = np.abs(den_a) / (np.linalg.norm(ea[:, :2], axis=1)[:, None] * len1[None])
        sin_b = np.abs(den_b) / (np.linalg.norm(eb[:, :2], axis=1)[:, None] * len1[None])
    min_sin = np.sin(np.deg2rad(cfg.line_min_angle_deg))
    ok = np.isfinite(sa) & np.isfinite(sb) & (sin_a > min_sin) & (sin_b > min_sin)
    if cfg.line_polarity:
        ok &= sa < sb
    lo = np.maximum(np.minimum(sa, sb), 0.0)
    hi = np.minimum(np.maximum(sa, sb), 1.0)
    common = (hi - lo) * len1[None]
    shorter = np.minimum(np.abs(sb - sa) * len1[None], len1[None])
    with np.errstate(divide="ignore", invalid="ignore"):
        ok &= (common >= cfg.min_matched_length) & (common / shorter >= cfg.line_min_overlap)
    if guide is not None:
        pred = _guided_midpoints(lines0, guide[0], guide[1], int(cfg.line_guide_k))
        if pred is not None:
            ok &= _near_prediction(pred, lines1, image_size1, cfg)
    i0, i1 = np.nonzero(ok)
    flip = sa[i0, i1] > sb[i0, i1]
    lo, hi = lo[i0, i1], hi[i0, i1]
    # Clipped endpoints on segment 1, then back to segment 0 through F^T.
    q_lo = P1[i1] + lo[:, None] * D1[i1]
    q_hi = P1[i1] + hi[:, None] * D1[i1]
    e_lo, e_hi = _hom(q_lo) @ F, _hom(q_hi) @ F  # epipolar lines in image 0
    with np.errstate(divide="ignore", invalid="ignore"):
        r_lo = -np.einsum("ij,ij->i", e_lo, _hom(P0[i0])) / np.einsum("ij,ij->i", e_lo[:, :2],
                                                                       D0[i0])
        r_hi = -np.einsum("ij,ij->i", e_hi, _hom(P0[i0])) / np.einsum("ij,ij->i", e_hi[:, :2],
                                                                       D0[i0])
    r_lo, r_hi = np.clip(r_lo, 0, 1), np.clip(r_hi, 0, 1)
    c0 = np.stack([P0[i0] + r_lo[:, None] * D0[i0], P0[i0] + r_hi[:, None] * D0[i0]], axis=1)
    c1 = np.stack([q_lo, q_hi], axis=1).reshape(-1, 2, 2)
    c0 = c0.reshape(-1, 2, 2)
    len_c0 = np.linalg.norm(c0[:, 1] - c0[:, 0], axis=1)
    keep = np.isfinite(c0).all((1, 2)) & (len_c0 >= cfg.min_matched_length)
    return i0[keep], i1[keep], c0[keep], c1[keep], flip[keep]


def _mutual_best(i0: np.ndarray, i1: np.ndarray, scores: np.ndarray, min_score: float,
                 cap: int) -> np.ndarray:
    """Indices of the candidates kept: greedy in decreasing score (ties by ``(i0, i1)``), each
    segment used once, score at least ``min_score``; at most ``cap``."""
    good = np.flatnonzero(scores >= min_score)
    order = good[np.lexsort((i1[good], i0[good], -scores[good]))]
    used0, used1, chosen = set(), set(), []
    for c in order:  # greedy in decreasing score == mutual best among the remaining
        if len(chosen) >= cap:
            break
        if i0[c] in used0 or i1[c] in used1:
            continue
        used0.add(i0[c])
        used1.add(i1[c])
        chosen.append(c)
    return np.asarray(chosen, dtype=np.int64)


def match_lines(
    lines0: np.ndarray,
    lines1: np.ndarray,
    gray0: np.ndarray,
    gray1: np.ndarray,
    F: np.ndarray,
    cfg: FrontendConfig | None = None,
    guide: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matches LSD segments under a fundamental matrix (module docstring).

    Args:
        lines0, lines1: detected segments ``[N0, 2, 2]``, ``[N1, 2, 2]`` pixels.
        gray0, gray1: grey uint8 images.
        F: ``[3, 3]`` with ``x1^T F x0 = 0`` (pixels).
        cfg: :class:`~strl_pyg.frontend.FrontendConfig`.
        guide: point matches ``(points0 [M, 2], points1 [M, 2])`` consistent with ``F``, used to
            predict where a segment lies in image 1.

    Returns:
        clipped ``lines0 [L, 2, 2]``, ``lines1 [L, 2, 2]`` (endpoint ``k`` matches endpoint
        ``k``) and ``scores [L]`` (normalised cross-correlation), best first.
    """
    cfg = cfg or FrontendConfig()
    empty = np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), np.zeros(0)
    if len(lines0) == 0 or len(lines1) == 0:
        return empty
    i0, i1, c0, c1, flip = candidate_pairs(lines0, lines1, F, gray1.shape[:2], cfg, guide)
    if len(i0) == 0:
        return empty
    scores = line_descriptor_scores(c0, c1, flip, gray0, gray1, cfg)
    chosen = _mutual_best(i0, i1, scores, cfg.line_min_score, int(cfg.max_lines))
    if len(chosen) == 0:
        return empty
    return c0[chosen], c1[chosen], scores[chosen]


def match_lines_by_descriptor(
    lines0: np.ndarray,
    lines1: np.ndarray,
    gray0: np.ndarray,
    gray1: np.ndarray,
    cfg: FrontendConfig | None = None,
    guide: tuple[np.ndarray, np.ndarray] | None = None,
    min_guide_points: int = 3,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matches LSD segments without a fundamental matrix: mutual nearest neighbours of their
    :func:`~strl_pyg.frontend.line_descriptors.band_descriptors` that pass Lowe's ratio test
    (``cfg.line_descriptor_ratio``, against the second nearest of *all* segments of image 1)
    and score at least ``cfg.line_min_score`` (cosine similarity). A segment with a single
    candidate has no ratio and is not matched.

    The segments are returned as detected (not clipped: without epipolar geometry their
    endpoints do not correspond; only their supporting lines and orientations do, which is what
    the vanishing-point solver reads). With ``guide`` point matches (at least
    ``min_guide_points``), the nearest neighbour must also lie near where the nearest point
    matches' median displacement predicts it in image 1 (``cfg.line_guide_tol`` of the
    diagonal); the guidance only narrows the candidates, the ratio test stays as strict.

    Returns:
        ``lines0 [L, 2, 2]``, ``lines1 [L, 2, 2]`` and ``scores [L]`` (cosine similarity of the
        descriptors), best first, at most ``cfg.max_lines``.
    """
    cfg = cfg or FrontendConfig()
    empty = np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), np.zeros(0)
    a, b = band_descriptors(lines0, gray0), band_descriptors(lines1, gray1)  # checks inputs
    if len(a) == 0 or len(b) < 2:
        return empty
    lines0 = np.asarray(lines0, dtype=np.float64).reshape(-1, 2, 2)
    lines1 = np.asarray(lines1, dtype=np.float64).reshape(-1, 2, 2)
    dist = np.sqrt(np.maximum(2.0 - 2.0 * matmul(a, b.T), 0.0))  # unit descriptors: L2
    rows = np.arange(len(a))
    # the ratio's second nearest: over every segment of image 1, guided or not
    two = np.partition(dist, 1, axis=1)
    nearest_any, second = two[:, 0], two[:, 1]
    cand = dist
    if guide is not None and len(guide[0]) >= min_guide_points:
        k = min(int(cfg.line_guide_k), len(guide[0]))
        pred = _guided_midpoints(lines0, guide[0], guide[1], k)
        cand = np.where(_near_prediction(pred, lines1, gray1.shape[:2], cfg), dist, np.inf)
    nn01 = cand.argmin(axis=1)
    nn10 = cand.argmin(axis=0)
    best = cand[rows, nn01]
    # the chosen one must be the nearest of all (guidance does not promote a second best)
    keep = (np.isfinite(best) & (best <= nearest_any) & (nn10[nn01] == rows)
            & (best < cfg.line_descriptor_ratio * second))
    i0 = np.flatnonzero(keep)
    i1 = nn01[i0]
    score = 1.0 - best[i0] ** 2 / 2.0
    good = score >= cfg.line_min_score
    i0, i1, score = i0[good], i1[good], score[good]
    order = np.lexsort((i0, -score))[: int(cfg.max_lines)]
    i0, i1 = i0[order], i1[order]
    return lines0[i0].copy(), lines1[i1].copy(), score[order]
