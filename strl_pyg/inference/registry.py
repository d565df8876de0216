"""The registry of pose methods: one :class:`MethodSpec` per name (:data:`METHODS`, in
registration order), the tables derived from it and the check of method names.

It imports nothing of :mod:`strl_pyg.inference` but the record, so every module of the
folder (the configuration, the support check, the estimator) can read it: the methods
themselves are registered by :mod:`strl_pyg.inference.estimator`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

from strl_pyg.estimation.classical import BASELINE_METHODS, MIN_POINTS

__all__ = ["RECOMMENDED", "PoseMethod", "MethodSpec", "METHODS", "register_method", "methods_where",
           "methods_needed", "network_free_methods", "classical_method",
           "checked_method_names"]

#: A method: ``fn(matches, context) -> MethodResult`` (:mod:`strl_pyg.inference.methods`).
MethodFn = Callable[..., Any]

#: ``methods="recommended"``: the recommended pose with only the methods it needs
#: (:meth:`PoseEstimator.estimate`; ``strl-pose predict``'s default); not a method name.
RECOMMENDED = "recommended"


@dataclass(frozen=True)
class MethodSpec:
    """Everything about one registered method, the one record every other table is derived
    from (:func:`methods_where`): ``fn``; the point matches it needs (fewer:
    ``"degenerate"``); whether it needs ``K0``/``K1`` (missing: ``"failed"``) and whether it is
    installed; ``label``, what it is in words (the CLI prints it); whether it ``reads_lines``
    (the front end then matches lines for it) and ``uses_network`` (the model is loaded for
    it); ``depends_on``, the methods whose results it reads (``"classical"``: PoseLib if
    installed, else OpenCV); ``support_checked``, whether its pose must be supported by the
    point matches (:func:`~strl_pyg.inference.support.check_support`); ``bootstrapped``,
    whether its covariance carries the classical bootstrap (its calibration then holds only
    for the bootstrap count it was fitted with); ``classical_base``, whether it starts from
    the classical solver's pose (its calibration was fitted with PoseLib as that base);
    ``needs_geometric_head``, whether it reads the network's geometric head (a checkpoint
    without one cannot run it)."""

    fn: MethodFn
    min_points: int = MIN_POINTS
    needs_intrinsics: bool = True
    available: Callable[[], bool] = lambda: True
    label: str = ""
    reads_lines: bool = False
    uses_network: bool = False
    depends_on: tuple[str, ...] = ()
    support_checked: bool = True
    bootstrapped: bool = False
    classical_base: bool = False
    needs_geometric_head: bool = False


class PoseMethod:
    """A pose method, the way :class:`~strl_pyg.inference.PoseEstimator` runs it: called with
    one pair's checked matches and the pair's :class:`~strl_pyg.inference.methods.MethodContext`,
    it returns one :class:`~strl_pyg.inference.MethodResult`. What it needs and how its result
    is treated are class attributes, the fields of :class:`MethodSpec` (``name``, ``label``,
    ``min_points``, ``needs_intrinsics``, ``reads_lines``, ``uses_network``, ``depends_on``,
    ``support_checked``, ``bootstrapped``, ``classical_base``, ``needs_geometric_head``), and
    :meth:`available` says whether it is installed. Register one with
    ``register_method(MyMethod())``; the built-in ones are in
    :mod:`strl_pyg.inference.methods` and :mod:`strl_pyg.inference.line_methods`."""

    name: str = ""
    label: str = ""
    min_points: int = MIN_POINTS
    needs_intrinsics: bool = True
    reads_lines: bool = False
    uses_network: bool = False
    depends_on: tuple[str, ...] = ()
    support_checked: bool = True
    bootstrapped: bool = False
    classical_base: bool = False
    needs_geometric_head: bool = False

    def available(self) -> bool:
        return True

    def __call__(self, matches: Any, ctx: Any) -> Any:
        raise NotImplementedError(f"{type(self).__name__} runs no pose method (define "
                                  "__call__(matches, ctx) -> MethodResult)")

    def spec(self) -> MethodSpec:
        """This method's :class:`MethodSpec`."""
        given = {f.name: getattr(self, f.name) for f in fields(MethodSpec) if f.name != "fn"}
        return MethodSpec(self, **{**given, "label": self.label or self.name,
                                   "depends_on": tuple(self.depends_on)})


#: ``name -> MethodSpec``, run in this order.
METHODS: dict[str, MethodSpec] = {}


def register_method(name: str | PoseMethod, fn: MethodFn | None = None, *,
                    min_points: int = MIN_POINTS, needs_intrinsics: bool = True,
                    available: Callable[[], bool] | None = None,
                    replace_existing: bool = False, **spec: Any) -> None:
    """Adds a method to :data:`METHODS` (run after the ones registered before it): a
    :class:`PoseMethod` (``register_method(MyMethod())``, its attributes say what it needs), or
    a name and a function ``fn(matches, context) -> MethodResult`` with ``spec``, the other
    fields of :class:`MethodSpec` (``label``, ``reads_lines``, ...). The method is then in
    ``strl-pose predict --methods``, ``evaluate``, the support check and the labels."""
    if isinstance(name, PoseMethod):
        if fn is not None or spec:
            raise ValueError("Expected a PoseMethod alone (its attributes are its spec) (got "
                             f"{'fn and ' if fn is not None else ''}{sorted(spec)} too)")
        method, name = name, name.name
        if not isinstance(name, str) or not name:
            raise ValueError(f"Expected a PoseMethod with a name (got {name!r} for "
                             f"{type(method).__name__})")
        _check_new(name, replace_existing)
        METHODS[name] = method.spec()
        return
    if not callable(fn):
        raise TypeError(f"Expected fn(matches, context) -> MethodResult for method {name!r} "
                        f"(got {type(fn).__name__})")
    _check_new(name, replace_existing)
    known = {f for f in MethodSpec.__dataclass_fields__} - {"fn", "min_points",
                                                             "needs_intrinsics", "available"}
    unknown = sorted(set(spec) - known)
    if unknown:
        raise ValueError(f"Expected MethodSpec fields {sorted(known)} (got {unknown})")
    METHODS[name] = MethodSpec(fn, min_points, needs_intrinsics, available or (lambda: True),
                               **{"label": name, **spec})


def _check_new(name: str, replace_existing: bool) -> None:
    if name in METHODS and not replace_existing:
        raise ValueError(f"Expected a new method name (got {name!r}, already registered)")
    if name == RECOMMENDED:
        raise ValueError(f"Expected a method name other than {RECOMMENDED!r} (it selects the "
                         "recommended methods)")


def methods_where(**flags: Any) -> tuple[str, ...]:
    """The registered methods whose :class:`MethodSpec` has these field values, in
    registration order: ``methods_where(uses_network=True)``."""
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
    :class:`PoseEstimator` runs them). A ``"classical"`` dependency is the classical solver
    among ``names`` if there is one, else :func:`classical_method`."""
    classical = next((n for n in names if n in BASELINE_METHODS), None) or classical_method()
    want, todo = set(), list(names)
    while todo:  # dependencies of dependencies too
        name = todo.pop()
        if name in want:
            continue
        want.add(name)
        deps = METHODS[name].depends_on if name in METHODS else ()
        todo.extend(classical if d == "classical" else d for d in deps)
    return tuple(m for m in METHODS if m in want)


def network_free_methods() -> tuple[str, ...]:
    """The registered methods whose result does not read the network, not even through a
    method they depend on (PoseLib, OpenCV, ``vp``): their calibration does not depend on
    the checkpoint."""
    return tuple(n for n in METHODS
                 if not any(METHODS[m].uses_network for m in methods_needed((n,))))


def classical_method() -> str:
    """The classical solver other methods start from: PoseLib if installed, else OpenCV."""
    return "poselib" if METHODS["poselib"].available() else "opencv"


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
