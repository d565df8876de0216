"""The ablation study's plumbing (benchmarks/ablation.py): every row of Table 3 trains and
infers on one shared front-end cache, a second run does not recompute it, rows of other seeds
train on the same pairs in the same order, and the plan is what the study promises."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
import torch

from strl_pyg.datasets import synthetic as synthetic_ds
from strl_pyg.inference.network import network_pose
from strl_pyg.model import ABLATIONS
from strl_pyg.synthetic import generate_pair
from strl_pyg.synthetic.distributions import scene_distribution
from strl_pyg.training import TrainConfig, train
from strl_pyg.training.data import StepBatchSampler

REPO = Path(__file__).resolve().parents[2]


def _tiny(row: str, tmp_path: Path, **kw) -> TrainConfig:
    return TrainConfig(scene_mix="lines_small", matches="frontend",
                       cache_dir=str(tmp_path / "cache"), train_pairs=4, val_pairs=2, steps=2,
                       val_every=2, batch_size=2, num_points=32, num_lines=16, model=row,
                       model_overrides=dict(hidden=16, layers=1, heads=2), tensorboard=False,
                       out_dir=str(tmp_path / "runs" / row.replace("+", "p")), **kw)


@pytest.mark.slow
def test_every_row_trains_and_infers_on_one_shared_cache(tmp_path, monkeypatch):
    first = train(_tiny("full", tmp_path), progress=False)
    folders = list((tmp_path / "cache").iterdir())
    assert len(folders) == 1  # one fingerprint: the rows share the matches

    def no_matching(*args, **kwargs):
        raise AssertionError("the front end ran again: the cache was not reused")

    monkeypatch.setattr(synthetic_ds, "_match_synthetic", no_matching)
    pair = generate_pair(7, scene_distribution("lines_small").config(7))
    for row in ABLATIONS:
        res = first if row == "full" else train(_tiny(row, tmp_path), progress=False)
        assert res["step"] == 2 and torch.isfinite(torch.tensor(res["rot_err_deg"]))
        out = network_pose(res["model"], pair.matches, resample=(32, 16))
        assert out.quaternion.shape == (1, 4) and torch.isfinite(out.translation).all()
    assert list((tmp_path / "cache").iterdir()) == folders


def test_seeds_vary_the_initialisation_not_the_data():
    a = TrainConfig(seed=0, data_seed=0)
    b = TrainConfig(seed=2, data_seed=0)
    assert a.resolved_data_seed == b.resolved_data_seed == 0
    assert TrainConfig(seed=2).resolved_data_seed == 2  # without data_seed: as before
    s0 = StepBatchSampler(100, 16, 0, 10, a.resolved_data_seed)
    s1 = StepBatchSampler(100, 16, 0, 10, b.resolved_data_seed)
    assert [s0.global_batch(k) for k in range(10)] == [s1.global_batch(k) for k in range(10)]
    with pytest.raises(ValueError, match="data_seed"):
        TrainConfig(data_seed=-1)


def _ablation_module():
    sys.path.insert(0, str(REPO / "benchmarks"))
    spec = importlib.util.spec_from_file_location("ablation", REPO / "benchmarks" / "ablation.py")
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
    # the shipped checkpoint as a reference row, and full against it (every ratio 2)
    assert "| shipped `geometric` (reference) | 1.25 [" in text
    assert "| full vs shipped `geometric` | trans | 2.00 [2.00-2.00]" in text
    assert fig.stat().st_size > 0
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

    repo = Path(__file__).resolve().parents[2]
    if shutil.which("git") is None or not (repo / ".git").exists():
        pytest.skip("not a git checkout")
    for rel in ("runs/full-s0.json", "history/full-s0.json", "sets.json", "poselib.json"):
        path = f"benchmarks/results_ablation/{rel}"
        out = subprocess.run(["git", "check-ignore", "--no-index", "-v", path], cwd=repo,
                             capture_output=True, text=True)
        assert out.returncode == 1, f"{path} is git-ignored: {out.stdout.strip()}"
