"""One-line command-line errors, shared by ``strl-pose``, ``examples/*.py`` and
``strl_pyg.evaluation.run``: :class:`UsageError` and :class:`OneLineArgumentParser`, which
reports a bad flag or value as ``Expected valid arguments (got ...)`` (with a "did you mean"
for a mistyped flag) instead of argparse's usage block. Imports nothing else of strl_pyg but
:func:`strl_pyg.utils.io.one_line`."""

from __future__ import annotations

import argparse
import difflib

from strl_pyg.utils.io import one_line

__all__ = ["UsageError", "OneLineArgumentParser"]


class UsageError(ValueError):
    """Bad input from the command line (printed without a traceback, exit code 2)."""


class OneLineArgumentParser(argparse.ArgumentParser):
    """An ``argparse`` parser that reports a bad command line as one line (``UsageError``:
    ``Expected valid arguments (got ...); did you mean ...?``) instead of argparse's usage
    block. ``strl_pyg.cli.run_guarded`` prints it as ``error: ...`` with exit code 2."""

    def error(self, message: str):
        message = one_line(message)
        if message.startswith("Expected"):  # the caller's own one-line message
            raise UsageError(message)
        hint = _did_you_mean(self, message)
        raise UsageError(f"Expected valid arguments (got {message}){hint}; see "
                         f"'{self.prog} --help'")


def _did_you_mean(parser: argparse.ArgumentParser, message: str) -> str:
    """``"; did you mean --K?"`` for an unrecognised flag close to one of the parser's or of
    its commands' (case first: ``--k`` is ``--K``)."""
    if "unrecognized arguments:" not in message:
        return ""
    options = set(parser._option_string_actions)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                options |= set(sub._option_string_actions)
    hints = []
    for token in message.split("unrecognized arguments:", 1)[1].split():
        flag = token.split("=", 1)[0]
        if not flag.startswith("-"):
            continue
        same_case = [o for o in options if o.lower() == flag.lower()]
        close = same_case or difflib.get_close_matches(flag, sorted(options), n=1, cutoff=0.75)
        if close:
            hints.append((flag, close[0]))
    if len(hints) == 1:
        return f"; did you mean {hints[0][1]}?"
    return "; did you mean " + ", ".join(f"{c} for {f}" for f, c in hints) + "?" if hints else ""
