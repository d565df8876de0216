"""Drawings of point and line matches on an image pair (OpenCV, no display needed).

The two images are placed side by side (image 0 left, image 1 right, top-aligned, different
sizes allowed); pixel coordinates follow OpenCV's convention. Inliers are drawn in green,
outliers in red; without an inlier mask every match is drawn in green.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from strl_pyg.data.matches import PairMatches
from strl_pyg.utils.io import atomic_open

__all__ = ["draw_matches", "save_matches_png", "INLIER_COLOUR", "OUTLIER_COLOUR"]

#: BGR colours of inlier and outlier matches.
INLIER_COLOUR = (60, 200, 60)
OUTLIER_COLOUR = (40, 40, 230)


def _to_bgr(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        img = np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    return cv2.cvtColor(img, cv2.COLOR_RGB2BGR)


def _mask(value: Any, n: int, name: str) -> np.ndarray | None:
    if value is None:
        return None
    arr = np.asarray(value).reshape(-1)
    if arr.dtype != np.bool_ or len(arr) != n:
        raise ValueError(f"Expected '{name}' as a bool array of length {n} "
                         f"(got dtype {arr.dtype}, length {len(arr)})")
    return arr


def draw_matches(
    matches: PairMatches,
    point_inliers: Any = None,
    line_inliers: Any = None,
    connect: bool = True,
    max_connectors: int = 200,
    layout: str = "auto",
    max_points: int | None = None,
    max_lines: int | None = None,
    title: str | None = None,
    legend: bool = False,
) -> np.ndarray:
    """Draws the matches of ``matches`` (which must carry both images).

    Args:
        matches: a :class:`PairMatches` with ``image0`` and ``image1``.
        point_inliers: optional bool ``[Np]``.
        line_inliers: optional bool ``[Nl]``.
        connect: draw thin connectors between matched points / line midpoints.
        max_connectors: at most this many connectors (evenly picked) to keep it readable.
        layout: ``"horizontal"`` (side by side), ``"vertical"`` (image 1 below image 0) or
            ``"auto"`` (vertical for wide images such as KITTI's, where W > 1.5 H).
        max_points, max_lines: draw at most this many point / line matches (evenly picked,
            every one when ``None``), so that hundreds of lines do not cover the images.
        title: a line of text in a header band above the images.
        legend: the colours' meaning in the header band (inlier, outlier; circles are points,
            segments lines) and how many matches are drawn of how many.

    Returns:
        BGR uint8 canvas ``[max(H0, H1), W0 + W1, 3]`` (horizontal) or
        ``[H0 + H1, max(W0, W1), 3]`` (vertical), plus the header band when ``title`` or
        ``legend`` is given.
    """
    if layout not in ("auto", "horizontal", "vertical"):
        raise ValueError(f"Expected layout 'auto', 'horizontal' or 'vertical' (got {layout!r})")
    if not matches.has_images:
        raise ValueError("Expected matches with image0 and image1 attached (got none)")
    pin = _mask(point_inliers, matches.num_points, "point_inliers")
    lin = _mask(line_inliers, matches.num_lines, "line_inliers")
    a, b = _to_bgr(matches.image0), _to_bgr(matches.image1)
    if layout == "auto":
        layout = "vertical" if a.shape[1] > 1.5 * a.shape[0] else "horizontal"
    if layout == "horizontal":
        h = max(a.shape[0], b.shape[0])
        canvas = np.zeros((h, a.shape[1] + b.shape[1], 3), np.uint8)
        canvas[: a.shape[0], : a.shape[1]] = a
        canvas[: b.shape[0], a.shape[1] :] = b
        shift = np.array([a.shape[1], 0.0])
    else:
        h = a.shape[0] + b.shape[0]
        canvas = np.zeros((h, max(a.shape[1], b.shape[1]), 3), np.uint8)
        canvas[: a.shape[0], : a.shape[1]] = a
        canvas[a.shape[0] :, : b.shape[1]] = b
        shift = np.array([0.0, a.shape[0]])
    sub = 16  # fixed-point drawing: sub-pixel positions

    def pt(x):
        return tuple(int(v) for v in np.round(np.asarray(x) * sub))

    def colour(mask, i):
        return INLIER_COLOUR if mask is None or mask[i] else OUTLIER_COLOUR

    thick = max(1, int(round(min(canvas.shape[:2]) / 300)))
    line_pick = _pick(matches.num_lines, max_lines)
    point_pick = _pick(matches.num_points, max_points)
    for i in line_pick:
        c = colour(lin, i)
        l0, l1 = matches.lines0[i], matches.lines1[i]
        cv2.line(canvas, pt(l0[0]), pt(l0[1]), c, thick, cv2.LINE_AA, shift=4)
        cv2.line(canvas, pt(l1[0] + shift), pt(l1[1] + shift), c, thick, cv2.LINE_AA, shift=4)
        cv2.circle(canvas, pt(l0[0]), 2 * sub, c, -1, cv2.LINE_AA, shift=4)  # endpoint 0
        cv2.circle(canvas, pt(l1[0] + shift), 2 * sub, c, -1, cv2.LINE_AA, shift=4)
    for i in point_pick:
        c = colour(pin, i)
        cv2.circle(canvas, pt(matches.points0[i]), 2 * sub, c, 1, cv2.LINE_AA, shift=4)
        cv2.circle(canvas, pt(matches.points1[i] + shift), 2 * sub, c, 1, cv2.LINE_AA, shift=4)
    if connect:
        ends = [(matches.points0, matches.points1, pin, point_pick),
                (matches.lines0.mean(1), matches.lines1.mean(1), lin, line_pick)]
        for x0, x1, mask, drawn in ends:
            if len(drawn) == 0:
                continue
            for i in drawn[_pick(len(drawn), max_connectors)]:
                cv2.line(canvas, pt(x0[i]), pt(x1[i] + shift), colour(mask, i), 1,
                         cv2.LINE_AA, shift=4)
    if title is None and not legend:
        return canvas
    return _with_header(canvas, title, legend, (len(point_pick), matches.num_points),
                        (len(line_pick), matches.num_lines), pin is not None or lin is not None)


def _pick(n: int, at_most: int | None) -> np.ndarray:
    """``min(n, at_most)`` indices spread evenly over ``range(n)``."""
    if at_most is None or n <= at_most:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max(at_most, 1)).astype(int))


def _with_header(canvas: np.ndarray, title: str | None, legend: bool, points: tuple,
                 lines: tuple, masked: bool) -> np.ndarray:
    """``canvas`` below a white band with the title and the legend."""
    scale = max(0.45, canvas.shape[1] / 1600)
    row = int(28 * scale / 0.6)
    width = canvas.shape[1] - 20
    rows = [(t, (20, 20, 20)) for t in _wrap(title, width, scale)] if title else []
    if legend:
        drawn = (f"points (circles): {points[0]} of {points[1]} drawn; lines (segments): "
                 f"{lines[0]} of {lines[1]} drawn")
        rows += [(t, (60, 60, 60)) for t in _wrap(drawn, width, scale)]
    band = np.full((row * (len(rows) + (1 if legend else 0)) + row // 2, canvas.shape[1], 3),
                   255, np.uint8)
    y = row
    for text, colour in rows:
        cv2.putText(band, text, (10, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1,
                    cv2.LINE_AA)
        y += row
    if legend:
        x = 10
        keys = [("inlier", INLIER_COLOUR), ("outlier", OUTLIER_COLOUR)] if masked else \
            [("match (no inlier test)", INLIER_COLOUR)]
        for text, colour in keys:
            cv2.rectangle(band, (x, y - row // 2), (x + row // 2, y), colour, -1)
            cv2.putText(band, text, (x + row // 2 + 6, y), cv2.FONT_HERSHEY_SIMPLEX, scale,
                        (20, 20, 20), 1, cv2.LINE_AA)
            x += int(row * 0.6 * len(text)) + row
    return np.concatenate([band, canvas], axis=0)


def _wrap(text: str, width: int, scale: float) -> list[str]:
    """``text`` in lines no wider than ``width`` pixels at ``scale`` (breaking at spaces; a
    single word wider than that stands alone), so a small image's header is not cut off."""
    out, line = [], ""
    for word in text.split(" "):
        cand = f"{line} {word}" if line else word
        if line and cv2.getTextSize(cand, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] > width:
            out.append(line)
            cand = word
        line = cand
    return out + ([line] if line else [])


def save_matches_png(
    path: str | os.PathLike,
    matches: PairMatches,
    point_inliers: Any = None,
    line_inliers: Any = None,
    **kwargs: Any,
) -> Path:
    """Draws with :func:`draw_matches` and writes a PNG atomically (temporary file in the same
    folder, then rename), so a reader never sees a half-written file. Returns the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"Expected a .png path (got '{path}')")
    canvas = draw_matches(matches, point_inliers, line_inliers, **kwargs)
    ok, buf = cv2.imencode(".png", canvas)
    if not ok:  # pragma: no cover - imencode fails only on invalid input
        raise RuntimeError(f"Could not encode the drawing for '{path}'")
    with atomic_open(path) as f:
        f.write(buf.tobytes())
    return path
