"""Own checkpoints, intrinsics of resized images, match files without K, line segments in
other conventions: each case as a user met it, then what it gets."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from strl_pyg import PairMatches
from strl_pyg.inference import PoseEstimator
from strl_pyg.model import StrLPose, StrLPoseConfig
from strl_pyg.synthetic import generate_pair


@pytest.fixture(scope="module")
def pair():
    return generate_pair(2_000_017)


def _pm(pair, **kw):
    m = pair.matches
    return PairMatches(m.points0, m.points1, m.lines0, m.lines1, K0=pair.K, K1=pair.K,
                       image_size0=pair.image0.shape[:2], image_size1=pair.image1.shape[:2],
                       **kw)


# ------------------------------------------------------------ a checkpoint of one's own
def test_own_checkpoint_keeps_poselib_calibrated(pair, tmp_path):
    """Before: `--checkpoint runs/tiny/model.pt` (a 20-step run, no --calibrate) shrank
    PoseLib's sigma on a KITTI pair from 0.027 / 0.334 to 0.006 / 0.077 deg (its error
    0.14 / 0.59): PoseLib's calibration was read from the given checkpoint, which has none.
    PoseLib's covariance does not read the network: the shipped scale applies."""
    own = StrLPose(StrLPoseConfig(hidden=32, layers=1, heads=2))
    path = tmp_path / "own.pt"
    own.save(path)
    m = _pm(pair)
    shipped = PoseEstimator(methods="poselib").estimate(m).pose
    mine = PoseEstimator(path, methods="poselib").estimate(m).pose
    assert shipped.status == mine.status == "ok"
    np.testing.assert_allclose(mine.covariance, shipped.covariance, rtol=1e-9)
    assert mine.info["calibration_from"] == "shipped"
    assert "calibration_from" not in shipped.info
    # a checkpoint that says "calibration: none yet" (benchmarks/bench_pose.py --calibrate
    # while it fits) gets the raw covariance: the fit must not read the shipped scale
    own.metadata = {**own.metadata, "calibration": {}}
    raw = PoseEstimator(own, methods="poselib").estimate(m).pose
    assert "calibration_scale" not in raw.info
    np.testing.assert_allclose(raw.covariance * shipped.info["calibration_scale"],
                               shipped.covariance, rtol=1e-9)
    # a method that reads the network keeps only the checkpoint's own scale: none here
    reg = PoseEstimator(own, methods="regression").estimate(
        _pm(pair, image0=pair.image0, image1=pair.image1)).methods["regression"]
    assert "calibration_scale" not in reg.info
    assert any("regression: covariance not calibrated" in w for w in reg.warnings)


def test_uncalibrated_sigma_is_named_in_the_python_record(pair):
    """Before: `vp`'s covariance is not calibrated (docs/methods.md said "the pose's
    warnings say so"), yet `est.pose.warnings == []`: only the CLI printed it."""
    est = PoseEstimator(methods=("poselib", "vp")).estimate(_pm(pair))
    vp = est.methods["vp"]
    assert vp.status == "ok" and "calibration_scale" not in vp.info
    assert any(w.startswith("vp: covariance not calibrated") for w in vp.warnings)
    assert not any("not calibrated" in w for w in est.methods["poselib"].warnings)
    # vp_checked carries a classical record's calibrated covariance: no such warning
    # (found in review)
    chk = PoseEstimator(methods=("poselib", "vp", "vp_checked")).estimate(
        _pm(pair)).methods["vp_checked"]
    assert chk.info.get("calibration_scale") is not None  # PoseLib's record, kept here
    assert not any("not calibrated" in w for w in chk.warnings)


# ------------------------------------------------------------ K of the image before a resize
def test_k_of_the_full_size_image_on_a_resized_one_is_unreliable(pair):
    """Before: KITTI 20 -> 23 resized by 0.5 with the full-size K: 'ok' from poselib, sigma
    0.15 / 0.66 deg, no warning, 24 deg off in translation; the principal point (601, 183)
    lay inside the 613x185 image (at 99 % of its height), so no check saw it."""
    m, (h, w) = pair.matches, pair.image0.shape[:2]
    half = dict(image_size0=(h // 2, w // 2), image_size1=(h // 2, w // 2))
    est = PoseEstimator(methods="poselib").estimate(
        PairMatches(m.points0 / 2, m.points1 / 2, K0=pair.K, K1=pair.K, **half))
    assert est.status == "unreliable" and est.T_0to1 is None
    assert any("K looks made for the image 2x this size" in w and "K[:2] *= 0.5" in w
               for w in est.warnings)
    # the K of the half-size image on it: no such warning, a pose
    K = pair.K.copy()
    K[:2] *= 0.5
    ok = PoseEstimator(methods="poselib").estimate(
        PairMatches(m.points0 / 2, m.points1 / 2, K0=K, K1=K, **half))
    assert ok.status == "ok" and not any("looks made" in w for w in ok.warnings)
    # the other way round (the half-size K on the full image), and a crop that moves the
    # principal point in one axis only is not taken for a resize
    from strl_pyg.inference.checks import intrinsics_problems

    assert any("0.5x this size" in p for p in intrinsics_problems((h, w), (h, w), K, K))
    crop = pair.K.copy()
    crop[0, 2] = 0.9 * w
    assert intrinsics_problems((h, w), (h, w), crop, crop) == []


# ------------------------------------------------------------ a match file without K
def test_match_file_without_k_prints_one_line_each(pair, tmp_path, capsys):
    """Before: `strl-pose predict --matches lg.npz` (a LightGlue file whose matches reuse
    keypoints of image 1, no K, no images) printed Python's warning with its source line
    (`.../formats.py:174: UserWarning: ...` then `kw = READERS[fmt](...)`), said
    `regression skipped: regression skipped: ...` and warned that "the network's coordinates
    are normalised by the image size" though the network did not run."""
    from strl_pyg.cli import main as cli_main

    m = pair.matches
    n = 200
    idx = np.stack([np.arange(n), np.arange(n)], 1)
    idx[150:, 1] = idx[:50, 1]  # 50 matches onto keypoints of image 1 already matched
    path = tmp_path / "lg.npz"
    size = np.array(pair.image0.shape[:2][::-1])  # LightGlue's image_size is (W, H)
    np.savez(path, keypoints0=m.points0[:n], keypoints1=m.points1[:n], matches=idx,
             scores=np.ones(n), image_size0=size, image_size1=size)
    rc = cli_main(["predict", "--matches", str(path)])
    out, err = capsys.readouterr()
    assert rc == 1 and "pose: failed" in out and "fundamental matrix" in out
    assert "UserWarning" not in err and "formats.py" not in err and "READERS" not in err
    assert "warning: Expected one-to-one matches in 'matches'" in err
    assert "regression skipped: regression skipped" not in err + out
    assert "regression skipped: the model reads the images" in out + err
    assert "the network's coordinates are normalised" not in out + err


def test_size_given_as_w_h_is_named(pair):
    """Before: a size passed as (W, H) = (1226, 370) with points of a 370x1226 image said
    "inside the 370x1226 image", which read as right to the user (the message printed
    W x H, everything else H x W), with no hint that the size was transposed."""
    m, (h, w) = pair.matches, pair.image0.shape[:2]
    with pytest.raises(ValueError, match=rf"inside the {w}x{h} px image \(H x W.*"
                                         r"was image_size0 given as \(W, H\)\? Sizes are \(H, W\)"):
        PairMatches(m.points0, m.points1, image_size0=(w, h), image_size1=(w, h))


# ------------------------------------------------------------ a PyG user's habits
def test_attention_conv_pyg_habits_get_one_line_each():
    """Before: `AttentionConv(32, 64)` (GATConv's in, out) said "got 64 heads for 32
    channels" without saying the second argument is heads; `out_channels=64` was a raw
    TypeError from MessagePassing.__init__; an int32 edge_index was
    `RuntimeError: expected scalar type Long but found Int` from PyG's scatter."""
    import torch

    from strl_pyg.nn import AttentionConv, LineEndpointConv

    with pytest.raises(ValueError, match=r"got 64 heads for 32 channels\) \(AttentionConv"
                                         r"\(channels, heads\): the second argument"):
        AttentionConv(32, 64)
    with pytest.raises(TypeError, match=r"^Expected no out_channels .*\(got out_channels=64\)$"):
        AttentionConv(32, out_channels=64)
    torch.manual_seed(0)
    conv = AttentionConv(32, heads=4)
    x = torch.randn(6, 32)
    ei = torch.tensor([[0, 1, 2, 3, 4, 5, 0], [1, 2, 3, 4, 5, 0, 3]])
    torch.testing.assert_close(conv(x, ei.int()), conv(x, ei))
    from torch_geometric import EdgeIndex

    torch.testing.assert_close(conv(x, EdgeIndex(ei.int(), sparse_size=(6, 6))), conv(x, ei))
    with pytest.raises(ValueError, match=r"^Expected an integer edge_index \(got torch.float32\)$"):
        conv(x, ei.float())
    line = LineEndpointConv(32, line_channels=8)
    lf = torch.randn(6, 8)
    torch.testing.assert_close(line(x, ei.int(), lf), line(x, ei, lf))


# ------------------------------------------------------------ line segments of one's own
def test_lsd_rows_are_read_as_segments(pair):
    """Before: OpenCV's LSD output, (N, 1, 4) rows (x1, y1, x2, y2), or its (N, 4) squeeze
    was refused ("Expected 'lines0' of shape [N, 2, 2]") with no hint."""
    m = pair.matches
    ref = PairMatches(m.points0, m.points1, m.lines0, m.lines1, image_size0=m.image_size0,
                      image_size1=m.image_size1)
    for shape in ((-1, 4), (-1, 1, 4)):
        got = PairMatches(m.points0, m.points1, m.lines0.reshape(shape).astype(np.float32),
                          m.lines1.reshape(shape), image_size0=m.image_size0,
                          image_size1=m.image_size1)
        np.testing.assert_allclose(got.lines0, ref.lines0, rtol=1e-6)
        np.testing.assert_array_equal(got.lines1, ref.lines1)
    with pytest.raises(ValueError, match=r"Expected 'lines0' of shape \[N, 2, 2\] \(got \(5, 3\)\)"):
        PairMatches(m.points0, m.points1, np.ones((5, 3)), np.ones((5, 3)),
                    image_size0=m.image_size0, image_size1=m.image_size1)


def test_flipped_line_endpoints_are_named(pair):
    """Before: reversing half of lines1's endpoints (one's own LSD matching keeps the
    detector's order) gave no warning; the regression went from 0.53 / 3.5 to 1.45 / 14 deg
    on a KITTI pair."""
    from strl_pyg.data.matches import ENDPOINTS_AS_DETECTED, LINE_ENDPOINTS

    m = _pm(pair)
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


def test_a_rolled_camera_or_outlier_lines_are_not_flipped_endpoints(pair):
    """Found in review: the first version of the check compared directions without the
    pair's own turning, so image 1 turned by 180 deg with rightly matched endpoints gave
    "256 of 256 line matches run opposite ways", and 40 % random outlier lines crossed the
    threshold too."""
    from strl_pyg.inference.checks import flipped_lines

    m = pair.matches
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


def test_mistyped_set_key_names_the_closest(capsys):
    """Before: `--set hiden=3` listed every field without the "did you mean" that `--k` and
    `--methods poselibb` get."""
    from strl_pyg.training.config import TrainConfig

    with pytest.raises(ValueError, match=r"\(got hiden\); did you mean hidden\?$"):
        TrainConfig(model_overrides={"hiden": 3}).model_config()
    with pytest.raises(ValueError, match=r"\(got zzz\)$"):
        TrainConfig(model_overrides={"zzz": 3}).model_config()
