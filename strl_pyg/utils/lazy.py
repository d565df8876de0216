"""Lazy package exports (PEP 562): a package ``__init__`` names what it exports and where it
lives, and the defining module is imported on first access. Keeps ``import strl_pyg`` and the
``strl-pose`` parser free of torch, PyG, OpenCV and kornia until a name is used."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: dict[str, str], namespace: dict[str, Any],
                 fallback: str | None = None
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``.

    Args:
        package: the package's ``__name__``.
        exports: public name -> defining module (absolute), or ``""`` for a submodule of the
            same name (``{"datasets": ""}`` imports ``package.datasets``).
        namespace: the package's ``globals()``; a resolved name is cached there.
        fallback: a module of the package whose other names the package also gives (the
            module a folder was before it became one, so that ``package.NAME`` of 0.2 code
            keeps resolving); ``None``: none.
    """

    def __getattr__(name: str) -> Any:
        if name not in exports:
            if fallback is not None and not name.startswith("__"):
                module = importlib.import_module(fallback)
                if hasattr(module, name):
                    return getattr(module, name)
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module = importlib.import_module(exports[name] or f"{package}.{name}")
        value = module if not exports[name] else getattr(module, name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
