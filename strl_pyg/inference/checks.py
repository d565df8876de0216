"""The checks of a pair's matches, intrinsics and device that turn into warnings,
``"unreliable"`` or ``"degenerate"`` (:mod:`strl_pyg.inference.estimator`), or a one-line
``ValueError``."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from strl_pyg.data.matches import PairMatches

__all__ = [
    "ZERO_PARALLAX_PX", "ZERO_PARALLAX_FRACTION", "FOCAL_RANGE", "NORMALISED_K_MAX",
    "BAD_INTRINSICS", "input_warnings", "intrinsics_problems", "zero_parallax", "flipped_lines",
    "check_device"]

#: pixels (image 1 re-expressed in image 0's camera when both K are known).
ZERO_PARALLAX_PX = 0.5
ZERO_PARALLAX_FRACTION = 0.8
#: Plausible focal lengths, as multiples of the image width.
FOCAL_RANGE = (0.1, 10.0)

#: A principal point at this many times the image centre's coordinates or more (or as many
#: times less), by the same factor in x and y (within ``RESIZED_AGREE``), says K was made
#: for a resized image (:func:`intrinsics_problems`): at 1.75 the principal point sits
#: beyond 87.5 % (or within 28.6 %) of the image in both axes, which a calibrated camera's
#: does not; a 2x resize puts it at the corner. A 1.5x resize (1080p to 720p) is missed.
RESIZED_MIN = 1.75
RESIZED_AGREE = 1.25

#: A K whose focal lengths are at most this and whose principal point lies within this of
#: the origin looks normalised (by the image width or size) rather than in pixels.
NORMALISED_K_MAX = 10.0


#: The reason every pose of a pair whose intrinsics fail the input checks is ``"unreliable"``.
BAD_INTRINSICS = "computed with intrinsics that fail the input checks"

def intrinsics_problems(size0: Any, size1: Any, K0: Any, K1: Any) -> list[str]:
    """Why the intrinsics do not fit the images (``[]`` when they do, or when there are
    none): one K for images of different sizes; a principal point outside the image (with a
    hint when ``cx`` and ``cy`` look swapped) or, by one factor in x and y, far from its
    centre (a K of the image before it was resized); a normalised K (focal lengths and principal
    point of at most :data:`NORMALISED_K_MAX`) with pixel coordinates; a focal length outside
    :data:`FOCAL_RANGE` times the width. Sizes are ``(H, W)``; every pose computed with such
    intrinsics is ``"unreliable"`` (:class:`~strl_pyg.inference.estimator.PoseEstimator`)."""
    if K0 is None or K1 is None:
        return []
    out = []
    (h0, w0), (h1, w1) = (tuple(int(v) for v in s) for s in (size0, size1))
    if (h0, w0) != (h1, w1) and np.allclose(K0, K1):
        out.append(f"the images have different sizes ({h0}x{w0} and {h1}x{w1} px, H x W) but "
                   "one K: pass each image's own intrinsics (K0, K1); the pose is likely wrong")
    lo, hi = FOCAL_RANGE
    same = (h0, w0) == (h1, w1) and np.allclose(K0, K1)
    for name, K, (h, w) in ((("K" if same else "K0"), K0, (h0, w0)), ("K1", K1, (h1, w1))):
        if name == "K1" and same:
            break
        K = np.asarray(K, dtype=np.float64)
        cx, cy, fx, fy = K[0, 2], K[1, 2], K[0, 0], K[1, 1]
        size = f"{h}x{w} px (H x W)"
        if max(abs(fx), abs(fy), abs(cx), abs(cy)) <= NORMALISED_K_MAX and w > 4 * \
                NORMALISED_K_MAX:
            out.append(f"{name} looks normalised (fx={fx:.4g}, fy={fy:.4g}, cx={cx:.4g}, "
                       f"cy={cy:.4g}) but the points are pixels of a {size} image: pass K in "
                       "pixels (a K normalised by the image size: multiply row 0 by W and row 1 "
                       "by H)")
            continue
        scale = _resized_by(cx, cy, w, h)
        if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
            swapped = -0.5 <= cy <= w - 0.5 and -0.5 <= cx <= h - 0.5
            hint = (f": cx and cy look swapped (cx is the column, at most {w - 0.5:g} here)"
                    if swapped else
                    f": K looks made for the image {scale:.3g}x this size (a resized image "
                    f"needs its K resized with it: K[:2] *= {1 / scale:.3g})"
                    if scale is not None else ": is K for this image, in pixels?")
            out.append(f"{name}: principal point (cx={cx:.1f}, cy={cy:.1f}) lies outside the "
                       f"{size} image{hint}")
        elif scale is not None:
            out.append(f"{name}: principal point (cx={cx:.1f}, cy={cy:.1f}) is at "
                       f"{2 * cx / (w - 1):.2f}x and {2 * cy / (h - 1):.2f}x the centre of the "
                       f"{size} "
                       f"image: K looks made for the image {scale:.3g}x this size (a resized "
                       f"image needs its K resized with it: K[:2] *= {1 / scale:.3g})")
        if not (lo * w <= fx <= hi * w and lo * w <= fy <= hi * w):
            out.append(f"{name}: focal length (fx={fx:.4g}, fy={fy:.4g} px) is outside "
                       f"{lo:g}-{hi:g}x the image width ({w} px): is K for this image, in "
                       "pixels?")
    return out


def _resized_by(cx: float, cy: float, w: int, h: int) -> float | None:
    """The factor by which the image would have to be resized for K's principal point to
    sit at its centre, when both axes agree on one (within :data:`RESIZED_AGREE`) that is
    at least :data:`RESIZED_MIN` away from 1 (a K of the full-size image on a half-size
    one: 2); else ``None``. A principal point off-centre in one axis only (a crop) is not
    one."""
    if cx <= 0 or cy <= 0 or w < 2 or h < 2:
        return None
    rx, ry = 2 * cx / (w - 1), 2 * cy / (h - 1)  # the centre of pixel centres 0..w-1
    if abs(np.log(rx / ry)) > np.log(RESIZED_AGREE):
        return None
    scale = float(np.sqrt(rx * ry))
    if abs(np.log(scale)) < np.log(RESIZED_MIN):
        return None
    for nice in (1 / 4, 1 / 3, 1 / 2, 2, 3, 4):  # the usual resize factors, where it is one
        if abs(np.log(scale / nice)) < np.log(1.05):
            return nice
    return scale


def input_warnings(size0: Any, size1: Any, K0: Any, K1: Any) -> list[str]:
    """Warnings about the intrinsics: none at all (the classical solvers cannot run), or
    :func:`intrinsics_problems`."""
    if K0 is None or K1 is None:
        return ["no intrinsics (K0, K1): the classical solvers cannot run, and a network "
                "pose (from coordinates normalised by the image size) is not a metric one"]
    return intrinsics_problems(size0, size1, K0, K1)


#: The share of line matches running opposite ways in the two images, against the pair's
#: own in-plane rotation, above which their endpoints look unmatched (:func:`flipped_lines`).
FLIPPED_LINES_SHARE = 0.2
#: How close (deg) a line's turn must be to the pair's rotation, or to it plus 180 deg, to count.
FLIPPED_LINES_WINDOW_DEG = 30.0


def flipped_lines(matches: PairMatches) -> list[str]:
    """A warning when, of the line matches whose endpoints are said to correspond, more
    than :data:`FLIPPED_LINES_SHARE` turn by the pair's in-plane rotation plus 180 deg
    instead of by it (at least 5 lines within :data:`FLIPPED_LINES_WINDOW_DEG` of either):
    endpoint order as a line detector gave it, which the network reads as a half-turn of
    the segment. The rotation is the lines' own mode of turning, taken modulo 180 deg (so a
    rolled camera is not a flip) with the larger group as the unflipped one; lines that
    turn otherwise (outliers) are left out."""
    if matches.num_lines < 5 or not matches.line_endpoints_correspond:
        return []
    d0 = matches.lines0[:, 1] - matches.lines0[:, 0]
    d1 = matches.lines1[:, 1] - matches.lines1[:, 0]
    if matches.has_intrinsics:  # image 1's directions seen with image 0's camera
        A = matches.K0[:2, :2] @ np.linalg.inv(matches.K1[:2, :2])
        d1 = d1 @ A.T
    turn = np.arctan2(d1[:, 1], d1[:, 0]) - np.arctan2(d0[:, 1], d0[:, 0])
    mode = np.angle(np.exp(2j * turn).mean()) / 2  # modulo 180 deg: flip-blind
    off = np.angle(np.exp(1j * (turn - mode)))  # (-pi, pi]: 0 as the mode, pi flipped
    win = np.radians(FLIPPED_LINES_WINDOW_DEG)
    same = int(np.sum(np.abs(off) < win))
    opposite = int(np.sum(np.abs(off) > np.pi - win))
    same, opposite = max(same, opposite), min(same, opposite)
    if same + opposite < 5 or opposite <= FLIPPED_LINES_SHARE * (same + opposite):
        return []
    return [f"{opposite} of {same + opposite} line matches run opposite ways in the two "
            "images (against how the others turn): are their endpoints matched (endpoint k "
            "to endpoint k)? If not, say so with info={'line_endpoints': 'as detected'}, or "
            "order them alike"]


def zero_parallax(matches: PairMatches) -> bool:
    """Whether at least :data:`ZERO_PARALLAX_FRACTION` of the point matches moved less than
    :data:`ZERO_PARALLAX_PX` pixels (identical or near-identical images)."""
    if matches.num_points == 0:
        return False
    p0, p1 = matches.points0, matches.points1
    if matches.has_intrinsics:
        K0, K1 = matches.K0, matches.K1
        x1 = np.c_[p1, np.ones(len(p1))] @ np.linalg.inv(K1).T
        p1 = (x1 @ K0.T)[:, :2] / (x1 @ K0.T)[:, 2:]
    moved = np.linalg.norm(p1 - p0, axis=1)
    return float(np.mean(moved < ZERO_PARALLAX_PX)) >= ZERO_PARALLAX_FRACTION


def check_device(device: Any) -> torch.device | None:
    """``device`` as a ``torch.device`` (``None`` stays ``None``); ``ValueError`` for a name
    torch does not know or a device this machine does not have."""
    if device is None:
        return None
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(f"Expected a torch device such as 'cpu' or 'cuda' (got {device!r})"
                         ) from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(f"Expected a device this machine has (got {device!r}: CUDA is not "
                             "available here); use device='cpu', or None for the model's own")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ValueError(f"Expected a CUDA device index below {torch.cuda.device_count()} "
                             f"(got {device!r})")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"Expected a device this machine has (got {device!r}: MPS is not "
                         "available here); use device='cpu', or None for the model's own")
    elif dev.type == "meta":
        raise ValueError(f"Expected a device that holds data (got {device!r})")
    return dev
