import math

import numpy as np
import pytest
from matplotlib import image as mpimg
from matplotlib.figure import Figure

from strl_pyg.geometry import Pose
from strl_pyg.metrics import kitti_odometry_errors, kitti_odometry_summary
from strl_pyg.viz.plots import plot_segment_errors, plot_trajectory_topview, save_figure

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def read_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    return mpimg.imread(str(path))


def circle(n=100, radius=50.0):
    a = np.linspace(0, 1.5 * math.pi, n)
    return np.column_stack([radius * np.sin(a), np.zeros(n), radius * (1 - np.cos(a))])


def coloured(img):
    """Pixels that are neither grey nor white (the ground truth is drawn in black)."""
    return int((np.ptp(img[..., :3], axis=-1) > 0.2).sum())


def test_topview_writes_png_and_draws_estimates(tmp_path):
    gt = circle()
    out = plot_trajectory_topview(tmp_path / "a.png", gt)
    img_gt = read_png(out)
    assert img_gt.shape == (600, 600, 4)
    # an estimate is drawn: more coloured pixels than with the ground truth alone
    est = gt * 1.1
    out2 = plot_trajectory_topview(tmp_path / "sub" / "b.png", gt, {"model": est},
                                   title="seq 06")
    img = read_png(out2)
    assert coloured(img) > coloured(img_gt) + 100
    # no temporary files left behind
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["a.png", "b.png"]


def test_topview_accepts_poses(tmp_path, kitti_root):
    rows = np.loadtxt(kitti_root / "poses" / "06.txt")[:300]
    p = plot_trajectory_topview(tmp_path / "k.png", rows, {"gt as Pose": Pose.from_kitti_row(rows)})
    assert p.stat().st_size > 1000


def test_segment_errors_plot(tmp_path, kitti_root):
    gt = np.loadtxt(kitti_root / "poses" / "06.txt").reshape(-1, 3, 4)
    est = gt.copy()
    est[:, :, 3] *= 1.02
    seg = kitti_odometry_errors(gt, est)
    out = plot_segment_errors(tmp_path / "drift.png",
                              {"scaled": seg, "summary": kitti_odometry_summary(seg)})
    assert read_png(out).shape == (400, 1000, 4)


def test_plot_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"positions \[N, 3\]"):
        plot_trajectory_topview(tmp_path / "x.png", np.zeros((5, 2)))
    with pytest.raises(ValueError, match="Expected two axes"):
        plot_trajectory_topview(tmp_path / "x.png", circle(), axes=("x", "w"))
    with pytest.raises(ValueError, match=r"\.png"):
        save_figure(Figure(), tmp_path / "x.jpg")
    with pytest.raises(ValueError, match="at least one"):
        plot_segment_errors(tmp_path / "x.png", {})
    assert not list(tmp_path.iterdir())
