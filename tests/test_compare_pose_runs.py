"""benchmarks/compare_pose_runs.py: two bench_pose.py outputs side by side, and (from their
per-pair files) paired ratios and the generated sets' pooled translation error."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import compare_pose_runs as cpr  # noqa: E402

TABLE = """### generated/driving (4 pairs)

| method | rot med | trans med | x | AUC@10 | y | z | 1-sigma | 2-sigma |
|---|---|---|---|---|---|---|---|---|
| regression | {r} | {t} | - | 50.0 | - | - | 60 % | 90 % |
"""


def _pairs(scale: float, failed: str | None = None) -> dict:
    out = {}
    for name in ("generated/driving", "KITTI 06 (i, i+1)"):
        records = []
        for i in range(4):
            status = "failed" if f"{name}/{i}" == failed else "ok"
            reg = {"status": status, "rot": scale * (i + 1), "trans": scale * 10 * (i + 1)}
            if status != "ok":
                reg = {"status": status}
            records.append({"pair": f"{name}/{i}", "methods": {
                "regression": reg, "poselib": {"status": "ok", "rot": 0.1, "trans": 1.0}}})
        out[name] = records
    return out


def test_paired_ratios_and_pooled_mean_are_known_answers():
    old, new = _pairs(1.0), _pairs(2.0, failed="generated/driving/3")
    rows = {(s, m): (rot, trans, n) for s, m, rot, trans, n in
            cpr.paired_ratios(old, new, ["regression", "poselib"])}
    rot, trans, n = rows[("generated/driving", "regression")]
    assert n == 3  # the pair the new run failed is left out of both
    assert rot == pytest.approx((2.0, 2.0, 2.0)) and trans == pytest.approx((2.0, 2.0, 2.0))
    assert rows[("KITTI 06 (i, i+1)", "poselib")][0] == pytest.approx((1.0, 1.0, 1.0))
    # pooled over the generated sets only: 10, 20, 30, 40 deg
    assert cpr.pooled_generated(old, "regression") == pytest.approx((4, 25.0, 25.0))
    assert cpr.pooled_generated(new, "regression") == pytest.approx((3, 40.0, 40.0))
    assert cpr.pooled_generated(old, "missing") is None


def test_main_prints_the_paired_table_where_both_json_files_exist(tmp_path, capsys):
    for label, scale in (("old", 1.0), ("new", 0.5)):
        (tmp_path / f"{label}.md").write_text(TABLE.format(r=scale, t=10 * scale))
        (tmp_path / f"{label}.json").write_text(json.dumps({"pairs": _pairs(scale)}))
    assert cpr.main([str(tmp_path / "old.md"), str(tmp_path / "new.md"),
                     "--labels", "shipped,cand", "--methods", "regression"]) == 0
    out = capsys.readouterr().out
    assert "| generated/driving | regression | 1.0 / 10.0 |" in out
    assert "| generated/driving | regression | 0.50 [0.50, 0.50] | 0.50 [0.50, 0.50] | 4 |" in out
    assert "| regression | 4, 25.0 / 25.0 | 4, 12.5 / 12.5 |" in out
    (tmp_path / "new.json").unlink()  # without the per-pair files: the medians only
    cpr.main([str(tmp_path / "old.md"), str(tmp_path / "new.md")])
    assert "Paired" not in capsys.readouterr().out
