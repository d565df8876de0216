"""benchmarks/ablation.py, the paper's Table 3 on one shared budget: the plan is what the
study promises, a run is claimed by one worker, the report and the curves read only the
committed results (which git does not ignore), another recipe's files go under studies/, and
the reference recipe stays pinned while the package's defaults move on. (The training
package's side, every row training on one shared cache and seeds that vary only the
initialisation, is tests/training/test_ablation.py.)"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

import pytest

from strl_pyg.model import ABLATIONS

BENCH = Path(__file__).resolve().parents[1]


def _ablation_module():
    """A fresh ``ablation`` module: ``use_recipe`` changes its globals."""
    spec = importlib.util.spec_from_file_location("ablation", BENCH / "ablation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_plan_covers_every_row_and_three_seeds_of_the_key_ones(tmp_path):
    ab = _ablation_module()
    assert {r for r, _ in ab.PLAN} == set(ABLATIONS)
    for row in ABLATIONS:
        seeds = sorted(s for r, s in ab.PLAN if r == row)
        assert seeds == ([0, 1, 2] if row in ("baseline", "LP", "V", "full") else [0])
    cmd = ab.train_command(tmp_path, "LP+V", 1)
    assert "--data-seed" in cmd and cmd[cmd.index("--data-seed") + 1] == "0"
    assert cmd[cmd.index("--model") + 1] == "LP+V" and "--resume" not in cmd
    run = tmp_path / "runs" / ab.run_name("LP+V", 1)
    run.mkdir(parents=True)
    (run / "last.pt").write_bytes(b"")
    assert "--resume" in ab.train_command(tmp_path, "LP+V", 1)


def test_a_run_is_claimed_by_one_live_worker_and_a_dead_workers_claim_is_taken_over(tmp_path):
    import os
    import subprocess

    ab = _ablation_module()
    run = tmp_path / "runs" / "full-s0"
    assert ab.claim(run)
    assert (run / "claim").read_text() == str(os.getpid())
    # a second worker (another live pid) holding the claim keeps it
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        (run / "claim").write_text(str(other.pid))
        assert not ab.claim(run)
        ab.release(run)  # not ours: left alone
        assert (run / "claim").read_text() == str(other.pid)
    finally:
        other.kill()
        other.wait()
    # the worker died (machine reset, kill -9): its claim is stale and is taken over
    assert ab.claim(run)
    ab.release(run)
    assert not (run / "claim").exists()


def test_scored_sets_must_match_the_committed_ones(tmp_path):
    _ablation_module()
    import ablation_eval as ae

    ids = {"point_poor": ["point_poor/2100001"], "kitti06": ["kitti06/0-1"]}
    ae.check_or_save_sets(tmp_path / "sets.json", ids)
    ae.check_or_save_sets(tmp_path / "sets.json", ids)  # same pairs: fine
    with pytest.raises(SystemExit, match=r"differ .* sets \['kitti06'\]"):
        ae.check_or_save_sets(tmp_path / "sets.json", {**ids, "kitti06": ["kitti06/1-2"]})


def test_report_and_curves_read_only_the_committed_results(tmp_path):
    """A later session on a fresh machine (no run folders) still writes Table 3 and the curves
    from the small committed files; a run scored as seed 0 and 1 shows the seeds' spread."""
    import json

    ab = _ablation_module()
    res = tmp_path / "results"
    (res / "runs").mkdir(parents=True)
    (res / "history").mkdir()
    sets = {"point_poor": ["a", "b", "c", "d"], "kitti06": ["e", "f", "g", "h"]}
    (res / "sets.json").write_text(json.dumps(sets))
    errs = lambda k: {n: [[k * (i + 1), 2 * k * (i + 1)] for i in range(4)] for n in sets}  # noqa: E731
    (res / "poselib.json").write_text(json.dumps({n: [[1, 1], None, [3, 3], [4, 4]] for n in sets}))
    (res / "runs" / "full-s0.json").write_text(json.dumps(errs(1.0)))
    (res / "runs" / "full-s1.json").write_text(json.dumps(errs(2.0)))
    (res / "runs" / "baseline-s0.json").write_text(json.dumps(errs(4.0)))
    (res / "reference").mkdir()
    (res / "reference" / "geometric.json").write_text(json.dumps(errs(0.5)))
    (res / "reference" / "my_weights.json").write_text(json.dumps(errs(0.25)))
    hist = [{"step": 250 * k, "rot_err_deg": 9.0 - k, "trans_err_deg": 80.0 - k} for k in (1, 2)]
    (res / "history" / "full-s0.json").write_text(json.dumps({"step": 500, "history": hist}))
    out, fig = tmp_path / "t3.md", tmp_path / "c.png"
    assert ab.main(["--root", str(tmp_path / "gone"), "report", "--results", str(res),
                    "--out", str(out), "--figure", str(fig)]) == 0
    text = out.read_text()
    # full: seed 0 median rotation 2.50 over [1, 2, 3, 4], seeds' medians 2.50 and 5.00
    assert "| full | 2.50 [" in text and "(seeds 2.50-5.00)" in text
    assert "| baseline | 10.00 [" in text
    # full vs baseline: every pair's ratio is 1/4
    assert "| full vs baseline | rot | 0.25 [0.25-0.25]" in text
    # over the seeds: full's seeds' medians 2.5 and 5 (mean 3.75) against baseline's 10; the
    # seeds resampled give 0.25 (seed 0 twice) to 0.50 (seed 1 twice)
    assert "## Paired comparisons over the seeds" in text
    assert "| full vs baseline (2 / 1) | rot | 0.38 [0.25-0.50]" in text
    # the shipped checkpoint as a reference row, and full against it (every ratio 2)
    assert "| shipped `geometric` (reference) | 1.25 [" in text
    assert "| full vs shipped `geometric` | trans | 2.00 [2.00-2.00]" in text
    # weights given as a .pt file: named by the file, not called shipped
    assert "| `my_weights.pt` (reference) | 0.62 [" in text
    assert "| full vs `my_weights.pt` | rot | 4.00 [4.00-4.00]" in text
    assert fig.stat().st_size > 0
    assert (tmp_path / "c_medians.png").stat().st_size > 0  # the medians beside the curves
    out2 = tmp_path / "curves.md"
    assert ab.main(["--root", str(tmp_path / "gone"), "curves", "--results", str(res),
                    "--out", str(out2), "--figure", str(fig)]) == 0
    assert "| full-s0 | 500 | 7.00 | 78.00 |" in out2.read_text()
    # the shipped checkpoint must be one the package ships
    with pytest.raises(SystemExit, match="expected a shipped checkpoint"):
        ab._Scorer(tmp_path, 1).score_reference("nope")
    # nothing scored: one line, exit 2
    assert ab.main(["report", "--results", str(tmp_path / "none"), "--out", str(out),
                    "--figure", str(fig)]) == 2


def test_the_results_that_must_outlive_the_machine_are_not_git_ignored():
    # the study's committed results (runs/<run>.json, history/, sets, PoseLib) were once
    # matched by the ignore pattern "runs/" and silently left out of every commit
    import shutil
    import subprocess

    repo = BENCH.parent
    if shutil.which("git") is None or not (repo / ".git").exists():
        pytest.skip("not a git checkout")
    for folder in ("benchmarks/results_ablation", "benchmarks/studies/results_ablation_balanced",
                   "benchmarks/results_ablation/real_photographs"):
        for rel in ("runs/full-s0.json", "history/full-s0.json", "sets.json", "poselib.json"):
            path = f"{folder}/{rel}"
            out = subprocess.run(["git", "check-ignore", "--no-index", "-v", path], cwd=repo,
                                 capture_output=True, text=True)
            assert out.returncode == 1, f"{path} is git-ignored: {out.stdout.strip()}"


def test_table3_and_the_study_pin_their_reference_recipe():
    """The package's defaults changed in 0.4; Table 3 (benchmarks/ablation.py) and the recipe
    study (benchmarks/studies/study_pose_recipe.py) keep the settings their committed runs
    trained with."""
    import study_pose_recipe as study

    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ablation = _ablation_module()
    ap = add_train_arguments(argparse.ArgumentParser())
    for args in (ablation.TRAIN_ARGS, study.COMMON + study.VARIANTS["both"]):
        cfg = config_from_args(ap.parse_args(args), ap)
        assert (cfg.lr, cfg.lr_schedule, cfg.warmup_steps, cfg.beta) == (3e-4, "constant", 0, 0.5)
    winner_args = study.COMMON + study.VARIANTS["both-cos1e-3-b0.25"]
    winner = config_from_args(ap.parse_args(winner_args), ap)
    assert (winner.lr, winner.lr_schedule, winner.warmup_steps, winner.beta) == (
        1e-3, "cosine", 100, 0.25)


def test_the_default_files_are_table_3s_at_the_top_and_another_recipes_under_studies(tmp_path):
    """Table 3 (the paper's recipe) is the topic's current file at the top of benchmarks/; the
    balanced recipe's Table 3 is a study: its report, figure and results are in studies/."""
    for recipe, results, report, figure in (
            ("paper", BENCH / "results_ablation", BENCH / "results_ablation.md",
             BENCH / "figures" / "ablation_curves.png"),
            ("balanced", BENCH / "studies" / "results_ablation_balanced",
             BENCH / "studies" / "results_ablation_balanced.md",
             BENCH / "studies" / "figures" / "ablation_balanced.png")):
        ab = _ablation_module()
        ab.use_recipe(recipe, tmp_path / recipe)
        for command in ("report", "curves"):
            args = argparse.Namespace(command=command, recipe=recipe, results=None, out=None,
                                      figure=None)
            ab._default_paths(args)
            assert args.results == str(results) and args.figure == str(figure)
            assert args.out == str(report if command == "report" else results / "curves.md")
        assert results.is_dir() and report.is_file() and figure.is_file()
    assert (BENCH / "results_ablation" / "curves.md").is_file()
    given = argparse.Namespace(command="report", recipe="paper", results="r", out="o",
                               figure="f")
    ab._default_paths(given)
    assert (given.results, given.out, given.figure) == ("r", "o", "f")


def test_table3_on_real_photographs_trains_posed_pairs_with_its_own_plan(tmp_path):
    """Recipe ``real``: baseline, LP and full x 3 seeds on the real_scenes training scenes mixed
    1:1 with generated pairs, at its own step budget, scored on the real sets, its results
    under results_ablation/ (Table 3's topic, not a new top-level file)."""
    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ab = _ablation_module()
    root = ab.use_recipe("real", tmp_path)
    assert root == tmp_path / "real" and (root / "cache").is_symlink()
    assert sorted(ab.PLAN[:9]) == sorted((r, s) for r in ("baseline", "LP", "full")
                                         for s in range(3))
    assert ab.PLAN[:3] == [("baseline", 0), ("LP", 0), ("full", 0)]
    assert ab.PLAN[9:] == [("L", 0), ("V", 0), ("L", 1), ("L", 2)]  # after the three rows
    assert ab.STEPS == ab.REAL_STEPS
    assert ab.RESULTS == BENCH / "results_ablation" / "real_photographs"
    ap = add_train_arguments(argparse.ArgumentParser())
    cfg = config_from_args(ap.parse_args([*ab.TRAIN_ARGS, "--model", "LP"]), ap)
    assert (cfg.dataset, cfg.synthetic_share, cfg.steps, cfg.loss) == (
        "posed", 0.5, ab.REAL_STEPS, "balanced")
    assert cfg.model_config().use_lines and cfg.train_scenes is None  # the fixed split
    cmd = ab.train_command(root, "full", 1)
    assert cmd[cmd.index("--model") + 1] == "full" and cmd[cmd.index("--seed") + 1] == "1"
    args = argparse.Namespace(command="report", recipe="real", results=None, out=None,
                              figure=None)
    ab._default_paths(args)
    assert args.out == str(ab.RESULTS / "report.md") and args.results == str(ab.RESULTS)
    import bench_real_scenes

    assert ab.EVAL_SETS is bench_real_scenes.pair_sets
