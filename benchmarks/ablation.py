"""The paper's ablation (Table 3) trained on one shared budget: every row on the same cached
front-end matches of the same generated pairs, in the same order, for the same steps, width and
learning rate; only the model row and the initialisation seed differ.

    # train every run of the plan, resuming the unfinished ones (safe to re-run at any time;
    # a SIGTERM / Ctrl-C checkpoints the run in progress and the next call resumes it)
    nice -n 10 python benchmarks/ablation.py train
    # what is done, what is left, and the cost so far
    python benchmarks/ablation.py status

Runs live under ``--root`` (default ``$STRL_ABLATION_ROOT`` or
``~/.cache/strl-pyg/ablation``): ``cache/`` (the front-end match cache, built once by the
first run and shared by all) and ``runs/<row>-s<seed>/`` (each run's ``last.pt``, ``log.csv``,
``curves.png``). None of it belongs in the repository; the results files do
(``benchmarks/results_ablation.md``).

The plan (:data:`PLAN`): all nine rows with seed 0, then seeds 1 and 2 of ``baseline``, ``LP``,
``V`` and ``full`` (17 runs). The budget (:data:`TRAIN_ARGS`): 2000 training pairs of the
``lines_small`` mix (all four scene kinds at 240x320, low texture 35 %), front-end matches
(SIFT + LSD, our line matcher), 1000 steps of batch 16 (8 epochs), Adam 3e-4, width 64, 3
layers, 4 heads (the shipped size), validation on 100 held-out pairs every 250 steps. One
step costs about 1 s on one core of the 2-core development machine, so the plan is about
5-6 CPU-hours.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT_DEFAULT = os.environ.get("STRL_ABLATION_ROOT",
                              str(Path.home() / ".cache" / "strl-pyg" / "ablation"))
ROWS = ("baseline", "L", "LP", "R", "V", "V+W", "LP+R", "LP+V", "full")
MULTI_SEED_ROWS = ("baseline", "LP", "V", "full")
#: (row, seed) in training order: the comparisons the issue asks for first.
PLAN = ([(r, 0) for r in ("full", "baseline", "LP", "L", "V", "V+W", "LP+V", "R", "LP+R")]
        + [(r, s) for s in (1, 2) for r in MULTI_SEED_ROWS])
STEPS = 1000
TRAIN_ARGS = [
    "--scene-mix", "lines_small", "--matches", "frontend",
    "--train-pairs", "2000", "--val-pairs", "100", "--data-seed", "0",
    "--steps", str(STEPS), "--val-every", "250", "--batch-size", "16", "--lr", "3e-4",
    "--set", "hidden=64", "--set", "layers=3", "--set", "heads=4",
    "--checkpoint-minutes", "5", "--no-progress", "--no-tensorboard",
]
TRAIN_SCRIPT = Path(__file__).resolve().parents[1] / "examples" / "train.py"


def run_name(row: str, seed: int) -> str:
    return f"{row.replace('+', 'p')}-s{seed}"


def run_step(run_dir: Path) -> int:
    """The step of a run's ``last.pt`` (0 when there is none)."""
    ckpt = run_dir / "last.pt"
    if not ckpt.exists():
        return 0
    import torch

    return int(torch.load(ckpt, map_location="cpu", weights_only=True)["step"])


def train_command(root: Path, row: str, seed: int) -> list[str]:
    out = root / "runs" / run_name(row, seed)
    cmd = [sys.executable, str(TRAIN_SCRIPT), *TRAIN_ARGS, "--cache-dir", str(root / "cache"),
           "--model", row, "--seed", str(seed), "--out", str(out)]
    if (out / "last.pt").exists():
        cmd.append("--resume")
    return cmd


def cmd_train(args: argparse.Namespace) -> int:
    root = Path(args.root)
    env = {**os.environ, "OMP_NUM_THREADS": str(args.threads),
           "MKL_NUM_THREADS": str(args.threads)}
    plan = [(r, s) for r, s in PLAN if not args.only or r in args.only]
    for row, seed in plan:
        out = root / "runs" / run_name(row, seed)
        if run_step(out) >= STEPS:
            continue
        cmd = train_command(root, row, seed)
        print(f"[{time.strftime('%H:%M:%S')}] {run_name(row, seed)}: "
              f"{'resume' if '--resume' in cmd else 'start'}", flush=True)
        out.mkdir(parents=True, exist_ok=True)
        with open(out / "train.log", "a") as log:
            proc = subprocess.run(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
        if proc.returncode == 130:  # stopped by a signal: checkpointed, stop the plan too
            print(f"{run_name(row, seed)}: stopped, checkpoint kept; re-run to resume")
            return 130
        if proc.returncode != 0:
            print(f"{run_name(row, seed)}: failed with exit code {proc.returncode}, see "
                  f"{out / 'train.log'}")
            return proc.returncode
    print("plan complete" if not args.only else "selected runs complete")
    return 0


def cmd_status(args: argparse.Namespace) -> int:
    root = Path(args.root)
    done = 0
    for row, seed in PLAN:
        step = run_step(root / "runs" / run_name(row, seed))
        done += step
        print(f"{run_name(row, seed):14s} {step:5d} / {STEPS}")
    print(f"{done} of {len(PLAN) * STEPS} steps done")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default=ROOT_DEFAULT, help="cache and run folders")
    sub = ap.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train (or resume) every run of the plan")
    t.add_argument("--only", nargs="*", choices=ROWS, help="only these rows")
    t.add_argument("--threads", type=int, default=1, help="torch threads per run")
    sub.add_parser("status", help="steps done per run")
    args = ap.parse_args(argv)
    return {"train": cmd_train, "status": cmd_status}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
