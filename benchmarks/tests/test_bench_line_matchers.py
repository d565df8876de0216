"""benchmarks/studies/bench_line_matchers.py's geometry check (``consistent``): the band
descriptor matcher's matches on a generated pair are consistent with the true epipolar
geometry, and the same segments paired with another's match mostly are not (the check's
chance level)."""

from __future__ import annotations

import cv2
import numpy as np
from bench_line_matchers import consistent

from strl_pyg.frontend.lines import detect_lines, match_lines_by_descriptor
from strl_pyg.geometry.epipolar import fundamental_from_pose
from strl_pyg.synthetic import generate_pair


def test_generated_pair_matches_follow_the_true_geometry():
    pair = generate_pair(5)
    g0 = cv2.cvtColor(pair.image0, cv2.COLOR_RGB2GRAY) if pair.image0.ndim == 3 else pair.image0
    g1 = cv2.cvtColor(pair.image1, cv2.COLOR_RGB2GRAY) if pair.image1.ndim == 3 else pair.image1
    s0, s1 = detect_lines(g0), detect_lines(g1)
    l0, l1, _ = match_lines_by_descriptor(s0, s1, g0, g1)
    assert len(l0) >= 10
    K = np.asarray(pair.K, dtype=np.float64)
    c = consistent(l0, l1, fundamental_from_pose(pair.T_0to1, K, K))
    assert (c >= 0).sum() >= 5
    assert (c == 1).sum() / (c >= 0).sum() >= 0.8
    # each segment paired with another's match, the same check passes far less often
    cr = consistent(l0, np.roll(l1, 1, axis=0),
                    fundamental_from_pose(pair.T_0to1, K, K))
    assert (cr == 1).sum() / max((cr >= 0).sum(), 1) < 0.5
