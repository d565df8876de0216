"""The benchmarks' layout (issue 49): the scripts users run and one current results file per
topic at the top of ``benchmarks/``, the studies and their results in ``benchmarks/studies/``,
every script still starts from where it is, and the package's tests (``tests/``) never import
a benchmark: a benchmark is tested here."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1]
REPO = BENCH.parent
SCRIPTS = sorted([*BENCH.glob("*.py"), *(BENCH / "studies").glob("*.py")])
#: Helpers imported by the scripts, not run.
HELPERS = {"strl_bench_common.py", "ablation_eval.py"}
MAX_TOP_RESULTS = 12
#: Calls that put a folder on the import path or load a file as a module.
PATH_CALLS = {"insert", "append", "syspath_prepend", "spec_from_file_location",
              "import_module", "run_path"}


def _top_results() -> list[str]:
    """Results files and folders at the top of benchmarks/ (not the README, the scripts, the
    figures, the models or the folders of studies and tests)."""
    keep = {"README.md", "figures", "models", "studies", "tests", "__pycache__"}
    return sorted(p.name for p in BENCH.iterdir()
                  if p.name not in keep and p.suffix != ".py")


def test_at_most_twelve_results_at_the_top():
    top = _top_results()
    assert len(top) <= MAX_TOP_RESULTS, top
    assert {"results_pose.md", "results_predict.md", "training.md", "results_ablation.md",
            "results_two_view.md"} <= set(top)
    assert not [n for n in top if "ship_candidate" in n]
    assert (BENCH / "studies" / "ship_candidates.md").is_file()


def _benchmark_use(path: Path, modules: set[str]) -> list[str]:
    """Lines of ``path`` that put benchmarks/ on the import path, load a file from it, or
    import one of its scripts."""
    text = path.read_text()
    bad = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Call):
            func = node.func.attr if isinstance(node.func, ast.Attribute) else \
                getattr(node.func, "id", "")
            call = (ast.get_source_segment(text, node) or "") if func in PATH_CALLS else ""
            if "benchmarks" in call:
                bad.append(f"{path}:{node.lineno}: {' '.join(call.split())}")
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                 else [])
        bad += [f"{path}:{node.lineno}: import {n}" for n in names
                if n.split(".")[0] in modules]
    return bad


def test_the_package_tests_never_import_a_benchmark(tmp_path):
    modules = {p.stem for p in SCRIPTS}
    bad = [e for f in sorted((REPO / "tests").rglob("*.py")) for e in _benchmark_use(f, modules)]
    assert not bad, "\n".join(bad)
    planted = tmp_path / "test_x.py"
    planted.write_text('import importlib.util, sys\nsys.path.insert(0, "benchmarks")\n'
                       'import bench_pose\nspec = importlib.util.spec_from_file_location(\n'
                       '    "x", ROOT / "benchmarks" / "x.py")\n')
    assert len(_benchmark_use(planted, modules)) == 3


RUNNABLE = [p for p in SCRIPTS if p.name not in HELPERS]


@pytest.fixture(scope="module")
def help_runs(script_help):
    """Every script's ``--help``, in one process (the root conftest's ``script_help``)."""
    return script_help(RUNNABLE)


def test_help_runner_gives_each_script_its_own_import_path(tmp_path, script_help):
    """The one-process ``--help`` runner (root conftest) sees what separate processes see: a
    helper found beside one script is not found by a script elsewhere that imports it, and a
    script's failure does not stop the next."""
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
    (tmp_path / "a" / "planted_helper.py").write_text("NAME = 'x'\n")
    script = ("import argparse\nimport planted_helper\n"
              "argparse.ArgumentParser(description=planted_helper.NAME).parse_args()\n")
    (tmp_path / "a" / "beside.py").write_text(script)
    (tmp_path / "b" / "elsewhere.py").write_text(script)
    (tmp_path / "b" / "plain.py").write_text("import argparse\n"
                                            "argparse.ArgumentParser().parse_args()\n")
    runs = script_help([tmp_path / "a" / "beside.py", tmp_path / "b" / "elsewhere.py",
                        tmp_path / "b" / "plain.py"])
    beside, elsewhere, plain = (runs[tmp_path / p] for p in
                                ("a/beside.py", "b/elsewhere.py", "b/plain.py"))
    assert beside[0] == 0 and "usage: beside.py" in beside[1]
    assert elsewhere[0] == 1 and "No module named 'planted_helper'" in elsewhere[2]
    assert plain[0] == 0 and "usage: plain.py" in plain[1]


@pytest.mark.slow
@pytest.mark.parametrize("script", RUNNABLE, ids=lambda p: str(p.relative_to(BENCH)))
def test_every_script_answers_help_from_where_it_is(script, help_runs):
    """A moved script still finds the shared helpers and the scripts it reads (and this
    checkout's package)."""
    code, stdout, stderr = help_runs[script]
    assert code == 0, stderr[-2000:]
    assert "usage:" in stdout
