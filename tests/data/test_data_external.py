"""Readers of other tools' match files: each layout built from the tool's documented keys with
known correspondences, and every bad input answered by a one-line error."""

import sys
import warnings

import numpy as np
import pytest
import torch

from strl_pyg.data.external import MatchFormatError
from strl_pyg.data.external.formats import (
    FORMATS,
    detect_format,
    from_lightglue,
    load_external_matches,
)
from strl_pyg.data.external.hloc import load_hloc_matches
from strl_pyg.data.matches import PairMatches
from strl_pyg.inference import PoseEstimator

H, W = 120, 160  # not square: a swapped (W, H) shows
rng = np.random.default_rng(0)
KP0 = rng.uniform([0, 0], [W - 1, H - 1], (7, 2))
KP1 = rng.uniform([0, 0], [W - 1, H - 1], (5, 2))
M0 = np.array([2, -1, 0, -1, 4, -1, 1])  # keypoint i of image 0 <-> M0[i] of image 1
CONF = np.array([0.9, 0.0, 0.2, 0.0, 0.7, 0.0, 0.4])
PAIRS = [(0, 2), (2, 0), (4, 4), (6, 1)]


def assert_pairs(pm, pairs=PAIRS, kp0=KP0, kp1=KP1):
    i0, i1 = np.array(pairs).T
    np.testing.assert_array_equal(pm.points0, kp0[i0])
    np.testing.assert_array_equal(pm.points1, kp1[i1])


# ------------------------------------------------------------------------------- SuperGlue
@pytest.mark.parametrize("n0", [7, 6])  # odd N0 made a reshape error, even N0 wrong pairs
def test_superglue_match_pairs_npz(tmp_path, n0):
    path = tmp_path / "a_b_matches.npz"
    np.savez(path, keypoints0=KP0[:n0], keypoints1=KP1, matches=M0[:n0],
             match_confidence=CONF[:n0])
    pm = load_external_matches(path, image_size0=(H, W), image_size1=(H, W))
    pairs = [p for p in PAIRS if p[0] < n0]
    assert_pairs(pm, pairs)
    np.testing.assert_array_equal(pm.point_scores, CONF[[p[0] for p in pairs]])
    assert pm.image_size0 == (H, W) and pm.info["source_format"] == "superglue"
    kept = load_external_matches(path, (H, W), (H, W), min_score=0.5)
    assert_pairs(kept, [(0, 2), (4, 4)])


def test_superglue_needs_sizes(tmp_path):
    path = tmp_path / "m.npz"
    np.savez(path, keypoints0=KP0, keypoints1=KP1, matches=M0, match_confidence=CONF)
    with pytest.raises(ValueError, match=r"image_size0=\(H, W\) for superglue"):
        load_external_matches(path)


# ------------------------------------------------------------------------------- LightGlue
def test_lightglue_rbd_pairs_and_scores():
    d = dict(keypoints0=KP0, keypoints1=KP1, matches=np.array(PAIRS)[::-1],
             scores=np.array([0.4, 0.7, 0.2, 0.9]))
    pm = load_external_matches(d, (H, W), (H, W))
    assert_pairs(pm, PAIRS[::-1])
    assert_pairs(load_external_matches(d, (H, W), (H, W), min_score=0.5), [(4, 4), (0, 2)])


def test_lightglue_batched_per_keypoint_scores_and_wh_size():
    """Batched tensors, ``matching_scores0`` used by min_score, image_size read as (W, H)."""
    d = dict(keypoints0=torch.tensor(KP0)[None], keypoints1=torch.tensor(KP1)[None],
             matches0=torch.tensor(M0)[None], matching_scores0=torch.tensor(CONF)[None],
             image_size0=torch.tensor([[W, H]], dtype=torch.float32),
             image_size1=torch.tensor([[W, H]], dtype=torch.float32))
    pm = load_external_matches(d)
    assert_pairs(pm)
    assert pm.image_size0 == (H, W) and pm.image_size1 == (H, W)
    assert_pairs(load_external_matches(d, min_score=0.5), [(0, 2), (4, 4)])


def test_from_lightglue_three_dicts():
    feats = [{"keypoints": torch.tensor(k)[None], "image_size": torch.tensor([[W, H]])}
             for k in (KP0, KP1)]
    out = {"matches0": torch.tensor(M0)[None], "matching_scores0": torch.tensor(CONF)[None],
           "matches": [torch.tensor(PAIRS)], "scores": [torch.tensor(CONF[[0, 2, 4, 6]])],
           "stop": 9, "prune0": torch.ones(1, 7)}
    pm = from_lightglue(*feats, out)
    assert_pairs(pm)
    assert pm.image_size0 == (H, W)
    out["matches"] = [torch.tensor([[0, 2], [2, 1]])]
    with pytest.raises(MatchFormatError, match="same matches"):
        from_lightglue(*feats, out)


def test_lightglue_single_match_keeps_its_row():
    pm = load_external_matches(dict(keypoints0=KP0, keypoints1=KP1, matches=np.array([[6, 1]])),
                               (H, W), (H, W))
    assert_pairs(pm, [(6, 1)])


def test_batch_needs_index():
    d = dict(keypoints0=np.stack([KP0, KP0[::-1]]), keypoints1=np.stack([KP1, KP1]),
             matches0=np.stack([M0, M0]))
    with pytest.raises(MatchFormatError, match="batch of 2.*batch_index"):
        load_external_matches(d, (H, W), (H, W))
    assert_pairs(load_external_matches(d, (H, W), (H, W), batch_index=1),
                 PAIRS, kp0=KP0[::-1])
    with pytest.raises(MatchFormatError, match="batched input"):
        load_external_matches(dict(keypoints0=KP0, keypoints1=KP1, matches0=M0), (H, W),
                              (H, W), batch_index=0)


# ------------------------------------------------------------------------------- sizes
def test_size_argument_is_hw_and_must_agree_with_file():
    d = dict(keypoints0=KP0, keypoints1=KP1, matches0=M0, image_size0=[W, H],
             image_size1=[W, H])
    assert load_external_matches(d, image_size0=(H, W)).image_size0 == (H, W)
    with pytest.raises(ValueError, match="agree"):
        load_external_matches(d, image_size0=(W, H))


def test_transposed_size_errors_with_hint():
    kp0 = np.array([[150.0, 10.0], [20.0, 110.0]])  # fits 120x160 (H x W), not 160x120
    d = dict(points0=kp0, points1=kp0, image_size0=(W, H), image_size1=(H, W))
    with pytest.raises(ValueError, match=r"given as \(W, H\)"):
        load_external_matches(d)


# ------------------------------------------------------------------------------- one row
def test_own_file_with_one_point_or_one_line(tmp_path):
    one = PairMatches(KP0[:1], KP1[:1], image_size0=(H, W), image_size1=(H, W),
                      point_scores=[0.5], info={"a": 1})
    back = load_external_matches(one.save(tmp_path / "p.npz"))
    np.testing.assert_array_equal(back.points1, KP1[:1])
    assert back.info == {"a": 1} and PairMatches.load(tmp_path / "p.npz").num_points == 1
    line = KP0[:2].reshape(1, 2, 2)
    one = PairMatches(None, None, lines0=line, lines1=line, image_size0=(H, W),
                      image_size1=(H, W))
    back = load_external_matches(one.save(tmp_path / "l.npz"))
    np.testing.assert_array_equal(back.lines0, line)
    assert PairMatches.load(tmp_path / "l.npz").num_lines == 1


# ------------------------------------------------------------------------------- GlueStick
def gluestick_pred(flip_stored=(False, True, False)):
    """Three lines whose endpoints are keypoints (as GlueStick's wireframe merges them)."""
    kp0 = np.array([[10, 10], [60, 15], [20, 90], [100, 80], [140, 20], [150, 100], [5, 50.0]])
    kp1 = kp0 + [3.0, 2.0]
    m0 = np.array([0, 1, 2, 3, -1, -1, 6])  # kp 4 and 5 unmatched
    junc0 = np.array([[0, 1], [2, 3], [4, 5]])
    junc1 = np.array([j[::-1] if f else j for j, f in zip(junc0, flip_stored, strict=True)])
    return dict(keypoints0=kp0[None], keypoints1=kp1[None], matches0=m0[None],
                match_scores0=np.full((1, 7), 0.8), lines0=kp0[junc0][None],
                lines1=kp1[junc1][None], line_matches0=np.array([[0, 1, 2]]),
                line_match_scores0=np.array([[0.9, 0.3, 0.8]]))


@pytest.mark.parametrize("with_junc_idx", [False, True])
def test_gluestick_lines_oriented_by_point_matches(with_junc_idx):
    d = gluestick_pred()
    if with_junc_idx:
        d["lines_junc_idx0"] = np.array([[[0, 1], [2, 3], [4, 5]]])
        d["lines_junc_idx1"] = np.array([[[0, 1], [3, 2], [4, 5]]])
    kp0, kp1 = d["keypoints0"][0], d["keypoints1"][0]
    with pytest.warns(UserWarning, match="Dropped 1 of 3") as record:
        pm = load_external_matches(d, (H, W), (H, W))
    assert record[0].filename == __file__  # the warning names the caller's line
    assert_pairs(pm, [(0, 0), (1, 1), (2, 2), (3, 3), (6, 6)], kp0, kp1)
    np.testing.assert_array_equal(pm.lines1, kp1[[[0, 1], [2, 3]]])  # flipped line fixed
    np.testing.assert_array_equal(pm.lines0, kp0[[[0, 1], [2, 3]]])
    assert pm.info["lines_flipped"] == 1 and pm.info["lines_unoriented"] == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stored = load_external_matches(d, (H, W), (H, W), line_endpoints="as_stored",
                                       min_line_score=0.5)
    np.testing.assert_array_equal(stored.lines1, d["lines1"][0][[0, 2]])


@pytest.mark.parametrize("batched", [True, False])
def test_gluestick_one_line(batched):
    d = gluestick_pred()
    d.update(lines0=d["lines0"][:, :1], lines1=d["lines1"][:, :1],
             line_matches0=np.array([[0]]), line_match_scores0=np.array([[0.9]]))
    if not batched:
        d = {k: v[0] for k, v in d.items()}
    pm = load_external_matches(d, (H, W), (H, W))
    assert pm.num_lines == 1 and pm.line_scores.tolist() == [0.9]


# ------------------------------------------------------------------------------- kornia
def test_kornia_matcher_dict():
    b = torch.tensor([0, 0, 1, 1, 1])
    d = dict(keypoints0=torch.tensor(KP1), keypoints1=torch.tensor(KP0[:5]),
             confidence=torch.linspace(0.1, 0.9, 5), batch_indexes=b)
    with pytest.raises(MatchFormatError, match=r"batch indexes \[0, 1\].*batch_index"):
        load_external_matches(d, (H, W), (H, W))
    pm = load_external_matches(d, (H, W), (H, W), batch_index=1, min_score=0.6)
    np.testing.assert_array_equal(pm.points0, KP1[3:])
    np.testing.assert_array_equal(pm.points1, KP0[3:5])
    one = load_external_matches({k: v[:2] for k, v in d.items()}, (H, W), (H, W))
    assert one.num_points == 2 and detect_format(d) == "kornia"


# ------------------------------------------------------------------------------- hloc
def write_hloc(tmp_path, pair_name, reverse=False):
    h5py = pytest.importorskip("h5py")
    feats, matches = tmp_path / "feats-superpoint.h5", tmp_path / "matches.h5"
    with h5py.File(feats, "w") as f:
        for name, kp in (("db/a.jpg", KP0), ("query/b.jpg", KP1)):
            g = f.create_group(name)
            g["keypoints"] = kp.astype(np.float16)  # hloc's as_half
            g["image_size"] = np.array([W, H])
            g["scores"] = np.ones(len(kp))
    with h5py.File(matches, "w") as f:
        g = f.create_group(pair_name)
        if reverse:  # stored as (b, a): matches0 indexes a's keypoints for each of b's
            m1 = np.full(len(KP1), -1)
            s1 = np.zeros(len(KP1))
            for i0, i1 in PAIRS:
                m1[i1], s1[i1] = i0, CONF[i0]
            g["matches0"], g["matching_scores0"] = m1, s1
        else:
            g["matches0"], g["matching_scores0"] = M0, CONF
    return feats, matches


@pytest.mark.parametrize("pair_name, reverse", [
    ("db-a.jpg/query-b.jpg", False), ("query-b.jpg/db-a.jpg", True),
    ("db-a.jpg_query-b.jpg", False), ("query-b.jpg_db-a.jpg", True)])
def test_hloc_h5(tmp_path, pair_name, reverse):
    feats, matches = write_hloc(tmp_path, pair_name, reverse)
    pm = load_hloc_matches(feats, matches, "db/a.jpg", "query/b.jpg", min_score=0.3)
    kp0, kp1 = KP0.astype(np.float16), KP1.astype(np.float16)
    order = np.argsort(pm.points0[:, 0])
    expect = sorted([(0, 2), (4, 4), (6, 1)], key=lambda p: kp0[p[0], 0])
    assert_pairs(pm.select(order), expect, kp0.astype(float), kp1.astype(float))
    assert pm.image_size0 == (H, W) and pm.info["hloc_reversed"] == reverse


def test_hloc_errors(tmp_path, monkeypatch):
    feats, matches = write_hloc(tmp_path, "db-a.jpg/other.jpg")  # not the pair asked for
    with pytest.raises(ValueError, match="Expected the pair.*db-a.jpg/query-b.jpg"):
        load_hloc_matches(feats, matches, "db/a.jpg", "query/b.jpg")
    with pytest.raises(ValueError, match="Expected image 'nope.jpg'"):
        load_hloc_matches(feats, matches, "nope.jpg", "query/b.jpg")
    with pytest.raises(MatchFormatError, match="HDF5.*load_hloc_matches"):
        load_external_matches(matches)  # used to fail with a pickle error
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(ImportError, match="pip install h5py"):
        load_hloc_matches(feats, matches, "db/a.jpg", "query/b.jpg")


# ------------------------------------------------------------------------------- others
def test_package_exports():
    import strl_pyg.data.external as external

    assert external.load_external_matches is load_external_matches
    assert external.load_hloc_matches is load_hloc_matches
    assert external.MatchFormatError is MatchFormatError
    assert external.from_lightglue is from_lightglue


def test_readers_split_by_layout():
    """The layouts are split over modules (readers, shared checks): every format but strl has
    one reader and one rank table, and the shared error is one class."""
    from strl_pyg.data.external import checks as external_checks
    from strl_pyg.data.external import readers as external_readers

    assert set(FORMATS) == {"strl", *external_readers.READERS} == {"strl", *external_readers.RANKS}
    assert external_checks.MatchFormatError is MatchFormatError
    with pytest.raises(MatchFormatError, match=r"Expected 'matches0' values in \[-1, 5\)"):
        load_external_matches(dict(keypoints0=KP0, keypoints1=KP1, matches0=M0 + 5,
                                   matching_scores0=CONF), (H, W), (H, W))


def test_matched_arrays():
    d = dict(mkpts0=KP0[:3], mkpts1=KP1[:3], mconf=[0.1, 0.5, 0.9])
    pm = load_external_matches(d, (H, W), (H, W), min_score=0.5)
    assert_pairs(pm, [(1, 1), (2, 2)])


def test_existing_gluestick_and_lightglue_layouts():
    """The layouts of the first loader still read the same (moved from test_data_matches)."""
    r = np.random.default_rng(0)
    kp0, kp1 = r.uniform(0, 100, (8, 2)), r.uniform(0, 100, (5, 2))
    l0, l1 = r.uniform(0, 100, (3, 2, 2)), r.uniform(0, 100, (4, 2, 2))
    glue = dict(keypoints0=kp0[None], keypoints1=kp1[None], matches0=np.array([[2, -1, 0, -1,
                4, -1, -1, 1]]), match_scores0=np.linspace(0, 1, 8)[None], lines0=l0[None],
                lines1=l1[None], line_matches0=np.array([[3, -1, 0]]))
    pm = load_external_matches(glue, (H, W), (H, W), line_endpoints="as_stored")
    assert_pairs(pm, [(0, 2), (2, 0), (4, 4), (7, 1)], kp0, kp1)
    np.testing.assert_array_equal(pm.lines1, l1[[3, 0]])
    assert load_external_matches(glue, (H, W), (H, W), min_score=0.5,
                                 line_endpoints="as_stored").num_points == 2


@pytest.mark.parametrize("data, match", [
    ({}, "empty"),
    ({"foo": np.zeros(3)}, r"strl \(points0, points1\).*got keys \['foo'\]"),
    (dict(points0=KP0, points1=KP0, mkpts0=KP0, mkpts1=KP0), "several layouts strl, matched"),
    (dict(keypoints0=KP0, keypoints1=KP0), "format='kornia'"),
])
def test_unknown_or_ambiguous_layouts(tmp_path, data, match):
    path = tmp_path / "x.npz"
    np.savez(path, **data)
    with pytest.raises(MatchFormatError, match=match):
        load_external_matches(path, (H, W), (H, W))


@pytest.mark.parametrize("change, match", [
    (dict(matches0=np.array([2, -1, 0, -1, 5, -1, 1])), r"values in \[-1, 5\)"),
    (dict(matches0=M0[:6]), "length 7"),
    (dict(matches0=M0 + 0.5), "integer"),
    (dict(matching_scores0=CONF[:3]), "length 7"),
    (dict(keypoints0=KP0[:, :1]), r"shape \[N, 2\]"),
    (dict(matches=np.array([[0, 9]])), r"in \[0, 5\)"),
])
def test_bad_indices_and_shapes(change, match):
    d = dict(keypoints0=KP0, keypoints1=KP1, matches0=M0, matching_scores0=CONF)
    d.update(change)
    with pytest.raises(MatchFormatError, match=match):
        load_external_matches(d, (H, W), (H, W), format="lightglue")


def test_min_score_without_scores_and_bad_arguments():
    d = dict(keypoints0=KP0, keypoints1=KP1, matches0=M0)
    with pytest.raises(ValueError, match="point scores to apply min_score"):
        load_external_matches(d, (H, W), (H, W), min_score=0.5)
    with pytest.raises(ValueError, match="line scores"):
        load_external_matches(d, (H, W), (H, W), min_line_score=0.5)
    with pytest.raises(ValueError, match="Expected format"):
        load_external_matches(d, (H, W), (H, W), format="colmap")
    with pytest.raises(TypeError, match="path or a dict"):
        load_external_matches(3)
    assert set(FORMATS) >= {"strl", "superglue", "lightglue", "gluestick", "kornia"}


def test_missing_corrupt_and_pickled_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_external_matches(tmp_path / "none.npz")
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(ValueError, match="readable .npz"):
        load_external_matches(tmp_path / "bad.npz")
    np.savez(tmp_path / "obj.npz", points0=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError, match="never read") as err:
        load_external_matches(tmp_path / "obj.npz")
    assert "allow_pickle=True" not in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("seed", range(5))
def test_all_layouts_agree_on_random_matches(tmp_path, seed):
    """One random matching written in every layout reads back as the same correspondences."""
    r = np.random.default_rng(seed)
    n0, n1 = r.integers(1, 30, 2)
    kp0 = r.uniform([0, 0], [W - 1, H - 1], (n0, 2))
    kp1 = r.uniform([0, 0], [W - 1, H - 1], (n1, 2))
    k = int(r.integers(1, min(n0, n1) + 1))
    i0, i1 = r.choice(n0, k, replace=False), r.choice(n1, k, replace=False)
    m0 = np.full(n0, -1)
    m0[i0] = i1
    conf = r.uniform(0, 1, n0)
    ref = sorted(zip(i0.tolist(), i1.tolist(), strict=True))
    sizes = dict(image_size0=(H, W), image_size1=(H, W))
    kp = dict(keypoints0=kp0, keypoints1=kp1)
    order = np.argsort(i0)
    inputs = {
        "superglue": dict(**kp, matches=m0, match_confidence=conf),
        "lightglue": dict(**kp, matches=np.stack([i0, i1], 1)[order], scores=conf[i0][order]),
        "lightglue0": dict(**kp, matches0=m0[None], matching_scores0=conf[None]),
        "gluestick": dict(**kp, matches0=m0, match_scores0=conf),
        "matched": dict(mkpts0=kp0[i0][order], mkpts1=kp1[i1][order], mconf=conf[i0][order]),
        "kornia": dict(keypoints0=torch.tensor(kp0[i0][order]),
                       keypoints1=torch.tensor(kp1[i1][order]),
                       confidence=torch.tensor(conf[i0][order])),
    }
    for name, data in inputs.items():
        np.savez(tmp_path / f"{name}.npz", **{k: np.asarray(v) for k, v in data.items()})
        for src in (data, tmp_path / f"{name}.npz"):
            pm = load_external_matches(src, **sizes)
            assert pm.info["source_format"] == name.rstrip("0")
            assert_pairs(pm, ref, kp0, kp1)
            np.testing.assert_allclose(pm.point_scores, conf[[p[0] for p in ref]])


def test_intrinsics_from_file_must_agree():
    K = np.array([[100.0, 0, 80], [0, 100, 60], [0, 0, 1]])
    d = dict(mkpts0=KP0, mkpts1=KP0, K0=K, K1=K)
    assert load_external_matches(d, (H, W), (H, W)).has_intrinsics
    with pytest.raises(ValueError, match="K0 to agree"):
        load_external_matches(d, (H, W), (H, W), K0=2 * K + np.diag([0, 0, -1]), K1=K)


def test_all_matches_onto_one_keypoint_warn_at_load_and_are_degenerate(held_out_pair):
    """Before: a SuperGlue dict whose 512 matches all point at keypoint 0 of image 1 was
    accepted silently and gave 'ok' from opencv."""
    m = held_out_pair.matches
    n = m.num_points
    d = {"keypoints0": m.points0, "keypoints1": m.points1,
         "matches0": np.zeros(n, dtype=np.int64), "matching_scores0": np.ones(n)}
    with pytest.warns(UserWarning, match=r"onto 1 distinct keypoints of image 1"):
        pm = load_external_matches(d, image_size0=held_out_pair.image0.shape[:2],
                                   image_size1=held_out_pair.image1.shape[:2],
                                   K0=held_out_pair.K, K1=held_out_pair.K)
    est = PoseEstimator(methods=("opencv", "poselib")).estimate(pm)
    assert est.status == "degenerate"
    assert any("one-to-many" in w for w in est.warnings)


def test_external_matches_take_their_images(held_out_pair):
    m = held_out_pair.matches
    pm = load_external_matches({"mkpts0": m.points0, "mkpts1": m.points1},
                               image0=held_out_pair.image0, image1=held_out_pair.image1,
                               K0=held_out_pair.K, K1=held_out_pair.K)
    assert pm.has_images and pm.image_size0 == tuple(held_out_pair.image0.shape[:2])

