"""How ``strl-pose`` and the example scripts end: a user error is one ``error: Expected ...``
line on stderr and exit code 2 (never a traceback), a closed stdout ends quietly with 141,
Ctrl-C with 130."""

from __future__ import annotations

import os
import sys
import warnings

from strl_pyg.utils.commandline import UsageError

__all__ = ["run_guarded"]


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


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A Python warning as the command's other warnings: one ``warning: ...`` line on stderr
    (not the source file and line that raised it)."""
    kind = "" if issubclass(category, UserWarning) else f"{category.__name__}: "
    first = str(message).splitlines()[0] if str(message) else category.__name__
    print(f"warning: {kind}{first}", file=sys.stderr if file is None else file)


def run_guarded(fn, *args) -> int:
    """Runs ``fn(*args)`` and returns its exit code; a user error (bad flag or value, bad or
    missing file, unwritable output, refused checkpoint: ``UsageError``, ``OSError``, or a
    library ``ValueError`` / ``TypeError`` / ``KeyError`` saying "Expected ...") is printed as
    one ``error: ...`` line on stderr and gives exit code 2, never a traceback; a closed
    stdout (``| head``) ends quietly with 141."""
    try:
        try:
            with warnings.catch_warnings():
                warnings.showwarning = _one_line_warning
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
