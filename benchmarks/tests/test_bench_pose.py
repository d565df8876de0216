"""benchmarks/bench_pose.py.

The match cache (``match_cache`` / ``_cached``): an entry is read back only for the same
front-end configuration and the same generated distribution. Reproduces the bug it fixes: the
cache was keyed by the pair's name alone (``gen_driving_7``), so matches made for another
distribution or by another front end were silently reused with a new ground truth.

``--calibrate`` fits on the checkpoint with its calibration removed (``uncalibrated``)."""

from __future__ import annotations

import bench_pose
import numpy as np
import pytest

from strl_pyg.data.matches import PairMatches
from strl_pyg.frontend import FrontendConfig
from strl_pyg.inference import PoseEstimator
from strl_pyg.model import StrLPose
from strl_pyg.synthetic import generate_pair
from strl_pyg.synthetic.distributions import eval_distribution


def _matches(n: int, offset: float = 0.0) -> PairMatches:
    rng = np.random.default_rng(n)
    p0 = rng.uniform(10, 200, size=(n, 2)) + offset
    return PairMatches(points0=p0, points1=p0 + 3.0, image_size0=(240, 320),
                       image_size1=(240, 320))


class _Maker:
    def __init__(self, m: PairMatches):
        self.m, self.calls = m, 0

    def __call__(self) -> PairMatches:
        self.calls += 1
        return self.m


def test_same_fingerprint_reads_back_without_matching_again(tmp_path):
    dist = eval_distribution("driving")
    first = _Maker(_matches(12))
    a = bench_pose._cached(tmp_path, "gen_driving_7", first, scene=dist)
    again = _Maker(_matches(30))
    b = bench_pose._cached(tmp_path, "gen_driving_7", again, scene=dist)
    assert (first.calls, again.calls) == (1, 0)
    np.testing.assert_array_equal(np.asarray(a.points0), np.asarray(b.points0))
    # one folder per fingerprint, with the fingerprint written beside the entries
    (folder,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert (folder / "fingerprint.json").is_file()
    assert (folder / "gen_driving_7.npz").is_file()


def test_another_distribution_or_front_end_is_not_served_stale_matches(tmp_path):
    driving = eval_distribution("driving")
    bench_pose._cached(tmp_path, "gen_x_7", _Maker(_matches(12)), scene=driving)
    other_scene = _Maker(_matches(20))
    m = bench_pose._cached(tmp_path, "gen_x_7", other_scene, scene=eval_distribution("indoor"))
    assert other_scene.calls == 1 and m.num_points == 20
    other_frontend = _Maker(_matches(25))
    m = bench_pose._cached(tmp_path, "gen_x_7", other_frontend,
                           FrontendConfig.preset("legacy", max_keypoints=512),
                           scene=eval_distribution("driving"))
    assert other_frontend.calls == 1 and m.num_points == 25
    # the first entry is still there for its own fingerprint
    same = _Maker(_matches(40))
    m = bench_pose._cached(tmp_path, "gen_x_7", same, scene=eval_distribution("driving"))
    assert same.calls == 0 and m.num_points == 12


def test_a_failed_match_stores_nothing_and_is_retried(tmp_path):
    def fails():
        raise RuntimeError("no scene")

    with pytest.raises(RuntimeError, match="no scene"):
        bench_pose._cached(tmp_path, "calib_1", fails)
    retry = _Maker(_matches(9))
    assert bench_pose._cached(tmp_path, "calib_1", retry).num_points == 9
    assert retry.calls == 1


def test_a_corrupt_entry_is_made_again(tmp_path):
    bench_pose._cached(tmp_path, "dino_a_b", _Maker(_matches(10)))
    path = bench_pose.match_cache(tmp_path).path("dino_a_b")
    path.write_bytes(b"not an npz")
    redo = _Maker(_matches(11))
    with pytest.warns(UserWarning, match="Corrupt cache entry"):
        m = bench_pose._cached(tmp_path, "dino_a_b", redo)
    assert redo.calls == 1 and m.num_points == 11


def test_the_calibration_fit_reads_raw_covariances():
    """`bench_pose.py --calibrate` fits on the
    checkpoint with its calibration removed; with the shipped fallback, PoseLib's covariance
    would have been scaled during the fit, and the stored scale ~1 (sigma 4-5x too small)."""
    pair = generate_pair(2_000_017)
    m = pair.matches
    matches = PairMatches(m.points0, m.points1, m.lines0, m.lines1, K0=pair.K, K1=pair.K,
                          image_size0=pair.image0.shape[:2], image_size1=pair.image1.shape[:2])
    model = StrLPose.from_pretrained()
    md = bench_pose.uncalibrated(model.metadata)
    assert md["calibration"] == {} and "recommended_order" not in md
    model.metadata = md
    rec = PoseEstimator(model, methods="poselib").estimate(matches).pose
    assert rec.status == "ok" and "calibration_scale" not in rec.info
