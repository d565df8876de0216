"""Package layering: the lower layers import without OpenCV and kornia, and the modules of
``strl_pyg`` import each other without cycles and only downwards at module level.

Layers, lowest first: geometry -> data (containers, graphs) -> nn (layers) -> model (and the
losses, metrics and the differentiable solver it uses) -> front end / generated scenes /
datasets / classical baselines -> training / evaluation / inference / fusion -> cli.
Imports inside functions (the lazy ones that keep heavy dependencies at the edges) and under
``if TYPE_CHECKING:`` are not module-level imports and are ignored.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "strl_pyg"

#: Layer of each module (prefix match, longest first); lower never imports higher.
LAYERS: dict[str, int] = {
    "strl_pyg._lazy": 0,
    "strl_pyg._dataclass": 0,
    "strl_pyg.pose_uncertainty": 5,
    "strl_pyg.io": 0,
    "strl_pyg.images": 1,
    "strl_pyg.geometry": 0,
    "strl_pyg.data": 1,
    "strl_pyg.nn": 2,
    "strl_pyg.model": 3,
    "strl_pyg.model_config": 3,
    "strl_pyg.model_inputs": 3,
    "strl_pyg.loss": 3,
    "strl_pyg.metrics": 3,
    "strl_pyg.odometry": 3,
    "strl_pyg.pose_stats": 3,
    "strl_pyg.trajectory": 3,
    "strl_pyg.essential": 3,
    "strl_pyg.frontend": 4,
    "strl_pyg.synthetic": 4,
    "strl_pyg.data.datasets": 4,
    "strl_pyg.baselines": 4,
    "strl_pyg.train_config": 5,
    "strl_pyg.train_data": 5,
    "strl_pyg.train_log": 5,
    "strl_pyg.validation": 5,
    "strl_pyg.checkpoints": 5,
    "strl_pyg.training": 5,
    "strl_pyg.evaluation": 5,
    "strl_pyg.eval_pairs": 5,
    "strl_pyg.eval_report": 5,
    "strl_pyg.inference": 5,
    "strl_pyg.pose_record": 5,
    "strl_pyg.pose_input": 5,
    "strl_pyg.pose_methods": 5,
    "strl_pyg.pose_fusion": 5,
    "strl_pyg.fusion": 5,
    "strl_pyg.guided": 5,
    "strl_pyg.recommended": 5,
    "strl_pyg.viz": 5,
    "strl_pyg.cli_inputs": 6,
    "strl_pyg.cli": 6,
    "strl_pyg": 7,  # the package itself only re-exports, lazily
}


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _targets(module: str, node: ast.stmt, is_package: bool) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    assert isinstance(node, ast.ImportFrom)
    if node.level:
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        name = ".".join(base + ([node.module] if node.module else []))
    else:
        name = node.module or ""
    return [name] + [f"{name}.{a.name}" for a in node.names]


def _module_level_imports(tree: ast.Module) -> list[ast.stmt]:
    found: list[ast.stmt] = []

    def visit(body: list[ast.stmt]) -> None:
        for node in body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                found.append(node)
            elif isinstance(node, ast.If):
                if "TYPE_CHECKING" in ast.dump(node.test):
                    continue
                visit(node.body)
                visit(node.orelse)
            elif isinstance(node, ast.Try):
                visit(node.body)
                for handler in node.handlers:
                    visit(handler.body)
                visit(node.orelse)
                visit(node.finalbody)
            # function and class bodies are not module level: lazy imports live there

    visit(tree.body)
    return found


def import_graph() -> dict[str, set[str]]:
    """Module-level import edges between the modules of ``strl_pyg``."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps: set[str] = set()
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in _module_level_imports(tree):
            for target in _targets(name, node, path.name == "__init__.py"):
                while target and target not in modules:  # an attribute: its module
                    target = target.rpartition(".")[0]
                if target and target != name:
                    deps.add(target)
        graph[name] = deps
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``graph`` as a list of nodes (first repeated last), or ``None``."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph.get(node, ())):
            if state.get(dep) == 1:
                return stack[stack.index(dep):] + [dep]
            if dep not in state:
                found = visit(dep)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def layer(module: str) -> int:
    best = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len,
               default=None)
    if best is None:
        raise AssertionError(f"Expected a layer for module {module} in tests/test_layering.py "
                             "LAYERS (got none): add the new module there")
    return LAYERS[best]


def test_cycle_finder_finds_a_planted_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_graph_sees_module_level_imports_only(tmp_path):
    tree = ast.parse(
        "import os\n"
        "from typing import TYPE_CHECKING\n"
        "from strl_pyg.geometry import Pose\n"
        "if TYPE_CHECKING:\n    from strl_pyg.model import StrLPose\n"
        "def f():\n    from strl_pyg.cli import main\n"
    )
    names = [t for n in _module_level_imports(tree) for t in _targets("strl_pyg.x", n, False)]
    assert "strl_pyg.geometry.Pose" in names
    assert not any("model" in n or "cli" in n for n in names)


def test_no_import_cycles_between_modules():
    graph = import_graph()
    assert "strl_pyg.nn.attention" in graph and "strl_pyg.geometry.pose" in graph
    cycle = find_cycle(graph)
    assert cycle is None, f"module-level import cycle: {' -> '.join(cycle)}"


def test_lower_layers_never_import_higher_ones():
    bad = [f"{a} (layer {layer(a)}) imports {b} (layer {layer(b)})"
           for a, deps in import_graph().items() for b in deps if layer(b) > layer(a)]
    assert not bad, "upward imports at module level:\n" + "\n".join(sorted(bad))


_BLOCKER = r"""
import importlib.abc, sys

class _Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {"cv2", "kornia"}:
            raise ImportError(f"{name} blocked by test_layering")
        return None

sys.meta_path.insert(0, _Block())
for name in list(sys.modules):
    if name.split(".")[0] in {"cv2", "kornia"}:
        del sys.modules[name]
"""


def _run(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-c", _BLOCKER + code], capture_output=True,
                          text=True, timeout=300, cwd=ROOT, env=env)


def test_blocker_blocks():
    res = _run("import cv2\n")
    assert res.returncode != 0 and "blocked by test_layering" in res.stderr


@pytest.mark.parametrize("module", ["strl_pyg.geometry", "strl_pyg.data", "strl_pyg.nn",
                                    "strl_pyg.data.graph", "strl_pyg.model"])
def test_lower_layers_import_without_opencv_and_kornia(module):
    res = _run(f"import {module}\nprint('ok')\n")
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr[-2000:]


def test_graphs_and_layers_work_without_opencv_and_kornia():
    code = """
import numpy as np, torch
from strl_pyg.data import PairMatches, build_pair_graph
from strl_pyg.data import keys
from strl_pyg.geometry import Pose, sampson_error, so3_exp
from strl_pyg.nn import AttentionConv
rng = np.random.default_rng(0)
p0 = rng.uniform(0, 100, (20, 2)); p1 = p0 + 1.0
m = PairMatches(points0=p0, points1=p1, image_size0=(120, 120), image_size1=(120, 120))
g = build_pair_graph(m)
x = torch.randn(g[keys.POINT].num_nodes, 8)
conv = AttentionConv(8, heads=2)
out = conv(x, complete=True)
pose = Pose(so3_exp(torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)), [1.0, 0.0, 0.0])
print(tuple(out.shape), float(pose.inv().compose(pose).t.norm()) < 1e-12)
"""
    res = _run(code)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split()[-1] == "True"


def test_match_containers_import_without_torch():
    code = ("import sys\nimport strl_pyg.data\nfrom strl_pyg.data import PairMatches\n"
            "print('torch' in sys.modules)\n")
    res = _run(code)
    assert res.returncode == 0 and res.stdout.strip() == "False", res.stderr[-2000:]
