"""The paper's ablation (Table 3) trained on one shared budget: every row on the same cached
front-end matches of the same generated pairs, in the same order, for the same steps, width and
learning rate; only the model row and the initialisation seed differ.

    # train every run of the plan, resuming the unfinished ones (safe to re-run at any time;
    # a SIGTERM / Ctrl-C checkpoints the run in progress and the next call resumes it)
    nice -n 10 python benchmarks/ablation.py train
    # what is done, what is left, and the cost so far
    python benchmarks/ablation.py status

Runs live under ``--root`` (default ``$STRL_ABLATION_ROOT`` or
``~/.cache/strl-pyg/ablation``): ``cache/`` (the front-end match cache, built once and shared
by all), ``eval_cache/`` (the evaluation sets' matches) and ``runs/<row>-s<seed>/`` (each run's
``last.pt``, ``log.csv``, ``curves.png``). None of it belongs in the repository.

What does belong there, and is all that a later session needs when the machine (and with it
``--root``) is gone: :data:`RESULTS` (``benchmarks/results_ablation/``) holds, per finished run,
its per-pair errors on every evaluation set (``runs/<run>.json``) and its validation history
(``history/<run>.json``), plus PoseLib's errors and the pair ids of every set. A finished run
is scored as soon as it ends (``train --eval``), so the study accumulates across sessions on
machines that do not keep ``--root``; ``report`` and ``curves`` read only :data:`RESULTS`
(and ``notes.md`` there, what the runs say in words, placed above the report's tables).

Two workers (one per core) share the plan: each run is claimed by a ``claim`` file (with the
worker's pid) before it starts, so ``train`` may be started twice::

    python benchmarks/ablation.py cache --workers 2        # the training cache on both cores
    nice -n 10 python benchmarks/ablation.py train --eval &
    nice -n 10 python benchmarks/ablation.py train --eval &

The shipped checkpoint, scored once on the same sets, is the reference row that a ``full`` run
must beat before its weights would be shipped::

    python benchmarks/ablation.py eval --reference        # results_ablation/reference/

The plan (:data:`PLAN`): all nine rows with seed 0, then seeds 1 and 2 of ``baseline``, ``LP``,
``V`` and ``full`` (17 runs). The budget (:data:`TRAIN_ARGS`): 2000 training pairs of the
``lines_small`` mix (all four scene kinds at 240x320, low texture 35 %), front-end matches
(SIFT + LSD, our line matcher), :data:`STEPS` steps of batch 16, Adam 3e-4 (constant, so a
run resumed to more steps equals a longer run), width 64, 3 layers, 4 heads (the shipped
size), validation on 100 held-out pairs every 250 steps.

**Table 3 on real photographs** (``--recipe real``, :data:`PLAN_REAL`, :data:`REAL_ARGS`):
baseline, LP and full with 3 seeds each, then L with 3 and V with one, trained on the
real_scenes training scenes (the fixed split) mixed 1:1 with generated pairs, the balanced
loss and flow inputs at this protocol's constant 3e-4, :data:`REAL_STEPS` steps of batch 16,
and scored on the 4 validation scenes and the KITTI 06, DeMoN and dino slices
(``bench_real_scenes.pair_sets``); results in ``results_ablation/real_photographs/``. The
posed matches are cached once in ``<root>/cache`` (point it at an existing match cache with a
symlink)::

    nice -n 10 python benchmarks/ablation.py --recipe real train --eval
    python benchmarks/ablation.py --recipe real report

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
#: The paired comparisons of the report: the issue's two (full vs baseline, LP vs L), then one
#: per finding of the paper (L alone slightly worse than baseline, LP and V better, W on V),
#: and the visual branch's two forms (R: CNN features of the points' neighbourhoods; V: the
#: pixel visual graph), alone and with the lines.
COMPARISONS = (("full", "baseline"), ("LP", "L"), ("L", "baseline"), ("LP", "baseline"),
               ("V", "baseline"), ("V+W", "V"), ("full", "LP"), ("R", "baseline"),
               ("V", "R"), ("LP+R", "LP"), ("LP+V", "LP+R"))
STEPS = 2000
TRAIN_ARGS = [
    "--scene-mix", "lines_small", "--matches", "frontend",
    "--train-pairs", "2000", "--val-pairs", "100", "--data-seed", "0",
    "--steps", str(STEPS), "--val-every", "250", "--batch-size", "16", "--lr", "3e-4",
    # Table 3's optimiser and beta, pinned: the package's defaults changed in 0.4
    "--lr-schedule", "constant", "--warmup-steps", "0", "--beta", "0.5",
    "--set", "hidden=64", "--set", "layers=3", "--set", "heads=4",
    "--checkpoint-minutes", "5", "--no-progress", "--no-tensorboard",
]
_BASE_ARGS = list(TRAIN_ARGS)
TRAIN_SCRIPT = Path(__file__).resolve().parents[1] / "examples" / "train.py"
#: Where the results that outlive the machine go (committed): see the module docstring.
RESULTS = Path(__file__).resolve().parent / "results_ablation"
#: Another recipe's Table 3 is a study: its results go under ``benchmarks/studies/``.
STUDIES = Path(__file__).resolve().parent / "studies"


#: The two training recipes (issue "A network that learns its pose"): ``paper`` is the paper's
#: (its four coordinates per node, the aleatoric loss on all 7 components), the recipe of the
#: first Table 3 (``results_ablation/``); ``balanced`` is the flow node inputs and beta-NLL
#: with an angular translation term (``benchmarks/studies/results_pose_recipe.md``), at this
#: protocol's constant 3e-4 and beta 0.5 (the package's defaults moved on to the study's
#: winner in 0.4; :data:`TRAIN_ARGS` pins these)
#: and is scored into ``studies/results_ablation_balanced/``. Everything else is the same
#: protocol.
RECIPES = {"paper": ["--loss", "paper", "--set", "inputs=paper"],
           "balanced": ["--loss", "balanced", "--set", "inputs=flow"],
           "real": []}  # its own flags: REAL_ARGS
#: The balanced recipe's plan: 3 seeds of baseline, LP, V and full, and L (seed 0 of every
#: row first).
PLAN_BALANCED = ([(r, 0) for r in ("baseline", "LP", "V", "full", "L")]
                 + [(r, s) for s in (1, 2) for r in MULTI_SEED_ROWS])


#: Table 3 on real photographs (recipe ``real``): baseline, LP and full, 3 seeds each, on the
#: real_scenes training scenes mixed 1:1 with generated pairs (the package's posed-photograph
#: training, ``--dataset posed``), scored on the 4 validation scenes and the KITTI 06, DeMoN and
#: dino slices (``bench_real_scenes.pair_sets``). Seed 0 of the three rows first; then L and V
#: with one seed (LP against L: the lines' own message passing; V against baseline: the visual
#: graph), then L's seeds 1 and 2 (so that L, like the rows it is compared with, has 3).
PLAN_REAL = ([(r, s) for s in (0, 1, 2) for r in ("baseline", "LP", "full")]
             + [("L", 0), ("V", 0), ("L", 1), ("L", 2)])
#: The real recipe's budget: steps of batch 16 per run (on one core of the 2-core development
#: CPU with a second run on the other: baseline 9-12 minutes, LP 25-43, full 65-75, its
#: complete-graph attention over 768 nodes a pair being most of a step).
REAL_STEPS = 1200
#: The real_scenes folder (``$STRL_REAL_SCENES``, default ``../shared/data/real_scenes``).
REAL_SCENES = os.environ.get("STRL_REAL_SCENES", str(
    Path(__file__).resolve().parents[2] / "shared" / "data" / "real_scenes"))
REAL_ARGS = [
    "--dataset", "posed", "--data-root", REAL_SCENES, "--synthetic-share", "0.5",
    "--synthetic-pairs", "800", "--val-gap", "2", "--val-stride", "4",
    "--steps", str(REAL_STEPS), "--val-every", "200", "--batch-size", "16", "--lr", "3e-4",
    "--lr-schedule", "constant", "--warmup-steps", "0", "--beta", "0.5",
    "--set", "hidden=64", "--set", "layers=3", "--set", "heads=4",
    "--loss", "balanced", "--set", "inputs=flow",
    "--checkpoint-minutes", "5", "--no-progress", "--no-tensorboard",
]
#: The evaluation sets of a recipe: ``cache folder -> {name: [(pair id, matches, T_0to1)]}``.
EVAL_SETS = None


def use_recipe(name: str, root: Path) -> Path:
    """Points the module at recipe ``name``: its training flags, plan, results folder; returns
    its run root (``<root>/runs`` for the paper's, ``<root>/<recipe>`` for the others, so all
    share the caches)."""
    global RESULTS, PLAN, STEPS, EVAL_SETS
    TRAIN_ARGS[:] = [a for a in _BASE_ARGS] + RECIPES[name]
    if name == "paper":
        return root
    RESULTS = STUDIES / f"results_ablation_{name}"
    PLAN = PLAN_BALANCED
    if name == "real":
        import bench_real_scenes as brs

        TRAIN_ARGS[:] = list(REAL_ARGS)
        RESULTS = Path(__file__).resolve().parent / "results_ablation" / "real_photographs"
        PLAN, STEPS, EVAL_SETS = PLAN_REAL, REAL_STEPS, brs.pair_sets
    run_root = root / name
    run_root.mkdir(parents=True, exist_ok=True)
    for shared in ("cache", "eval_cache"):
        link = run_root / shared
        (root / shared).mkdir(parents=True, exist_ok=True)
        if not (link.exists() or link.is_symlink()):
            link.symlink_to(root / shared, target_is_directory=True)
    return run_root


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


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, someone else's
        return True
    return True


def claim(run_dir: Path) -> bool:
    """Claims a run for this process (``True``), or ``False`` when a live process holds it. A
    claim left by a dead process (a killed worker, a reset machine) is taken over."""
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / "claim"
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                pid = int(path.read_text().strip() or 0)
            except (OSError, ValueError):
                pid = 0
            if pid and _pid_alive(pid):
                return False
            path.unlink(missing_ok=True)  # stale
            continue
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        return True
    return False


def release(run_dir: Path) -> None:
    path = run_dir / "claim"
    try:
        if int(path.read_text().strip() or 0) == os.getpid():
            path.unlink()
    except (OSError, ValueError):
        pass


def save_history(run_dir: Path, name: str) -> None:
    """The run's validation history (and step) into :data:`RESULTS` ``history/<name>.json``."""
    import ablation_eval as ae
    import torch

    ckpt = run_dir / "last.pt"
    if not ckpt.exists():
        return
    state = torch.load(ckpt, map_location="cpu", weights_only=True)
    ae.save_json(RESULTS / "history" / f"{name}.json",
                 {"step": int(state["step"]), "steps": STEPS,
                  "history": state.get("history", [])})


class _Scorer:
    """Scores finished runs into :data:`RESULTS`; the evaluation sets are loaded on first use."""

    def __init__(self, root: Path, threads: int, quick: bool = False) -> None:
        self.root, self.threads, self.quick = root, threads, quick
        self._sets = None

    @property
    def out(self) -> Path:
        return RESULTS if not self.quick else self.root / "eval_quick"

    def sets(self) -> dict:
        import ablation_eval as ae

        if self._sets is None:
            if EVAL_SETS is not None:
                self._sets = EVAL_SETS(self.root / "eval_cache")
            else:
                self._sets = ae.all_sets(self.root / "eval_cache", quick=self.quick)
            ids = {k: [pid for pid, _, _ in v] for k, v in self._sets.items()}
            ae.check_or_save_sets(self.out / "sets.json", ids)
            if not (self.out / "poselib.json").exists():
                ae.save_json(self.out / "poselib.json", ae.poselib_errors(self._sets))
        return self._sets

    def score(self, row: str, seed: int, run_dir: Path) -> bool:
        """Scores one finished run unless its results exist; ``True`` when it scored it."""
        from strl_pyg.model.strl_pose import StrLPose

        path = self.out / "runs" / f"{run_name(row, seed)}.json"
        if path.exists():
            return False
        self._save(path, lambda: StrLPose.load(run_dir / "model.pt"), run_name(row, seed))
        return True

    def _save(self, path: Path, load_model, label: str) -> None:
        import ablation_eval as ae
        import torch

        torch.set_num_threads(self.threads)
        sets = self.sets()
        ae.save_json(path, ae.model_errors(load_model(), sets))
        print(f"[{time.strftime('%H:%M:%S')}] {label}: scored on {len(sets)} sets -> {path}",
              flush=True)

    def score_reference(self, name: str) -> bool:
        """Scores the shipped checkpoint ``name`` (not trained on this study's budget: the
        figure the study's ``full`` rows must beat before their weights would be shipped), or
        the weights of a ``.pt`` file (reference row named by the file's stem)."""
        from strl_pyg.model.strl_pose import StrLPose

        file = Path(name)
        if file.suffix == ".pt":
            if not file.is_file():
                raise SystemExit(f"error: expected a checkpoint file at '{file}' (got none)")
            path = self.out / "reference" / f"{file.stem}.json"
            load, what = (lambda: StrLPose.load(file)), f"'{file}'"
        else:
            if name not in StrLPose.PRETRAINED:
                raise SystemExit(f"error: expected a shipped checkpoint in "
                                 f"{sorted(StrLPose.PRETRAINED)} or a .pt file (got {name!r})")
            path = self.out / "reference" / f"{name}.json"
            load, what = (lambda: StrLPose.from_pretrained(name)), f"shipped '{name}'"
        if path.exists():
            return False
        self._save(path, load, what)
        return True


def cmd_cache(args: argparse.Namespace) -> int:
    """Builds the training match cache (``--workers`` processes) and, with ``--eval``, the
    evaluation sets' matches, PoseLib's errors and the sets' pair ids."""
    if not args.eval_only:
        from strl_pyg.training.commandline import config_from_args
        from strl_pyg.training.config import add_train_arguments
        from strl_pyg.training.data import build_datasets

        ap = add_train_arguments(argparse.ArgumentParser())
        targs = ap.parse_args([*TRAIN_ARGS, "--cache-dir", str(Path(args.root) / "cache"),
                               "--workers", str(args.workers), "--out", "unused"])
        t0 = time.time()
        train, val = build_datasets(config_from_args(targs, ap))
        print(f"training cache: {len(train)} + {len(val)} pairs in {time.time() - t0:.0f} s",
              flush=True)
    if args.eval or args.eval_only:
        t0 = time.time()
        sets = _Scorer(Path(args.root), args.threads).sets()
        print(f"evaluation sets: {sum(len(v) for v in sets.values())} pairs in "
              f"{len(sets)} sets, {time.time() - t0:.0f} s", flush=True)
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    root = Path(args.root)
    env = {**os.environ, "OMP_NUM_THREADS": str(args.threads),
           "MKL_NUM_THREADS": str(args.threads)}
    plan = [(r, s) for r, s in PLAN if not args.only or r in args.only]
    scorer = _Scorer(root, args.threads) if args.eval else None
    skipped = []
    for row, seed in plan:
        name = run_name(row, seed)
        out = root / "runs" / name
        if (RESULTS / "runs" / f"{name}.json").exists() and run_step(out) == 0:
            continue  # trained and scored in an earlier session (its folder is gone)
        if run_step(out) >= STEPS:
            if scorer is not None and claim(out):
                try:
                    scorer.score(row, seed, out)
                finally:
                    release(out)
            continue
        if not claim(out):
            skipped.append(name)
            continue
        try:
            cmd = train_command(root, row, seed)
            print(f"[{time.strftime('%H:%M:%S')}] {name}: "
                  f"{'resume' if '--resume' in cmd else 'start'} (pid {os.getpid()})",
                  flush=True)
            with open(out / "train.log", "a") as log:
                proc = subprocess.run(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
            save_history(out, name)
            if proc.returncode == 130:  # stopped by a signal: checkpointed, stop the plan too
                print(f"{name}: stopped, checkpoint kept; re-run to resume")
                return 130
            if proc.returncode != 0:
                print(f"{name}: failed with exit code {proc.returncode}, see "
                      f"{out / 'train.log'}")
                return proc.returncode
            print(f"[{time.strftime('%H:%M:%S')}] {name}: finished", flush=True)
            if scorer is not None:
                scorer.score(row, seed, out)
        finally:
            release(out)
    if skipped:
        print(f"left to the other worker(s): {', '.join(skipped)}")
    print("plan complete" if not args.only else "selected runs complete")
    return 0


def cmd_status(args: argparse.Namespace) -> int:
    root = Path(args.root)
    done = 0
    for row, seed in PLAN:
        name = run_name(row, seed)
        step = run_step(root / "runs" / name)
        scored = (RESULTS / "runs" / f"{name}.json").exists()
        if scored:
            step = STEPS
        done += step
        claimed = (root / "runs" / name / "claim").exists()
        print(f"{name:14s} {step:5d} / {STEPS}{'  scored' if scored else ''}"
              f"{'  (claimed)' if claimed and not scored else ''}")
    print(f"{done} of {len(PLAN) * STEPS} steps done")
    return 0


def _finished_runs(root: Path, min_steps: int | None = None) -> list[tuple[str, int, Path]]:
    min_steps = STEPS if min_steps is None else min_steps
    return [(r, s, root / "runs" / run_name(r, s)) for r, s in PLAN
            if run_step(root / "runs" / run_name(r, s)) >= min_steps]


def cmd_eval(args: argparse.Namespace) -> int:
    """Scores every finished run (and PoseLib) on the evaluation sets, once per run."""
    root = Path(args.root)
    scorer = _Scorer(root, args.threads, quick=args.quick)
    scorer.sets()
    for row, seed, run in _finished_runs(root, args.min_steps):
        scorer.score(row, seed, run)
    if args.reference:
        scorer.score_reference(args.reference)
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
    from strl_bench_common import banner

    ev = Path(args.results)
    if not (ev / "sets.json").exists() or not (ev / "poselib.json").exists():
        print(f"error: no scored runs in '{ev}' (expected sets.json and poselib.json written by "
              f"'ablation.py train --eval' or 'ablation.py eval')", file=sys.stderr)
        return 2
    sets = json.loads((ev / "sets.json").read_text())
    poselib = json.loads((ev / "poselib.json").read_text())
    runs = {}
    for row, seed in PLAN:
        path = ev / "runs" / f"{run_name(row, seed)}.json"
        if path.exists():
            runs.setdefault(row, {})[seed] = json.loads(path.read_text())
    refs = {p.stem: json.loads(p.read_text())
            for p in sorted((ev / "reference").glob("*.json"))}
    names = list(sets)
    recipe = "" if args.recipe == "paper" else f" --recipe {args.recipe}"
    title = ("Table 3 on real photographs" if args.recipe == "real"
             else "The ablation (Table 3) in our implementation")
    lines = [f"# {title}", "", "```", banner(), "```", "",
             f"`python benchmarks/ablation.py{recipe} report` (from `{_rel(ev)}`, written by "
             f"`ablation.py{recipe} train --eval`); "
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
        for ref, errs in refs.items():
            lines.append(f"| {_ref_label(ref)} (reference) | " + " | ".join(
                _cell([errs[n]], which) for n in names) + " |")
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
    for ref, errs in refs.items():
        lines.append(f"| {_ref_label(ref)} (reference) | " + " | ".join(
            f"{100 * ae.auc20(ae._rows(errs[n])[2]):.1f}" for n in names) + " |")
    lines.append("| PoseLib | " + " | ".join(
        f"{100 * ae.auc20(ae._rows(poselib[n])[2]):.1f}" for n in names) + " |")
    lines.append("")
    lines += ["## Paired comparisons (seed 0): median ratio a / b [95 % paired bootstrap]", "",
              "| a vs b | error | " + " | ".join(names) + " |",
              "|---|---" + "|---" * len(names) + "|"]
    pairs = [(a, b, runs.get(a, {}).get(0), runs.get(b, {}).get(0))
             for a, b in COMPARISONS]
    pairs += [("full", _ref_label(ref), runs.get("full", {}).get(0), errs)
              for ref, errs in refs.items()]
    for a, b, ea, eb in pairs:
        if ea is not None and eb is not None:
            for which, label in ((0, "rot"), (1, "trans")):
                cells = []
                for n in names:
                    r, lo, hi, k = ae.paired_ratio(ea[n], eb[n], which)
                    cells.append(f"{r:.2f} [{lo:.2f}-{hi:.2f}]" if k else "-")
                lines.append(f"| {a} vs {b} | {label} | " + " | ".join(cells) + " |")
    multi = [(a, b) for a, b in COMPARISONS
             if a in runs and b in runs and max(len(runs[a]), len(runs[b])) > 1]
    if multi:
        lines += ["", "## Paired comparisons over the seeds: mean of the seeds' medians, a / b "
                  "[95 % bootstrap over pairs and seeds]", "",
                  "Each resample draws the pairs (the same for both rows) and, for each row, "
                  "its seeds with replacement: an interval that excludes 1 is a difference "
                  "beyond the pairs' noise and the spread between training seeds "
                  "(`strl_pyg.metrics.seeded_median_ratio_interval`).", "",
                  "| a vs b (seeds) | error | " + " | ".join(names) + " |",
                  "|---|---" + "|---" * len(names) + "|"]
        for a, b in multi:
            sa, sb = sorted(runs[a]), sorted(runs[b])
            for which, label in ((0, "rot"), (1, "trans")):
                cells = []
                for n in names:
                    r, lo, hi, k = ae.seeded_paired_ratio(
                        [runs[a][s][n] for s in sa], [runs[b][s][n] for s in sb], which)
                    cells.append(f"{r:.2f} [{lo:.2f}-{hi:.2f}]" if k else "-")
                lines.append(f"| {a} vs {b} ({len(sa)} / {len(sb)}) | {label} | "
                             + " | ".join(cells) + " |")
    notes = ev / "notes.md"  # what the runs say, written by hand: kept above the tables
    if notes.is_file():
        lines[1:1] = ["", notes.read_text().rstrip()]
    out = Path(args.out)
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    plot_curves(_histories(ev), Path(args.figure), _recipe_title(args.recipe))
    print(f"wrote {args.figure}")
    medians = medians_figure(Path(args.figure))
    plot_medians(runs, {**{_ref_label(r).replace("`", ""): e for r, e in refs.items()},
                        "PoseLib": poselib},
                 names, medians, f"{title}: median errors on the evaluation sets")
    print(f"wrote {medians}")
    return 0


def _ref_label(ref: str) -> str:
    """A reference row's name: ``shipped `geometric``` for a shipped checkpoint, the file's
    stem for other weights."""
    from strl_pyg.model.strl_pose import StrLPose

    return f"shipped `{ref}`" if ref in StrLPose.PRETRAINED else f"`{ref}.pt`"


def _recipe_title(recipe: str) -> str:
    if recipe == "real":
        return ("Table 3 rows on real photographs (real_scenes train + generated, 1200 steps); "
                "validation: the 4 held-out scenes")
    return "Ablation rows on the shared budget (lines_small, front-end matches)"


def medians_figure(curves: Path) -> Path:
    """The medians figure beside the curves figure (``curves.png`` -> ``medians.png``)."""
    stem = (curves.stem.replace("curves", "medians") if "curves" in curves.stem
            else curves.stem + "_medians")
    return curves.with_name(stem + curves.suffix)


def plot_medians(runs: dict, refs: dict, names: list[str], path: Path, title: str) -> None:
    """Per evaluation set, each row's median rotation and translation error: seed 0 with its
    bootstrap interval over pairs, the other seeds as open markers; the reference rows
    (shipped weights, PoseLib) as black / grey marks."""
    import matplotlib

    matplotlib.use("Agg")
    import ablation_eval as ae
    import matplotlib.pyplot as plt
    import numpy as np

    rows = [r for r in ROWS if r in runs]
    fig, axes = plt.subplots(2, 1, figsize=(max(8, 1.2 * len(names)), 7.5), sharex=True)
    width = 0.8 / max(1, len(rows) + len(refs))
    colours = plt.get_cmap("tab10")
    x = np.arange(len(names))
    for which, ax in enumerate(axes):
        for k, row in enumerate(rows):
            seeds = sorted(runs[row])
            pos = x + (k - (len(rows) + len(refs) - 1) / 2) * width
            m = np.array([ae.median_interval(ae._rows(runs[row][seeds[0]][n])[which])
                          for n in names])
            ax.errorbar(pos, m[:, 0], yerr=[m[:, 0] - m[:, 1], m[:, 2] - m[:, 0]], fmt="o",
                        color=colours(k), capsize=2, markersize=4,
                        label=f"{row} (seed {seeds[0]}, 95 % interval)")
            for s in seeds[1:]:
                ax.plot(pos, [ae.median_interval(ae._rows(runs[row][s][n])[which])[0]
                              for n in names], "o", mfc="none", color=colours(k), markersize=4,
                        label=f"{row} (other seeds)" if s == seeds[1] else None)
        for j, (ref, errs) in enumerate(refs.items()):
            pos = x + (len(rows) + j - (len(rows) + len(refs) - 1) / 2) * width
            ax.plot(pos, [ae.median_interval(ae._rows(errs[n])[which])[0] for n in names],
                    "s" if ref == "PoseLib" else "D", color="black" if ref == "PoseLib"
                    else "dimgrey", markersize=4, label=ref)
        ax.set_yscale("log")
        ax.set_ylabel(("rotation", "translation direction")[which] + " error (deg, median)")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7, ncol=2)
    axes[1].set_xticks(x, names, rotation=20, ha="right")
    axes[1].set_xlabel("evaluation set")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _rel(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(Path(__file__).resolve().parents[1]))
    except ValueError:
        return str(path)


def _histories(results: Path, root: Path | None = None) -> dict[str, list[dict]]:
    """Validation history per run: the committed ``history/<run>.json`` files, updated from
    the live checkpoints under ``root`` where those are further along."""
    import json

    import torch

    out = {}
    for row, seed in PLAN:
        name = run_name(row, seed)
        path = results / "history" / f"{name}.json"
        if path.exists():
            out[name] = json.loads(path.read_text())["history"]
        ckpt = None if root is None else root / "runs" / name / "last.pt"
        if ckpt is not None and ckpt.exists():
            hist = torch.load(ckpt, map_location="cpu", weights_only=True).get("history", [])
            if len(hist) > len(out.get(name, [])):
                out[name] = hist
    return out


def cmd_curves(args: argparse.Namespace) -> int:
    """The validation history of every run so far (finished or not) as a markdown table, and
    the curves figure: what a partial study can already say (are the curves still falling?)."""
    from strl_bench_common import banner

    hists = _histories(Path(args.results), Path(args.root))
    lines = ["# Ablation runs so far: validation curves", "", "```", banner(), "```", "",
             "`python benchmarks/ablation.py curves`: mean validation rotation / translation-"
             "direction error (deg) of each run's checkpoints on the 100 held-out pairs of the "
             "training mix; trivial: the errors of always predicting the mean training pose. "
             f"From `{_rel(Path(args.results))}/history` and any live runs; runs of the plan "
             "that have not started are not listed.", "",
             "| run | step | val rot | val trans | AUC@10 | trivial rot / trans |",
             "|---|---|---|---|---|---|"]
    for name, hist in hists.items():
        for h in hist:
            lines.append(f"| {name} | {h['step']} | {h['rot_err_deg']:.2f} | "
                         f"{h['trans_err_deg']:.2f} | {h.get('auc10', float('nan')):.3f} | "
                         f"{h.get('trivial_rot_err_deg', float('nan')):.2f} / "
                         f"{h.get('trivial_trans_err_deg', float('nan')):.2f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    plot_curves(hists, Path(args.figure), _recipe_title(args.recipe))
    print(f"wrote {args.figure}")
    return 0


def plot_curves(hists: dict[str, list[dict]], path: Path,
                title: str = "Ablation rows on the shared budget (lines_small, front-end "
                             "matches)") -> None:
    """Validation rotation / translation errors of the key rows over the steps (seed 0 solid,
    other seeds faint in the same colour)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    colours = dict(zip(("baseline", "L", "LP", "V", "full"),
                       ("tab:grey", "tab:orange", "tab:green", "tab:blue", "tab:red"),
                       strict=True))
    for row, colour in colours.items():
        for seed in (0, 1, 2):
            hist = hists.get(run_name(row, seed), [])
            if not hist:  # not started, or not yet validated
                continue
            for ax, key in zip(axes, ("rot_err_deg", "trans_err_deg"), strict=True):
                ax.plot([h["step"] for h in hist], [h[key] for h in hist],
                        "o-" if seed == 0 else "--", color=colour, alpha=1.0 if seed == 0 else 0.4,
                        label=row if seed == 0 else None, markersize=3)
    for ax, title in zip(axes, ("validation rotation error (deg, mean)",
                                "validation translation-direction error (deg, mean)"),
                         strict=True):
        ax.set_xlabel("training step (batch 16)")
        ax.set_ylabel("degrees")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(title="row (seed 0; dashed: seeds 1-2)")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _default_paths(args: argparse.Namespace) -> None:
    """The report's and the curves' files where the command line gives none: the paper
    recipe's Table 3 at the top of ``benchmarks/``, another recipe's under ``studies/``."""
    if args.command not in ("report", "curves"):
        return
    here = Path(__file__).resolve().parent
    if args.recipe == "real":  # Table 3's topic: under results_ablation/
        args.results = args.results or str(RESULTS)
        args.figure = args.figure or str(RESULTS / "curves.png")
        args.out = args.out or str(RESULTS / ("curves.md" if args.command == "curves"
                                              else "report.md"))
        return
    paper = args.recipe == "paper"
    top = here if paper else STUDIES
    args.results = args.results or str(RESULTS)
    args.figure = args.figure or str(
        top / "figures" / ("ablation_curves.png" if paper else f"ablation_{args.recipe}.png"))
    if args.out is None and args.command == "curves":
        args.out = str(Path(args.results) / "curves.md")
    elif args.out is None:
        args.out = str(top / ("results_ablation.md" if paper
                              else f"results_ablation_{args.recipe}.md"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default=ROOT_DEFAULT, help="cache and run folders")
    ap.add_argument("--recipe", choices=tuple(RECIPES), default="paper",
                    help="training recipe (RECIPES): 'paper' (the first Table 3), "
                         "'balanced' (its own plan and results folder) or 'real' (Table 3 on "
                         "real photographs: PLAN_REAL, REAL_ARGS)")
    sub = ap.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train (or resume) every run of the plan")
    t.add_argument("--only", nargs="*", choices=ROWS, help="only these rows")
    t.add_argument("--threads", type=int, default=1, help="torch threads per run")
    t.add_argument("--eval", action="store_true",
                   help="score each run as soon as it finishes (results into RESULTS)")
    k = sub.add_parser("cache", help="build the training match cache (and the evaluation sets)")
    k.add_argument("--workers", type=int, default=2, help="processes for the training cache")
    k.add_argument("--eval", action="store_true", help="also the evaluation sets")
    k.add_argument("--eval-only", action="store_true", help="only the evaluation sets")
    k.add_argument("--threads", type=int, default=1, help="torch threads")
    sub.add_parser("status", help="steps done per run")
    e = sub.add_parser("eval", help="score the finished runs and PoseLib on every set")
    e.add_argument("--threads", type=int, default=1, help="torch threads")
    e.add_argument("--quick", action="store_true", help="4 pairs per set (a smoke run)")
    e.add_argument("--min-steps", type=int, default=None,
                   help="score runs that reached this step (default: the recipe's STEPS)")
    e.add_argument("--reference", nargs="?", const="geometric", default=None,
                   metavar="NAME",
                   help="also score a shipped checkpoint (StrLPose.PRETRAINED name, default "
                        "'geometric') or a .pt file as a reference row, once "
                        "(reference/<NAME or stem>.json)")
    r = sub.add_parser("report", help="write the results table and the curves plot")
    r.add_argument("--results", default=None, help="the scored runs (default: RESULTS)")
    r.add_argument("--out", default=None,
                   help="default: results_ablation.md (another recipe: studies/"
                        "results_ablation_<recipe>.md)")
    r.add_argument("--figure", default=None,
                   help="default: figures/ablation_curves.png (another recipe: studies/"
                        "figures/ablation_<recipe>.png)")
    c = sub.add_parser("curves", help="validation curves of the runs so far (table + plot)")
    c.add_argument("--out", default=None, help="default: curves.md in RESULTS")
    c.add_argument("--figure", default=None, help="default: the report's")
    c.add_argument("--results", default=None, help="the committed histories (default: RESULTS)")
    args = ap.parse_args(argv)
    args.root = str(use_recipe(args.recipe, Path(args.root)))
    _default_paths(args)
    return {"train": cmd_train, "cache": cmd_cache, "status": cmd_status, "eval": cmd_eval,
            "report": cmd_report, "curves": cmd_curves}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
