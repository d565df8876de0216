"""The training command line: the :class:`~strl_pyg.training.TrainConfig` of parsed
``examples/train.py`` / ``strl-pose train`` flags, ``--resume`` taking the settings a command
leaves out from the run, the device check, and :func:`run_from_args`, which runs
:func:`~strl_pyg.training.train` and turns its outcome into an exit code and one line."""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from strl_pyg.training.checkpoints import load_checkpoint
from strl_pyg.training.config import TrainConfig, add_train_arguments
from strl_pyg.training.log import plot_history
from strl_pyg.training.loop import TrainingDiverged, train
from strl_pyg.training.options import config_values, flag_dest, option_fields

__all__ = ["config_from_args", "FLAG_FIELDS", "given_fields", "settings_from_run",
           "run_from_args", "check_device"]


def config_from_args(args: argparse.Namespace, ap: argparse.ArgumentParser,
                     config: type[TrainConfig] = TrainConfig) -> TrainConfig:
    """The :class:`TrainConfig` (or subclass ``config``) of parsed :func:`add_train_arguments`
    flags (``ValueError`` / ``TypeError`` on bad values; a malformed list or ``KEY=VALUE`` is
    ``ap.error``)."""
    try:
        values = config_values(args, config)
    except ValueError as err:
        ap.error(str(err))
    return config(**values)


#: ``add_train_arguments`` flags whose destination is not the :class:`TrainConfig` field of the
#: same name (``None``: not a setting of the run), from the fields' options.
FLAG_FIELDS = {**{flag_dest(f): f.name for f in option_fields(TrainConfig)
                  if flag_dest(f) != f.name},
               "resume": None, "overwrite": None, "no_progress": None, "help": None}


def given_fields(argv: Sequence[str]) -> set[str]:
    """The :class:`TrainConfig` fields that the command line ``argv`` sets explicitly (a flag
    given with the default value counts as given); tokens that are not training flags are
    ignored."""
    ap = argparse.ArgumentParser(add_help=False, argument_default=argparse.SUPPRESS)
    add_train_arguments(ap)
    for action in ap._actions:
        action.default = argparse.SUPPRESS
    given, _ = ap.parse_known_args(list(argv))
    return {FLAG_FIELDS.get(dest, dest) for dest in vars(given)} - {None}


def settings_from_run(cfg: TrainConfig, given: set[str]) -> tuple[TrainConfig, dict[str, Any]]:
    """For ``--resume``: ``cfg`` with every setting its command line did not give (``given``:
    :func:`given_fields`) taken from the run's ``last.pt``, so ``--out RUN --resume``
    continues a run without retyping its options, and what was taken. The run folder, device
    and workers stay this command's; what the command gives is kept (and checked against the
    run by :func:`train`). No ``last.pt``: ``cfg`` unchanged (:func:`train` reports it)."""
    last = Path(cfg.out_dir) / "last.pt"
    if not last.is_file():
        return cfg, {}
    raw = load_checkpoint(last).get("train_config")
    if not isinstance(raw, dict):
        return cfg, {}
    saved = asdict(TrainConfig.from_dict(raw))  # older runs: the fields added since, filled
    own = {"out_dir", "device", "num_workers"} | set(given)
    taken = {k: v for k, v in saved.items() if k not in own and getattr(cfg, k) != v}
    if not taken:
        return cfg, {}
    return TrainConfig.from_dict({**asdict(cfg), **taken}), taken


def run_from_args(args: argparse.Namespace, ap: argparse.ArgumentParser,
                  argv: Sequence[str] | None = None) -> int:
    """Runs training from parsed :func:`add_train_arguments` flags; returns an exit code.
    With ``--resume`` and the command line ``argv``, the settings it does not give come from
    the run (:func:`settings_from_run`, printed); without ``argv``, every setting must match
    the run."""
    try:
        cfg = config_from_args(args, ap)
        if args.resume and not args.overwrite and argv is not None:
            cfg, taken = settings_from_run(cfg, given_fields(argv))
            if taken and int(os.environ.get("RANK", "0")) == 0:
                print("resuming with the run's own settings for what the command left out: "
                      + ", ".join(f"{k}={v!r}" for k, v in taken.items()))
        cfg.model_config()  # validate the model overrides before any work
        check_device(cfg.device)
        if args.resume and args.overwrite:
            raise ValueError("Expected at most one of --resume and --overwrite (got both)")
        if cfg.data_root is not None and not Path(cfg.data_root).is_dir():
            what = "a file" if Path(cfg.data_root).exists() else "no such folder"
            raise ValueError(f"Expected --data-root to be the {cfg.dataset} dataset's folder "
                             f"(got {what}: '{cfg.data_root}')")
        result = train(cfg, resume=args.resume, progress=not args.no_progress,
                       overwrite=args.overwrite)
    except (ValueError, TypeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except TrainingDiverged as err:  # not a usage error: the run itself failed
        print(f"error: {err}", file=sys.stderr)
        return 1
    last = Path(cfg.out_dir) / "last.pt"
    if result.get("already_finished"):
        how = ("pass a larger --steps with --resume to continue"
               if cfg.lr_schedule == "constant" else
               f"its {cfg.lr_schedule} schedule has ended: start a new run with --init-from "
               f"'{last}' to train on")
        print(f"run already finished: '{last}' is at step {result['step']} = --steps; nothing "
              f"to train ({how})")
        return 0
    if result.get("interrupted"):
        print(f"stopped by {result['interrupted']} at step {result['step']} of {cfg.steps}: "
              f"kept '{last}' (model, optimiser, RNG, step); continue with the same command "
              f"and --resume", file=sys.stderr)
    if result.get("budget_reached"):
        print(f"stopped at step {result['step']} of {cfg.steps}: the budget of "
              f"{cfg.budget_minutes:g} minutes is spent; kept '{last}' (continue with the same "
              f"command and --resume)", file=sys.stderr)
    if result.get("history"):
        png = plot_history(result["history"], Path(cfg.out_dir) / "curves.png",
                           log=Path(cfg.out_dir) / "log.csv")
        print(f"curves: {png}")
    keys = ("rot_err_deg", "trans_err_deg", "auc10", "trivial_rot_err_deg",
            "trivial_trans_err_deg", "pairs_per_s")
    summary = json.dumps({"step": result["step"], **{k: result[k] for k in keys if k in result}})
    if result.get("interrupted"):  # stdout carries the summary of a finished run only
        return 130
    print(summary)
    return 0


def check_device(device: str) -> None:
    """One-line ``ValueError`` for a device string torch cannot parse or that is absent."""
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(f"Expected --device cpu, cuda, cuda:N or mps (got {device!r})") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"Expected --device cpu on this machine (got {device!r}: torch "
                         f"{torch.__version__} sees no CUDA device)")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ValueError(f"Expected a CUDA device index below {torch.cuda.device_count()} "
                         f"(got {device!r})")
    if dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"Expected --device cpu on this machine (got {device!r}: MPS is not "
                         f"available)")
    if dev.type not in ("cpu", "cuda", "mps"):
        raise ValueError(f"Expected --device cpu, cuda, cuda:N or mps (got {device!r})")
