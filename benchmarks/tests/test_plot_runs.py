"""benchmarks/plot_runs.py: validation curves of several runs from their log.csv files."""

from __future__ import annotations

from pathlib import Path

import plot_runs
import pytest


def _log(run: Path, rows: list[tuple[int, str, str, float]]) -> Path:
    run.mkdir()
    lines = ["step,split,key,value"] + [f"{s},{sp},{k},{v}" for s, sp, k, v in rows]
    (run / "log.csv").write_text("\n".join(lines) + "\n")
    return run


def test_reads_only_validation_rows_in_step_order(tmp_path):
    run = _log(tmp_path / "a", [(250, "val", "rot_err_deg", 5.0), (10, "train", "loss", 1.0),
                                (500, "val", "rot_err_deg", 4.5)])
    log = plot_runs.read_validation(run)
    assert dict(log) == {"rot_err_deg": [(250, 5.0), (500, 4.5)]}


def test_writes_a_png_for_two_runs(tmp_path):
    a = _log(tmp_path / "a", [(250, "val", "rot_err_deg", 5.0), (250, "val", "trans_err_deg", 3.0)])
    b = _log(tmp_path / "b", [(250, "val", "rot_err_deg", 6.0), (250, "val", "trans_err_deg", 4.0)])
    out = tmp_path / "fig.png"
    assert plot_runs.main([str(a), str(b), "--labels", "x,y", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_input_is_one_line(tmp_path):
    with pytest.raises(SystemExit, match="expected a training log at"):
        plot_runs.main([str(tmp_path / "missing"), "--out", str(tmp_path / "f.png")])
    a = _log(tmp_path / "a", [(250, "val", "rot_err_deg", 5.0)])
    with pytest.raises(SystemExit, match="one label per run"):
        plot_runs.main([str(a), "--labels", "x,y", "--out", str(tmp_path / "f.png")])
