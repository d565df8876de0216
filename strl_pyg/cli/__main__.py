"""``python -m strl_pyg.cli``: the ``strl-pose`` command without its console script (e.g. from a
checkout that is not installed)."""

from __future__ import annotations

import sys

from strl_pyg.cli import main

if __name__ == "__main__":
    sys.exit(main())
