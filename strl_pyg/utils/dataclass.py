"""A dataclass built from a dict that must hold only its fields (configs read from
checkpoints and JSON); torch-free."""

from __future__ import annotations

from dataclasses import fields
from typing import Any, TypeVar

T = TypeVar("T")

__all__ = ["strict_from_dict"]


def strict_from_dict(cls: type[T], d: dict[str, Any]) -> T:
    """``cls(**d)``, with a one-line ``ValueError`` naming the unknown keys instead of a
    ``TypeError`` from the constructor."""
    if not isinstance(d, dict):
        raise TypeError(f"Expected a dict of {cls.__name__} fields (got {type(d).__name__})")
    unknown = sorted(set(d) - {f.name for f in fields(cls)})
    if unknown:
        raise ValueError(f"Expected {cls.__name__} fields (got unknown keys {unknown})")
    return cls(**d)
