"""Exact checks of matches on a generated pair, through the plane-induced homographies.

Every surface is a plane ``n . X0 = d`` (camera-0 frame), so a pixel of image 0 seen on quad
``q`` maps to image 1 by ``H_q = K (R + t n^T / d) K^-1`` with ``T_0to1 = [R | t]``. Unlike the
epipolar constraint this also checks the position along the epipolar line, which is what makes
it a real test of line matches (two segments are always consistent with *some* 3D line).

(The pose metrics are :mod:`strl_pyg.metrics.two_view`.)
"""

from __future__ import annotations

import numpy as np

from strl_pyg.data.matches import ENDPOINTS_AS_DETECTED, LINE_ENDPOINTS, PairMatches
from strl_pyg.geometry.epipolar import epipolar_residuals
from strl_pyg.synthetic.pair import SyntheticPair

__all__ = ["plane_homographies", "point_transfer_error", "line_transfer_error",
           "evaluate_matches"]


def plane_homographies(pair: SyntheticPair) -> np.ndarray:
    """``[Q, 3, 3]`` homographies image 0 -> image 1 of every quad of the scene."""
    R, t = pair.T_0to1[:3, :3], pair.T_0to1[:3, 3]
    n, d = pair.planes[:, :3], pair.planes[:, 3]
    M = R[None] + t[None, :, None] * (n / d[:, None])[:, None, :]
    K_inv = np.linalg.inv(pair.K)
    return pair.K[None] @ M @ K_inv[None]


def _transfer(H: np.ndarray, x: np.ndarray) -> np.ndarray:
    y = np.concatenate([x, np.ones((*x.shape[:-1], 1))], -1) @ np.swapaxes(H, -1, -2)
    return y[..., :2] / y[..., 2:3]


def _ids_near(pair: SyntheticPair, xy: np.ndarray) -> np.ndarray:
    """Quad ids of the 3x3 pixels around each ``xy`` ``[N, 2]`` -> ``[N, 9]`` (-1: none)."""
    h, w = pair.plane_id0.shape
    xi, yi = np.round(xy[:, 0]).astype(int), np.round(xy[:, 1]).astype(int)
    out = []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            x, y = np.clip(xi + dx, 0, w - 1), np.clip(yi + dy, 0, h - 1)
            out.append(pair.plane_id0[y, x])
    return np.stack(out, 1)


def point_transfer_error(pair: SyntheticPair, points0: np.ndarray, points1: np.ndarray):
    """Distance (pixels) between ``points1`` ``[N, 2]`` and ``points0`` ``[N, 2]`` mapped by
    the homography of the plane they lie on (the best of the 3x3 pixels around them); ``inf``
    on the background."""
    Hs = plane_homographies(pair)
    ids = _ids_near(pair, points0)
    err = np.full(len(points0), np.inf)
    for j in range(ids.shape[1]):
        ok = ids[:, j] >= 0
        if ok.any():
            y = _transfer(Hs[ids[ok, j]], points0[ok][:, None, :])[:, 0]
            err[ok] = np.minimum(err[ok], np.linalg.norm(y - points1[ok], axis=1))
    return err


def line_transfer_error(pair: SyntheticPair, lines0: np.ndarray, lines1: np.ndarray):
    """Per line ``[N]``: the larger distance between endpoint ``k`` of ``lines1`` and endpoint
    ``k`` of ``lines0`` mapped by a plane homography, for the best plane among those seen
    along and beside segment 0 (either side of an occluding edge). Pixels; ``inf`` when only
    background is seen there."""
    Hs = plane_homographies(pair)
    err = np.full(len(lines0), np.inf)
    if len(lines0) == 0:
        return err
    d = lines0[:, 1] - lines0[:, 0]
    n = np.stack([-d[:, 1], d[:, 0]], 1) / np.maximum(np.linalg.norm(d, axis=1), 1e-9)[:, None]
    u = np.array([0.2, 0.5, 0.8])
    pos = lines0[:, None, 0] + u[None, :, None] * d[:, None]
    cand = np.concatenate(
        [_ids_near(pair, (pos + s * 2.0 * n[:, None]).reshape(-1, 2)).reshape(len(d), -1)
         for s in (-1, 0, 1)], axis=1)
    for i in range(len(lines0)):
        for q in np.unique(cand[i][cand[i] >= 0]):
            e = np.linalg.norm(_transfer(Hs[q], lines0[i]) - lines1[i], axis=1).max()
            err[i] = min(err[i], e)
    return err


def _on_segment(seg: np.ndarray, gt: np.ndarray, tol: float) -> np.ndarray:
    """``[N, G]``: segment ``n`` lies within ``tol`` px of the supporting line of GT segment
    ``g`` and at least half of it projects inside ``g``."""
    g0, gd = gt[:, 0], gt[:, 1] - gt[:, 0]
    glen = np.maximum(np.linalg.norm(gd, axis=1), 1e-9)
    gu = gd / glen[:, None]
    gn = np.stack([-gu[:, 1], gu[:, 0]], 1)
    rel = seg[:, None, :, :] - g0[None, :, None, :]  # [N, G, 2, 2]
    perp = np.abs(np.einsum("ngkc,gc->ngk", rel, gn)).max(-1)
    along = np.einsum("ngkc,gc->ngk", rel, gu)
    a, b = along.min(-1), along.max(-1)
    inside = np.clip(np.minimum(b, glen[None]) - np.maximum(a, 0.0), 0, None)
    return (perp <= tol) & (inside >= 0.5 * np.maximum(b - a, 1e-9))


def evaluate_matches(
    pair: SyntheticPair,
    matches: PairMatches,
    point_px: float = 2.0,
    line_px: float = 4.0,
    recall_px: float = 2.5,
) -> dict:
    """Scores matches found on a generated pair against its exact ground truth.

    Returns a dict with: ``num_points``; ``point_inlier_ratio`` (Sampson error under the true
    pose below ``point_px``); ``point_correct_ratio`` (plane transfer error below
    ``point_px``); ``num_lines``; ``line_epipolar_precision`` (both endpoints' Sampson errors
    below ``point_px``); ``line_precision`` (line transfer error below ``line_px``);
    ``line_recall`` (fraction of the ground-truth lines of ``pair.lines_clean*`` on which a
    correct match lies, within ``recall_px``, in both images).
    """
    if matches.num_lines and not matches.line_endpoints_correspond:
        raise ValueError("Expected lines whose endpoint k matches endpoint k (got "
                         f"info['{LINE_ENDPOINTS}'] = '{ENDPOINTS_AS_DETECTED}': the descriptor "
                         "matcher's segments as detected, which have no endpoint errors)")
    pe, le = epipolar_residuals(matches, pair.T_0to1)
    out = {"num_points": matches.num_points, "num_lines": matches.num_lines}
    if matches.num_points:
        pt = point_transfer_error(pair, matches.points0, matches.points1)
        out["point_inlier_ratio"] = float((pe < point_px).mean())
        out["point_correct_ratio"] = float((pt < point_px).mean())
    lt = line_transfer_error(pair, matches.lines0, matches.lines1)
    correct = lt < line_px
    out["line_epipolar_precision"] = float((le < point_px).mean()) if len(le) else float("nan")
    out["line_precision"] = float(correct.mean()) if len(lt) else float("nan")
    g0, g1 = pair.lines_clean0, pair.lines_clean1
    if len(g0) and correct.any():
        hit = _on_segment(matches.lines0[correct], g0, recall_px) & _on_segment(
            matches.lines1[correct], g1, recall_px)
        out["line_recall"] = float(hit.any(0).mean())
    else:
        out["line_recall"] = 0.0 if len(g0) else float("nan")
    out["num_gt_lines"] = len(g0)
    return out
