"""The registry of pose methods: one :class:`PoseMethod` per name (:data:`METHODS`, in
registration order; the method is its own record), the tables derived from it and the check
of method names.

Its first entries are the built-in methods (:func:`strl_pyg.inference.methods.builtin_methods`),
put there here, in the registry's own definition: importing a module registers nothing, and the
registry reads the same whichever module reads it first. The methods do not read it (what a
method is, :class:`~strl_pyg.inference.methods.base.PoseMethod`, lives below it).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from strl_pyg.estimation.classical import BASELINE_METHODS, MIN_POINTS, POSELIB
from strl_pyg.inference.methods.base import CLASSICAL, FunctionMethod, PoseMethod
from strl_pyg.inference.methods.builtin import builtin_methods
from strl_pyg.inference.methods.context import MethodFn, classical_solver

__all__ = ["RECOMMENDED", "METHODS", "ENTRY_POINT_GROUP", "methods_table",
           "register_method", "methods_where",
           "methods_needed", "network_free_methods", "classical_method",
           "checked_method_names"]

#: ``methods="recommended"``: the recommended pose with only the methods it needs
#: (:meth:`PoseEstimator.estimate`; ``strl-pose predict``'s default); not a method name.
RECOMMENDED = "recommended"

#: ``name -> PoseMethod`` (the method is its own record), run in this order: the built-in
#: methods (:func:`~strl_pyg.inference.methods.builtin_methods`), the installed packages'
#: (:data:`ENTRY_POINT_GROUP`), then the ones registered at run time.
METHODS: dict[str, PoseMethod] = {method.name: method for method in builtin_methods()}

#: The entry-point group through which an installed package adds pose methods: in its
#: ``pyproject.toml``, ``[project.entry-points."strl-pyg.methods"]`` ``mysolver =
#: "mypackage.mysolver:MySolver"`` (a :class:`PoseMethod` class or instance); the registry
#: holds it from its definition, so ``strl-pose predict --methods mysolver`` runs it.
ENTRY_POINT_GROUP = "strl-pyg.methods"


def _installed_methods() -> list[PoseMethod]:
    """The methods installed packages declare (:data:`ENTRY_POINT_GROUP`); one that does not
    load, or whose name is taken (a built-in's, another plugin's, ``"recommended"``), is left
    out with a one-line warning naming it. A plugin module is imported while
    :mod:`strl_pyg.inference` loads: it may import what a method is and returns
    (:mod:`strl_pyg.inference.methods`, :mod:`strl_pyg.inference.record`) and the lower
    floors (:mod:`strl_pyg.estimation`, :mod:`strl_pyg.geometry`, :mod:`strl_pyg.data`),
    not the estimator or its configuration, and registers nothing itself."""
    from strl_pyg.utils.plugins import load_plugins

    def check(method: PoseMethod, loaded: list) -> None:
        _check_new(method.name, replace_existing=False)
        if any(m.name == method.name for m in loaded):
            raise ValueError(f"another plugin already took the name {method.name!r}")

    return load_plugins(ENTRY_POINT_GROUP, PoseMethod, "pose method", check)


def register_method(name: str | PoseMethod, fn: MethodFn | None = None, *,
                    min_points: int = MIN_POINTS, needs_intrinsics: bool = True,
                    available: Callable[[], bool] | None = None,
                    replace_existing: bool = False, **description: Any) -> None:
    """Adds a method to :data:`METHODS` (run after the ones registered before it): a
    :class:`PoseMethod` (``register_method(MyMethod())``, its attributes say what it needs), or
    a name and a function ``fn(matches, context) -> MethodResult`` with its ``description``
    (:data:`DESCRIPTION`: ``label``, ``reads_lines``, ...), made a :class:`FunctionMethod`.
    The method is then in ``strl-pose predict --methods``, ``evaluate``, the support check
    and the labels."""
    if isinstance(name, PoseMethod):
        if fn is not None or description:
            raise ValueError("Expected a PoseMethod alone (its attributes describe it) (got "
                             f"{'fn and ' if fn is not None else ''}{sorted(description)} too)")
        method, name = name, name.name
        if not isinstance(name, str) or not name:
            raise ValueError(f"Expected a PoseMethod with a name (got {name!r} for "
                             f"{type(method).__name__})")
        _check_new(name, replace_existing)
        if not method.label:
            method.label = name
        METHODS[name] = method
        return
    if not callable(fn):
        raise TypeError(f"Expected fn(matches, context) -> MethodResult for method {name!r} "
                        f"(got {type(fn).__name__})")
    _check_new(name, replace_existing)
    METHODS[name] = FunctionMethod(name, fn, available, min_points=min_points,
                                   needs_intrinsics=needs_intrinsics,
                                   **{"label": name, **description})


def methods_table(names: Any = None) -> str:
    """The registered methods (``names``: these only) as a Markdown table: name, what it is
    (``summary``, else ``label``), what it needs (:meth:`PoseMethod.needs`). docs/methods.md
    holds the built-in methods' table; ``strl-pose methods`` prints this one."""
    rows = ["| name | what it is | needs |", "|---|---|---|"]
    for name, method in METHODS.items():
        if names is None or name in names:
            what = method.summary or method.label or name
            rows.append(f"| `{name}` | {what} | {method.needs()} |")
    return "\n".join(rows)


def _check_new(name: str, replace_existing: bool) -> None:
    if name in METHODS and not replace_existing:
        raise ValueError(f"Expected a new method name (got {name!r}, already registered)")
    if name == RECOMMENDED:
        raise ValueError(f"Expected a method name other than {RECOMMENDED!r} (it selects the "
                         "recommended methods)")


def methods_where(**flags: Any) -> tuple[str, ...]:
    """The registered methods with these attribute values, in registration order:
    ``methods_where(uses_network=True)``."""
    return tuple(n for n, s in METHODS.items()
                 if all(getattr(s, k) == v for k, v in flags.items()))


#: Tables derived from the registry (module ``__getattr__``: always the registry's current
#: state, a method registered later included).
DERIVED = {
    "SUPPORT_CHECKED": lambda: methods_where(support_checked=True),
    "BOOTSTRAPPED": lambda: methods_where(bootstrapped=True),
    "NETWORK_METHODS": lambda: methods_where(uses_network=True),
    "LINE_METHODS": lambda: methods_where(reads_lines=True),
    "DEPENDENCIES": lambda: {n: s.depends_on for n, s in METHODS.items() if s.depends_on},
    "METHOD_LABELS": lambda: {n: s.label for n, s in METHODS.items()},
}


def __getattr__(name: str) -> Any:
    if name in DERIVED:
        return DERIVED[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def methods_needed(names: Any) -> tuple[str, ...]:
    """``names`` with the methods they depend on, in registration order (the order
    :class:`PoseEstimator` runs them). A :data:`CLASSICAL` dependency is the classical solver
    among ``names`` if there is one, else :func:`classical_method`."""
    classical = next((n for n in names if n in BASELINE_METHODS), None) or classical_method()
    want, todo = set(), list(names)
    while todo:  # dependencies of dependencies too
        name = todo.pop()
        if name in want:
            continue
        want.add(name)
        deps = METHODS[name].depends_on if name in METHODS else ()
        todo.extend(classical if d == CLASSICAL else d for d in deps)
    return tuple(m for m in METHODS if m in want)


def network_free_methods() -> tuple[str, ...]:
    """The registered methods whose result does not read the network, not even through a
    method they depend on (PoseLib, OpenCV, ``vp``): their calibration does not depend on
    the checkpoint."""
    return tuple(n for n in METHODS
                 if not any(METHODS[m].uses_network for m in methods_needed((n,))))


def classical_method(results: Any = None) -> str:
    """The classical solver the inference layer starts from, decided here only: the one the
    run holds a result of (``results``: a pair's method results; PoseLib first), else PoseLib
    if its method is available (the registry's say, which a caller may change), else OpenCV.
    The decision is :func:`~strl_pyg.inference.methods.context.classical_solver`'s."""
    return classical_solver(results, METHODS[POSELIB].available())


def checked_method_names(methods: Any) -> tuple[str, ...] | str:
    """Method names to run (``None`` or ``"all"``: every installed one; one ``str``: one
    method, or comma-separated names as ``strl-pose predict --methods`` takes them, in any
    case: ``"OpenCV"`` is ``opencv``; :data:`RECOMMENDED` stays as it is). The one parser of
    method names: the estimator, its configuration and the command line call it."""
    if isinstance(methods, str) and methods.strip().lower() == RECOMMENDED:
        return RECOMMENDED
    if isinstance(methods, str) and methods.strip().lower() == "all":
        methods = None
    if isinstance(methods, str):
        methods = tuple(n for n in methods.split(",") if n.strip())
    by_lower = {m.lower(): m for m in METHODS}
    names = tuple(by_lower.get(str(n).strip().lower(), n) for n in methods) \
        if methods is not None else tuple(n for n, s in METHODS.items() if s.available())
    unknown = [n for n in names if n not in METHODS]
    if unknown or not names:
        import difflib

        close = difflib.get_close_matches(str(unknown[0]), list(METHODS), n=1) \
            if unknown else []
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise ValueError(f"Expected methods from {tuple(METHODS)}, 'all' or "
                         f"'{RECOMMENDED}' (got {list(names)}){hint}")
    missing = [n for n in names if not METHODS[n].available()]
    if missing:
        raise ValueError(f"Expected installed methods (got {missing}: not importable here)")
    return names


for _method in _installed_methods():
    register_method(_method)
