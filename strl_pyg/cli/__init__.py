"""The ``strl-pose`` command: the subcommands and the parser (:mod:`.commands`), how a run
ends on an error (:mod:`.guard`), argument reading (:mod:`.inputs`) and ``bench``
(:mod:`.bench`). Torch-free until a command runs.
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

__all__ = [
    "run_guarded",
    "OneLineArgumentParser",
    "read_intrinsics",
    "read_image_file",
    "default_checkpoint",
    "downscale_for_matching",
    "PairInputs",
    "MAX_SIDE",
    "main",
    "check_train_files",
    "build_parser",
    "predict_pair",
    "UsageError",
    "read_pair",
    "non_negative_int",
    "bootstrap_count",
    "cmd_bench",
    "DEFAULT_WEIGHTS",
]

# 0.2 code read other names of the module this folder was: they resolve too
__getattr__, __dir__ = lazy_exports(__name__, {
    "run_guarded": "strl_pyg.cli.guard",
    "OneLineArgumentParser": "strl_pyg.cli.guard",
    "DEFAULT_WEIGHTS": "strl_pyg.training.checkpoints",
    "read_intrinsics": "strl_pyg.cli.readers",
    "read_image_file": "strl_pyg.cli.readers",
    "default_checkpoint": "strl_pyg.cli.commands",
    "downscale_for_matching": "strl_pyg.cli.readers",
    "PairInputs": "strl_pyg.cli.readers",
    "MAX_SIDE": "strl_pyg.cli.readers",
    "main": "strl_pyg.cli.commands",
    "check_train_files": "strl_pyg.cli.commands",
    "build_parser": "strl_pyg.cli.commands",
    "predict_pair": "strl_pyg.cli.commands",
    "UsageError": "strl_pyg.cli.readers",
    "read_pair": "strl_pyg.cli.readers",
    "non_negative_int": "strl_pyg.cli.readers",
    "bootstrap_count": "strl_pyg.cli.readers",
    "cmd_bench": "strl_pyg.cli.bench",
}, globals())
