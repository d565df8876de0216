"""The public surface: each object is public in the module that defines it and at most in its
folder's face; faces list their names once; the package face gives the pipeline's headline
names. Read from the source (AST) so that a stray re-export fails here before it reaches a
user's ``import``."""

from __future__ import annotations

import ast
import functools
import importlib
import inspect
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "strl_pyg"
#: The package face (``import strl_pyg``): the pipeline's entry points, a third path by design.
HEADLINE = {"PairMatches", "build_pair_graph", "Pose", "StrLPose", "StrLPoseConfig",
            "PoseOutput", "ABLATIONS", "__version__"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _top_level(path: Path) -> tuple[frozenset[str], tuple[str, ...] | None, ast.AST | None]:
    """Names a module defines at top level, its literal ``__all__`` (None where computed) and
    the ``_EXPORTS`` dict node of a lazy face."""
    return _top_level_of(path.read_text())


@functools.cache
def _top_level_of(source: str) -> tuple[frozenset[str], tuple[str, ...] | None, ast.AST | None]:
    """``_top_level`` of a source text, parsed once per text (the faces' checks look up every
    module for each exported name: ~3500 parses of ~200 files); read-only, as it is shared."""
    tree = ast.parse(source)
    defined: set[str] = set()
    names = exports = None
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                defined |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
                if isinstance(target, ast.Name) and target.id == "__all__":
                    try:
                        names = ast.literal_eval(node.value)
                    except ValueError:
                        names = None
                if isinstance(target, ast.Name) and target.id == "_EXPORTS":
                    exports = node.value
    return frozenset(defined), None if names is None else tuple(names), exports


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py")) if p.stem != "__main__"}
FACES = {name for name, p in MODULES.items() if p.name == "__init__.py"}


@pytest.mark.parametrize("module", sorted(set(MODULES) - FACES))
def test_a_module_lists_only_what_it_defines(module):
    defined, names, _ = _top_level(MODULES[module])
    if names is None:  # no __all__, or a computed one (checked at import below)
        names = list(getattr(importlib.import_module(module), "__all__", []))
    foreign = sorted(set(names) - defined)
    assert not foreign, f"{module}.__all__ re-exports {foreign}: list them only where defined"
    assert len(names) == len(set(names)), f"{module}.__all__ lists a name twice"


@pytest.mark.parametrize("face", sorted(FACES))
def test_a_face_exports_its_own_folder_once(face):
    module = importlib.import_module(face)
    names = list(getattr(module, "__all__", []))
    assert len(names) == len(set(names)), f"{face}.__all__ lists a name twice"
    folder = "" if face == "strl_pyg" else face + "."
    for name in names:
        if name == "__version__":
            continue
        obj = getattr(module, name)  # every listed name resolves
        _, _, exports = _top_level(MODULES[face])
        if exports is not None and name not in _literal_map(exports):
            continue  # computed by the face on access (the registry's derived tables)
        if inspect.ismodule(obj):
            assert obj.__name__ == f"{face}.{name}", f"{face}.{name} is another folder's module"
            continue
        home = _home(face, name, obj)
        if face == "strl_pyg":
            assert name in HEADLINE, f"strl_pyg.{name}: the package face gives headline names only"
            continue
        assert home is not None and home.startswith(folder), (
            f"{face}.{name} is defined in {home}, outside the folder: import it from there")
        _, home_names, _ = _top_level(MODULES[home])
        if home_names is not None:
            assert name in home_names, f"{face}.{name}: not in {home}.__all__"


def _home(face, name, obj):
    """The module of the package that defines ``name``: a lazy face's map says it; otherwise
    the object's own ``__module__`` or the one module that assigns the name."""
    _, _, exports = _top_level(MODULES[face])
    if exports is not None:
        target = _literal_map(exports).get(name)
        if target and name in _top_level(MODULES[target])[0]:
            return target
    defining = getattr(obj, "__module__", None)
    if isinstance(defining, str) and defining in MODULES and defining not in FACES \
            and getattr(obj, "__name__", None) == name:
        return defining
    homes = [m for m in sorted(set(MODULES) - FACES) if name in _top_level(MODULES[m])[0]]
    return homes[0] if len(homes) == 1 else None


def _literal_map(node) -> dict[str, str]:
    return {k.value: v.value for k, v in zip(node.keys, node.values, strict=True)
            if isinstance(k, ast.Constant) and isinstance(v, ast.Constant)}


def test_a_lazy_face_has_one_list():
    """A lazy face's ``__all__`` is derived from its one export map, not written out again."""
    for face in sorted(FACES):
        source = MODULES[face].read_text()
        _, names, exports = _top_level(MODULES[face])
        if exports is not None:
            assert names is None, f"{face}: __all__ written beside _EXPORTS (keep one list)"
            assert "lazy_exports(__name__, _EXPORTS" in source, face


def test_no_object_has_three_public_paths_outside_the_headline():
    paths: dict[int, list[str]] = {}
    keep = []
    for module in sorted(MODULES):
        mod = importlib.import_module(module)
        for name in getattr(mod, "__all__", []):
            obj = getattr(mod, name)
            if isinstance(obj, (int, float, str, bool, tuple, frozenset, type(None))):
                continue  # equal constants share an id; each has its own definition
            keep.append(obj)
            paths.setdefault(id(obj), []).append(f"{module}.{name}")
    crowded = {tuple(p) for p in paths.values() if len(p) >= 3
               and not any(q.count(".") == 1 and q.split(".")[1] in HEADLINE for q in p)}
    assert not crowded, f"objects with three or more public paths: {sorted(crowded)}"


def test_a_planted_re_export_fails(tmp_path):
    module = tmp_path / "planted.py"
    module.write_text("from os.path import join\n\n__all__ = ['join', 'f']\n\n\ndef f():\n"
                      "    return 1\n")
    defined, names, _ = _top_level(module)
    assert set(names) - defined == {"join"}
