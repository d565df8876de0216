"""What a pose method is: :class:`PoseMethod` (a class whose attributes describe it and whose
call is the method), :class:`FunctionMethod` (a function as one) and :data:`CLASSICAL`, the
dependency on the run's classical solver."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from strl_pyg.estimation.classical import MIN_POINTS

__all__ = ["PoseMethod", "FunctionMethod", "DESCRIPTION", "CLASSICAL"]


#: In a method's ``depends_on``: the classical solver of the run (PoseLib where installed, else
#: OpenCV; the one the caller asked for if any), not a method name.
CLASSICAL = "classical"


class PoseMethod:
    """A pose method, the way :class:`~strl_pyg.inference.PoseEstimator` runs it: called with
    one pair's checked matches and the pair's :class:`~strl_pyg.inference.methods.MethodContext`,
    it returns one :class:`~strl_pyg.inference.MethodResult`. What it needs and how its result
    is treated are class attributes, its description (:data:`DESCRIPTION`: ``name``, ``label``,
    ``summary`` (a sentence for the methods table), ``requires`` (an optional package),
    ``needs_lines`` (skipped without line matches), ``min_points``, ``needs_intrinsics``,
    ``reads_lines``, ``uses_network``, ``depends_on``,
    ``support_checked``, ``bootstrapped``, ``classical_base``, ``needs_geometric_head``), and
    :meth:`available` says whether it is installed. Register one with
    ``register_method(MyMethod())``; the built-in ones are in
    :mod:`strl_pyg.inference.methods`, a module per concept."""

    name: str = ""
    label: str = ""
    summary: str = ""
    requires: str = ""
    min_points: int = MIN_POINTS
    needs_intrinsics: bool = True
    reads_lines: bool = False
    needs_lines: bool = False
    uses_network: bool = False
    depends_on: tuple[str, ...] = ()
    support_checked: bool = True
    bootstrapped: bool = False
    classical_base: bool = False
    needs_geometric_head: bool = False

    def available(self) -> bool:
        return True

    def needs(self) -> str:
        """What it needs, in words, from its attributes (the methods table's third column)."""
        out = [f"{self.requires} installed"] if self.requires else []
        if self.needs_geometric_head:
            out.append("a model with the geometric head")
        elif self.uses_network:
            out.append("the model")
        out.append("intrinsics" if self.needs_intrinsics else "no intrinsics")
        if self.needs_lines:
            out.append("line matches")
        elif self.reads_lines:
            out.append("reads the line matches where there are any")
        out.append(f">= {self.min_points} point matches")
        deps = ["the classical pose" if d == CLASSICAL else f"`{d}`" for d in self.depends_on]
        return ", ".join(out + deps)

    def __call__(self, matches: Any, ctx: Any) -> Any:
        raise NotImplementedError(f"{type(self).__name__} runs no pose method (define "
                                  "__call__(matches, ctx) -> MethodResult)")

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


#: The attributes that describe a method (:class:`PoseMethod`'s class attributes).
DESCRIPTION = ("label", "summary", "requires", "min_points", "needs_intrinsics", "reads_lines",
               "needs_lines", "uses_network",
               "depends_on", "support_checked", "bootstrapped", "classical_base",
               "needs_geometric_head")


class FunctionMethod(PoseMethod):
    """A function ``fn(matches, context) -> MethodResult`` as a :class:`PoseMethod`, with its
    description given as keywords (:data:`DESCRIPTION`) and ``available`` a callable."""

    def __init__(self, name: str, fn: Callable[..., Any],
                 available: Callable[[], bool] | None = None,
                 **description: Any) -> None:
        unknown = sorted(set(description) - set(DESCRIPTION))
        if unknown:
            raise ValueError(f"Expected method attributes from {sorted(DESCRIPTION)} (got "
                             f"{unknown})")
        self.name, self.fn, self._available = name, fn, available or (lambda: True)
        for key, value in description.items():
            setattr(self, key, tuple(value) if key == "depends_on" else value)

    @classmethod
    def like(cls, method: PoseMethod, fn: Callable[..., Any] | None = None,
             available: Callable[[], bool] | None = None) -> FunctionMethod:
        """``method``'s name and description with another call and / or availability (tests
        plant failures so)."""
        return cls(method.name, fn or method, available or method.available,
                   **{k: getattr(method, k) for k in DESCRIPTION})

    def available(self) -> bool:
        return bool(self._available())

    def __call__(self, matches: Any, ctx: Any) -> Any:
        return self.fn(matches, ctx)
