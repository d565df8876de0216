"""The ``strl-pose`` command: the subcommands and the parser (:mod:`.commands`), how a run
ends on an error (:mod:`.guard`), argument reading (:mod:`.readers`), ``predict``
(:mod:`.predict`), ``export`` (:mod:`.export`) and ``bench`` (:mod:`.bench`). Torch-free until a
command runs.
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "run_guarded": "strl_pyg.cli.guard",
    "read_intrinsics": "strl_pyg.cli.readers",
    "read_image_file": "strl_pyg.cli.readers",
    "downscale_for_matching": "strl_pyg.cli.readers",
    "PairInputs": "strl_pyg.cli.readers",
    "MAX_SIDE": "strl_pyg.cli.readers",
    "main": "strl_pyg.cli.commands",
    "check_train_files": "strl_pyg.cli.commands",
    "build_parser": "strl_pyg.cli.commands",
    "predict_pair": "strl_pyg.cli.predict",
    "read_pair": "strl_pyg.cli.readers",
    "non_negative_int": "strl_pyg.cli.readers",
    "bootstrap_count": "strl_pyg.cli.readers",
    "cmd_bench": "strl_pyg.cli.bench",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
