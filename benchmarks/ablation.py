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
(SIFT + LSD, our line matcher), :data:`STEPS` steps of batch 16, Adam 3e-4 (constant, so a
run resumed to more steps equals a longer run), width 64, 3 layers, 4 heads (the shipped
size), validation on 100 held-out pairs every 250 steps.

Cost, measured on the 2-core development machine with other work on the second core: the
cache ~20 min once; per 1000 steps baseline 4 min, L / LP 11 min, V 13 min, full ~25 min
(quiet: about 1 s per step for the full row). The first five rows' validation curves at 1000
steps were still falling and did not separate the rows (translation 78 deg against 92 for the
mean pose), so the budget is 2000 steps (16 epochs): about 6-7 CPU-hours for the plan.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT_DEFAULT = os.environ.get("STRL_ABLATION_ROOT",
                              str(Path.home() / ".cache" / "strl-pyg" / "ablation"))
ROWS = ("baseline", "L", "LP", "R", "V", "V+W", "LP+R", "LP+V", "full")
MULTI_SEED_ROWS = ("baseline", "LP", "V", "full")
#: (row, seed) in training order: the comparisons the issue asks for first.
PLAN = ([(r, 0) for r in ("full", "baseline", "LP", "L", "V", "V+W", "LP+V", "R", "LP+R")]
        + [(r, s) for s in (1, 2) for r in MULTI_SEED_ROWS])
STEPS = 2000
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


def _finished_runs(root: Path, min_steps: int = STEPS) -> list[tuple[str, int, Path]]:
    return [(r, s, root / "runs" / run_name(r, s)) for r, s in PLAN
            if run_step(root / "runs" / run_name(r, s)) >= min_steps]


def cmd_eval(args: argparse.Namespace) -> int:
    """Scores every finished run (and PoseLib) on the evaluation sets, once per run."""
    import ablation_eval as ae
    import torch

    from strl_pyg.model.strl_pose import StrLPose

    torch.set_num_threads(args.threads)
    root = Path(args.root)
    sets = ae.all_sets(root / "eval_cache", quick=args.quick)
    out = root / ("eval_quick" if args.quick else "eval")
    ids = {k: [pid for pid, _, _ in v] for k, v in sets.items()}
    ae.save_json(out / "sets.json", ids)
    if not (out / "poselib.json").exists():
        ae.save_json(out / "poselib.json", ae.poselib_errors(sets))
    for row, seed, run in _finished_runs(root, args.min_steps):
        path = out / f"{run_name(row, seed)}.json"
        if path.exists():
            continue
        model = StrLPose.load(run / "model.pt")
        ae.save_json(path, ae.model_errors(model, sets))
        print(f"{run_name(row, seed)}: scored on {len(sets)} sets", flush=True)
    return 0


def _cell(errs_by_seed: list[list], which: int) -> str:
    import ablation_eval as ae

    meds = [ae.median_interval(ae._rows(e)[which])[0] for e in errs_by_seed]
    m, lo, hi = ae.median_interval(ae._rows(errs_by_seed[0])[which])
    text = f"{m:.2f} [{lo:.2f}-{hi:.2f}]"
    if len(meds) > 1:
        text += f" (seeds {min(meds):.2f}-{max(meds):.2f})"
    return text


def cmd_report(args: argparse.Namespace) -> int:
    """Table 3 of the paper for our runs, the paired comparisons and the training curves."""
    import json

    import ablation_eval as ae
    from common import banner

    root = Path(args.root)
    ev = root / "eval"
    sets = json.loads((ev / "sets.json").read_text())
    poselib = json.loads((ev / "poselib.json").read_text())
    runs = {}
    for row, seed in PLAN:
        path = ev / f"{run_name(row, seed)}.json"
        if path.exists():
            runs.setdefault(row, {})[seed] = json.loads(path.read_text())
    names = list(sets)
    lines = ["# The ablation (Table 3) in our implementation", "", "```", banner(), "```", "",
             f"`python benchmarks/ablation.py eval && python benchmarks/ablation.py report`; "
             f"runs: {', '.join(f'{r} ({len(v)} seed(s))' for r, v in runs.items())}. Median "
             "rotation and translation-direction errors (deg) over the pairs where the method "
             "gave a pose, [95 % bootstrap interval over pairs] of seed 0, (range of the "
             "seeds' medians). Pairs per set: "
             + ", ".join(f"{k} {len(v)}" for k, v in sets.items()) + ".", ""]
    for which, label in ((0, "rotation"), (1, "translation direction")):
        lines += [f"## Median {label} error (deg)", "",
                  "| row | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
        for row in ROWS:
            if row not in runs:
                continue
            seeds = [runs[row][s] for s in sorted(runs[row])]
            lines.append(f"| {row} | " + " | ".join(
                _cell([e[n] for e in seeds], which) for n in names) + " |")
        lines.append("| PoseLib | " + " | ".join(_cell([poselib[n]], which) for n in names)
                     + " |")
        lines.append("")
    lines += ["## AUC@20 (%) of max(rotation, translation); no pose = 180 deg", "",
              "| row | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for row in ROWS:
        if row in runs:
            lines.append(f"| {row} | " + " | ".join(
                f"{100 * ae.auc20(ae._rows(runs[row][min(runs[row])][n])[2]):.1f}"
                for n in names) + " |")
    lines.append("| PoseLib | " + " | ".join(
        f"{100 * ae.auc20(ae._rows(poselib[n])[2]):.1f}" for n in names) + " |")
    lines.append("")
    lines += ["## Paired comparisons (seed 0): median ratio a / b [95 % paired bootstrap]", "",
              "| a vs b | error | " + " | ".join(names) + " |",
              "|---|---" + "|---" * len(names) + "|"]
    for a, b in (("full", "baseline"), ("LP", "L")):
        if a in runs and b in runs:
            for which, label in ((0, "rot"), (1, "trans")):
                cells = []
                for n in names:
                    r, lo, hi, k = ae.paired_ratio(runs[a][0][n], runs[b][0][n], which)
                    cells.append(f"{r:.2f} [{lo:.2f}-{hi:.2f}]" if k else "-")
                lines.append(f"| {a} vs {b} | {label} | " + " | ".join(cells) + " |")
    out = Path(args.out)
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    plot_curves(root, Path(args.figure))
    print(f"wrote {args.figure}")
    return 0


def cmd_curves(args: argparse.Namespace) -> int:
    """The validation history of every run so far (finished or not) as a markdown table, and
    the curves figure: what a partial study can already say (are the curves still falling?)."""
    import torch
    from common import banner

    root = Path(args.root)
    lines = ["# Ablation runs so far: validation curves", "", "```", banner(), "```", "",
             "`python benchmarks/ablation.py curves`: mean validation rotation / translation-"
             "direction error (deg) of each run's checkpoints on the 100 held-out pairs of the "
             "training mix; trivial: the errors of always predicting the mean training pose. "
             "Runs of the plan that have not started are not listed.", "",
             "| run | step | val rot | val trans | AUC@10 | trivial rot / trans |",
             "|---|---|---|---|---|---|"]
    for row, seed in PLAN:
        ckpt = root / "runs" / run_name(row, seed) / "last.pt"
        if not ckpt.exists():
            continue
        hist = torch.load(ckpt, map_location="cpu", weights_only=True).get("history", [])
        for h in hist:
            lines.append(f"| {run_name(row, seed)} | {h['step']} | {h['rot_err_deg']:.2f} | "
                         f"{h['trans_err_deg']:.2f} | {h.get('auc10', float('nan')):.3f} | "
                         f"{h.get('trivial_rot_err_deg', float('nan')):.2f} / "
                         f"{h.get('trivial_trans_err_deg', float('nan')):.2f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    plot_curves(root, Path(args.figure))
    print(f"wrote {args.figure}")
    return 0


def plot_curves(root: Path, path: Path) -> None:
    """Validation rotation / translation errors of the key rows (seed 0) over the steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import torch

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for row in ("baseline", "L", "LP", "V", "full"):
        ckpt = root / "runs" / run_name(row, 0) / "last.pt"
        if not ckpt.exists():
            continue
        hist = torch.load(ckpt, map_location="cpu", weights_only=True).get("history", [])
        if not hist:  # started, not yet validated
            continue
        for ax, key in zip(axes, ("rot_err_deg", "trans_err_deg"), strict=True):
            ax.plot([h["step"] for h in hist], [h[key] for h in hist], "o-", label=row)
    for ax, title in zip(axes, ("validation rotation error (deg, mean)",
                                "validation translation-direction error (deg, mean)"),
                         strict=True):
        ax.set_xlabel("training step (batch 16)")
        ax.set_ylabel("degrees")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle("Ablation rows on the shared budget (lines_small, front-end matches)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default=ROOT_DEFAULT, help="cache and run folders")
    sub = ap.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train (or resume) every run of the plan")
    t.add_argument("--only", nargs="*", choices=ROWS, help="only these rows")
    t.add_argument("--threads", type=int, default=1, help="torch threads per run")
    sub.add_parser("status", help="steps done per run")
    e = sub.add_parser("eval", help="score the finished runs and PoseLib on every set")
    e.add_argument("--threads", type=int, default=1, help="torch threads")
    e.add_argument("--quick", action="store_true", help="4 pairs per set (a smoke run)")
    e.add_argument("--min-steps", type=int, default=STEPS,
                   help="score runs that reached this step (default: the plan's)")
    r = sub.add_parser("report", help="write the results table and the curves plot")
    here = Path(__file__).resolve().parent
    r.add_argument("--out", default=str(here / "results_ablation.md"))
    r.add_argument("--figure", default=str(here / "figures" / "ablation_curves.png"))
    c = sub.add_parser("curves", help="validation curves of the runs so far (table + plot)")
    c.add_argument("--out", default=str(here / "results_ablation_curves.md"))
    c.add_argument("--figure", default=str(here / "figures" / "ablation_curves.png"))
    args = ap.parse_args(argv)
    return {"train": cmd_train, "status": cmd_status, "eval": cmd_eval,
            "report": cmd_report, "curves": cmd_curves}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
