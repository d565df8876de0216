"""Image front end: two images -> matched points and line segments (:class:`PairMatches`).

Points: OpenCV SIFT (or ORB) with Lowe's ratio test and a mutual nearest-neighbour check.
Lines: OpenCV's LSD detector and our own matcher:

1. A fundamental matrix ``F`` is fitted to the point matches (OpenCV USAC-MAGSAC).
2. For every pair of segments, the epipolar lines of the two endpoints of segment ``i`` in
   image 0 cut the supporting line of segment ``j`` in image 1; pairs whose cut interval
   overlaps segment ``j`` too little, that meet the epipolar lines at a grazing angle, or whose
   contrast polarity differs (LSD orients segments by their gradient) are discarded; so are
   pairs far from where the nearby point matches predict the segment in image 1.
3. The two segments are clipped to their common part, so endpoint ``k`` of the clipped
   segment in image 0 lies on the epipolar line of endpoint ``k`` in image 1 (the same 3D
   point under ``F``).
4. A descriptor of each clipped segment is sampled along it: grey-level profiles across the
   segment at evenly spaced positions (bilinear, on a lightly blurred image); the normalised
   cross-correlation of the two descriptors scores the pair; mutual best pairs above a
   threshold are kept.

Conventions: pixels with OpenCV's convention (centre of the top-left pixel is ``(0, 0)``);
image suffixes 0 (reference) and 1 (target); ``T_0to1`` maps camera-0 points into camera 1.

Errors: empty images, wrong dtype or ndim raise ``TypeError``/``ValueError`` with an
``Expected ... (got ...)`` message. Images of different sizes are allowed (the two cameras may
differ; each image keeps its own size in the result). When neither a point nor a line match is
found (all-black, featureless or unrelated images) :class:`NoMatchesError` is raised, because an
empty :class:`PairMatches` is invalid.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np

from strl_pyg.data.matches import PairMatches

__all__ = [
    "FrontendConfig",
    "NoMatchesError",
    "match_images",
    "detect_lines",
    "match_points",
    "match_lines",
    "epipolar_residuals",
    "fundamental_from_pose",
]


class NoMatchesError(ValueError):
    """No point and no line match was found between the two images (featureless, all-black or
    unrelated images)."""


@dataclass
class FrontendConfig:
    """Configuration of :func:`match_images`.

    Args:
        detector: ``"sift"`` (default) or ``"orb"`` (faster, fewer and less precise matches).
        max_keypoints: keypoints detected per image (strongest first). (default: 2048)
        ratio: Lowe's ratio test threshold on nearest / second nearest descriptor distance.
            (default: 0.8)
        mutual: keep only mutual nearest neighbours. (default: True)
        max_points: cap on returned point matches, lowest ratio first. (default: 1024)
        filter_points: keep only the point matches consistent with the fitted ``F``
            (default: False, the learned model sees the outliers).
        ransac_threshold: epipolar threshold (px) of the ``F`` fit. (default: 1.0)
        ransac_confidence, ransac_max_iters: of the ``F`` fit. (default: 0.999, 10000)
        lsd_scale: image scale at which LSD runs (its ``scale`` parameter). (default: 1.0)
        min_line_length: shortest detected segment kept, pixels. (default: 15.0)
        max_detected_lines: segments kept per image, longest first. (default: 512)
        max_lines: cap on returned line matches, best score first. (default: 256)
        min_matched_length: shortest clipped segment kept, pixels. (default: 10.0)
        line_min_overlap: common part / shorter of the two segments (measured on the segment
            in image 1) below which a pair is discarded. (default: 0.5)
        line_min_angle_deg: smallest angle between a segment and the epipolar lines (a segment
            along its epipolar lines has no defined endpoints). (default: 10.0)
        line_polarity: require the same contrast polarity in both images. (default: True)
        line_guide_k: point matches near a segment whose median displacement predicts it in
            image 1; 0 disables the guidance. (default: 8)
        line_guide_tol: allowed distance (fraction of the image-1 diagonal) between the
            predicted midpoint and the supporting line of the candidate. (default: 0.05)
        line_samples: descriptor positions along a segment. (default: 12)
        line_profile: samples across a segment at each position. (default: 9)
        line_profile_halfwidth: half width of the profile, pixels. (default: 6.0)
        line_min_score: smallest normalised cross-correlation kept. (default: 0.6)
        seed: seeds OpenCV's RNG before the robust fit, for determinism. (default: 0)
    """

    detector: str = "sift"
    max_keypoints: int = 2048
    ratio: float = 0.8
    mutual: bool = True
    max_points: int = 1024
    filter_points: bool = False
    ransac_threshold: float = 1.0
    ransac_confidence: float = 0.999
    ransac_max_iters: int = 10000
    lsd_scale: float = 1.0
    min_line_length: float = 15.0
    max_detected_lines: int = 512
    max_lines: int = 256
    min_matched_length: float = 10.0
    line_min_overlap: float = 0.5
    line_min_angle_deg: float = 10.0
    line_polarity: bool = True
    line_guide_k: int = 8
    line_guide_tol: float = 0.05
    line_samples: int = 12
    line_profile: int = 9
    line_profile_halfwidth: float = 6.0
    line_min_score: float = 0.6
    seed: int = 0

    def __post_init__(self) -> None:
        if self.detector not in ("sift", "orb"):
            raise ValueError(f"Expected detector 'sift' or 'orb' (got {self.detector!r})")
        if not 0.0 < self.ratio <= 1.0:
            raise ValueError(f"Expected ratio in (0, 1] (got {self.ratio})")
        for name in ("max_keypoints", "max_points", "max_lines", "max_detected_lines"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"Expected {name} >= 0 (got {getattr(self, name)})")
        if self.line_samples < 2 or self.line_profile < 1:
            raise ValueError(
                "Expected line_samples >= 2 and line_profile >= 1 "
                f"(got {self.line_samples}, {self.line_profile})"
            )
        if not 0.0 < self.lsd_scale <= 1.0:
            raise ValueError(f"Expected lsd_scale in (0, 1] (got {self.lsd_scale})")


# ---------------------------------------------------------------- validation
def _check_image(img: Any, name: str) -> np.ndarray:
    """Validates an image and returns it as grey uint8 ``[H, W]``."""
    if not isinstance(img, np.ndarray):
        raise TypeError(f"Expected '{name}' as a numpy array (got {type(img).__name__})")
    if img.dtype != np.uint8:
        raise TypeError(f"Expected '{name}' of dtype uint8 (got {img.dtype})")
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3)):
        raise ValueError(f"Expected '{name}' of shape (H, W) or (H, W, 3) (got {img.shape})")
    if img.size == 0:
        raise ValueError(f"Expected a non-empty '{name}' (got shape {img.shape})")
    if min(img.shape[:2]) < 16:
        raise ValueError(f"Expected '{name}' of at least 16x16 pixels (got {img.shape[:2]})")
    if img.ndim == 3:
        img = img[..., 0] if img.shape[2] == 1 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img)


# ---------------------------------------------------------------- points
def _detector(cfg: FrontendConfig):
    if cfg.detector == "sift":
        return cv2.SIFT_create(nfeatures=int(cfg.max_keypoints)), cv2.NORM_L2
    return cv2.ORB_create(nfeatures=int(cfg.max_keypoints)), cv2.NORM_HAMMING


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


def match_points(
    gray0: np.ndarray, gray1: np.ndarray, cfg: FrontendConfig | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Detects and matches keypoints.

    Args:
        gray0, gray1: grey uint8 images ``[H0, W0]``, ``[H1, W1]``.
        cfg: :class:`FrontendConfig`.

    Returns:
        ``points0 [M, 2]``, ``points1 [M, 2]`` pixels, ``scores [M]`` (``1 - ratio``, higher is
        better), sorted by score, and a dict of counts and timings in ms.
    """
    cfg = cfg or FrontendConfig()
    t0 = time.perf_counter()
    det, norm = _detector(cfg)
    kp0, d0 = det.detectAndCompute(gray0, None)
    kp1, d1 = det.detectAndCompute(gray1, None)
    t1 = time.perf_counter()
    stats = {"keypoints0": len(kp0), "keypoints1": len(kp1)}
    empty = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    if d0 is None or d1 is None or len(kp0) < 2 or len(kp1) < 2:
        stats["timings_ms"] = {"points_detect": 1e3 * (t1 - t0), "points_match": 0.0}
        return (*empty, stats)
    nn01, ratio01 = _knn2(d0, d1, norm)
    keep = (nn01 >= 0) & (ratio01 < cfg.ratio)
    if cfg.mutual:
        nn10, _ = _knn2(d1, d0, norm)
        idx = np.flatnonzero(keep)
        keep[idx] = nn10[nn01[idx]] == idx
    idx0 = np.flatnonzero(keep)
    idx1 = nn01[idx0]
    order = np.lexsort((idx0, ratio01[idx0]))[: int(cfg.max_points)]  # ties: by index
    idx0, idx1 = idx0[order], idx1[order]
    p0 = np.array([kp0[i].pt for i in idx0], dtype=np.float64).reshape(-1, 2)
    p1 = np.array([kp1[i].pt for i in idx1], dtype=np.float64).reshape(-1, 2)
    t2 = time.perf_counter()
    stats["timings_ms"] = {"points_detect": 1e3 * (t1 - t0), "points_match": 1e3 * (t2 - t1)}
    return p0, p1, 1.0 - ratio01[idx0], stats


def _fit_fundamental(p0, p1, cfg: FrontendConfig):
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


# ---------------------------------------------------------------- lines
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


def _bilinear(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Samples ``img`` ``[H, W]`` at ``xy`` ``[..., 2]`` with border replication."""
    h, w = img.shape
    x = np.clip(xy[..., 0], 0, w - 1.001)
    y = np.clip(xy[..., 1], 0, h - 1.001)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    a, b = img[y0, x0], img[y0, x0 + 1]
    c, d = img[y0 + 1, x0], img[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def _hom(x: np.ndarray) -> np.ndarray:
    return np.concatenate([x, np.ones((*x.shape[:-1], 1))], axis=-1)


def _guided_midpoints(lines0, p0, p1, k: int):
    """Predicted image-1 midpoints of ``lines0`` from the median displacement of the ``k``
    nearest point matches; ``None`` without enough matches."""
    if k <= 0 or len(p0) < k:
        return None
    mid = lines0.mean(1)
    d2 = ((mid[:, None, :] - p0[None, :, :]) ** 2).sum(-1)
    nearest = np.argsort(d2, axis=1, kind="stable")[:, :k]
    shift = np.median((p1 - p0)[nearest], axis=1)
    return mid + shift


def match_lines(
    lines0: np.ndarray,
    lines1: np.ndarray,
    gray0: np.ndarray,
    gray1: np.ndarray,
    F: np.ndarray,
    cfg: FrontendConfig | None = None,
    guide: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matches LSD segments under a fundamental matrix (see the module docstring).

    Args:
        lines0, lines1: detected segments ``[N0, 2, 2]``, ``[N1, 2, 2]`` pixels.
        gray0, gray1: grey uint8 images.
        F: ``[3, 3]`` with ``x1^T F x0 = 0`` (pixels).
        cfg: :class:`FrontendConfig`.
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
    P0, D0 = lines0[:, 0], lines0[:, 1] - lines0[:, 0]
    P1, D1 = lines1[:, 0], lines1[:, 1] - lines1[:, 0]
    len1 = np.linalg.norm(D1, axis=1)
    # Epipolar lines in image 1 of both endpoints of every segment 0: [N0, 3].
    ea, eb = _hom(lines0[:, 0]) @ F.T, _hom(lines0[:, 1]) @ F.T
    with np.errstate(divide="ignore", invalid="ignore"):
        den_a, den_b = ea[:, :2] @ D1.T, eb[:, :2] @ D1.T  # [N0, N1]
        sa = -(ea @ _hom(P1).T) / den_a  # parameter on segment 1 where epipolar line a cuts it
        sb = -(eb @ _hom(P1).T) / den_b
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
            n1 = np.stack([-D1[:, 1], D1[:, 0]], axis=1) / len1[:, None]
            dist = np.abs(np.einsum("ijk,jk->ij", pred[:, None, :] - P1[None], n1))
            tol = cfg.line_guide_tol * float(np.hypot(*gray1.shape))
            ok &= dist <= tol
    i0, i1 = np.nonzero(ok)
    if len(i0) == 0:
        return empty
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
    c1 = np.stack([q_lo, q_hi], axis=1)
    len_c0 = np.linalg.norm(c0[:, 1] - c0[:, 0], axis=1)
    keep = np.isfinite(c0).all((1, 2)) & (len_c0 >= cfg.min_matched_length)
    i0, i1, c0, c1, flip = i0[keep], i1[keep], c0[keep], c1[keep], flip[keep]
    if len(i0) == 0:
        return empty
    scores = _line_ncc(c0, c1, flip, gray0, gray1, cfg)
    # Mutual best above the threshold.
    good = np.flatnonzero(scores >= cfg.line_min_score)
    order = good[np.lexsort((i1[good], i0[good], -scores[good]))]
    used0, used1, chosen = set(), set(), []
    for c in order:  # greedy in decreasing score == mutual best among the remaining
        if i0[c] in used0 or i1[c] in used1:
            continue
        used0.add(i0[c])
        used1.add(i1[c])
        chosen.append(c)
    chosen = np.asarray(chosen[: int(cfg.max_lines)], dtype=np.int64)
    return c0[chosen], c1[chosen], scores[chosen]


def _line_ncc(c0, c1, flip, gray0, gray1, cfg: FrontendConfig) -> np.ndarray:
    """Normalised cross-correlation of grey-level profiles sampled across the clipped segments
    ``c0``, ``c1`` ``[C, 2, 2]`` at corresponding positions along them."""
    g0 = cv2.GaussianBlur(gray0.astype(np.float32), (0, 0), 1.0)
    g1 = cv2.GaussianBlur(gray1.astype(np.float32), (0, 0), 1.0)
    u = np.linspace(0.0, 1.0, cfg.line_samples + 2)[1:-1]
    off = np.linspace(-1.0, 1.0, cfg.line_profile) * cfg.line_profile_halfwidth
    len0 = np.linalg.norm(c0[:, 1] - c0[:, 0], axis=1)
    len1 = np.linalg.norm(c1[:, 1] - c1[:, 0], axis=1)
    scale1 = np.clip(len1 / np.maximum(len0, 1e-9), 0.5, 2.0)
    descs = []
    for c, g, scale, sign in ((c0, g0, np.ones_like(scale1), np.ones(len(c0))),
                              (c1, g1, scale1, np.where(flip, -1.0, 1.0))):
        d = c[:, 1] - c[:, 0]
        n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.linalg.norm(d, axis=1, keepdims=True)
        n = n * (sign * scale)[:, None]
        pos = c[:, None, 0] + u[None, :, None] * d[:, None]  # [C, S, 2]
        xy = pos[:, :, None, :] + off[None, None, :, None] * n[:, None, None, :]
        descs.append(_bilinear(g, xy).reshape(len(c), -1))
    a, b = descs
    a = a - a.mean(1, keepdims=True)
    b = b - b.mean(1, keepdims=True)
    den = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    return np.where(den > 1e-6, (a * b).sum(1) / np.maximum(den, 1e-12), -1.0)


# ---------------------------------------------------------------- pipeline
def match_images(
    image0: np.ndarray,
    image1: np.ndarray,
    K0: Any = None,
    K1: Any = None,
    config: FrontendConfig | None = None,
) -> PairMatches:
    """Matches points and line segments between two images.

    Args:
        image0, image1: numpy uint8 ``(H, W)`` or ``(H, W, 3)`` (RGB) images; the two may have
            different sizes.
        K0, K1: optional intrinsics ``[3, 3]`` (pixels), attached to the result (both or none).
        config: :class:`FrontendConfig` (default ``FrontendConfig()``).

    Returns:
        :class:`PairMatches` with ``points0/1 [Np, 2]``, ``lines0/1 [Nl, 2, 2]`` (endpoint ``k``
        matches endpoint ``k``), ``point_scores`` (``1 - ratio``), ``line_scores`` (NCC), the
        grey images attached, and ``info`` holding ``timings_ms`` per stage
        (``points_detect``, ``points_match``, ``geometry``, ``lines_detect``, ``lines_match``,
        ``total``), counts, ``lines_status`` and the configuration. Lines need a fundamental
        matrix from at least 8 point matches; without one the result has points only.

    Raises:
        TypeError, ValueError: invalid images.
        NoMatchesError: no point and no line match (e.g. an all-black image).
    """
    cfg = config if config is not None else FrontendConfig()
    if not isinstance(cfg, FrontendConfig):
        raise TypeError(f"Expected a FrontendConfig (got {type(cfg).__name__})")
    gray0, gray1 = _check_image(image0, "image0"), _check_image(image1, "image1")
    t_start = time.perf_counter()
    p0, p1, p_scores, stats = match_points(gray0, gray1, cfg)
    timings = dict(stats.pop("timings_ms"))

    t = time.perf_counter()
    F, inl = _fit_fundamental(p0, p1, cfg)
    timings["geometry"] = 1e3 * (time.perf_counter() - t)
    if cfg.filter_points and F is not None:
        p0, p1, p_scores, inl = p0[inl], p1[inl], p_scores[inl], inl[inl]

    t = time.perf_counter()
    seg0, seg1 = detect_lines(gray0, cfg), detect_lines(gray1, cfg)
    timings["lines_detect"] = 1e3 * (time.perf_counter() - t)

    t = time.perf_counter()
    if F is None:
        l0 = l1 = np.zeros((0, 2, 2))
        l_scores = np.zeros(0)
        status = "skipped: fewer than 8 point matches or no fundamental matrix"
    else:
        l0, l1, l_scores = match_lines(seg0, seg1, gray0, gray1, F, cfg, guide=(p0[inl], p1[inl]))
        status = "ok"
    timings["lines_match"] = 1e3 * (time.perf_counter() - t)
    timings["total"] = 1e3 * (time.perf_counter() - t_start)

    if len(p0) == 0 and len(l0) == 0:
        raise NoMatchesError(
            "Expected at least one point or line match (got none: "
            f"{stats['keypoints0']}/{stats['keypoints1']} keypoints, "
            f"{len(seg0)}/{len(seg1)} segments); the images may be featureless "
            "(e.g. all black) or show different scenes"
        )
    info = {
        "source": f"strl_pyg.frontend ({cfg.detector}+lsd)",
        "timings_ms": timings,
        **stats,
        "segments0": len(seg0),
        "segments1": len(seg1),
        "point_geometric_inliers": int(inl.sum()),
        "lines_status": status,
        "config": asdict(cfg),
    }
    return PairMatches(
        p0, p1, lines0=l0, lines1=l1, point_scores=p_scores, line_scores=l_scores,
        K0=K0, K1=K1, image0=gray0, image1=gray1, info=info,
    )


# ---------------------------------------------------------------- evaluation helpers
def fundamental_from_pose(T_0to1: Any, K0: Any, K1: Any) -> np.ndarray:
    """``F [3, 3]`` (float64 numpy) with ``x1^T F x0 = 0`` for ``T_0to1`` ``[4, 4]`` and
    intrinsics ``K0``, ``K1`` ``[3, 3]``, via :mod:`strl_pyg.geometry`."""
    from strl_pyg.geometry import essential_from_pose, fundamental_from_essential

    T = np.asarray(T_0to1, dtype=np.float64)
    E = essential_from_pose(T[:3, :3], T[:3, 3])
    F = fundamental_from_essential(E, np.asarray(K0, np.float64), np.asarray(K1, np.float64))
    return F.detach().cpu().numpy().astype(np.float64)


def epipolar_residuals(matches: PairMatches, T_0to1: Any) -> tuple[np.ndarray, np.ndarray]:
    """Sampson errors (pixels, not squared) of the matches under a pose.

    Args:
        matches: with ``K0``, ``K1``.
        T_0to1: ``[4, 4]``, ``X1 = R X0 + t``.

    Returns:
        ``point_err [Np]`` and ``line_err [Nl]``, the larger of the two endpoints' errors.
    """
    from strl_pyg.geometry import sampson_error

    if not matches.has_intrinsics:
        raise ValueError("Expected matches with K0 and K1 (got none)")
    F = fundamental_from_pose(T_0to1, matches.K0, matches.K1)

    def err(x0, x1):
        if len(x0) == 0:
            return np.zeros(0)
        return sampson_error(F, x0, x1, squared=False).detach().cpu().numpy()

    pe = err(matches.points0, matches.points1)
    le = err(matches.lines0.reshape(-1, 2), matches.lines1.reshape(-1, 2)).reshape(-1, 2).max(1)
    return pe, le
