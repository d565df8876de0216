"""The estimator's input checks (strl_pyg.inference.checks): the K of an image before a
resize, line matches whose endpoints run opposite ways, and what is taken for neither."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from strl_pyg.data.matches import PairMatches
from strl_pyg.inference.estimator import PoseEstimator


def _pm(pair, **kw):
    m = pair.matches
    return PairMatches(m.points0, m.points1, m.lines0, m.lines1, K0=pair.K, K1=pair.K,
                       image_size0=pair.image0.shape[:2], image_size1=pair.image1.shape[:2],
                       **kw)


def test_k_of_the_full_size_image_on_a_resized_one_is_unreliable(held_out_pair):
    """Before: KITTI 20 -> 23 resized by 0.5 with the full-size K: 'ok' from poselib, sigma
    0.15 / 0.66 deg, no warning, 24 deg off in translation; the principal point (601, 183)
    lay inside the 613x185 image (at 99 % of its height), so no check saw it."""
    m, (h, w) = held_out_pair.matches, held_out_pair.image0.shape[:2]
    half = dict(image_size0=(h // 2, w // 2), image_size1=(h // 2, w // 2))
    est = PoseEstimator(methods="poselib").estimate(
        PairMatches(m.points0 / 2, m.points1 / 2, K0=held_out_pair.K, K1=held_out_pair.K, **half))
    assert est.status == "unreliable" and est.T_0to1 is None
    assert any("K looks made for the image 2x this size" in w and "K[:2] *= 0.5" in w
               for w in est.warnings)
    # the K of the half-size image on it: no such warning, a pose
    K = held_out_pair.K.copy()
    K[:2] *= 0.5
    ok = PoseEstimator(methods="poselib").estimate(
        PairMatches(m.points0 / 2, m.points1 / 2, K0=K, K1=K, **half))
    assert ok.status == "ok" and not any("looks made" in w for w in ok.warnings)
    # the other way round (the half-size K on the full image), and a crop that moves the
    # principal point in one axis only is not taken for a resize
    from strl_pyg.inference.checks import intrinsics_problems

    assert any("0.5x this size" in p for p in intrinsics_problems((h, w), (h, w), K, K))
    crop = held_out_pair.K.copy()
    crop[0, 2] = 0.9 * w
    assert intrinsics_problems((h, w), (h, w), crop, crop) == []


def test_flipped_line_endpoints_are_named(held_out_pair):
    """Before: reversing half of lines1's endpoints (one's own LSD matching keeps the
    detector's order) gave no warning; the regression went from 0.53 / 3.5 to 1.45 / 14 deg
    on a KITTI pair."""
    from strl_pyg.data.matches import ENDPOINTS_AS_DETECTED, LINE_ENDPOINTS

    m = _pm(held_out_pair)
    clean = PoseEstimator(methods="poselib").estimate(m)
    assert not any("run opposite ways" in w for w in clean.warnings)
    flipped = m.lines1.copy()
    flipped[::2] = flipped[::2, ::-1]
    est = PoseEstimator(methods="poselib").estimate(replace(m, lines1=flipped))
    n = m.num_lines
    assert any(w.startswith(f"{n // 2} of {n} line matches run opposite ways")
               for w in est.warnings)
    # said so: no warning
    said = PoseEstimator(methods="poselib").estimate(
        replace(m, lines1=flipped, info={LINE_ENDPOINTS: ENDPOINTS_AS_DETECTED}))
    assert not any("run opposite ways" in w for w in said.warnings)


def test_a_rolled_camera_or_outlier_lines_are_not_flipped_endpoints(held_out_pair):
    """Found in review: the first version of the check compared directions without the
    pair's own turning, so image 1 turned by 180 deg with rightly matched endpoints gave
    "256 of 256 line matches run opposite ways", and 40 % random outlier lines crossed the
    threshold too."""
    from strl_pyg.inference.checks import flipped_lines

    m = held_out_pair.matches
    h, w = m.image_size1
    turned = np.array([w - 1.0, h - 1.0]) - m.lines1  # 180 deg about the image centre
    assert flipped_lines(replace(m, lines1=turned)) == []
    rng = np.random.default_rng(0)
    noisy = m.lines1.copy()
    k = int(0.4 * len(noisy))
    noisy[:k] = rng.uniform([0, 0], [w - 1, h - 1], size=(k, 2, 2))
    assert flipped_lines(replace(m, lines1=noisy)) == []
    # turned and half flipped: named
    half = turned.copy()
    half[::2] = half[::2, ::-1]
    assert flipped_lines(replace(m, lines1=half))

