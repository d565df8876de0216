"""``python -m strl_pyg.evaluation``: the ``strl-pose evaluate`` command line."""

import sys

from strl_pyg.evaluation.run import main

sys.exit(main(prog="python -m strl_pyg.evaluation"))
