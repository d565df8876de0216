from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from strl_pyg.data import PairMatches
from strl_pyg.data.checks import OUT_OF_IMAGE_TOLERANCE

H, W = 120, 160


def make(num_points=6, num_lines=3, seed=0, **kw):
    rng = np.random.default_rng(seed)
    pts = lambda n: rng.uniform([0, 0], [W - 1, H - 1], (n, 2))  # noqa: E731
    args = dict(
        points0=pts(num_points),
        points1=pts(num_points),
        lines0=pts(2 * num_lines).reshape(-1, 2, 2),
        lines1=pts(2 * num_lines).reshape(-1, 2, 2),
        image_size0=(H, W),
        image_size1=(H, W),
    )
    args.update(kw)
    return PairMatches(**args)


def test_valid_and_counts():
    m = make(6, 3)
    assert m.num_points == 6 and m.num_lines == 3
    assert m.points0.dtype == np.float64 and m.lines0.shape == (3, 2, 2)
    assert "points=6" in repr(m)


def test_points_only_and_lines_only_are_valid():
    assert make(5, 0).num_lines == 0
    assert make(0, 4).num_points == 0


def test_size_taken_from_images():
    img = np.zeros((H, W, 3), np.uint8)
    m = make(image_size0=None, image_size1=None, image0=img, image1=img[..., 0])
    assert m.image_size0 == (H, W) and m.image1.ndim == 2


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(points1=np.zeros((5, 2))), "as many points"),
        (dict(points0=np.zeros((6, 3))), r"shape \[N, 2\]"),
        (dict(lines1=np.zeros((2, 2, 2)) + 5), "as many lines"),
        (dict(image_size0=(0, 5)), "two positive integers"),
        (dict(K0=np.eye(3), K1=np.eye(4)), r"shape \(3, 3\)"),
        (dict(K0=np.eye(3), K1=np.diag([1.0, 0.0, 1.0])), "positive focal"),
        (dict(K0=np.eye(3)), "both K0 and K1"),
        (dict(K0=np.ones((3, 3)), K1=np.eye(3)), "last row"),
        (dict(image0=np.zeros((H + 1, W), np.uint8)), "image0' of size"),
        (dict(image0=np.zeros((H, W), np.int32)), "dtype uint8"),
        (dict(image0=np.full((H, W), 2.0, np.float32)), r"\[0, 1\]"),
        (dict(point_scores=np.ones(2)), "length 6"),
    ],
)
def test_bad_input_errors(kw, match):
    with pytest.raises((ValueError, TypeError), match=match):
        make(**kw)


def test_no_matches_error():
    with pytest.raises(ValueError, match="at least one point or line"):
        make(0, 0)


def test_nan_and_zero_length_and_outside():
    with pytest.raises(ValueError, match="finite"):
        make(points0=np.full((6, 2), np.nan))
    lines = np.ones((3, 2, 2)) * 10
    with pytest.raises(ValueError, match="zero-length"):
        make(lines0=lines)
    pts = make().points0.copy()
    pts[2] = [W + OUT_OF_IMAGE_TOLERANCE + 1, 3]
    # the size as everywhere else, (H, W) (it said "160x120", W x H, stop 46)
    with pytest.raises(ValueError, match=r"inside the 120x160 px image \(H x W") as err:
        make(points0=pts)
    assert "(W, H)?" not in str(err.value)


def test_save_load_roundtrip(tmp_path):
    img = np.random.default_rng(1).integers(0, 255, (H, W), dtype=np.uint8)
    K = np.array([[100.0, 0, 80], [0, 100, 60], [0, 0, 1]])
    m = make(
        point_scores=np.linspace(0, 1, 6),
        K0=K,
        K1=K,
        image0=img,
        image1=img,
        info={"timings_ms": {"detect": 1.5}},
    )
    path = m.save(tmp_path / "m.npz")
    r = PairMatches.load(path)
    for key in ("points0", "points1", "lines0", "lines1", "point_scores", "K0", "image0"):
        np.testing.assert_array_equal(getattr(r, key), getattr(m, key))
    assert r.line_scores is None and r.image_size1 == (H, W) and r.info == m.info
    assert not list(tmp_path.glob(".*tmp"))  # no temporary left behind


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        PairMatches.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="readable .npz"):
        PairMatches.load(bad)
    # a text file, an empty file, a lone .npy: said as such (before: numpy's "pickled data"
    # for all of them, which the error turned into "an object array")
    text = tmp_path / "loadbad.py"
    text.write_text("print(1)\n")
    with pytest.raises(ValueError, match=r"not an \.npz archive: it starts with b'print\('"):
        PairMatches.load(text)
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match=r"\(got an empty file\)"):
        PairMatches.load(empty)
    npy = tmp_path / "a.npy"
    np.save(npy, np.zeros(3))
    with pytest.raises(ValueError, match=r"\(got a single \.npy array\)"):
        PairMatches.load(npy)
    obj = tmp_path / "obj.npz"  # a real .npz holding a pickled (object) array
    np.savez(obj, points0=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError, match="object array") as err:
        PairMatches.load(obj)
    assert "allow_pickle" not in str(err.value)


finite = st.floats(-1e4, 1e4, allow_nan=False)
bad_value = st.sampled_from([np.nan, np.inf, -np.inf, 1e9, -1e9])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(1, 20),
    row=st.integers(0, 19),
    col=st.integers(0, 1),
    value=bad_value,
    which=st.sampled_from(["points0", "points1"]),
)
def test_fuzz_bad_coordinates_raise_value_error(n, row, col, value, which):
    m = make(n, 2)
    arr = getattr(m, which).copy()
    arr[row % n, col] = value
    kw = {which: arr}
    with pytest.raises(ValueError, match="Expected"):
        make(n, 2, **kw)


@settings(max_examples=60, deadline=None)
@given(n0=st.integers(0, 8), n1=st.integers(0, 8), d=st.integers(1, 4))
def test_fuzz_shapes(n0, n1, d):
    p0 = np.zeros((n0, d)) + 1.0
    p1 = np.zeros((n1, d)) + 1.0
    ok = n0 == n1 and d == 2 and n0 > 0
    if ok:
        assert PairMatches(p0, p1, image_size0=(H, W), image_size1=(H, W)).num_points == n0
    else:
        with pytest.raises(ValueError, match="Expected"):
            PairMatches(p0, p1, image_size0=(H, W), image_size1=(H, W))


def test_an_empty_npz_is_a_one_line_value_error(tmp_path):
    import numpy as np

    from strl_pyg.data.matches import MatchFileKeyError

    path = tmp_path / "empty.npz"
    np.savez(path)
    with pytest.raises(ValueError, match=r"^Expected keys \['points0'") as info:
        PairMatches.load(path)
    assert isinstance(info.value, MatchFileKeyError) and isinstance(info.value, KeyError)
    assert "\n" not in str(info.value) and not str(info.value).startswith('"')


def _pm(pair, p0, p1, **kw):
    return PairMatches(p0, p1, K0=pair.K, K1=pair.K, image_size0=pair.image0.shape[:2],
                       image_size1=pair.image1.shape[:2], **kw)


def test_deduplicated_keeps_first_rows_and_maps_every_input_row(held_out_pair):
    m = held_out_pair.matches
    idx = np.array([3, 1, 3, 0, 1, 2])
    pm = _pm(held_out_pair, m.points0[idx], m.points1[idx])
    out, notes, inverse = pm.deduplicated()
    np.testing.assert_array_equal(out.points0, m.points0[[3, 1, 0, 2]])
    np.testing.assert_array_equal(inverse, [0, 1, 0, 2, 1, 3])
    assert len(notes) == 1 and "2 repeated point matches removed" in notes[0]
    same, none, _ = _pm(held_out_pair, m.points0, m.points1).deduplicated()
    assert none == [] and same.num_points == m.num_points


def test_select_keeps_the_front_ends_inlier_rows_in_step(held_out_pair):
    """Before: select() copied info['fundamental_inliers'] unchanged, so add_lines read other
    rows (or past the end) as the fundamental matrix's inliers."""
    m = held_out_pair.matches
    pm = replace(_pm(held_out_pair, m.points0[:6], m.points1[:6]),
                 info={"fundamental_inliers": [0, 2, 3, 5]})
    assert pm.select([5, 1, 2]).info["fundamental_inliers"] == [0, 2]
    assert pm.select([3, 3]).info["fundamental_inliers"] == [0, 1]
    assert pm.select(line_index=[]).info["fundamental_inliers"] == [0, 2, 3, 5]
    stale = replace(pm, info={"fundamental_inliers": [0, 9]})
    assert "fundamental_inliers" not in stale.select([0, 1]).info


def test_size_given_as_w_h_is_named(held_out_pair):
    """Before: a size passed as (W, H) = (1226, 370) with points of a 370x1226 image said
    "inside the 370x1226 image", which read as right to the user (the message printed
    W x H, everything else H x W), with no hint that the size was transposed."""
    m, (h, w) = held_out_pair.matches, held_out_pair.image0.shape[:2]
    with pytest.raises(ValueError, match=rf"inside the {w}x{h} px image \(H x W.*"
                                         r"was image_size0 given as \(W, H\)\? Sizes are \(H, W\)"):
        PairMatches(m.points0, m.points1, image_size0=(w, h), image_size1=(w, h))


def test_lsd_rows_are_read_as_segments(held_out_pair):
    """Before: OpenCV's LSD output, (N, 1, 4) rows (x1, y1, x2, y2), or its (N, 4) squeeze
    was refused ("Expected 'lines0' of shape [N, 2, 2]") with no hint."""
    m = held_out_pair.matches
    ref = PairMatches(m.points0, m.points1, m.lines0, m.lines1, image_size0=m.image_size0,
                      image_size1=m.image_size1)
    for shape in ((-1, 4), (-1, 1, 4)):
        got = PairMatches(m.points0, m.points1, m.lines0.reshape(shape).astype(np.float32),
                          m.lines1.reshape(shape), image_size0=m.image_size0,
                          image_size1=m.image_size1)
        np.testing.assert_allclose(got.lines0, ref.lines0, rtol=1e-6)
        np.testing.assert_array_equal(got.lines1, ref.lines1)
    with pytest.raises(ValueError,
                       match=r"Expected 'lines0' of shape \[N, 2, 2\] \(got \(5, 3\)\)"):
        PairMatches(m.points0, m.points1, np.ones((5, 3)), np.ones((5, 3)),
                    image_size0=m.image_size0, image_size1=m.image_size1)

