"""benchmarks/study_pose_recipe.py motion: validation errors grouped by the generator's
motion (where the validation mean of issue 30's study comes from)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import study_pose_recipe as spr  # noqa: E402

RESULT = {"motions": ["forward", "rotation", "forward", "orbit"],
          "errors": {"PoseLib": [[0.1, 2.0], [0.5, 100.0], None, [0.2, 4.0]],
                     "run": [[1.0, 10.0], [5.0, 170.0], [2.0, 20.0], [9.0, 60.0]]}}


def test_groups_by_motion_and_counts_a_missing_pose_as_90_deg():
    kinds, table = spr._by_motion(RESULT)
    assert kinds == ["forward", "orbit", "rotation"]
    n, mean, med, over90 = table["PoseLib"]["forward"]
    assert (n, mean, med, over90) == (2, 46.0, 46.0, 0.0)  # (2 + 90) / 2
    assert table["run"]["all"] == (4, 65.0, 40.0, 0.25)
    assert table["run"]["rotation"] == (1, 170.0, 170.0, 1.0)


def test_table_and_figure(tmp_path):
    text = spr.motion_table(RESULT)
    assert "| method | all | forward (2) | orbit (1) | rotation (1) |" in text
    assert "| run | 65.0 / 40.0 | 15.0 / 15.0 | 60.0 / 60.0 | 170.0 / 170.0 |" in text
    out = tmp_path / "m.png"
    spr.plot_by_motion(RESULT, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_schedule_variants_parse():
    assert spr.parse_run("fe:both-cos:2") == ("fe", "both-cos", 2)
    assert "--lr-schedule" in spr.VARIANTS["both-cos1e-3"]
    with pytest.raises(SystemExit, match="MATCHES:VARIANT"):
        spr.parse_run("fe:cosine")
