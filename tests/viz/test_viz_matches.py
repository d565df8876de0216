"""Match drawings: layout, colours by inlier mask, atomic PNG writes, clear errors."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from strl_pyg.data import PairMatches
from strl_pyg.synthetic import SceneConfig
from strl_pyg.viz.matches import OUTLIER_COLOUR, draw_matches, save_matches_png


@pytest.fixture(scope="module")
def pair(generated_pair):
    return generated_pair(0, SceneConfig(kind="boxes", image_size=(96, 160),
                                        outlier_fraction=0.3, max_points=40, max_lines=20))


def _count(canvas, colour):
    return int(np.all(canvas == np.array(colour, np.uint8), axis=-1).sum())


def test_draw_layout_and_colours(pair):
    canvas = draw_matches(pair.matches, pair.point_inliers, pair.line_inliers,
                          layout="horizontal")
    assert canvas.shape == (96, 320, 3) and canvas.dtype == np.uint8
    # wide images stack vertically by default; both layouts draw the same matches
    auto = draw_matches(pair.matches, pair.point_inliers, pair.line_inliers)
    assert auto.shape == (192, 160, 3)
    assert _count(auto, OUTLIER_COLOUR) > 0
    with pytest.raises(ValueError, match="layout"):
        draw_matches(pair.matches, layout="diagonal")
    assert _count(canvas, OUTLIER_COLOUR) > 0
    all_in = draw_matches(pair.matches, np.ones_like(pair.point_inliers),
                          np.ones_like(pair.line_inliers))
    assert _count(all_in, OUTLIER_COLOUR) == 0


def test_different_sizes():
    a = np.full((40, 60), 100, np.uint8)
    b = np.full((50, 30), 100, np.uint8)
    m = PairMatches([[5.0, 5.0]], [[6.0, 7.0]], image0=a, image1=b)
    assert draw_matches(m).shape == (50, 90, 3)


def test_save_png_atomic(pair, tmp_path):
    path = save_matches_png(tmp_path / "sub" / "m.png", pair.matches, pair.point_inliers,
                            pair.line_inliers, layout="horizontal")
    img = cv2.imread(str(path))
    assert img is not None and img.shape == (96, 320, 3)
    assert [p.name for p in path.parent.iterdir()] == ["m.png"]  # no temporary file left


def test_errors(pair, tmp_path):
    with pytest.raises(ValueError, match="point_inliers"):
        draw_matches(pair.matches, np.ones(3, bool))
    no_img = PairMatches(pair.matches.points0, pair.matches.points1, image_size0=(96, 160),
                         image_size1=(96, 160))
    with pytest.raises(ValueError, match="image0 and image1"):
        draw_matches(no_img)
    with pytest.raises(ValueError, match=".png"):
        save_matches_png(tmp_path / "m.jpg", pair.matches)


def test_the_match_drawing_has_a_title_a_legend_and_subsamples(held_out_pair):
    from strl_pyg.viz.matches import draw_matches

    m = replace(held_out_pair.matches, image0=held_out_pair.image0, image1=held_out_pair.image1)
    plain = draw_matches(m, layout="horizontal")
    few = draw_matches(m, layout="horizontal", max_points=10, max_lines=5, title="t",
                       legend=True, point_inliers=np.ones(m.num_points, bool))
    assert few.shape[1] == plain.shape[1] and few.shape[0] > plain.shape[0]  # header band
    band = few[: few.shape[0] - plain.shape[0]]
    assert (band < 128).any() and (band == 255).mean() > 0.8  # text on white
    # fewer matches drawn: less of the image is covered by drawing
    changed = lambda c: (c[-plain.shape[0]:] != plain).any(-1).mean()  # noqa: E731
    assert changed(few) > 0 and (draw_matches(m, layout="horizontal", max_points=10,
                                               max_lines=5) != plain).any()

