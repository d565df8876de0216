"""The benchmarks' shared helper has a name no user script of its own would have: a script
named common.py beside a user's run used to shadow it (or be shadowed)."""

from __future__ import annotations

from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def test_no_benchmark_imports_a_generic_module_name():
    assert not (BENCH / "common.py").exists()
    for script in BENCH.glob("*.py"):
        text = script.read_text()
        assert "from common import" not in text and "\nimport common\n" not in text, script
