"""A photo collection end to end (strl_pyg.collection.scene, database, distributed;
``strl-pose scene``): features once, resumable, the COLMAP database that pycolmap's own mappers
read."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from strl_pyg.collection import (
    SceneOptions,
    exhaustive_pairs,
    read_collection,
    run_scene,
    sequential_pairs,
)
from strl_pyg.frontend.features import LINES, POINTS
from strl_pyg.frontend.store import FeatureStore
from strl_pyg.synthetic import generate_pair

h5py = pytest.importorskip("h5py")


def rotation_error_deg(R: np.ndarray, R_gt: np.ndarray) -> float:
    c = (np.trace(np.asarray(R).T @ R_gt) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def write_scene(folder: Path, seeds=(2_000_017, 7)) -> dict[str, dict]:
    """Generated views written as a real_scenes folder (images + cameras.json): both views of
    the first seed's pair, then the first view of each other seed (unrelated to the others)."""
    (folder / "images").mkdir(parents=True)
    entries, gt = [], {}
    for n, seed in enumerate(seeds):
        p = generate_pair(seed)
        views = [(p.image0, p.T_w_c0), (p.image1, p.T_w_c1)] if n == 0 else \
            [(p.image0, p.T_w_c0)]
        for k, (img, T) in enumerate(views):
            name = f"s{n}_{k}.png"
            cv2.imwrite(str(folder / "images" / name), img)
            T = np.asarray(T, dtype=float)
            entries.append({"file": f"images/{name}", "K": np.asarray(p.K).tolist(),
                            "T_cam_to_world": T.tolist(), "width": img.shape[1],
                            "height": img.shape[0]})
            gt[name] = {"T": T, "scene": n}
    (folder / "cameras.json").write_text(json.dumps({"images": entries}))
    return gt


#: The default tier's runs: PoseLib's pose alone (the recommended walk runs in the slow tier)
FAST = SceneOptions(methods=("poselib",), progress=False)


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("collection")
    gt = write_scene(folder)
    images = read_collection(folder / "images", cameras=folder)
    pairs = exhaustive_pairs(len(images))
    out = folder / "out"
    summary = run_scene(images, pairs, out, FAST)
    return folder, images, pairs, out, summary, gt


def test_each_images_features_are_computed_once(generated):
    folder, images, pairs, out, summary, _ = generated
    assert summary.pairs == summary.pairs_computed == 3
    with FeatureStore(out / "features", writable=False) as store:
        from strl_pyg.frontend import FrontendConfig
        from strl_pyg.frontend.pipeline import thorough_points

        cfg = FrontendConfig()
        first = store.names(POINTS, cfg)
        second = store.names(POINTS, thorough_points(cfg))
        lines = store.names(LINES, cfg)
    assert sorted(first) == sorted(lines) == sorted(im.name for im in images)
    # one computation per stored (image, setting): the summary counts what was written
    assert summary.features_computed == {POINTS: len(first) + len(second), LINES: len(lines)}
    # a rerun finds everything done: nothing is computed again
    again = run_scene(images, pairs, out, FAST)
    assert again.pairs_computed == 0 and again.features_computed == {POINTS: 0, LINES: 0}
    assert again.statuses == summary.statuses


def test_the_table_holds_each_pair_once_with_its_status(generated):
    folder, images, pairs, out, summary, gt = generated
    rows = [json.loads(line) for line in (out / "pairs.jsonl").read_text().splitlines()]
    assert len(rows) == 3 and len({(r["image0"], r["image1"]) for r in rows}) == 3
    by = {(r["image0"], r["image1"]): r for r in rows}
    same = by[("s0_0.png", "s0_1.png")]
    assert same["status"] == "ok"
    T_gt = np.linalg.inv(gt["s0_1.png"]["T"]) @ gt["s0_0.png"]["T"]
    assert rotation_error_deg(np.asarray(same["T_0to1"])[:3, :3], T_gt[:3, :3]) < 1.0
    for key in (("s0_0.png", "s1_0.png"), ("s0_1.png", "s1_0.png")):  # different scenes
        assert by[key]["status"] != "ok"
    csv = (out / "pairs.csv").read_text().splitlines()
    assert csv[0].startswith("image0,image1,status") and len(csv) == 4


def test_the_database_holds_what_the_table_says(generated):
    pycolmap = pytest.importorskip("pycolmap")
    folder, images, pairs, out, summary, _ = generated
    rows = {(r["image0"], r["image1"]): r for r in
            map(json.loads, (out / "pairs.jsonl").read_text().splitlines())}
    with pycolmap.Database.open(str(out / "database.db")) as db:
        assert db.num_images() == 3 and db.num_frames() == 3 and db.num_cameras() == 1
        ids = {im.name: im.image_id for im in db.read_all_images()}
        cam = db.read_all_cameras()[0]
        K = images[0].camera.K  # COLMAP's pixel corners: c + 0.5
        assert cam.model.name == "PINHOLE"
        np.testing.assert_allclose(cam.params, [K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5])
        with FeatureStore(out / "features", writable=False) as store:
            from strl_pyg.frontend import FrontendConfig

            xy = store.points("s0_0.png", FrontendConfig()).keypoints
        kp = db.read_keypoints(ids["s0_0.png"])
        np.testing.assert_allclose(kp[: len(xy), :2], xy + 0.5, atol=1e-4)
        geo = db.read_two_view_geometry(ids["s0_0.png"], ids["s0_1.png"])
        rec = rows[("s0_0.png", "s0_1.png")]
        assert geo.config == pycolmap.TwoViewGeometryConfiguration.CALIBRATED
        with h5py.File(out / "matches.h5", "r") as mh5:
            stored = int(np.asarray(mh5["s0_0.png::s0_1.png"]["inliers"]).sum())
        # the pose's inlier mask over the matches (repeated rows each count)
        assert len(geo.inlier_matches) == stored
        assert abs(stored - rec["num_inliers"]) <= 0.02 * rec["num_inliers"]
        T = np.asarray(rec["T_0to1"])
        np.testing.assert_allclose(geo.cam2_from_cam1.rotation.matrix(), T[:3, :3], atol=1e-9)
        # the inlier matches satisfy the pose: small Sampson distances under its E
        m = np.asarray(geo.inlier_matches)
        kp1 = db.read_keypoints(ids["s0_1.png"])
        x0 = np.linalg.solve(K, np.c_[kp[m[:, 0], :2] - 0.5, np.ones(len(m))].T)
        x1 = np.linalg.solve(K, np.c_[kp1[m[:, 1], :2] - 0.5, np.ones(len(m))].T)
        r = np.abs(np.sum(x1 * (geo.E @ x0), axis=0))
        assert np.median(r) * K[0, 0] < 1.0
        bad = db.read_two_view_geometry(ids["s0_0.png"], ids["s1_0.png"])
        assert bad.config == pycolmap.TwoViewGeometryConfiguration.DEGENERATE


def test_other_settings_in_the_same_folder_are_refused(generated):
    from strl_pyg.frontend import FrontendConfig

    folder, images, pairs, out, *_ = generated
    with pytest.raises(ValueError, match="another frontend"):
        run_scene(images, pairs, out, SceneOptions(frontend=FrontendConfig(max_keypoints=100),
                                                   methods=FAST.methods, progress=False))


def test_the_command_line_runs_a_collection(generated, tmp_path):
    from strl_pyg.cli import main

    folder = generated[0]
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("s0_0.png s0_1.png\n")
    assert main(["scene", str(folder / "images"), "--out", str(tmp_path / "o"), "--pairs",
                 str(pairs), "--cameras", str(folder), "--no-database", "--quiet"]) == 0
    rows = (tmp_path / "o" / "pairs.jsonl").read_text().splitlines()
    assert len(rows) == 1 and json.loads(rows[0])["status"] == "ok"
    assert main(["scene", str(folder / "images"), "--out", str(tmp_path / "p"),
                 "--pairs", "sequential:0", "--quiet"]) == 2
    assert main(["scene", str(folder / "images"), "--out", str(tmp_path / "p"),
                 "--verified", "fine", "--quiet"]) == 2


# -- the slow tier: real photographs, COLMAP's mappers, processes ---------------------------

@pytest.fixture(scope="module")
def robot_table(shared_data):
    scene = shared_data / "real_scenes" / "robot_table"
    if not scene.is_dir():
        pytest.skip("real_scenes/robot_table not found")
    return scene


def _real_collection(scene: Path, first: int, count: int):
    from strl_pyg.datasets.camera_files import read_real_scene

    posed = read_real_scene(scene)[first:first + count]
    names = [Path(p.path).name for p in posed]
    return read_collection(scene / "images", names=names, cameras=scene), posed


@pytest.mark.slow
def test_colmaps_mappers_reconstruct_from_our_database(robot_table, tmp_path):
    """pycolmap's incremental mapper and GLOMAP's global mapper on the database of 8 real
    photographs: every image registered, relative rotations after reconstruction within 2 deg
    of the verified poses."""
    pycolmap = pytest.importorskip("pycolmap")
    images, posed = _real_collection(robot_table, 3, 8)
    summary = run_scene(images, exhaustive_pairs(len(images)), tmp_path / "out",
                        SceneOptions(progress=False))
    gt = {Path(p.path).name: p.T_c2w for p in posed}
    for mapper in (pycolmap.incremental_mapping, pycolmap.global_mapping):
        out = tmp_path / mapper.__name__
        out.mkdir()
        recs = mapper(summary.outputs["database"], str(robot_table / "images"), str(out))
        rec = max(recs.values(), key=lambda r: r.num_reg_images())
        assert rec.num_reg_images() == len(images), mapper.__name__
        poses = {im.name: np.linalg.inv(np.r_[im.cam_from_world().matrix(), [[0, 0, 0, 1]]])
                 for im in rec.images.values()}
        errs = [rotation_error_deg((np.linalg.inv(poses[b]) @ poses[a])[:3, :3],
                                   (np.linalg.inv(gt[b]) @ gt[a])[:3, :3])
                for a in poses for b in poses if a < b]
        assert np.median(errs) < 2.0, (mapper.__name__, np.median(errs))


@pytest.mark.slow
def test_a_killed_run_resumes_without_losing_or_repeating(robot_table, tmp_path):
    images, _ = _real_collection(robot_table, 3, 5)
    names = tmp_path / "names.txt"
    names.write_text("\n".join(im.name for im in images))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "strl_pyg.cli", "scene", str(robot_table / "images"), "--out",
           str(out), "--images-list", str(names), "--cameras", str(robot_table), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    jsonl = out / "pairs.jsonl"
    deadline = time.time() + 240
    while time.time() < deadline and proc.poll() is None:
        if jsonl.exists() and len(jsonl.read_text().splitlines()) >= 3:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = len(jsonl.read_text().splitlines())
    with FeatureStore(out / "features", writable=False) as store:
        from strl_pyg.frontend import FrontendConfig
        from strl_pyg.frontend.pipeline import thorough_points

        cfg = FrontendConfig()
        stored = len(store.names(POINTS, cfg)) + len(store.names(POINTS, thorough_points(cfg)))
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads(done.stdout)
    rows = [json.loads(line) for line in jsonl.read_text().splitlines()]
    assert len(rows) == len({(r["image0"], r["image1"]) for r in rows}) == 10
    assert summary["pairs_computed"] == 10 - before  # nothing repeated, nothing lost
    with FeatureStore(out / "features", writable=False) as store:
        total = len(store.names(POINTS, cfg)) + len(store.names(POINTS, thorough_points(cfg)))
    assert summary["features_computed"][POINTS] == total - stored


@pytest.mark.slow
def test_two_torchrun_ranks_give_the_one_process_result(robot_table, tmp_path):
    images, _ = _real_collection(robot_table, 3, 5)
    names = tmp_path / "names.txt"
    names.write_text("\n".join(im.name for im in images))
    args = ["scene", str(robot_table / "images"), "--images-list", str(names), "--cameras",
            str(robot_table), "--pairs", "sequential:3", "--quiet"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node",
           "2", "-m", "strl_pyg.cli", *args, "--out", str(tmp_path / "two")]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    single = run_scene(images, sequential_pairs(len(images), 3), tmp_path / "one",
                       SceneOptions(progress=False, database=False))

    def table(folder):
        rows = [json.loads(line) for line in (folder / "pairs.jsonl").read_text().splitlines()]
        return {(r["image0"], r["image1"]): {k: v for k, v in r.items() if k != "time_ms"}
                for r in rows}

    assert table(tmp_path / "two") == table(tmp_path / "one")
    assert single.pairs_computed == len(table(tmp_path / "one")) == 9
    assert (tmp_path / "two" / "database.db").is_file()


@pytest.mark.slow
def test_a_distorted_pair_is_as_accurate_as_its_undistorted_copy(tmp_path):
    """A generated pair rendered through a RADIAL lens (k1 = -0.2, k2 = 0.05): undistorted
    before matching, its pose is as close to the truth as the pinhole pair's."""
    from strl_pyg.geometry.distortion import undistort_points
    from strl_pyg.geometry.pose import rotation_to_quaternion

    p = generate_pair(2_000_017)
    K = np.asarray(p.K, dtype=float)
    coeffs = np.array([-0.2, 0.05, 0.0, 0.0])
    h, w = p.image0.shape[:2]
    grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 2).astype(float)
    # the distorted image at pixel x shows the pinhole image at undistort(x)
    src = undistort_points(grid, K, coeffs).reshape(h, w, 2).astype(np.float32)
    errors = {}
    for kind in ("pinhole", "distorted"):
        folder = tmp_path / kind
        (folder / "images").mkdir(parents=True)
        entries = []
        for k, (img, T) in enumerate([(p.image0, p.T_w_c0), (p.image1, p.T_w_c1)]):
            if kind == "distorted":
                img = cv2.remap(img, src[..., 0], src[..., 1], cv2.INTER_LINEAR)
            cv2.imwrite(str(folder / "images" / f"{k}.png"), img)
            entries.append((f"{k}.png", np.asarray(T, dtype=float)))
        cams = folder / "sparse"
        cams.mkdir()
        model = ("RADIAL", [K[0, 0], K[0, 2] + 0.5, K[1, 2] + 0.5, -0.2, 0.05]) \
            if kind == "distorted" else ("PINHOLE", [K[0, 0], K[1, 1], K[0, 2] + 0.5,
                                                     K[1, 2] + 0.5])
        (cams / "cameras.txt").write_text(
            f"1 {model[0]} {w} {h} {' '.join(map(str, model[1]))}\n")
        lines = []
        for n, (name, T) in enumerate(entries, 1):
            Tw = np.linalg.inv(T)  # COLMAP stores world-to-camera
            q = rotation_to_quaternion(Tw[:3, :3]).double().numpy().reshape(4)
            lines += [f"{n} {' '.join(map(str, q))} {' '.join(map(str, Tw[:3, 3]))} 1 {name}",
                      ""]
        (cams / "images.txt").write_text("\n".join(lines) + "\n")
        (cams / "points3D.txt").write_text("")
        images = read_collection(folder / "images", cameras=folder)
        assert (images[0].camera.model == "RADIAL") == (kind == "distorted")
        summary = run_scene(images, exhaustive_pairs(2), folder / "out",
                            SceneOptions(progress=False))
        (row,) = [json.loads(line) for line in
                  (folder / "out" / "pairs.jsonl").read_text().splitlines()]
        assert row["status"] == "ok", (kind, row)
        errors[kind] = rotation_error_deg(np.asarray(row["T_0to1"])[:3, :3],
                                          np.asarray(p.T_0to1)[:3, :3])
        assert summary.outputs["database"]
    assert errors["distorted"] <= errors["pinhole"] + 0.25, errors


def test_only_the_pairs_images_are_detected_and_written(generated, tmp_path):
    """Images outside every pair are neither detected nor written; without cameras the
    database guesses one (this raised a KeyError for the unpaired images before)."""
    pycolmap = pytest.importorskip("pycolmap")
    from strl_pyg.collection import Pair

    folder = generated[0]
    images = read_collection(folder / "images")  # no cameras
    with pytest.warns(UserWarning, match=r"^1 of 1 pairs have no intrinsics .* 'unreliable' "
                                         r"\(no_intrinsics\), so none enters the database as "
                                         r"a verified geometry at verified=ok; give a K"):
        s = run_scene(images, [Pair(0, 1)], tmp_path / "o", FAST)
    assert s.features_computed[LINES] == 2
    with pycolmap.Database.open(s.outputs["database"]) as db:
        assert sorted(im.name for im in db.read_all_images()) == ["s0_0.png", "s0_1.png"]
        assert db.read_all_cameras()[0].model.name == "SIMPLE_RADIAL"


def test_pairs_without_intrinsics_are_warned_of_only_where_the_database_loses_them(generated):
    """Before: a collection without cameras ran to the end and wrote a database without one
    verified geometry (every pose 'unreliable': no_intrinsics), and nothing said so."""
    import dataclasses
    import warnings

    from strl_pyg.collection import Pair
    from strl_pyg.collection.scene import intrinsics_warning

    folder, images, pairs, out, _, _ = generated
    blind = [dataclasses.replace(im, camera=None) for im in images]
    assert intrinsics_warning(images, pairs, FAST) is None  # every camera known
    assert intrinsics_warning(blind, pairs, FAST).startswith(f"{len(pairs)} of {len(pairs)} ")
    one = [blind[0], *images[1:]]  # one image without a camera: its pairs only
    assert intrinsics_warning(one, pairs, FAST).startswith(f"{len(images) - 1} of ")
    K = np.asarray(images[0].camera.K).tolist()
    assert intrinsics_warning(blind, [Pair(0, 1, K, K)], FAST) is None  # the pairs file's K
    for options in (dataclasses.replace(FAST, verified=("ok", "unreliable")),
                    dataclasses.replace(FAST, database=False)):
        assert intrinsics_warning(blind, pairs, options) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run_scene(images, pairs, out, FAST)  # the fixture's folder, resumed: nothing to warn
