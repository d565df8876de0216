"""Front-end presets and the point settings they choose: RootSIFT, a lower contrast
threshold, 2x upsampling of small images, the adaptive second pass, and the cache keys."""

from __future__ import annotations

import argparse

import cv2
import numpy as np
import pytest

from strl_pyg.frontend import FrontendConfig, match_images, match_points
from strl_pyg.frontend.config import PRESETS
from strl_pyg.frontend.pipeline import thorough_points
from strl_pyg.frontend.points import detect_points, root_sift, upsample_factor


def _textured(seed: int = 0, size=(240, 320)) -> np.ndarray:
    """A grey image with blobs and edges at many scales (SIFT finds hundreds of keypoints)."""
    rng = np.random.default_rng(seed)
    noise = rng.random((size[0] // 8, size[1] // 8)).astype(np.float32)
    img = cv2.resize(noise, (size[1], size[0]), interpolation=cv2.INTER_CUBIC)
    fine = cv2.GaussianBlur(rng.random(size).astype(np.float32), (0, 0), 1.2)
    img = 0.7 * img + 0.3 * fine
    img = (255 * (img - img.min()) / (img.max() - img.min())).astype(np.uint8)
    return img


def _shifted_pair(dx: int = 7, dy: int = 4):
    big = _textured(3, (260, 340))
    return big[10:250, 10:330].copy(), big[10 - dy:250 - dy, 10 - dx:330 - dx].copy(), (dx, dy)


def test_root_sift_is_integer_hellinger():
    d = np.zeros((2, 128), np.float32)
    d[0, 0] = 4.0  # all mass in one bin: sqrt(1) * 512 -> clipped at 255
    d[1, :4] = 1.0  # four equal bins: sqrt(1/4) * 512 = 256 -> 255; 0 elsewhere
    d[1, 4:8] = 0.0
    r = root_sift(d)
    assert r.dtype == np.float32 and np.array_equal(r, np.round(r))
    assert r[0, 0] == 255 and r[0, 1:].sum() == 0
    d2 = np.arange(1, 129, dtype=np.float32)[None]
    expect = np.minimum(np.round(512 * np.sqrt(d2 / d2.sum())), 255)
    np.testing.assert_array_equal(root_sift(d2), expect)


@pytest.mark.parametrize("upsample_below", [0, 1024])
def test_keypoints_in_the_image_frame_with_and_without_upsampling(upsample_below):
    """A known shift between two crops of one image: every mutual match with a small
    descriptor ratio moves by exactly that shift. Upsampled keypoints mapped back with a
    wrong scale or a wrong half-pixel offset break this by >= 0.25 px."""
    g0, g1, (dx, dy) = _shifted_pair()
    cfg = FrontendConfig(upsample_below=upsample_below, rootsift=True, lines=False)
    assert upsample_factor(g0.shape, cfg) == (2 if upsample_below else 1)
    p0, p1, scores, _ = match_points(g0, g1, cfg)
    good = scores > 0.5  # clear matches only
    assert good.sum() >= 30
    d = p1[good] - p0[good]
    np.testing.assert_allclose(np.median(d, axis=0), [dx, dy], atol=0.1)


def test_upsampling_finds_more_keypoints_on_a_small_image(held_out_pair):
    """A generated street image at half size: the upsampled detection finds the smaller
    features (measured 475 -> 1140 keypoints)."""
    g = cv2.cvtColor(held_out_pair.image0, cv2.COLOR_RGB2GRAY) \
        if held_out_pair.image0.ndim == 3 else held_out_pair.image0
    g = cv2.resize(g, (g.shape[1] // 2, g.shape[0] // 2), interpolation=cv2.INTER_AREA)
    n1 = len(detect_points(g, FrontendConfig(max_keypoints=20000))[0])
    n2 = len(detect_points(g, FrontendConfig(max_keypoints=20000, upsample_below=1024))[0])
    assert n2 > 1.5 * n1


def test_presets():
    assert set(PRESETS) == {"fast", "thorough", "adaptive", "legacy"}
    legacy = FrontendConfig.preset("legacy")
    assert (legacy.max_keypoints, legacy.ratio, legacy.mutual, legacy.max_points,
            legacy.contrast_threshold, legacy.rootsift, legacy.upsample_below,
            legacy.thorough_below) == (2048, 0.8, True, 1024, 0.04, False, 0, 0)
    assert FrontendConfig.preset("thorough", lines=False).lines is False
    assert FrontendConfig.preset("adaptive").thorough_below > 0
    with pytest.raises(ValueError, match=r"Expected a front-end preset in .* \(got 'best'\)"):
        FrontendConfig.preset("best")


def test_cli_preset_names_match_the_presets():
    from strl_pyg.cli.readers import MATCHER_PRESETS, frontend_config

    assert set(MATCHER_PRESETS) == set(PRESETS)
    args = argparse.Namespace(matcher="thorough", detector="sift")
    assert frontend_config(args) == FrontendConfig.preset("thorough")
    assert frontend_config(argparse.Namespace(matcher=None, detector="orb")) == \
        FrontendConfig(detector="orb")


def test_cache_keys_name_every_setting_that_changes_matches():
    """The legacy preset keeps the key of the matches made before the presets (the new fields
    at their old values are left out); every other preset's key differs from it and from each
    other, so an old cache is never read for new settings."""
    legacy = FrontendConfig.preset("legacy").result_fields()
    assert not {"contrast_threshold", "rootsift", "upsample_below", "thorough_below"} & set(legacy)
    keys = {name: FrontendConfig.preset(name).result_fields() for name in PRESETS}
    assert len({repr(sorted(k.items())) for k in keys.values()}) == len(PRESETS)
    assert FrontendConfig(rootsift=True).result_fields()["rootsift"] is True
    assert "concurrent" not in keys["thorough"]


def test_adaptive_second_pass_replaces_a_short_first_pass(generated_pair):
    pair = generated_pair(2_000_017)
    base = FrontendConfig.preset("fast", lines=False)
    once = match_images(pair.image0, pair.image1, pair.K, pair.K, config=base)
    assert once.info["second_pass"] is None
    n = once.info["point_geometric_inliers"]
    forced = match_images(pair.image0, pair.image1, pair.K, pair.K,
                          config=FrontendConfig.preset("fast", lines=False,
                                                       thorough_below=n + 1))
    sp = forced.info["second_pass"]
    assert sp["first_pass_inliers"] == n and "thorough_below" in sp["reason"]
    thorough = match_images(pair.image0, pair.image1, pair.K, pair.K,
                            config=thorough_points(base))
    np.testing.assert_array_equal(forced.points0, thorough.points0)
    np.testing.assert_array_equal(forced.points1, thorough.points1)
    assert set(forced.info["timings_ms"]) >= {"points_detect", "points_match", "geometry"}
    kept = match_images(pair.image0, pair.image1, pair.K, pair.K,
                        config=FrontendConfig.preset("fast", lines=False, thorough_below=n))
    assert kept.info["second_pass"] is None


def test_the_defaults_are_the_adaptive_preset():
    assert FrontendConfig() == FrontendConfig.preset("adaptive")
    assert FrontendConfig.preset("adaptive").thorough_below > 0
    assert FrontendConfig.preset("fast").thorough_below == 0


def test_the_second_pass_keeps_the_callers_caps_and_matching():
    """Before: the second pass took the thorough preset's caps, so max_points=50 returned
    436 matches."""
    cfg = FrontendConfig(detector="orb", max_points=50, ratio=0.7, mutual=False)
    t = thorough_points(cfg)
    assert (t.max_points, t.ratio, t.mutual, t.detector) == (50, 0.7, False, "orb")
    assert t.thorough_below == 0 and t.upsample_below >= 1024 and t.max_keypoints >= 8000
    assert thorough_points(FrontendConfig(max_keypoints=20000)).max_keypoints == 20000


@pytest.mark.parametrize("field, value", [("contrast_threshold", 0.0), ("upsample_below", -1),
                                          ("thorough_below", 2.5)])
def test_bad_point_settings_are_one_line_errors(field, value):
    with pytest.raises(ValueError, match=rf"Expected {field} .*\(got {value!r}\)"):
        FrontendConfig(**{field: value})
