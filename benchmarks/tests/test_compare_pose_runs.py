"""benchmarks/compare_pose_runs.py: two bench_pose.py outputs side by side, and (from their
per-pair files) paired ratios and the generated sets' pooled translation error."""

from __future__ import annotations

import json
import math

import compare_pose_runs as cpr
import pytest

TABLE = """### generated/driving (4 pairs)

| method | rot med | trans med | x | AUC@10 | y | z | 1-sigma | 2-sigma |
|---|---|---|---|---|---|---|---|---|
| regression | {r} | {t} | - | 50.0 | - | - | 60 % | 90 % |
"""


def _pairs(scale: float, failed: str | None = None, reverse: bool = False) -> dict:
    """Two sets of 4 pairs; pair i has regression errors scale * (i + 1) / scale * 10 * (i + 1)
    and PoseLib 0.1 / 1; ``failed`` names a pair whose regression failed."""
    out = {}
    for name in ("generated/driving", "KITTI 06 (i, i+1)"):
        records = []
        for i in range(4):
            reg = {"status": "ok", "rot": scale * (i + 1), "trans": scale * 10 * (i + 1)}
            if f"{name}/{i}" == failed:
                reg = {"status": "failed"}
            records.append({"pair": f"{name}/{i}", "methods": {
                "regression": reg, "poselib": {"status": "ok", "rot": 0.1, "trans": 1.0}}})
        out[name] = records[::-1] if reverse else records
    return out


def test_paired_ratios_match_pairs_by_name_and_are_new_over_old():
    # the old file lists its pairs in the other order: pairing by position would mix them
    old, new = _pairs(1.0, reverse=True), _pairs(2.0, failed="generated/driving/3")
    new["only in new"] = new["generated/driving"]
    rows = {(s, m): (rot, trans, n) for s, m, rot, trans, n in
            cpr.paired_ratios(old, new, ["regression", "poselib", "absent"])}
    rot, trans, n = rows[("generated/driving", "regression")]
    assert n == 3  # the pair the new run failed is left out of both
    assert rot == pytest.approx((2.0, 2.0, 2.0)) and trans == pytest.approx((2.0, 2.0, 2.0))
    assert rows[("KITTI 06 (i, i+1)", "poselib")][0] == pytest.approx((1.0, 1.0, 1.0))
    assert {s for s, _ in rows} == {"generated/driving", "KITTI 06 (i, i+1)"}
    assert {m for _, m in rows} == {"regression", "poselib"}


def test_pooled_mean_is_over_the_generated_pairs_both_solved():
    old, new = _pairs(1.0), _pairs(2.0, failed="generated/driving/3")
    # generated pairs 0-2 only (KITTI is not generated; pair 3 failed in new): 10, 20, 30
    n, before, after = cpr.pooled_generated(old, new, "regression")
    assert n == 3 and before == pytest.approx((20.0, 20.0)) and after == pytest.approx((40.0, 40.0))
    assert cpr.pooled_generated(old, new, "absent") is None


def test_a_translation_without_a_direction_counts_as_180_deg():
    old, new = _pairs(1.0), _pairs(1.0)
    new["generated/driving"][0]["methods"]["regression"]["trans"] = math.nan
    got = cpr.pooled_generated(old, new, "regression")
    assert got[2][0] == pytest.approx((180 + 20 + 30 + 40) / 4)


def test_main_prints_the_paired_table_where_both_json_files_exist(tmp_path, capsys):
    for label, scale in (("old", 1.0), ("new", 0.5)):
        (tmp_path / f"{label}.md").write_text(TABLE.format(r=scale, t=10 * scale))
        (tmp_path / f"{label}.json").write_text(json.dumps({"pairs": _pairs(scale)}))
    assert cpr.main([str(tmp_path / "old.md"), str(tmp_path / "new.md"),
                     "--labels", "shipped,cand", "--methods", "regression"]) == 0
    out = capsys.readouterr().out
    assert "| generated/driving | regression | 1.0 / 10.0 |" in out
    assert "| generated/driving | regression | 0.50 [0.50, 0.50] | 0.50 [0.50, 0.50] | 4 |" in out
    assert "| regression | 4 | 25.0 / 25.0 | 12.5 / 12.5 |" in out
    (tmp_path / "new.json").unlink()  # one per-pair file missing: said, the medians only
    assert cpr.main([str(tmp_path / "old.md"), str(tmp_path / "new.md")]) == 0
    out = capsys.readouterr().out
    assert "Paired" not in out and "no per-pair file" in out and "new.json" in out


@pytest.mark.parametrize("text", ["[1, 2]", "{not json", '{"pairs": {"s": [{"pair": 1}]}}'])
def test_a_bad_per_pair_file_is_one_line(tmp_path, capsys, text):
    for label in ("old", "new"):
        (tmp_path / f"{label}.md").write_text(TABLE.format(r=1, t=10))
    (tmp_path / "old.json").write_text(json.dumps({"pairs": _pairs(1.0)}))
    (tmp_path / "new.json").write_text(text)
    assert cpr.main([str(tmp_path / "old.md"), str(tmp_path / "new.md")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: Expected a bench_pose.py per-pair file") and "\n" not in err


def test_a_solved_record_without_its_errors_is_one_line(tmp_path, capsys):
    for label in ("old", "new"):
        (tmp_path / f"{label}.md").write_text(TABLE.format(r=1, t=10))
    (tmp_path / "old.json").write_text(json.dumps({"pairs": _pairs(1.0)}))
    bad = _pairs(1.0)
    bad["generated/driving"][0]["methods"]["regression"] = {"status": "ok", "rot": 1.0}
    (tmp_path / "new.json").write_text(json.dumps({"pairs": bad}))
    assert cpr.main([str(tmp_path / "old.md"), str(tmp_path / "new.md")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: Expected 'rot' and 'trans' numbers") and "\n" not in err
