"""How ``strl-pose`` and the example scripts end: a user error is one ``error: Expected ...``
line on stderr and exit code 2 (never a traceback), a closed stdout ends quietly with 141,
Ctrl-C with 130."""

from __future__ import annotations

import argparse
import os
import sys

from strl_pyg.cli.readers import UsageError

__all__ = ["run_guarded", "OneLineArgumentParser"]


def _report(err: BaseException) -> int:
    from strl_pyg.utils.io import one_line

    text = one_line(err.args[0] if isinstance(err, KeyError) and err.args else err)
    if isinstance(err, OSError) and not text.startswith("Expected"):
        name = f" '{err.filename}'" if err.filename else ""
        text = f"Expected a usable path{name} (got {err.strerror or type(err).__name__})"
    print(f"error: {text}", file=sys.stderr)
    return 2


def _stdout_closed() -> int:
    """Exit code 141 (128 + SIGPIPE, as a Unix tool killed by it) after stdout was closed;
    stdout is pointed at /dev/null so the interpreter's final flush stays quiet too."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # no real file descriptor (captured output)
        pass
    return 141


def run_guarded(fn, *args) -> int:
    """Runs ``fn(*args)`` and returns its exit code; a user error (bad flag or value, bad or
    missing file, unwritable output, refused checkpoint: ``UsageError``, ``OSError``, or a
    library ``ValueError`` / ``TypeError`` / ``KeyError`` saying "Expected ...") is printed as
    one ``error: ...`` line on stderr and gives exit code 2, never a traceback; a closed
    stdout (``| head``) ends quietly with 141."""
    try:
        try:
            return int(fn(*args) or 0)
        finally:  # a closed pipe shows here (also after --help's SystemExit), not at exit
            sys.stdout.flush()
    except BrokenPipeError:  # '| head' closed stdout: not the user's path, nothing to say
        return _stdout_closed()
    except (UsageError, OSError) as err:  # bad flags, missing / unwritable paths
        return _report(err)
    except (ValueError, TypeError, KeyError) as err:  # the library's "Expected ... (got ...)"
        if "Expected" not in str(err):
            raise
        return _report(err)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


class OneLineArgumentParser(argparse.ArgumentParser):
    """An ``argparse`` parser that reports a bad command line as one line (``UsageError``:
    ``error: Expected valid arguments (got ...); did you mean ...?`` and exit code 2 under
    :func:`run_guarded`) instead of argparse's usage block; parse inside ``run_guarded``."""

    def error(self, message: str):
        if message.startswith("Expected"):  # the caller's own one-line message
            raise UsageError(message)
        hint = _did_you_mean(self, message)
        raise UsageError(f"Expected valid arguments (got {message}){hint}; see "
                         f"'{self.prog} --help'")


def _did_you_mean(parser: argparse.ArgumentParser, message: str) -> str:
    """``", did you mean --K?"`` for an unrecognised flag close to one of the parser's or of
    its commands' (case first: ``--k`` is ``--K``)."""
    import difflib

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
