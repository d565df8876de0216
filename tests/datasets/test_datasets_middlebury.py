"""Middlebury multi-view parameters and pairs (real 'dino' slice where present)."""

from pathlib import Path

import numpy as np
import pytest

from strl_pyg.datasets.middlebury import middlebury_pairs, read_middlebury_parameters

DINO = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "middlebury_dino"


def _write(tmp_path, lines):
    p = tmp_path / "toy_par.txt"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_relative_pose_convention_on_a_known_pair(tmp_path):
    K = "100 0 50 0 100 40 0 0 1"
    # view a at the world origin; view b 1 m to the right (camera centre C_b = (1, 0, 0))
    lines = ["2", f"a.png {K} 1 0 0 0 1 0 0 0 1 0 0 0", f"b.png {K} 1 0 0 0 1 0 0 0 1 -1 0 0"]
    _write(tmp_path, lines)
    for n in ("a.png", "b.png"):
        (tmp_path / n).write_bytes(b"")
    (a, b, T), = middlebury_pairs(tmp_path)
    X_a = np.array([0.3, -0.2, 4.0])
    X_b = T[:3, :3] @ X_a + T[:3, 3]
    # the same world point seen from b, 1 m to the right: x decreases by 1
    assert np.allclose(X_b, X_a - [1.0, 0.0, 0.0])
    assert a.name == "a.png" and b.name == "b.png"


def test_only_existing_images_are_paired(tmp_path):
    K = "100 0 50 0 100 40 0 0 1"
    eye = "1 0 0 0 1 0 0 0 1"
    _write(tmp_path, ["3"] + [f"v{i}.png {K} {eye} {i} 0 0" for i in range(3)])
    for n in ("v0.png", "v2.png"):
        (tmp_path / n).write_bytes(b"")
    pairs = middlebury_pairs(tmp_path)
    assert [(a.name, b.name) for a, b, _ in pairs] == [("v0.png", "v2.png")]


def test_malformed_files_raise_one_line_errors(tmp_path):
    p = _write(tmp_path, ["1", "a.png 1 2 3"])
    with pytest.raises(ValueError, match="22 fields"):
        read_middlebury_parameters(p)
    with pytest.raises(FileNotFoundError, match="Expected a Middlebury parameter file"):
        read_middlebury_parameters(tmp_path / "missing_par.txt")
    with pytest.raises(ValueError, match="positive integer gap"):
        middlebury_pairs(tmp_path, gap=0)


@pytest.mark.skipif(not DINO.is_dir(), reason="shared/data/middlebury_dino not present")
def test_dino_pairs_have_small_epipolar_residuals():
    import cv2

    from strl_pyg.frontend import match_images
    from strl_pyg.geometry import epipolar_residuals

    pairs = middlebury_pairs(DINO)
    assert len(pairs) == len(list(DINO.glob("*.png"))) - 1
    a, b, T = pairs[10]
    img0 = cv2.imread(str(a.path), cv2.IMREAD_GRAYSCALE)
    img1 = cv2.imread(str(b.path), cv2.IMREAD_GRAYSCALE)
    m = match_images(img0, img1, K0=a.K, K1=b.K)
    perr, _ = epipolar_residuals(m, T)
    assert np.median(perr) < 2.0
