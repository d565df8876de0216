"""``bench_real_scenes.py``: PoseLib is scored on every pair where it returns a pose, the same
way Table 3's report scores it, not only where the estimator's support checks keep it."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_pose as bp  # noqa: E402
import bench_real_scenes as brs  # noqa: E402

from strl_pyg.estimation.classical import estimate_relative_pose  # noqa: E402
from strl_pyg.synthetic import SceneConfig, generate_pair  # noqa: E402

pytest.importorskip("poselib")


def _few_matches(seed: int, inliers: int, outliers: int):
    """A pair with ``inliers`` exact point matches and ``outliers`` wrong ones: too few for
    the estimator's support check, enough for PoseLib to return a pose."""
    p = generate_pair(seed, SceneConfig(kind="street", image_size=(96, 256)))
    m = p.matches.select(point_index=np.arange(inliers + outliers), line_index=[])
    pts1 = np.array(m.points1, dtype=np.float64)
    rng = np.random.default_rng(seed)
    pts1[inliers:] = rng.uniform([0, 0], [256, 96], size=(outliers, 2))
    m = type(m)(points0=m.points0, points1=pts1, image_size0=m.image_size0,
                image_size1=m.image_size1, K0=m.K0, K1=m.K1)
    return m, np.asarray(p.T_0to1, dtype=np.float64)


def test_poselib_is_scored_where_the_estimator_would_refuse_its_pose():
    from strl_pyg.inference import PoseEstimator
    from strl_pyg.model.strl_pose import StrLPose

    model = StrLPose.from_pretrained("geometric")
    pairs = []
    for seed in (3, 5, 8):
        m, T = _few_matches(seed, 9, 5)
        pairs.append((f"street/{seed}", m, T))
    refused = [PoseEstimator(model, methods=("poselib",)).estimate(m).methods["poselib"].status
               for _, m, _ in pairs]
    assert "failed" in refused  # the estimator's checks refuse a pose PoseLib returned
    out = brs.score(model, pairs, with_poselib=True)
    want = []
    for _, m, T in pairs:  # the reference: PoseLib itself, the estimator's threshold and seed
        res = estimate_relative_pose(m, "poselib", 1.0, seed=0)
        assert res.success
        want.append(bp.errors(res.T_0to1.matrix().numpy(), T))
    np.testing.assert_allclose(out["pl_rot"], [w[0] for w in want], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(out["pl_trans"], [w[1] for w in want], rtol=1e-9, atol=1e-9)
    assert out["rot"].shape == out["hit"].shape == (3,)
