"""Atomic file writing, shared by every writer of the package (matches, graphs, checkpoints,
cache markers, PNGs): a reader never sees a half-written file."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

__all__ = ["atomic_open"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """Opens a temporary file next to ``path`` for writing and renames it onto ``path`` when
    the block exits cleanly; on any exception the temporary file is removed and ``path`` is
    left as it was. Parent folders are created.

    Example::

        with atomic_open("model.pt") as f:
            torch.save(state, f)
    """
    if "w" not in mode:
        raise ValueError(f"Expected a writing mode such as 'wb' or 'w' (got {mode!r})")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            yield f
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
