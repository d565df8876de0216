"""Per-image features: sources, settings keys and the HDF5 store (strl_pyg.frontend.features,
strl_pyg.frontend.store)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from strl_pyg.frontend import FrontendConfig, match_images
from strl_pyg.frontend.features import (
    LINES,
    POINTS,
    Detect,
    MissingFeatures,
    Precomputed,
    settings_key,
)
from strl_pyg.frontend.pipeline import add_lines, thorough_points
from strl_pyg.frontend.store import FeatureStore
from strl_pyg.synthetic import generate_pair

h5py = pytest.importorskip("h5py")


@pytest.fixture(scope="module")
def pair():
    return generate_pair(2_000_017)


def _same(a, b):
    assert np.array_equal(a.points0, b.points0) and np.array_equal(a.points1, b.points1)
    assert np.array_equal(a.lines0, b.lines0) and np.array_equal(a.lines1, b.lines1)
    assert np.array_equal(a.point_scores, b.point_scores)


def test_sources_give_the_matches_of_detecting_in_the_matcher(pair):
    cfg = FrontendConfig(thorough_below=10_000)  # the second pass runs too
    direct = match_images(pair.image0, pair.image1, config=cfg)
    assert direct.info["second_pass"] is not None
    src = (Detect(pair.image0), Detect(pair.image1))
    _same(direct, match_images(pair.image0, pair.image1, config=cfg, features=src))
    # each setting detected once per image: the first pass, the second, the segments
    assert sorted(src[0].cache) == sorted([settings_key(POINTS, cfg),
                                           settings_key(POINTS, thorough_points(cfg)),
                                           settings_key(LINES, cfg)])


def test_lines_added_later_read_the_sources_too(pair):
    cfg = FrontendConfig()
    src = (Detect(pair.image0), Detect(pair.image1))
    first = match_images(pair.image0, pair.image1, config=replace(cfg, lines=False),
                         features=src)
    _same(match_images(pair.image0, pair.image1, config=cfg), add_lines(first, cfg, src))


def test_settings_key_follows_detection_settings_only():
    cfg = FrontendConfig()
    assert settings_key(POINTS, cfg) == settings_key(POINTS, replace(cfg, ratio=0.7,
                                                                     lines=False))
    assert settings_key(POINTS, cfg) != settings_key(POINTS, replace(cfg, max_keypoints=100))
    assert settings_key(LINES, cfg) != settings_key(LINES, replace(cfg, min_line_length=30.0))
    assert settings_key(LINES, cfg) == settings_key(LINES, replace(cfg, max_keypoints=100))
    with pytest.raises(ValueError, match="Expected the kind"):
        settings_key("edges", cfg)


def test_precomputed_refuses_a_setting_it_does_not_hold(pair):
    cfg = FrontendConfig(thorough_below=10_000)
    det = Detect(pair.image0)
    arrays = {settings_key(POINTS, cfg): det.points(cfg), settings_key(LINES, cfg):
              det.lines(cfg)}
    src = Precomputed(arrays, "a.png")
    assert src.points(cfg) is arrays[settings_key(POINTS, cfg)]
    with pytest.raises(MissingFeatures, match="points features points-.* of image 'a.png'") \
            as err:
        src.points(thorough_points(cfg))
    assert err.value.kind == POINTS and err.value.config == thorough_points(cfg)


def test_store_round_trip_in_hlocs_layout(tmp_path, pair):
    cfg = FrontendConfig()
    det = Detect(pair.image0)
    with FeatureStore(tmp_path) as store:
        store.put(POINTS, "seq/a.png", cfg, det.points(cfg), pair.image0.shape)
        store.put(LINES, "seq/a.png", cfg, det.lines(cfg), pair.image0.shape)
        assert store.computed == {POINTS: 1, LINES: 1}
        got = store.points("seq/a.png", cfg)
        assert np.array_equal(got.keypoints, det.points(cfg).keypoints)
        assert np.array_equal(got.descriptors, det.points(cfg).descriptors)
        assert np.array_equal(store.lines("seq/a.png", cfg), det.lines(cfg))
        assert store.names(POINTS, cfg) == ["seq/a.png"]
        assert not store.has(POINTS, "seq/a.png", thorough_points(cfg))
        with pytest.raises(KeyError, match="of 'b.png'"):
            store.points("b.png", cfg)
    with h5py.File(tmp_path / f"{settings_key(POINTS, cfg)}.h5", "r") as f:
        g = f["seq"]["a.png"]  # a name with '/' nests, as hloc's
        K = len(det.points(cfg))
        assert g["keypoints"].shape == (K, 2) and g["descriptors"].shape == (128, K)
        assert list(g["image_size"][()]) == [pair.image0.shape[1], pair.image0.shape[0]]
    read = FeatureStore(tmp_path, writable=False)
    with pytest.raises(ValueError, match="writable"):
        read.put(POINTS, "b.png", cfg, det.points(cfg), pair.image0.shape)
    read.close()


def test_a_group_cut_by_a_kill_is_dropped_and_computed_again(tmp_path, pair):
    cfg = FrontendConfig()
    det = Detect(pair.image0)
    with FeatureStore(tmp_path) as store:
        store.put(POINTS, "a.png", cfg, det.points(cfg), pair.image0.shape)
    with h5py.File(tmp_path / f"{settings_key(POINTS, cfg)}.h5", "a") as f:
        f.create_group("b.png").create_dataset("keypoints", data=np.zeros((3, 2)))
    with FeatureStore(tmp_path) as store:
        assert store.has(POINTS, "a.png", cfg) and not store.has(POINTS, "b.png", cfg)
        assert store.names(POINTS, cfg) == ["a.png"]


def test_an_unreadable_file_is_moved_aside_with_a_warning(tmp_path, pair):
    cfg = FrontendConfig()
    path = tmp_path / f"{settings_key(POINTS, cfg)}.h5"
    path.write_bytes(b"not hdf5")
    store = FeatureStore(tmp_path)
    with pytest.warns(UserWarning, match="moved to .*corrupt"):
        assert not store.has(POINTS, "a.png", cfg)
    store.put(POINTS, "a.png", cfg, Detect(pair.image0).points(cfg), pair.image0.shape)
    assert (tmp_path / f"{settings_key(POINTS, cfg)}.h5.corrupt").read_bytes() == b"not hdf5"
    assert store.has(POINTS, "a.png", cfg)
    store.close()
    with pytest.raises(FileNotFoundError, match="feature store folder"):
        FeatureStore(tmp_path / "none", writable=False)


def test_the_training_cache_detects_each_image_once_per_process(pair):
    from strl_pyg.datasets import base
    from strl_pyg.datasets.base import ImageSource, image_features

    base._FEATURES.clear()
    a, b = ImageSource("a.png"), ImageSource("b.png")
    first = image_features(a, pair.image0, None, True)
    assert image_features(a, pair.image0, None, True) is first
    assert image_features(b, pair.image1, None, True) is not first
    assert image_features(a, pair.image0, (96, 320), True) is not first  # another size
    cfg = FrontendConfig()
    first.points(cfg)
    assert list(first.cache) == [settings_key(POINTS, cfg)]
    for k in range(base.FEATURE_CACHE_IMAGES + 1):  # the oldest leaves the cache
        image_features(ImageSource(f"{k}.png"), pair.image1, None, True)
    assert image_features(a, pair.image0, None, True) is not first
    base._FEATURES.clear()
