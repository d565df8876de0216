"""strl-pose inputs that other tools write: KITTI's calib.txt without its labels, method
names in any case."""

from __future__ import annotations

import numpy as np
import pytest

from strl_pyg.cli.commands import _check_methods, _method_names
from strl_pyg.cli.readers import UsageError, read_intrinsics

P0 = "7.188560e+02 0 6.071928e+02 0 0 7.188560e+02 1.852157e+02 0 0 0 1 0"
P1 = "7.188560e+02 0 6.071928e+02 -3.861448e+02 0 7.188560e+02 1.852157e+02 0 0 0 1 0"


def test_kitti_calib_without_labels_reads_as_kitti(tmp_path):
    """Before: two rows of 12 numbers were refused with "got 24"."""
    bare, labelled = tmp_path / "bare.txt", tmp_path / "calib.txt"
    bare.write_text(f"{P0}\n{P1}\n")
    labelled.write_text(f"P0: {P0}\nP1: {P1}\n")
    np.testing.assert_array_equal(read_intrinsics(str(bare)), read_intrinsics(str(labelled)))
    assert read_intrinsics(str(bare))[0, 0] == pytest.approx(718.856)
    odd = tmp_path / "odd.txt"
    odd.write_text("1 2 3 4 5\n6 7 8 9 10\n")
    with pytest.raises(UsageError, match=r"Expected 4 \(fx,fy,cx,cy\), 9 \(3x3\) or 12"):
        read_intrinsics(str(odd))


def test_method_names_ignore_case():
    """Before: --methods OpenCV got no suggestion and no run."""
    assert _method_names("OpenCV, PoseLib") == ("opencv", "poselib")
    _check_methods("OpenCV")
    _check_methods("ALL")
    with pytest.raises(UsageError, match="did you mean 'poselib'"):
        _check_methods("poselibb")
