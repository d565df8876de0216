"""The two-view configuration of a pair of calibrated images, from its point matches.

Which kind of pose the matches can determine, decided as COLMAP's two-view geometry does (the
support of a homography beside the essential matrix's), with a rotation-only model that
COLMAP's "panoramic" case implies:

* ``"general"``: the essential matrix explains the matches clearly better than any
  homography: a full pose (rotation and translation direction).
* ``"planar"``: a homography explains about as many matches as the essential matrix
  (:data:`H_RATIO`), and a rotation alone does not: the scene is (close to) one plane. A pose
  exists, but the plane's homography has up to two decompositions in front of the camera that
  the matches cannot tell apart (:func:`planar_candidates`).
* ``"rotation"``: a rotation alone (``x1 ~ K1 R K0^-1 x0``) explains about as many matches as
  the essential matrix (:data:`ROTATION_RATIO`): no parallax, so no translation direction; the
  rotation is still well defined (:attr:`TwoViewGeometry.rotation`).
* ``"degenerate"``: fewer than :data:`MIN_INLIERS` matches fit any model.
* ``"multiple"``: set by the estimator, not here, where a second rigid motion explains a large
  share of the matches beside the pose's (COLMAP's MULTIPLE: a turntable's static room and its
  turning object; :func:`strl_pyg.inference.evidence.apply_multiple_motions`).
* ``"watermark"``: set by the estimator too, where many of the pose's inliers stay put near
  the image borders while the rest move (COLMAP's WATERMARK: a stamped overlay;
  :func:`strl_pyg.inference.evidence.apply_watermark`).

All counts are of distinct correspondences within ``threshold_px`` (symmetric transfer for
the homography and the rotation, Sampson for the essential matrix, all in pixels at the mean
focal length). The thresholds were measured on generated pairs with exact pure rotations,
planes and general scenes and on the real slices (``benchmarks/bench_two_view.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

__all__ = ["CONFIGURATIONS", "H_RATIO", "ROTATION_RATIO", "MIN_INLIERS", "TwoViewGeometry",
           "classify_two_view", "rotation_only", "planar_candidates", "bearings"]

CONFIGURATIONS = ("general", "planar", "rotation", "degenerate", "multiple", "watermark")
#: A homography with at least this share of the essential matrix's inliers makes a pair
#: planar (COLMAP's ``max_H_inlier_ratio``).
H_RATIO = 0.8
#: A rotation with at least this share of the essential matrix's inliers makes a pair a pure
#: rotation (its parallax is within the noise).
ROTATION_RATIO = 0.9
#: Fewer inliers than this for every model: degenerate.
MIN_INLIERS = 8
#: RANSAC iterations of the essential matrix and the homography. The decision reads their
#: support only where it is high (a homography with 80 % of the essential matrix's inliers),
#: which a few dozen samples find; a low support may be undercounted, which changes nothing.
#: (2000 cost 30 ms a KITTI pair, the default predict's whole budget.)
RANSAC_ITERATIONS = 200


@dataclass
class TwoViewGeometry:
    """The configuration of a pair (module docstring) and the evidence it was decided on.

    Attributes:
        configuration: one of :data:`CONFIGURATIONS`.
        num_points: distinct point matches read.
        inliers_E, inliers_H, inliers_R: inliers of the essential matrix, the homography and
            the rotation-only model.
        rotation: ``[3, 3]`` rotation-only estimate (refined on its inliers), or ``None``.
        rotation_sigma_deg: its RMS rotation uncertainty (first order, from the inliers'
            residuals), or ``None``.
        residual_px: median distance (px) of the essential inliers from the rotation-only
            model: the parallax left once the rotation is removed.
        H: ``[3, 3]`` homography in pixels (image 0 to image 1), or ``None``.
    """

    configuration: str
    num_points: int
    inliers_E: int
    inliers_H: int
    inliers_R: int
    rotation: np.ndarray | None = field(default=None, repr=False)
    rotation_sigma_deg: float | None = None
    residual_px: float | None = None
    H: np.ndarray | None = field(default=None, repr=False)
    #: the focal check (:func:`strl_pyg.inference.evidence.focal_consistency`): ``s2 / s1`` of
    #: ``K1^T F K0`` and the inliers of that F (``None``, 0: not checked)
    focal_sv_ratio: float | None = None
    focal_inliers: int = 0
    #: a second rigid motion among the recommended pose's outliers
    #: (:func:`strl_pyg.inference.evidence.apply_multiple_motions`): its inliers (0: none
    #: found or not looked for)
    second_motion_inliers: int = 0

    @property
    def h_ratio(self) -> float:
        return self.inliers_H / max(self.inliers_E, 1)

    @property
    def rotation_ratio(self) -> float:
        return self.inliers_R / max(self.inliers_E, 1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no matrices but the rotation)."""
        return {"configuration": self.configuration, "num_points": self.num_points,
                "inliers_E": self.inliers_E, "inliers_H": self.inliers_H,
                "inliers_R": self.inliers_R, "h_ratio": round(self.h_ratio, 4),
                "rotation_ratio": round(self.rotation_ratio, 4),
                "residual_px": None if self.residual_px is None else round(self.residual_px, 3),
                "focal_sv_ratio": None if self.focal_sv_ratio is None
                else round(self.focal_sv_ratio, 4), "focal_inliers": self.focal_inliers,
                "second_motion_inliers": self.second_motion_inliers}


def bearings(x: np.ndarray) -> np.ndarray:
    """Unit viewing rays ``[N, 3]`` of normalised image points ``x`` ``[N, 2]``."""
    b = np.concatenate([x, np.ones((len(x), 1))], axis=1)
    return b / np.linalg.norm(b, axis=1, keepdims=True)


def _kabsch(a: np.ndarray, b: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """Rotations ``R`` with ``b ~ R a`` (least squares), batched over leading axes:
    ``a``, ``b`` ``[..., n, 3]``."""
    if w is not None:
        a = a * w[..., None]
    M = np.einsum("...ni,...nj->...ij", b, a)
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones(U.shape[:-2] + (3,))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt


def _transfer_px(R: np.ndarray, x0: np.ndarray, x1: np.ndarray, focal: float) -> np.ndarray:
    """Symmetric transfer distance (px at ``focal``) of the matches under ``x1 ~ R x0``."""
    def err(Rm, a, b):
        p = bearings(a) @ Rm.T
        with np.errstate(divide="ignore", invalid="ignore"):
            q = p[:, :2] / p[:, 2:3]
        e = np.linalg.norm(q - b, axis=1)
        return np.where(p[:, 2] > 1e-9, e, np.inf)
    return 0.5 * (err(R, x0, x1) + err(R.T, x1, x0)) * focal


def rotation_only(x0: np.ndarray, x1: np.ndarray, focal: float, threshold_px: float = 1.0,
                  iterations: int = 64, seed: int = 0
                  ) -> tuple[np.ndarray | None, np.ndarray, float | None]:
    """The rotation ``R`` with ``x1 ~ R x0`` (normalised coordinates ``[N, 2]``) by RANSAC over
    two-match samples, refined on its inliers; returns ``(R, inlier mask, sigma_deg)``
    (``R`` ``None`` with fewer than 2 matches). ``sigma_deg`` is the first-order RMS rotation
    uncertainty from the inliers' residuals."""
    n = len(x0)
    mask = np.zeros(n, bool)
    if n < 2:
        return None, mask, None
    b0, b1 = bearings(x0), bearings(x1)
    rng = np.random.default_rng(seed)
    i = rng.integers(0, n, size=(iterations, 2))
    i[:, 1] = (i[:, 0] + 1 + rng.integers(0, n - 1, size=iterations)) % n
    Rs = _kabsch(b0[i], b1[i])
    p = np.matmul(b0[None], Rs.transpose(0, 2, 1))  # [k, n, 3]: R_k b0_n
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.linalg.norm(p[..., :2] / p[..., 2:3] - x1[None], axis=2) * focal
    counts = ((e < threshold_px) & (p[..., 2] > 0)).sum(1)
    R = Rs[int(np.argmax(counts))]
    for _ in range(3):  # refine on the inliers, then recount
        mask = _transfer_px(R, x0, x1, focal) < threshold_px
        if mask.sum() < 2:
            break
        R = _kabsch(b0[mask], b1[mask])
    mask = _transfer_px(R, x0, x1, focal) < threshold_px
    k = int(mask.sum())
    sigma = None
    if k >= 3:
        res = _transfer_px(R, x0[mask], x1[mask], focal) / focal  # radians at the centre
        # each inlier constrains two of the three rotation angles: 2k equations, 3 unknowns
        s2 = float(np.sum(res ** 2) / max(2 * k - 3, 1))
        sigma = float(np.degrees(np.sqrt(3 * s2 / k)))
    return R, mask, sigma


def classify_two_view(x0: np.ndarray, x1: np.ndarray, focal: float,
                      threshold_px: float = 1.0, seed: int = 0,
                      points0: np.ndarray | None = None,
                      points1: np.ndarray | None = None) -> TwoViewGeometry:
    """The configuration of a calibrated pair (module docstring) from its distinct point
    matches in normalised coordinates ``x0``, ``x1`` ``[N, 2]`` (``focal``: the mean focal
    length in px, turning ``threshold_px`` into normalised units). ``points0``, ``points1``:
    the same matches in pixels, for the homography (default: the normalised ones, scaled)."""
    x0 = np.asarray(x0, dtype=np.float64)
    x1 = np.asarray(x1, dtype=np.float64)
    n = len(x0)
    if n < MIN_INLIERS:
        return TwoViewGeometry("degenerate", n, 0, 0, 0)
    thr = threshold_px / focal
    cv2.setRNGSeed(int(seed))
    try:
        E, e_mask = cv2.findEssentialMat(x0, x1, np.eye(3), method=cv2.RANSAC, prob=0.999,
                                         threshold=thr, maxIters=RANSAC_ITERATIONS)
    except cv2.error:  # the five-point polynomial vanishes: matches without any parallax
        E, e_mask = None, None
    inl_E = 0 if E is None or e_mask is None else int(e_mask.ravel().astype(bool).sum())
    p0 = x0 * focal if points0 is None else np.asarray(points0, dtype=np.float64)
    p1 = x1 * focal if points1 is None else np.asarray(points1, dtype=np.float64)
    cv2.setRNGSeed(int(seed))
    H, h_mask = cv2.findHomography(p0, p1, cv2.RANSAC, threshold_px,
                                   maxIters=RANSAC_ITERATIONS, confidence=0.999)
    inl_H = 0 if H is None or h_mask is None else int(h_mask.ravel().astype(bool).sum())
    R, r_mask, sigma = rotation_only(x0, x1, focal, threshold_px, seed=seed)
    inl_R = int(r_mask.sum())
    residual = None
    if R is not None:
        e_in = e_mask.ravel().astype(bool) if inl_E else np.ones(n, bool)
        residual = float(np.median(_transfer_px(R, x0[e_in], x1[e_in], focal)))
    # a pure rotation fits an essential matrix with any t: E's support is then everyone's
    top = max(inl_E, inl_H)
    if max(top, inl_R) < MIN_INLIERS:
        config = "degenerate"
    elif inl_R >= ROTATION_RATIO * top:
        config = "rotation"
    elif inl_H >= H_RATIO * inl_E:
        config = "planar"
    else:
        config = "general"
    return TwoViewGeometry(config, n, inl_E, inl_H, inl_R, R, sigma, residual, H)


def planar_candidates(H: np.ndarray, K0: np.ndarray, K1: np.ndarray, x0: np.ndarray,
                      x1: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The decompositions ``(R, t_unit)`` of a plane's homography (pixels, image 0 to 1) that
    put the matches ``x0``, ``x1`` (normalised) in front of both cameras: up to two, which the
    matches of one plane cannot tell apart."""
    Hn = np.linalg.inv(K1) @ H @ K0
    _, Rs, ts, normals = cv2.decomposeHomographyMat(Hn, np.eye(3))
    pts0 = x0.reshape(-1, 1, 2).astype(np.float32)  # OpenCV reads float32 points here
    pts1 = x1.reshape(-1, 1, 2).astype(np.float32)
    keep = cv2.filterHomographyDecompByVisibleRefpoints(Rs, normals, pts0, pts1)
    idx = range(len(Rs)) if keep is None else [int(k) for k in np.asarray(keep).ravel()]
    out = []
    for k in idx:
        t = np.asarray(ts[k], dtype=np.float64).ravel()
        norm = np.linalg.norm(t)
        out.append((np.asarray(Rs[k], dtype=np.float64), t / norm if norm > 0 else t))
    return out
