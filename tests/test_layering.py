"""Package layering: one floor per folder of ``strl_pyg``, imports that only go down.

The rule, checked on every import of a package module by another (at module level and inside
functions alike; ``if TYPE_CHECKING:`` imports are exempt, as are imports of third-party
modules, which stay lazy so that ``strl-pose --help`` is torch-free):

- a folder imports only itself and folders on lower floors; folders on one floor never import
  each other;
- the lazy faces count too: a name a package ``__init__`` exports by string is an import of
  the module that defines it;
- no module-level import cycle;
- no ``from x import _name`` across folders (what two folders share is public, in the lower);
- functions read in a sitting: no body over :data:`MAX_FUNCTION_LINES` lines (the docstring
  not counted), except the few in :data:`LONG_FUNCTIONS`, which may shrink but not grow
  (files are split by concept, not to fit a line cap: the module cap is gone).

The root holds only the lazy face ``__init__.py``, above every folder (the 0.2 module paths
are gone: docs/changelog.md lists each with its replacement). Each rule has a planted
violation below to show it can fail.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "strl_pyg"
MAX_FUNCTION_LINES = 80
#: Functions allowed over the guide, at their length (they may shrink, not grow). The four
#: over it when the guide replaced the module cap (train 183, gather_inputs 138,
#: vanishing_point_pose 110, estimate 97) were split at their natural seams.
LONG_FUNCTIONS: dict[str, int] = {}

#: Floor of each folder of strl_pyg, lowest first. A folder imports only lower floors.
FLOORS: dict[str, int] = {
    "utils": 0,       # lazy faces, strict dataclasses, io, images
    "geometry": 1,    # pose, manifold, epipolar, essential
    "data": 2,        # PairMatches, keys, pair graph, transforms, external match files
    "metrics": 2,     # two-view errors, AUC, odometry, trajectories, statistics
    "nn": 3,          # the reusable MessagePassing layers
    "viz": 3,         # match drawings, plots
    "frontend": 4,    # SIFT / LSD matching
    "model": 4,       # StrLPose, its config and inputs
    "synthetic": 5,   # generated scenes (uses the front end's configs)
    "estimation": 5,  # classical solvers, guided, uncertainty, fusion
    "datasets": 6,    # KITTI, DeMoN, Middlebury, generated, the match cache
    "inference": 7,   # PoseEstimator, the method registry
    "training": 7,    # the loop, config, data, loss, checkpoints
    "evaluation": 8,  # the evaluate command on the inference registry
    "explain": 8,     # which matches and lines drove the network's pose (PyG explainers)
    "collection": 8,  # photo collections: features once, every pair, COLMAP databases
    "cli": 9,         # strl-pose
    "": 10,           # the package root: __init__ (the lazy face)
}


@dataclass(frozen=True)
class Edge:
    src: str  # importing module
    dst: str  # imported module
    name: str | None  # the name taken (from-imports), else None
    line: int
    local: bool  # inside a function
    lazy: bool = False  # a lazy-export string of a package face


def modules(package: Path = PACKAGE) -> dict[str, Path]:
    out = {}
    for path in package.rglob("*.py"):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def folder(module: str) -> str:
    """The folder of a package module (``""`` for the root modules)."""
    parts = module.split(".")
    if len(parts) == 1 or (len(parts) == 2 and parts[1] not in FLOORS):
        return ""
    return parts[1]


def _export_map(node: ast.AST) -> ast.Dict | None:
    """The name -> module dict of a lazy face: ``_EXPORTS = {...}`` or the literal given to
    ``lazy_exports(__name__, {...}, ...)``."""
    if (isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict)
            and any(isinstance(t, ast.Name) and t.id == "_EXPORTS" for t in node.targets)):
        return node.value
    if (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "lazy_exports"
            and len(node.args) >= 2 and isinstance(node.args[1], ast.Dict)):
        return node.args[1]
    return None


def _resolve(target: str, known: dict[str, Path]) -> str | None:
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target or None


def edges_of(module: str, source: str, known: dict[str, Path]) -> list[Edge]:
    """Every import of a package module in ``source`` (the code of ``module``)."""
    tree = ast.parse(source)
    skip: set[int] = set()
    local: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.dump(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            local.update(id(n) for n in ast.walk(node) if n is not node)
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            targets = [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            targets = [(node.module or "", a.name) for a in node.names]
        elif _export_map(node) is not None:
            exports = _export_map(node)
            for key, value in zip(exports.keys, exports.values, strict=True):
                if isinstance(value, ast.Constant) and isinstance(key, ast.Constant):
                    target = value.value or f"{module}.{key.value}"
                    dst = _resolve(target, known)
                    if dst and dst != module:
                        out.append(Edge(module, dst, key.value, node.lineno, False, True))
            continue
        else:
            continue
        for mod, attr in targets:
            if not mod.startswith("strl_pyg"):
                continue
            dst = _resolve(f"{mod}.{attr}" if attr else mod, known)
            if dst and dst != module:
                out.append(Edge(module, dst, attr, node.lineno, id(node) in local))
    return out


def all_edges(package: Path = PACKAGE) -> list[Edge]:
    known = modules(package)
    return [e for name, path in known.items() for e in edges_of(name, path.read_text(), known)]


def floor_violations(edges: list[Edge]) -> list[str]:
    bad = []
    for e in edges:
        a, b = folder(e.src), folder(e.dst)
        if a == b:
            continue
        if a not in FLOORS or b not in FLOORS:
            bad.append(f"{e.src}: folder '{a or b}' has no floor in tests/test_layering.py")
        elif FLOORS[b] >= FLOORS[a]:
            kind = "lazy export" if e.lazy else "import inside a function" if e.local else "import"
            bad.append(f"{e.src}:{e.line} ({a}, floor {FLOORS[a]}) {kind} of {e.dst} "
                       f"({b}, floor {FLOORS[b]})")
    return bad


def private_violations(edges: list[Edge]) -> list[str]:
    return [f"{e.src}:{e.line} takes {e.name} from {e.dst}" for e in edges
            if e.name and e.name.startswith("_") and not e.name.endswith("__")
            and not e.lazy and folder(e.src) != folder(e.dst)]


def module_level_graph(edges: list[Edge]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for e in edges:
        graph.setdefault(e.src, set())
        if not e.local and not e.lazy:
            graph[e.src].add(e.dst)
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


# ----------------------------------------------------------------------------- the package
@pytest.fixture(scope="module")
def package_edges() -> list[Edge]:
    """``all_edges()`` of the package, walked once for the four rules that read it."""
    return all_edges()


def test_the_root_holds_only_the_face():
    assert sorted(p.name for p in PACKAGE.glob("*.py")) == ["__init__.py"]


def test_every_folder_has_a_floor_and_a_face_that_says_what_lives_there():
    for path in sorted(p for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()):
        assert path.name in FLOORS, f"folder {path.name} has no floor in FLOORS"
        doc = ast.get_docstring(ast.parse((path / "__init__.py").read_text()))
        assert doc and len(doc.splitlines()) >= 2, f"{path.name}/__init__.py: no docstring"


def test_imports_only_go_down(package_edges):
    edges = package_edges
    assert any(e.local for e in edges) and any(e.lazy for e in edges)  # the walk sees both
    bad = floor_violations(edges)
    assert not bad, "imports that do not go down:\n" + "\n".join(sorted(bad))


def test_no_private_name_crosses_a_folder(package_edges):
    bad = private_violations(package_edges)
    assert not bad, "private names imported across folders:\n" + "\n".join(sorted(bad))


def import_graph(edges: list[Edge]) -> dict[str, set[str]]:
    """Every import between modules, those inside functions too (lazy exports of a folder's
    face aside): an import inside a function that closes a cycle only hides it."""
    graph: dict[str, set[str]] = {}
    for e in edges:
        graph.setdefault(e.src, set())
        if not e.lazy:
            graph[e.src].add(e.dst)
    return graph


def test_no_import_cycle_between_modules_even_inside_functions(package_edges):
    """Before: 7 cycles hidden by imports inside functions (cli/{bench,commands,export},
    data/matches <-> data/external, inference/{config,estimator,methods,support})."""
    cycle = find_cycle(import_graph(package_edges))
    assert cycle is None, f"import cycle: {' -> '.join(cycle)}"


def test_a_planted_cycle_inside_a_folder_is_caught(tmp_path):
    edges = _planted(tmp_path, {
        "inference/a.py": "from strl_pyg.inference.b import x\n",
        "inference/b.py": "def f():\n    from strl_pyg.inference.a import y\n",  # hidden
    })
    assert find_cycle(module_level_graph(edges)) is None  # the module-level view misses it
    cycle = find_cycle(import_graph(edges))
    assert cycle and set(cycle) == {"strl_pyg.inference.a", "strl_pyg.inference.b"}


def test_no_module_level_import_cycle(package_edges):
    cycle = find_cycle(module_level_graph(package_edges))
    assert cycle is None, f"module-level import cycle: {' -> '.join(cycle)}"


def function_lengths(package: Path) -> dict[str, int]:
    """``"path::name" -> lines`` of every function body, its docstring not counted."""
    out = {}
    for p in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(
                    getattr(body[0], "value", None), ast.Constant) and isinstance(
                    body[0].value.value, str):
                body = body[1:]
            if body:
                key = f"{p.relative_to(package.parent).as_posix()}::{node.name}"
                out[key] = max(out.get(key, 0), node.end_lineno - body[0].lineno + 1)
    return out


def test_functions_read_in_a_sitting():
    long = {k: n for k, n in function_lengths(PACKAGE).items()
            if n > LONG_FUNCTIONS.get(k, MAX_FUNCTION_LINES)}
    assert not long, f"function bodies over {MAX_FUNCTION_LINES} lines (or grown): {long}"


def test_the_function_guide_catches_a_planted_long_function(tmp_path):
    pkg = tmp_path / "strl_pyg"
    pkg.mkdir()
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES + 1))
    (pkg / "a.py").write_text(f'def f():\n    """Doc."""\n{body}\n')
    assert function_lengths(pkg) == {"strl_pyg/a.py::f": MAX_FUNCTION_LINES + 1}


# ----------------------------------------------------------------------------- planted
def _planted(tmp_path: Path, files: dict[str, str]) -> list[Edge]:
    for rel, text in files.items():
        path = tmp_path / "strl_pyg" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    for d in list((tmp_path / "strl_pyg").rglob("*")):
        if d.is_dir() and not (d / "__init__.py").exists():
            (d / "__init__.py").write_text("")
    return all_edges(tmp_path / "strl_pyg")


def test_planted_upward_and_sideways_imports_are_caught(tmp_path):
    edges = _planted(tmp_path, {
        "geometry/pose.py": "from strl_pyg.model.net import StrLPose\n",  # up, module level
        "data/graph.py": "def f():\n    from strl_pyg.nn.layer import Conv\n",  # up, local
        "nn/layer.py": "import strl_pyg.viz.plots\n",  # sideways: nn and viz share floor 3
        "model/net.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                        "    from strl_pyg.inference.est import PoseEstimator\n",  # exempt
        "viz/plots.py": "from strl_pyg.geometry.pose import Pose\n",  # down: fine
        "inference/est.py": "",
        "utils/__init__.py": "from strl_pyg.utils.lazy import lazy_exports\n"
                             "_EXPORTS = {'Pose': 'strl_pyg.geometry.pose'}\n"
                             "__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, "
                             "globals())\n",  # lazy up
        "utils/lazy.py": "",
    })
    bad = floor_violations(edges)
    assert len(bad) == 4, bad
    assert any("geometry.pose:1 (geometry, floor 1) import of strl_pyg.model.net" in b
               for b in bad)
    assert any("import inside a function of strl_pyg.nn.layer" in b for b in bad)
    assert any("strl_pyg.nn.layer:1 (nn, floor 3) import of strl_pyg.viz.plots" in b
               for b in bad)
    assert any("lazy export of strl_pyg.geometry.pose" in b for b in bad)


def test_planted_private_import_and_cycle_are_caught(tmp_path):
    edges = _planted(tmp_path, {
        "model/net.py": "from strl_pyg.geometry.pose import _as_pose\n",  # private, across
        "geometry/pose.py": "from strl_pyg.geometry.manifold import so3_exp\n",
        "geometry/manifold.py": "from strl_pyg.geometry.pose import Pose\n",  # cycle
        "data/a.py": "from strl_pyg.data.b import _x\n",  # private within a folder: fine
        "data/b.py": "",
    })
    assert private_violations(edges) == [
        "strl_pyg.model.net:1 takes _as_pose from strl_pyg.geometry.pose"]
    cycle = find_cycle(module_level_graph(edges))
    assert cycle and set(cycle) == {"strl_pyg.geometry.pose", "strl_pyg.geometry.manifold"}


def test_cycle_finder_finds_a_planted_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


# ----------------------------------------------------------------------------- heavy deps
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
    return subprocess.run([sys.executable, "-W", "error::DeprecationWarning:strl_pyg", "-c",
                           _BLOCKER + code], capture_output=True, text=True, timeout=300,
                          cwd=ROOT, env=env)


def test_blocker_blocks():
    res = _run("import cv2\n")
    assert res.returncode != 0 and "blocked by test_layering" in res.stderr


@pytest.mark.parametrize("module", ["strl_pyg.geometry", "strl_pyg.data", "strl_pyg.nn",
                                    "strl_pyg.data.build", "strl_pyg.model"])
@pytest.mark.slow
def test_lower_layers_import_without_opencv_and_kornia(module):
    res = _run(f"import {module}\nprint('ok')\n")
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr[-2000:]


@pytest.mark.slow
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


def test_the_command_line_parser_imports_without_torch():
    code = ("import sys\nfrom strl_pyg.cli import build_parser\nbuild_parser()\n"
            "print('torch' in sys.modules)\n")
    res = _run(code)
    assert res.returncode == 0 and res.stdout.strip() == "False", res.stderr[-2000:]


#: 0.3 module -> 0.4 module (docs/changelog.md): one concept per name.
RENAMED = {
    "strl_pyg.data.graph": "strl_pyg.data.build",
    "strl_pyg.model.inputs": "strl_pyg.model.gather",
    "strl_pyg.inference.inputs": "strl_pyg.inference.network",
    "strl_pyg.cli.inputs": "strl_pyg.cli.readers",
    "strl_pyg.estimation.fusion": "strl_pyg.estimation.pose_fusion",
    "strl_pyg.nn.fusion": "strl_pyg.nn.feature_fusion",
}


@pytest.mark.parametrize("old, new", sorted(RENAMED.items()))
def test_renamed_modules_are_in_the_changelog_and_the_old_names_are_gone(old, new):
    import importlib

    importlib.import_module(new)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
    changelog = (Path(__file__).resolve().parents[1] / "docs" / "changelog.md").read_text()
    assert f"| `{old}` | `{new}`" in changelog
