"""Train Str-L Pose on generated scenes, KITTI odometry, DeMoN or your own posed photographs.

Examples:
    # a small CPU run on generated scenes (no downloads)
    python examples/train.py --steps 500 --out runs/synthetic
    # after an interruption: continue it exactly where it stopped
    python examples/train.py --out runs/synthetic --resume
    # the paper's recipe (the default is the study's: cosine from 1e-3, beta 0.25)
    python examples/train.py --loss paper --set inputs=paper --lr 1e-4 \\
        --lr-schedule constant --warmup-steps 0 --out runs/paper
    # an ablation row of the paper, e.g. points only
    python examples/train.py --model baseline --out runs/baseline
    # KITTI odometry (official layout), 2 processes with DistributedDataParallel
    torchrun --nproc_per_node 2 examples/train.py --dataset kitti --data-root /data/kitti
    # posed photographs (scene folders: real_scenes cameras.json, COLMAP, transforms.json or
    # LLFF), mixed 1:1 with generated pairs, fine-tuning the shipped weights
    python examples/train.py --dataset posed --data-root my_scenes --train-scenes a,b,c \\
        --val-scenes d --synthetic-share 0.5 --init-from shipped:synthetic --lr 2e-4 \\
        --budget-minutes 120 --out runs/mine

All settings live in strl_pyg.training.config.TrainConfig; every run stores them in its
checkpoint. The default model takes its patch channels from the data (generated scenes and
KITTI are grey, DeMoN is RGB); a grey model on DeMoN (`--set patch_features=1 --set
image_channels=1`, e.g. to fine-tune the shipped weights with --init-from) reads its images as
grey. Validation sources that do not exist (KITTI's default 09/10, --val-sequences) are an
error before any training. Bad flags, an unwritable --out, a missing or refused checkpoint
(all load with weights_only=True) end with one error line and exit code 2.
"""

from __future__ import annotations

import argparse
import sys

from strl_pyg.cli.commands import check_train_files
from strl_pyg.cli.guard import run_guarded
from strl_pyg.training.config import add_train_arguments
from strl_pyg.utils import OneLineArgumentParser


class _Help(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """The examples as written, and every flag's default."""


def _run(args: argparse.Namespace, ap: argparse.ArgumentParser, argv: list[str]) -> int:
    check_train_files(args)  # before torch is imported
    from strl_pyg.training import run_from_args

    return run_from_args(args, ap, argv)  # argv: what --resume takes from the run


def main(argv: list[str] | None = None) -> int:
    ap = OneLineArgumentParser(description=__doc__, formatter_class=_Help)
    add_train_arguments(ap)
    # parsed under the guard: a bad flag or value is one error line, as in `strl-pose train`
    argv = sys.argv[1:] if argv is None else list(argv)
    return run_guarded(lambda: _run(ap.parse_args(argv), ap, argv))


if __name__ == "__main__":
    sys.exit(main())
