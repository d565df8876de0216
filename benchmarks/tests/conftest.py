"""The scripts these tests import: those users run (``benchmarks/``) and the studies
(``benchmarks/studies/``), as each script finds the other when it runs. ``tests/`` never
imports them; the test tiers (``--runslow``) are in the repository's root conftest.py."""

from __future__ import annotations

import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1]
for folder in (BENCH, BENCH / "studies"):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
