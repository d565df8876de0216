"""``calibrate_regression.py`` on the user's own posed photographs: the held-out pairs of any
posed folder, with their ground-truth relative poses."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import calibrate_regression as cr  # noqa: E402

from strl_pyg.synthetic import SceneConfig, generate_pair  # noqa: E402


def test_posed_pairs_read_any_scene_folder_with_its_poses(tmp_path):
    p = generate_pair(41, SceneConfig(kind="street", image_size=(96, 256)))
    scene = tmp_path / "data" / "street"
    (scene / "images").mkdir(parents=True)
    T1 = np.linalg.inv(np.asarray(p.T_0to1, dtype=np.float64))  # camera 1 to camera 0
    images = []
    for i, (img, T) in enumerate(((p.image0, np.eye(4)), (p.image1, T1))):
        cv2.imwrite(str(scene / "images" / f"{i}.png"), img)
        images.append({"file": f"images/{i}.png", "K": np.asarray(p.K).tolist(),
                       "T_cam_to_world": T.tolist(), "width": 256, "height": 96})
    (scene / "cameras.json").write_text(json.dumps({"images": images}))
    pairs = cr.posed_pairs(tmp_path / "data", ["street"], tmp_path / "cache", gap=1, stride=1)
    assert [pid for pid, _, _ in pairs] == ["street/0-1"]
    _, m, T = pairs[0]
    np.testing.assert_allclose(T, np.asarray(p.T_0to1, dtype=np.float64), atol=1e-9)
    assert m.num_points > 8 and m.image_size0 == (96, 256)
    again = cr.posed_pairs(tmp_path / "data", ["street"], tmp_path / "cache", gap=1, stride=1)
    np.testing.assert_array_equal(again[0][1].points0, m.points0)  # read back from the cache
    assert cr.posed_pairs(tmp_path / "data", ["street"], tmp_path / "cache", gap=2) == []


def test_report_writes_the_printed_coverage_with_its_command(tmp_path, monkeypatch):
    """``--report FILE`` appends the figures it prints, headed by the checkpoint and the
    command; a scene whose errors are far from the others' gets 0 % when left out."""
    from strl_pyg.model.strl_pose import StrLPose

    monkeypatch.setattr(StrLPose, "load", staticmethod(lambda path: object()))
    monkeypatch.setattr(cr.btv, "real_val_pairs",
                        lambda cache, gap, stride: [("a/0-2", None, None)])
    d2 = np.array([1.0, 1.0, 1.0, 100.0, 100.0, 100.0])  # scene b: 100x scene a's errors
    monkeypatch.setattr(cr, "mahalanobis", lambda model, pairs, own=False: (d2, list("aaabbb")))
    report = tmp_path / "calibration.md"
    for own in ([], ["--own"]):
        assert cr.main(["--model", "m.pt", "--report", str(report), *own]) == 0
    text = report.read_text()
    assert text.count("## `m.pt`, ") == 2 and "the network's own covariance" in text
    command = f"python benchmarks/calibrate_regression.py --model m.pt --report {report}"
    assert f"Command: `{command}`" in text
    assert "| a | 3 | 100% [" in text and "| b | 3 | 0% [" in text
