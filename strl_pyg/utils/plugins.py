"""Objects that installed packages declare through an entry-point group (pose methods, rules):
loaded one by one, each checked, and one that does not load left out with a one-line warning
naming it (a third party's plugin must not break the package)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["load_plugins"]


def load_plugins(group: str, kind: type, what: str,
                 check: Callable[[Any, list], None]) -> list:
    """Instances of ``kind`` declared in the entry-point ``group`` (an entry may name the class
    or an instance): each must have a non-empty ``name``, and ``check(obj, loaded_so_far)``
    raises for one that must be left out (a taken name). ``what`` names them in the warning
    (``"pose method"``)."""
    import warnings
    from importlib.metadata import entry_points

    out: list = []
    for ep in entry_points(group=group):
        try:
            obj = ep.load()
            item = obj() if isinstance(obj, type) else obj
            if not isinstance(item, kind) or not isinstance(getattr(item, "name", None), str) \
                    or not item.name:
                raise TypeError(f"expected a {kind.__name__} with a name, got {obj!r}")
            check(item, out)
        except Exception as err:  # a third party's plugin must not break the package
            warnings.warn(f"{what} entry point {ep.name!r} ({ep.value}) not loaded: "
                          f"{type(err).__name__}: {err}", stacklevel=3)
            continue
        out.append(item)
    return out
