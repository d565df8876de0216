"""Command-line flags generated from a config dataclass: each field declared with
:func:`option` is one flag, its help text, choices and kind written once beside the field.

``--field-name`` is the flag of ``field_name`` unless the option names another; the value
kinds are read from the field's annotation (``int``, ``float``, ``str``, with ``| None``) or
given (:data:`KINDS`). Only the standard library: ``--help`` returns before torch is loaded.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import MISSING, Field, field, fields
from typing import Any

__all__ = ["option", "KINDS", "add_config_arguments", "config_values", "flag_dest",
           "option_fields"]

#: Value kinds beyond the annotation's scalar: ``"list"`` (comma-separated strings),
#: ``"int_list"`` (comma-separated integers), ``"pairs"`` (``KEY=VALUE``, repeatable, JSON
#: values), ``"negated"`` (a bool set False by the flag, e.g. ``--no-tensorboard``),
#: ``"zero_is_none"`` (a number where 0 means ``None``: off).
KINDS = ("list", "int_list", "pairs", "negated", "zero_is_none")
_SCALARS = {"int": int, "float": float, "str": str}


def option(default: Any = MISSING, help: str = "", *, default_factory: Any = MISSING,
           flag: str | None = None, kind: str | None = None, choices: Any = None,
           metavar: str | None = None) -> Any:
    """A dataclass field with its command-line flag (module docstring)."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"Expected kind in {KINDS} or None (got {kind!r})")
    md = {"help": help, "flag": flag, "kind": kind, "choices": choices, "metavar": metavar}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata={"option": md})
    return field(default=default, metadata={"option": md})


def option_fields(cls: type) -> list[Field]:
    """The fields of ``cls`` declared with :func:`option`, in order."""
    return [f for f in fields(cls) if "option" in f.metadata]


def _flag(f: Field) -> str:
    return f.metadata["option"]["flag"] or "--" + f.name.replace("_", "-")


def flag_dest(f: Field) -> str:
    """The argparse destination of field ``f``'s flag (the flag's name: ``--out`` of
    ``out_dir`` is ``args.out``)."""
    return _flag(f)[2:].replace("-", "_")


def _scalar(f: Field) -> type:
    base = str(f.type).split("|")[0].strip()
    return _SCALARS.get(base, str)


def add_config_arguments(ap: argparse.ArgumentParser, cls: type) -> argparse.ArgumentParser:
    """One flag per :func:`option` field of ``cls``, with the field's default."""
    defaults = cls()
    for f in option_fields(cls):
        md = f.metadata["option"]
        value, kind = getattr(defaults, f.name), md["kind"]
        kw: dict[str, Any] = {"help": md["help"] or None, "dest": flag_dest(f)}
        if md["metavar"]:
            kw["metavar"] = md["metavar"]
        if kind == "negated":  # --no-NAME: given, the field is False
            ap.add_argument(_flag(f), action="store_true", **kw)
            continue
        if kind == "pairs":
            kw["metavar"] = md["metavar"] or "KEY=VALUE"
            ap.add_argument(_flag(f), action="append", default=[], **kw)
            continue
        if kind in ("list", "int_list"):
            kw["default"] = None if value is None else ",".join(map(str, value))
        elif kind == "zero_is_none":
            kw.update(type=_scalar(f), default=0 if value is None else value)
        else:
            kw.update(type=_scalar(f), default=value)
        if md["choices"] is not None:
            kw["choices"] = md["choices"]
        ap.add_argument(_flag(f), **kw)
    return ap


def _pairs(items: list[str], flag: str) -> dict[str, Any]:
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"Expected {flag} KEY=VALUE (got {item!r})")
        k, v = item.split("=", 1)
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
    return out


def config_values(args: argparse.Namespace, cls: type) -> dict[str, Any]:
    """The :func:`option` fields' values of parsed :func:`add_config_arguments` flags
    (``ValueError`` in one line for a malformed list or ``KEY=VALUE``)."""
    out = {}
    for f in option_fields(cls):
        raw, kind = getattr(args, flag_dest(f)), f.metadata["option"]["kind"]
        if kind == "pairs":
            raw = _pairs(raw, _flag(f))
        elif kind in ("list", "int_list") and raw is not None:
            raw = [x.strip() for x in raw.split(",")]
            if kind == "int_list":
                try:
                    raw = [int(x) for x in raw]
                except ValueError:
                    raise ValueError(f"Expected {_flag(f)} as comma-separated integers (got "
                                     f"{','.join(raw)!r})") from None
        elif kind == "zero_is_none" and raw == 0:
            raw = None
        elif kind == "negated":
            raw = not raw
        out[f.name] = raw
    return out
