"""File I/O shared by the package: atomic writing (matches, graphs, checkpoints, cache markers,
PNGs: a reader never sees a half-written file), checks that an output path can be written
*before* the work that produces it, and safe checkpoint loading (``torch.load`` with
``weights_only=True`` only; a file that needs code to load is refused with a one-line error).

Nothing here imports torch at module level.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = [
    "atomic_open",
    "check_output_file",
    "check_output_dir",
    "safe_torch_load",
    "UnsafeFileError",
    "one_line",
]

#: Phrases of third-party error texts that advise turning safe loading off; never shown.
_UNSAFE_ADVICE = re.compile(r"weights_only|allow_pickle|add_safe_globals|safe_globals", re.I)


class UnsafeFileError(ValueError):
    """A file that would need to run code (a pickled object other than tensors and plain
    containers) to load; it is refused, never loaded."""


def one_line(err: BaseException | str) -> str:
    """The first line of an error text, without ANSI codes, and with advice to disable safe
    loading removed (such sentences are dropped, the rest kept)."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(err)).strip()
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    first = lines[0] if lines else type(err).__name__ if isinstance(err, BaseException) else ""
    if _UNSAFE_ADVICE.search(first):
        kept = [s for s in re.split(r"(?<=[.!?])\s+", first) if not _UNSAFE_ADVICE.search(s)]
        first = " ".join(kept) or "a file that cannot be loaded safely"
    return first


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _existing_ancestor(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _probe_writable(folder: Path, what: str, target: Path) -> None:
    if not folder.is_dir():
        raise NotADirectoryError(f"Expected {what} (got '{target}', under '{folder}', which "
                                 "is a file)")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise PermissionError(f"Expected {what} in a writable folder (got '{target}': "
                              f"{err.strerror or type(err).__name__} in '{folder}')") from None


def check_output_file(path: str | os.PathLike, what: str = "an output file path") -> Path:
    """Checks, without creating anything, that a file can be written at ``path``: it is not
    a folder and its nearest existing parent is a writable folder. Raises an ``OSError``
    subclass with a one-line ``Expected ... (got ...)`` message; returns ``Path(path)``."""
    path = Path(path)
    if str(path) == "" or path.is_dir():
        raise IsADirectoryError(f"Expected {what} (got '{path}', which is a folder)")
    _probe_writable(_existing_ancestor(path.parent), what, path)
    return path


def check_output_dir(path: str | os.PathLike, what: str = "an output folder") -> Path:
    """Checks, without creating anything, that ``path`` is or can become a writable folder.
    Raises an ``OSError`` subclass with a one-line message; returns ``Path(path)``."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"Expected {what} (got '{path}', which is a file)")
    _probe_writable(_existing_ancestor(path), what, path)
    return path


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """Opens a temporary file next to ``path`` for writing and renames it onto ``path`` when
    the block exits cleanly; on any exception the temporary file is removed and ``path`` is
    left as it was. Parent folders are created. A path that cannot be written raises an
    ``OSError`` naming ``path`` (not the temporary file).

    Example::

        with atomic_open("model.pt") as f:
            torch.save(state, f)
    """
    if "w" not in mode:
        raise ValueError(f"Expected a writing mode such as 'wb' or 'w' (got {mode!r})")
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"Expected a file path to write (got '{path}', a folder)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as err:
        raise type(err)(f"Expected to write '{path}' (got {err.strerror or type(err).__name__}"
                        f" for its folder '{path.parent}')") from None
    try:
        with os.fdopen(fd, mode) as f:
            yield f
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _check_zip_crc(path: Path, what: str) -> None:
    """``ValueError`` when a zip-format torch file has a record whose bytes no longer match
    their CRC-32 (a damaged copy: ``torch.load`` does not check them and would load changed
    weights). Legacy non-zip files are left to ``torch.load``."""
    import zipfile

    try:
        if not zipfile.is_zipfile(path):
            return
        with zipfile.ZipFile(path) as z:
            bad = z.testzip()
    except (zipfile.BadZipFile, OSError, EOFError, RuntimeError) as err:
        raise ValueError(f"Expected a readable {what} at '{path}' (got a damaged archive: "
                         f"{one_line(err)})") from None
    if bad is not None:
        raise ValueError(f"Expected a readable {what} at '{path}' (got a damaged file: record "
                         f"'{bad}' fails its checksum; copy or download it again)")


def safe_torch_load(path: str | os.PathLike, what: str = "checkpoint",
                    map_location: Any = "cpu") -> Any:
    """``torch.load(path, weights_only=True)`` with one-line errors.

    Only tensors, numbers, strings and plain containers load; a pickle that references any
    other global (a class, a function: code that would run) raises :class:`UnsafeFileError`
    naming it, and nothing of the file runs. Missing paths raise ``FileNotFoundError``,
    folders ``IsADirectoryError``, unreadable or corrupt files ``ValueError``.
    """
    import pickle

    import torch

    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"Expected a {what} file at '{path}' (got a folder)")
    if not path.is_file():
        raise FileNotFoundError(f"Expected a {what} file at '{path}' (got no such file)")
    if path.stat().st_size == 0:
        raise ValueError(f"Expected a readable {what} at '{path}' (got an empty file, 0 bytes)")
    _check_zip_crc(path, what)
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as err:
        # torch names the global one of two ways (2.4-2.5: "Unsupported global: GLOBAL x",
        # 2.6 on: "unsupported GLOBAL x whose module ... is blocked")
        found = re.search(r"[Uu]nsupported (?:global: )?GLOBAL (\S+)", str(err))
        if found:
            raise UnsafeFileError(f"Expected a {what} of tensors and plain containers at "
                                  f"'{path}' (got a pickle that would run '{found.group(1)}'; "
                                  "refused, nothing was run)") from None
        # torch's own text suggests weights_only=False: never passed on
        lines = [ln for ln in str(err).split("error:")[-1].splitlines() if ln.strip()
                 and "weights_only" not in ln and "trusted source" not in ln]
        raise ValueError(f"Expected a readable {what} at '{path}' (got a pickle the safe "
                         f"loader refuses: {one_line(lines[0]) if lines else 'unreadable'})"
                         ) from None
    except Exception as err:  # zip / stream / EOF errors of corrupt or foreign files
        raise ValueError(f"Expected a readable {what} at '{path}' (got {type(err).__name__}: "
                         f"{one_line(err)})") from None
