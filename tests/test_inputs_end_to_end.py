"""Inputs as users give them, end to end: repeated matches, normalised coordinates, other
tools' files, odd images and flags; each case as a user met it, then what it gets."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from torch_geometric.data import HeteroData

from strl_pyg import PairMatches
from strl_pyg.cli import main as cli_main
from strl_pyg.cli.readers import UsageError, read_intrinsics
from strl_pyg.data import materialize_complete_edges
from strl_pyg.data.external import load_external_matches
from strl_pyg.estimation.uncertainty import MAX_SIGMA_DEG, cap_covariance
from strl_pyg.inference import PoseEstimator
from strl_pyg.nn import AttentionConv
from strl_pyg.synthetic import generate_pair


@pytest.fixture(scope="module")
def pair():
    return generate_pair(2_000_017)


def _pm(pair, p0, p1, **kw):
    return PairMatches(p0, p1, K0=pair.K, K1=pair.K, image_size0=pair.image0.shape[:2],
                       image_size1=pair.image1.shape[:2], **kw)


# ----------------------------------------------------------------------------- repeated matches
@pytest.mark.parametrize("unique, times", [(1, 100), (3, 30)])
def test_repeated_matches_are_one_correspondence(pair, unique, times):
    """Before: one match x100 -> 'ok' from poselib, sigma 0.002 deg, 124 / 175 deg wrong;
    3 unique x30 -> 'ok', 9 / 92 deg wrong."""
    m = pair.matches
    p0 = np.tile(m.points0[:unique], (times, 1))
    p1 = np.tile(m.points1[:unique], (times, 1))
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, p0, p1))
    assert est.status == "degenerate" and est.T_0to1 is None
    assert any(f"{unique * times - unique} repeated point matches removed" in w
               for w in est.warnings)
    assert est.num_points == unique


def test_repeating_every_match_does_not_shrink_sigma(pair):
    """Before: every match x5 shrank sigma by ~sqrt(5)."""
    m = pair.matches
    once = PoseEstimator(methods="poselib").estimate(_pm(pair, m.points0, m.points1))
    five = PoseEstimator(methods="poselib").estimate(
        _pm(pair, np.tile(m.points0, (5, 1)), np.tile(m.points1, (5, 1))))
    assert once.status == five.status == "ok"
    np.testing.assert_allclose(five.pose.covariance, once.pose.covariance, rtol=1e-9)
    assert five.pose.inliers.shape == (5 * m.num_points,)
    np.testing.assert_array_equal(five.pose.inliers, np.tile(once.pose.inliers, 5))


def test_all_matches_onto_one_keypoint_warn_at_load_and_are_degenerate(pair):
    """Before: a SuperGlue dict whose 512 matches all point at keypoint 0 of image 1 was
    accepted silently and gave 'ok' from opencv."""
    m = pair.matches
    n = m.num_points
    d = {"keypoints0": m.points0, "keypoints1": m.points1,
         "matches0": np.zeros(n, dtype=np.int64), "matching_scores0": np.ones(n)}
    with pytest.warns(UserWarning, match=r"onto 1 distinct keypoints of image 1"):
        pm = load_external_matches(d, image_size0=pair.image0.shape[:2],
                                   image_size1=pair.image1.shape[:2], K0=pair.K, K1=pair.K)
    est = PoseEstimator(methods=("opencv", "poselib")).estimate(pm)
    assert est.status == "degenerate"
    assert any("one-to-many" in w for w in est.warnings)


def test_deduplicated_keeps_first_rows_and_maps_every_input_row(pair):
    m = pair.matches
    idx = np.array([3, 1, 3, 0, 1, 2])
    pm = _pm(pair, m.points0[idx], m.points1[idx])
    out, notes, inverse = pm.deduplicated()
    np.testing.assert_array_equal(out.points0, m.points0[[3, 1, 0, 2]])
    np.testing.assert_array_equal(inverse, [0, 1, 0, 2, 1, 3])
    assert len(notes) == 1 and "2 repeated point matches removed" in notes[0]
    same, none, _ = _pm(pair, m.points0, m.points1).deduplicated()
    assert none == [] and same.num_points == m.num_points


def test_the_inlier_mask_marks_an_outlier_per_input_row(pair):
    m = pair.matches
    p1 = m.points1.copy()
    p1[10] += 40.0
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, m.points0, p1))
    assert est.pose.inliers.dtype == bool and est.pose.inliers.shape == (m.num_points,)
    assert not est.pose.inliers[10] and est.pose.inliers.sum() >= m.num_points - 3
    assert len(est.to_dict()["pose"]["inliers"]) == m.num_points


# ----------------------------------------------------------------------------- coordinates
def test_normalised_coordinates_with_a_pixel_K_are_named(pair):
    """Before: 'degenerate', 'zero parallax'."""
    m = pair.matches
    Ki = np.linalg.inv(pair.K)
    n0 = (np.c_[m.points0, np.ones(m.num_points)] @ Ki.T)[:, :2]
    n1 = (np.c_[m.points1, np.ones(m.num_points)] @ Ki.T)[:, :2]
    keep = (n0.min(1) > -3) & (n1.min(1) > -3)  # the in-image check allows 4 px outside
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, n0[keep], n1[keep]))
    assert est.status == "degenerate"
    assert any("Expected pixel coordinates" in w and "from_normalized" in w
               for w in est.warnings)
    pm = PairMatches.from_normalized(n0, n1, pair.K, pair.K, pair.image0.shape[:2],
                                     pair.image1.shape[:2])
    np.testing.assert_allclose(pm.points0, m.points0, atol=1e-9)
    assert PoseEstimator(methods="poselib").estimate(pm).status == "ok"
    with pytest.raises(ValueError, match="Expected K0 and K1"):
        PairMatches.from_normalized(n0, n1, None, None, (10, 10), (10, 10))


def test_external_matches_take_their_images(pair):
    m = pair.matches
    pm = load_external_matches({"mkpts0": m.points0, "mkpts1": m.points1},
                               image0=pair.image0, image1=pair.image1, K0=pair.K, K1=pair.K)
    assert pm.has_images and pm.image_size0 == tuple(pair.image0.shape[:2])


# ----------------------------------------------------------------------------- sigma
def test_cap_covariance_bounds_each_block_at_180_degrees():
    """Before: 'ok', 2.1 / 1.5 deg off, sigma 203 / 127 deg (a Strecha wide pair)."""
    cov = np.diag([4.0, 4.0, 4.0, 0.01, 0.01])  # rotation RMS ~ 198 deg
    cov[0, 3] = cov[3, 0] = 0.1
    capped, was = cap_covariance(cov)
    assert was
    assert math.degrees(math.sqrt(np.trace(capped[:3, :3]))) == pytest.approx(MAX_SIGMA_DEG)
    np.testing.assert_allclose(capped[3:, 3:], cov[3:, 3:])  # the other block unchanged
    assert np.all(np.linalg.eigvalsh(capped) >= -1e-12)
    small = np.diag([1e-4] * 5)
    np.testing.assert_array_equal(cap_covariance(small)[0], small)
    assert not cap_covariance(small)[1]


def test_a_clean_pair_has_no_far_bootstrap_resamples(pair):
    est = PoseEstimator(methods="poselib").estimate(pair.matches)
    assert est.pose.info["bootstrap_far"] == 0
    assert not any("resamples found another pose" in w for w in est.warnings)


# ----------------------------------------------------------------------------- layers
def test_materialize_complete_edges_on_a_users_graph_does_not_mutate_it():
    """Before: TypeError in zeros() on a 'kp' graph, and a 'point' node type added."""
    d = HeteroData()
    d["kp"].x = torch.randn(4, 3)
    d["kp", "all", "kp"].dense = torch.ones(1, dtype=torch.bool)
    out = materialize_complete_edges(d)
    assert out["kp", "all", "kp"].edge_index.shape == (2, 16)
    assert d.node_types == ["kp"] and "edge_index" not in d["kp", "all", "kp"]
    assert "dense" in d["kp", "all", "kp"] and "dense" not in out["kp", "all", "kp"]


def _complete(bs, bd):
    from strl_pyg.data.pair_graph import complete_edge_index

    return complete_edge_index(bs, bd, int(max(bs.max(), bd.max())) + 1)


def test_attention_conv_lazy_channels_and_attention_weights():
    torch.manual_seed(0)
    lazy = AttentionConv((-1, 16), heads=2)
    xs, xd = torch.randn(5, 7), torch.randn(4, 16)
    bs, bd = torch.tensor([0, 0, 1, 1, 1]), torch.tensor([0, 0, 1, 1])
    dense = lazy((xs, xd), complete=True, batch=(bs, bd))
    assert lazy.lin_k.weight.shape == (16, 7)
    ei = _complete(bs, bd)
    sparse, (ei2, alpha) = lazy((xs, xd), ei, return_attention_weights=True)
    torch.testing.assert_close(dense, sparse, atol=1e-5, rtol=1e-5)
    assert torch.equal(ei2, ei) and alpha.shape == (ei.shape[1], 2)
    sums = torch.zeros(4, 2).index_add_(0, ei[1], alpha)
    torch.testing.assert_close(sums, torch.ones(4, 2))
    out, (ei3, alpha3) = lazy((xs, xd), complete=True, batch=(bs, bd),
                              return_attention_weights=True)
    torch.testing.assert_close(out, dense, atol=1e-5, rtol=1e-5)
    assert torch.equal(ei3, ei) and torch.allclose(alpha3, alpha)
    with pytest.raises(ValueError, match="target channels"):
        AttentionConv(-1)


def test_attention_conv_edge_features():
    torch.manual_seed(1)
    conv = AttentionConv(16, heads=4, edge_dim=3)
    x = torch.randn(4, 16)
    ei = torch.tensor([[0, 1, 2, 0], [1, 2, 3, 3]])
    ea = torch.randn(4, 3)
    a, b = conv(x, ei, edge_attr=ea), conv(x, ei, edge_attr=2 * ea)
    assert a.shape == (4, 16) and not torch.allclose(a[1:], b[1:])
    torch.testing.assert_close(a[0], b[0])  # node 0 receives no edge
    assert "edge_dim=3" in repr(conv)
    with pytest.raises(ValueError, match="edge_attr of shape"):
        conv(x, ei, edge_attr=ea[:2])
    with pytest.raises(ValueError, match="edge_attr exactly when"):
        conv(x, ei)
    with pytest.raises(ValueError, match="explicit edges with edge_attr"):
        conv(x, complete=True, edge_attr=ea)
    gx = torch.randn(4, 16, dtype=torch.float64, requires_grad=True)
    conv64 = conv.double()
    assert torch.autograd.gradcheck(lambda t: conv64(t, ei, edge_attr=ea.double()), (gx,))


def test_onnx_inputs_of_a_pair_without_lines_fail_before_the_runtime(pair):
    from strl_pyg.inference.export import onnx_inputs
    from strl_pyg.inference.network import prepare_graph
    from strl_pyg.model import StrLPose

    model = StrLPose.from_pretrained()
    no_lines = replace(pair.matches, lines0=None, lines1=None)
    with pytest.raises(ValueError, match=r"Expected a pair graph at the exported sizes .*"
                                         r"'endpoints': 0"):
        onnx_inputs(model, prepare_graph(no_lines, model))


# ----------------------------------------------------------------------------- command line
def test_a_wrong_case_flag_gets_a_suggestion(capsys):
    assert cli_main(["predict", "a.png", "b.png", "--k", "1,1,1,1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "did you mean --K?" in err


def test_an_unknown_method_fails_before_anything_is_loaded(capsys, monkeypatch):
    """Before: '--methods poselibb' failed after 6 s of loading."""
    import strl_pyg.cli.commands as commands

    def boom(*a, **k):
        raise AssertionError("read before the method names were checked")

    monkeypatch.setattr(commands, "load_model", boom)
    monkeypatch.setattr(commands, "read_pair", boom)
    assert cli_main(["predict", "a.png", "b.png", "--methods", "poselibb"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'poselib'?" in err and err.count("\n") == 1


def test_a_folder_as_checkpoint_says_folder(tmp_path, pair, capsys):
    path = pair.matches.save(tmp_path / "m.npz")
    assert cli_main(["predict", "--matches", str(path), "--checkpoint", str(tmp_path)]) == 2
    assert "(got a folder)" in capsys.readouterr().err
    assert cli_main(["predict", "--matches", str(tmp_path)]) == 2
    assert "(got a folder)" in capsys.readouterr().err


def test_predict_reads_a_match_file(tmp_path, pair, capsys):
    path = pair.matches.save(tmp_path / "m.npz")
    code = cli_main(["predict", "--matches", str(path), "--methods", "poselib",
                     "--bootstrap", "0", "--json"])
    import json

    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["pose"]["status"] == "ok" and out["pose"]["method"] == "poselib"
    assert out["num_points"] == pair.matches.num_points
    assert cli_main(["predict", "a.png", "--matches", str(path)]) == 2
    assert "either two images or --matches" in capsys.readouterr().err


def test_intrinsics_from_colmap_and_strecha_files(tmp_path):
    (tmp_path / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n"
        "1 PINHOLE 3072 2048 2759.48 2764.16 1520.69 1006.81\n")
    K = read_intrinsics(str(tmp_path / "cameras.txt"))
    # COLMAP's pixel centres are at +0.5: this package's (OpenCV's) are at 0
    np.testing.assert_allclose(K, [[2759.48, 0, 1520.19], [0, 2764.16, 1006.31], [0, 0, 1]])
    (tmp_path / "one.txt").write_text("1 SIMPLE_RADIAL 640 480 500 320.5 240.5 0.01\n")
    np.testing.assert_allclose(read_intrinsics(str(tmp_path / "one.txt")),
                               [[500, 0, 320], [0, 500, 240], [0, 0, 1]])
    (tmp_path / "two.txt").write_text("1 PINHOLE 640 480 500 500 320 240\n"
                                      "2 PINHOLE 640 480 600 600 320 240\n")
    with pytest.raises(UsageError, match="Expected one camera"):
        read_intrinsics(str(tmp_path / "two.txt"))
    (tmp_path / "0004.jpg.camera").write_text(
        "2759.48 0 1520.69\n0 2764.16 1006.81\n0 0 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
        "-7.2 -7.5 0.2\n3072 2048\n")
    np.testing.assert_allclose(read_intrinsics(str(tmp_path / "0004.jpg.camera")),
                               [[2759.48, 0, 1520.69], [0, 2764.16, 1006.81], [0, 0, 1]])


# ----------------------------------------------------------------------------- smaller items
def test_twelve_bit_data_in_a_sixteen_bit_png_is_not_dark(tmp_path, pair):
    """Before: v // 257 made 4095 into 15: 'degenerate', 'featureless'."""
    import cv2

    from strl_pyg.utils.images import read_image_file

    twelve = [(img.astype(np.uint32) * 4095 // 255).astype(np.uint16)
              for img in (pair.image0, pair.image1)]
    cv2.imwrite(str(tmp_path / "a.png"), twelve[0])
    back = read_image_file(tmp_path / "a.png")
    assert back.dtype == np.uint8 and np.abs(back.astype(int) - pair.image0).max() <= 1
    est = PoseEstimator(methods="opencv").estimate_images(*twelve, K0=pair.K)
    assert est.status == "ok"


def test_a_missing_data_root_is_one_line(capsys):
    """Before: two UserWarnings blaming the sequences."""
    import warnings

    from strl_pyg.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["train", "--dataset", "kitti", "--data-root", "/nonexistent/kitti",
                     "--steps", "1", "--out", "/tmp/never_written_run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no such folder" in err


def test_the_match_drawing_has_a_title_a_legend_and_subsamples(pair):
    from strl_pyg.viz.matches import draw_matches

    m = replace(pair.matches, image0=pair.image0, image1=pair.image1)
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


def test_the_focal_warning_of_a_downscaled_pair_quotes_the_users_numbers(tmp_path, pair,
                                                                         capsys):
    """Before: fx=153.8 at 1600 px, numbers the user never gave."""
    import cv2

    for name, img in (("a.png", pair.image0), ("b.png", pair.image1)):
        cv2.imwrite(str(tmp_path / name), cv2.resize(img, (3200, 960)))
    code = cli_main(["predict", str(tmp_path / "a.png"), str(tmp_path / "b.png"),
                     "--K", "100000,100000,1600,480", "--methods", "opencv",
                     "--bootstrap", "0"])
    out = capsys.readouterr().out
    assert code == 3
    assert "fx=1e+05" in out and "(3200 px)" in out and "1600 px)" not in out


def test_methods_that_read_images_are_skipped_without_them(pair):
    """Before: 'failed' (found no pose) for the network's methods on a match file without
    images; they did not run at all."""
    no_images = replace(pair.matches, image0=None, image1=None,
                        image_size0=pair.image0.shape[:2], image_size1=pair.image1.shape[:2])
    est = PoseEstimator(methods=("regression", "poselib", "fused"), bootstrap=0).estimate(
        no_images)
    reg, fused = est.methods["regression"], est.methods["fused"]
    assert reg.status == fused.status == "skipped" and reg.T_0to1 is None
    assert "attach them" in reg.warnings[0] and "visual='pixel'" in reg.warnings[0]
    assert est.status == "ok" and est.pose.method == "poselib"
    with_images = PoseEstimator(methods="regression", bootstrap=0).estimate(pair.matches)
    assert with_images.methods["regression"].status == "ok"


def test_no_progress_reaches_the_match_cache_bar(monkeypatch):
    """Before: --no-progress left the front-end cache's bar on."""
    from strl_pyg.datasets import SyntheticPairs
    from strl_pyg.training.config import TrainConfig
    from strl_pyg.training.data import build_datasets

    seen = []
    monkeypatch.setattr(SyntheticPairs, "build_cache",
                        lambda self, num_workers=0, **kw: seen.append(kw.get("progress")))
    for mix in (None, "lines_small"):  # without a mix, --matches frontend was ignored
        seen.clear()
        cfg = TrainConfig(matches="frontend", scene_mix=mix, train_pairs=2, val_pairs=1)
        try:
            build_datasets(cfg, progress=False)
        except Exception:  # the patched cache builds nothing; what matters is what it was told
            pass
        assert seen and not any(seen), (mix, seen)


# ----------------------------------------------------------------------------- rows (review)
def test_the_fundamental_inlier_mask_follows_the_input_rows(pair):
    """Before: with repeated matches the mask had one entry per distinct match, not per input
    row as every other mask of the record."""
    m = pair.matches
    twice = PairMatches(np.tile(m.points0, (2, 1)), np.tile(m.points1, (2, 1)),
                        image_size0=m.image_size0, image_size1=m.image_size1)
    est = PoseEstimator(methods="poselib").estimate(twice)
    mask = est.pose.info["fundamental_inlier_mask"]
    assert mask.shape == (2 * m.num_points,) and mask.dtype == bool
    np.testing.assert_array_equal(mask[:m.num_points], mask[m.num_points:])
    assert est.pose.info["fundamental_inliers"] == int(mask[:m.num_points].sum())


def test_inliers_of_matches_index_the_matches_the_methods_ran_on(pair):
    m = pair.matches
    idx = np.r_[np.arange(m.num_points), np.arange(10)]
    est = PoseEstimator(methods="poselib").estimate(_pm(pair, m.points0[idx], m.points1[idx]))
    assert est.status == "ok" and est.matches.num_points == m.num_points
    np.testing.assert_array_equal(est.point_rows, np.r_[np.arange(m.num_points),
                                                        np.arange(10)])
    on_matches = est.inliers_of_matches()
    assert on_matches.shape == (m.num_points,)
    np.testing.assert_array_equal(on_matches[est.point_rows], est.pose.inliers)


def test_select_keeps_the_front_ends_inlier_rows_in_step(pair):
    """Before: select() copied info['fundamental_inliers'] unchanged, so add_lines read other
    rows (or past the end) as the fundamental matrix's inliers."""
    m = pair.matches
    pm = replace(_pm(pair, m.points0[:6], m.points1[:6]),
                 info={"fundamental_inliers": [0, 2, 3, 5]})
    assert pm.select([5, 1, 2]).info["fundamental_inliers"] == [0, 2]
    assert pm.select([3, 3]).info["fundamental_inliers"] == [0, 1]
    assert pm.select(line_index=[]).info["fundamental_inliers"] == [0, 2, 3, 5]
    stale = replace(pm, info={"fundamental_inliers": [0, 9]})
    assert "fundamental_inliers" not in stale.select([0, 1]).info


def test_add_lines_refuses_inlier_rows_past_the_points(pair):
    from strl_pyg.frontend.pipeline import add_lines

    m = pair.matches
    pm = _pm(pair, m.points0[:6], m.points1[:6], image0=pair.image0, image1=pair.image1,
             info={"fundamental": None, "fundamental_inliers": [0, 9]})
    with pytest.raises(ValueError, match=r"rows of the 6 point matches \(got indices 0\.\.9\)"):
        add_lines(pm)


def test_the_point_poor_regime_counts_distinct_matches(pair, monkeypatch):
    """Before: the recommended order read num_points (rows, one-to-many included) while the
    methods' minimum counts read the distinct ones."""
    import strl_pyg.inference.estimator as est_mod

    m = pair.matches
    # 25 distinct correspondences, then 15 rows reusing keypoints of image 1 (one-to-many)
    p0 = np.r_[m.points0[:25], m.points0[25:40]]
    p1 = np.r_[m.points1[:25], m.points1[:15]]
    pm = _pm(pair, p0, p1)
    assert pm.num_points == 40 and pm.num_distinct_points == 25
    seen = []
    real = est_mod.recommended_order
    monkeypatch.setattr(est_mod, "recommended_order",
                        lambda model, n=None: seen.append(n) or real(model, n))
    PoseEstimator(methods="poselib").estimate(pm)
    assert seen == [25]


def test_check_support_leaves_a_regression_record_as_it_is_by_default(pair):
    """Before: check_support's default checked=True failed the regression's record, which the
    estimator never checks."""
    from strl_pyg.inference.record import MethodResult
    from strl_pyg.inference.support import check_support

    m = pair.matches
    wrong = np.eye(4)
    wrong[:3, 3] = [0.0, 1.0, 0.0]
    reg = check_support(MethodResult("regression", "ok", wrong), m)
    assert reg.status == "ok" and "support_inliers" not in reg.info
    assert check_support(MethodResult("regression", "ok", wrong), m, checked=True).status \
        == "failed"
    assert check_support(MethodResult("poselib", "ok", wrong), m).status == "failed"


def test_complete_edges_of_unsorted_graph_ids_join_only_one_graphs_nodes():
    """Before: complete_edge_index assumed sorted ids, so AttentionConv's attention weights
    on a user's unsorted batch came with edges between graphs."""
    bs, bd = torch.tensor([1, 0, 1, 0, 2, 1]), torch.tensor([2, 0, 1, 1, 0])
    ei = _complete(bs, bd)
    want = {(j, i) for j in range(6) for i in range(5) if bs[j] == bd[i]}
    assert {tuple(e) for e in ei.t().tolist()} == want and ei.shape[1] == len(want)
    torch.manual_seed(0)
    conv = AttentionConv(8, heads=2)
    xs, xd = torch.randn(6, 8), torch.randn(5, 8)
    dense = conv((xs, xd), complete=True, batch=(bs, bd))
    out, (ei2, alpha) = conv((xs, xd), complete=True, batch=(bs, bd),
                             return_attention_weights=True)
    torch.testing.assert_close(out, dense, atol=1e-5, rtol=1e-5)
    assert {tuple(e) for e in ei2.t().tolist()} == want
    torch.testing.assert_close(torch.zeros(5, 2).index_add_(0, ei2[1], alpha),
                               torch.ones(5, 2))


def test_shipped_metadata_is_read_with_the_checkpoint_checks(tmp_path, monkeypatch):
    from strl_pyg.model import StrLPose

    assert StrLPose.pretrained_metadata() == StrLPose.from_pretrained().metadata
    monkeypatch.setitem(StrLPose.PRETRAINED, "geometric", ("missing.pt", {}))
    for read in (StrLPose.pretrained_metadata, StrLPose.from_pretrained):
        with pytest.raises(FileNotFoundError,
                           match="Expected the shipped checkpoint 'missing.pt'"):
            read()


def test_the_default_predict_does_not_build_the_network(tmp_path, pair, capsys, monkeypatch):
    """Before: predict loaded the model (~80 ms a process) for the default recommended pose,
    which on a pair with enough points is PoseLib's."""
    import json

    import cv2

    from strl_pyg.model import StrLPose

    def refuse(*a, **k):
        raise AssertionError("the network was built")

    monkeypatch.delenv("STRL_POSE_WEIGHTS", raising=False)
    monkeypatch.setattr(StrLPose, "from_pretrained", classmethod(refuse))
    monkeypatch.setattr(StrLPose, "load", classmethod(refuse))
    for i, img in enumerate((pair.image0, pair.image1)):
        cv2.imwrite(str(tmp_path / f"{i}.png"), img)
    K = pair.K
    code = cli_main(["predict", str(tmp_path / "0.png"), str(tmp_path / "1.png"), "--K",
                     f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["pose"]["status"] == "ok" and out["pose"]["method"] == "poselib"
    assert out["translation_kind"] == StrLPose.pretrained_header()[0].translation


def test_predict_on_a_match_file_runs_the_recommended_methods_only(tmp_path, pair, capsys):
    """Before, `predict --matches` with the default '--methods recommended' ran every method
    (the image path ran only the ones the recommended pose needs); the pose is the same."""
    import json

    path = pair.matches.save(tmp_path / "m.npz")
    runs = {}
    for methods in ("recommended", "all"):
        assert cli_main(["predict", "--matches", str(path), "--methods", methods,
                         "--json"]) == 0
        runs[methods] = json.loads(capsys.readouterr().out)
    lazy, full = runs["recommended"], runs["all"]
    assert lazy["pose"]["method"] == full["pose"]["method"]
    np.testing.assert_allclose(lazy["pose"]["T_0to1"], full["pose"]["T_0to1"], atol=1e-12)
    assert list(lazy["methods"]) == [lazy["pose"]["method"]]
    assert len(full["methods"]) > 1
