"""The files of a scene run: the pairs' table (``pairs.jsonl``, resumable) and the matches
file's pair names (``matches.h5``)."""

from __future__ import annotations

import json
from pathlib import Path

from strl_pyg.inference.status import Status

__all__ = ["pair_key", "read_done", "STATUS_TO_VERIFY"]

#: The statuses whose pose and inlier matches become verified two-view geometries by default.
STATUS_TO_VERIFY = (Status.OK.value,)


def pair_key(name0: str, name1: str) -> str:
    """The group of a pair in ``matches.h5`` (``/`` in names becomes ``|``)."""
    return f"{name0.replace('/', '|')}::{name1.replace('/', '|')}"


def read_done(path: Path) -> dict[tuple[str, str], dict]:
    """The finished pairs of a ``pairs.jsonl``, by ``(image0, image1)``; a last line cut by
    a kill is removed from the file (its pair runs again)."""
    done: dict[tuple[str, str], dict] = {}
    if not path.exists():
        return done
    good = 0
    with open(path, "rb") as f:
        for raw in f:
            try:
                rec = json.loads(raw)
            except json.JSONDecodeError:
                break
            if not raw.endswith(b"\n"):
                break
            done[(rec["image0"], rec["image1"])] = rec
            good += len(raw)
    if good != path.stat().st_size:
        with open(path, "r+b") as f:
            f.truncate(good)
    return done
