"""The line matcher that needs no fundamental matrix (band descriptors)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from strl_pyg.frontend import FrontendConfig
from strl_pyg.frontend.line_descriptors import band_descriptors
from strl_pyg.frontend.lines import detect_lines, match_lines_by_descriptor

#: sha1 of the default FrontendConfig's result fields before the descriptor matcher was added
DEFAULT_FIELDS_SHA = "3fdee2614eec"


def _scene(seed: int = 0, shape=(240, 320)) -> np.ndarray:
    """Grey image with rectangles of distinct contrasts (edges of many orientations)."""
    rng = np.random.default_rng(seed)
    img = np.full(shape, 90, np.uint8)
    for _ in range(12):
        x0, y0 = rng.integers(10, shape[1] - 80), rng.integers(10, shape[0] - 60)
        w, h = rng.integers(25, 70), rng.integers(20, 50)
        cv2.rectangle(img, (int(x0), int(y0)), (int(x0 + w), int(y0 + h)),
                      int(rng.integers(0, 256)), -1)
    return cv2.GaussianBlur(img, (0, 0), 0.8)


def test_band_descriptors_shape_norm_and_empty():
    g = _scene()
    segs = detect_lines(g)
    d = band_descriptors(segs, g)
    assert d.shape == (len(segs), 72) and len(segs) > 10
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-9)
    assert band_descriptors(np.zeros((0, 2, 2)), g).shape == (0, 72)


def test_a_fragment_describes_like_its_segment(generated_pair):
    # the descriptor pools along the segment: the middle 60 % of an edge is closer to the whole
    # edge than any other segment is (on a rendered scene: the plain step edges of _scene all
    # describe alike, a limit of any band descriptor)
    img = generated_pair(5).image0
    g = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
    segs = detect_lines(g)[:40]
    frag = segs[:, :1] + np.array([0.2, 0.8])[None, :, None] * (segs[:, 1:] - segs[:, :1])
    a, b = band_descriptors(segs, g), band_descriptors(frag, g)
    dist = np.linalg.norm(a[:, None] - b[None], axis=2)
    assert (dist.argmin(axis=0) == np.arange(len(segs))).mean() >= 0.8  # measured 0.9


def test_a_shifted_image_matches_every_segment_to_its_shifted_copy():
    g0 = _scene(2, (260, 340))
    shift = np.array([7.0, 4.0])
    g1 = np.full_like(g0, 90)
    g1[4:, 7:] = g0[:-4, :-7]
    s0, s1 = detect_lines(g0[20:-20, 20:-20]) + 20, detect_lines(g1[20:-20, 20:-20]) + 20
    l0, l1, sc = match_lines_by_descriptor(s0, s1, g0, g1)
    assert len(l0) >= 10
    # each match is the same edge: the image-1 segment lies on the shifted image-0 segment
    d = l1[:, 1] - l1[:, 0]
    n = np.stack([-d[:, 1], d[:, 0]], 1) / np.linalg.norm(d, axis=1, keepdims=True)
    off = np.abs(np.einsum("ikj,ij->ik", l0 + shift - l1[:, :1], n))
    assert (off.max(axis=1) < 1.5).mean() >= 0.9
    assert (np.diff(sc) <= 0).all() and ((sc >= 0) & (sc <= 1)).all()


def test_no_segments_and_bad_ratio():
    g = _scene(3)
    s = detect_lines(g)
    empty = match_lines_by_descriptor(np.zeros((0, 2, 2)), s, g, g)
    assert [len(x) for x in empty] == [0, 0, 0]
    with pytest.raises(ValueError, match="line_descriptor_ratio in"):
        FrontendConfig(line_descriptor_ratio=1.5)
    # one candidate in image 1: no second nearest, no ratio, no match (it was kept before)
    assert len(match_lines_by_descriptor(s[:5], s[:1], g, g)[0]) == 0
    assert len(match_lines_by_descriptor(s[:5], s[:2], g, g)[0]) >= 1  # itself: exact


@pytest.mark.parametrize("bad, msg", [
    (np.zeros((3, 2)), "shape \\[N, 2, 2\\]"),
    (np.array([[[0.0, 0.0], [np.nan, 5.0]]]), "finite"),
    (np.array([[[10.0, 10.0], [10.0, 10.0]]]), "at least 1 px long"),
])
def test_band_descriptors_bad_input_is_one_line(bad, msg):
    g = _scene(4)
    with pytest.raises(ValueError, match=msg):
        band_descriptors(bad, g)
    with pytest.raises(ValueError, match="grey image"):
        band_descriptors(detect_lines(g)[:3], np.dstack([g, g, g]))


def test_guidance_narrows_the_candidates_and_keeps_the_ratio_test(generated_pair):
    pair = generated_pair(5)
    g0 = cv2.cvtColor(pair.image0, cv2.COLOR_RGB2GRAY) if pair.image0.ndim == 3 else pair.image0
    g1 = cv2.cvtColor(pair.image1, cv2.COLOR_RGB2GRAY) if pair.image1.ndim == 3 else pair.image1
    s0, s1 = detect_lines(g0), detect_lines(g1)
    m = pair.matches
    guide = (np.asarray(m.points0), np.asarray(m.points1))
    free = match_lines_by_descriptor(s0, s1, g0, g1)
    guided = match_lines_by_descriptor(s0, s1, g0, g1, guide=guide)
    key = lambda out: {(tuple(a.ravel()), tuple(b.ravel())) for a, b in zip(*out[:2], strict=True)}  # noqa: E731
    assert 0 < len(guided[0]) and key(guided) <= key(free)  # a subset: never a looser match
    # a guide that points elsewhere (all displacements 200 px off) leaves almost nothing
    wrong = match_lines_by_descriptor(s0, s1, g0, g1, guide=(guide[0], guide[1] + 200.0))
    assert len(wrong[0]) < len(guided[0]) / 2


def test_config_line_matcher_and_cache_key():
    import hashlib
    import json

    def sha(cfg):
        text = json.dumps(cfg.result_fields(), sort_keys=True, default=repr)
        return hashlib.sha1(text.encode()).hexdigest()[:12]

    # earlier caches keep their keys: the legacy preset's fields (the defaults before the
    # presets) hash as before line_matcher existed (a new field must not enter that key
    # unnoticed); the present defaults make other matches, so their key differs
    legacy = FrontendConfig.preset("legacy")
    assert sha(legacy) == DEFAULT_FIELDS_SHA
    assert sha(FrontendConfig()) != DEFAULT_FIELDS_SHA
    fields = FrontendConfig().result_fields()
    assert "line_matcher" not in fields and "line_descriptor_ratio" not in fields
    assert FrontendConfig(line_matcher="descriptor").result_fields()["line_matcher"] == \
        "descriptor"
    with pytest.raises(ValueError, match="line_matcher in"):
        FrontendConfig(line_matcher="lbd")


def test_match_images_descriptor_matcher_below_eight_points(generated_pair):
    from strl_pyg.frontend import match_images

    pair = generated_pair(5)
    few = dict(max_keypoints=12, thorough_below=0)  # a point-poor front end
    epi = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                       config=FrontendConfig(**few))
    desc = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                        config=FrontendConfig(line_matcher="descriptor", **few))
    assert epi.num_points < 8 and epi.num_lines == 0  # no F: the epipolar matcher has none
    assert desc.num_points == epi.num_points and desc.num_lines >= 10
    assert desc.info["line_endpoints"] == "as detected"
    assert epi.info["line_endpoints"] == "corresponding"


def test_network_methods_refuse_descriptor_lines(generated_pair):
    from dataclasses import replace

    from strl_pyg.frontend import match_images
    from strl_pyg.inference import PoseEstimator

    pair = generated_pair(6)
    m = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                     config=FrontendConfig(line_matcher="descriptor"))
    assert m.num_points >= 8 and m.num_lines > 0
    est = PoseEstimator(methods=["regression", "poselib"]).estimate(m)
    reg = est.methods["regression"]
    assert reg.status == "failed" and "descriptor matcher" in reg.warnings[0]
    assert est.methods["poselib"].status == "ok"  # points only: unaffected
    # the same matches flagged as corresponding run the network as before
    ok = PoseEstimator(methods=["regression"]).estimate(
        replace(m, info={**m.info, "line_endpoints": "corresponding"}))
    assert ok.methods["regression"].status == "ok"


def test_graph_and_datasets_refuse_descriptor_lines(tmp_path, generated_pair):
    # every path into the network, not only PoseEstimator: prepare_graph (network_pose, the
    # evaluation, the CLI) and the training datasets
    from strl_pyg.datasets.synthetic import SyntheticPairs
    from strl_pyg.frontend import match_images
    from strl_pyg.inference.network import prepare_graph
    from strl_pyg.model.strl_pose import StrLPose

    pair = generated_pair(6)
    m = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                     config=FrontendConfig(line_matcher="descriptor"))
    assert not m.line_endpoints_correspond and pair.matches.line_endpoints_correspond
    with pytest.raises(ValueError, match="descriptor matcher"):
        prepare_graph(m, StrLPose.from_pretrained())
    with pytest.raises(ValueError, match="line_matcher='epipolar' for a dataset"):
        SyntheticPairs(4, matches="frontend", cache_dir=tmp_path,
                             frontend_config=FrontendConfig(line_matcher="descriptor"))


def test_endpoint_residuals_are_undefined_for_descriptor_lines(generated_pair):
    # endpoint k of a descriptor-matched segment is not endpoint k of its match: no epipolar
    # residual (NaN) and no endpoint-based match quality, instead of numbers that look real
    from dataclasses import replace

    from strl_pyg.frontend import match_images
    from strl_pyg.geometry.epipolar import epipolar_residuals
    from strl_pyg.synthetic.match_quality import evaluate_matches

    pair = generated_pair(6)
    m = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K,
                     config=FrontendConfig(line_matcher="descriptor"))
    assert m.num_lines > 0
    pe, le = epipolar_residuals(m, pair.T_0to1)
    assert len(pe) == m.num_points and np.isfinite(pe).all() and np.median(pe) < 1.0
    assert le.shape == (m.num_lines,) and np.isnan(le).all()
    as_corresponding = replace(m, info={**m.info, "line_endpoints": "corresponding"})
    assert np.isfinite(epipolar_residuals(as_corresponding, pair.T_0to1)[1]).all()
    with pytest.raises(ValueError, match=r"Expected lines whose endpoint k matches endpoint k "
                                         r"\(got info\['line_endpoints'\] = 'as detected'"):
        evaluate_matches(pair, m)
    assert evaluate_matches(pair, pair.matches)["num_lines"] == pair.matches.num_lines
    # no lines at all: nothing to refuse, the points are scored
    no_lines = replace(m, lines0=None, lines1=None, line_scores=None)
    assert evaluate_matches(pair, no_lines)["num_points"] == m.num_points
