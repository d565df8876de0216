"""The benchmarks' shared helper has a name no user script of its own would have: a script
named common.py beside a user's run used to shadow it (or be shadowed)."""

from __future__ import annotations

from pathlib import Path

BENCH = Path(__file__).resolve().parents[1]


def test_no_benchmark_imports_a_generic_module_name():
    scripts = [*BENCH.glob("*.py"), *(BENCH / "studies").glob("*.py")]
    assert len(scripts) >= 20
    for script in scripts:
        assert script.name != "common.py", script
        text = script.read_text()
        assert "from common import" not in text and "\nimport common\n" not in text, script
