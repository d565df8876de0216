"""benchmarks/studies/study_pose_recipe.py motion: validation errors grouped by the generator's
motion (where the validation mean of issue 30's study comes from)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import study_pose_recipe as spr

RESULT = {"motions": ["forward", "rotation", "forward", "orbit"],
          "errors": {"PoseLib": [[0.1, 2.0], [0.5, 100.0], None, [0.2, 4.0]],
                     "run": [[1.0, 10.0], [5.0, 170.0], [2.0, 20.0], [9.0, 60.0]]}}


def test_groups_by_motion_and_counts_a_missing_pose_as_90_deg():
    kinds, table = spr._by_motion(RESULT)
    assert kinds == ["forward", "orbit", "rotation"]
    n, mean, med, over90 = table["PoseLib"]["forward"]
    assert (n, mean, med, over90) == (2, 46.0, 46.0, 0.0)  # (2 + 90) / 2
    assert table["run"]["all"] == (4, 65.0, 40.0, 0.25)
    assert table["run"]["rotation"] == (1, 170.0, 170.0, 1.0)


def test_table_and_figure(tmp_path):
    text = spr.motion_table(RESULT)
    assert "| method | all | forward (2) | orbit (1) | rotation (1) |" in text
    assert "| run | 65.0 / 40.0 | 15.0 / 15.0 | 60.0 / 60.0 | 170.0 / 170.0 |" in text
    out = tmp_path / "m.png"
    spr.plot_by_motion(RESULT, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_schedule_variants_parse():
    assert spr.parse_run("fe:both-cos:2") == ("fe", "both-cos", 2)
    assert "--lr-schedule" in spr.VARIANTS["both-cos1e-3"]
    with pytest.raises(SystemExit, match="MATCHES:VARIANT"):
        spr.parse_run("fe:cosine")


def test_compare_pools_the_common_seeds_pairwise():
    def run(rows):
        return {"errors": {"driving": rows}}

    runs = {"t3-x-s0": run([[1.0, 2.0], [2.0, 4.0]]), "t3-x-s1": run([[1.0, 2.0], None]),
            "t3-y-s0": run([[2.0, 4.0], [4.0, 8.0]]), "t3-y-s1": run([[2.0, 4.0], [9.0, 9.0]]),
            "t3-y-s2": run([[5.0, 5.0], [5.0, 5.0]]), "t3-x-y-s0": run([[0.0, 0.0]] * 2)}
    assert sorted(spr.pooled_errors(runs, "t3-x")) == [0, 1]  # not t3-x-y
    text = spr.compare_table(runs, "t3-x", "t3-y")
    # seeds 0 and 1 (y's seed 2 has no partner); the pair without a pose is left out: 3 pairs,
    # every one exactly half
    assert "seeds 0, 1:" in text
    assert "| driving | 0.50 [0.50, 0.50], 3 | 0.50 [0.50, 0.50], 3 |" in text
    with pytest.raises(SystemExit, match="common seed"):
        spr.compare_table(runs, "t3-x", "t3-z")


def test_seeds_of_a_variant_share_a_bar():
    assert spr.split_seed("cos1e-3-s2") == ("cos1e-3", 2)
    assert spr.split_seed("PoseLib") == ("PoseLib", None)
    assert spr.split_seed("run-seed") == ("run-seed", None)


def test_parallax_oracle_finds_a_known_translation(tmp_path, monkeypatch, capsys):
    """`parallax RUN`: pixel matches of a known small motion (K with f = 500) give back the
    translation's axis; the JSON and the table name the motion."""
    import argparse
    import json
    from types import SimpleNamespace

    import numpy as np

    g = np.random.default_rng(0)
    X = (g.random((300, 2)) - 0.5) * 0.8
    rho = 1.0 / (2.0 + 4.0 * g.random(300))
    t = np.array([0.02, 0.005, 0.01])
    u = rho[:, None] * (t[:2] - X * t[2])  # x1 = (X + t) / z1, to first order
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    pix = lambda x: x * 500.0 + [320.0, 240.0]  # noqa: E731
    m = SimpleNamespace(points0=pix(X), points1=pix(X + u), K0=K, K1=K)
    T = np.eye(4)
    T[:3, 3] = t
    monkeypatch.setattr(spr, "validation_pairs", lambda run: [("lateral", m, T)])
    monkeypatch.setattr(spr, "RESULTS", tmp_path)
    assert spr.cmd_parallax(argparse.Namespace(run="runs/x")) == 0
    out = json.loads((tmp_path / "parallax_oracle.json").read_text())
    assert out["run"] == "x" and len(out["errors"]["lateral"]) == 1
    assert out["errors"]["lateral"][0] < 3.0
    assert "| lateral | 1 |" in capsys.readouterr().out


def test_curves_pool_the_seeds_of_a_variant(tmp_path):
    """One line per variant over the steps its seeds share (a run cut short does not break
    it), written as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    def run(steps, v):
        return {"history": [{"step": s, "trans_err_deg": v + s, "trans_err_med": v}
                            for s in steps]}

    runs = {"t3-x-s0": run([250, 500], 10.0), "t3-x-s1": run([250], 20.0),
            "gt-y-s0": run([250, 500], 5.0)}
    seen = {}
    real_savefig = plt.Figure.savefig

    def spy(fig, path, **kw):
        seen["lines"] = {ln.get_label(): (list(ln.get_xdata()), list(ln.get_ydata()))
                         for ln in fig.axes[0].get_lines()}
        return real_savefig(fig, path, **kw)

    plt.Figure.savefig = spy
    try:
        spr.plot(runs, tmp_path / "c.png")
    finally:
        plt.Figure.savefig = real_savefig
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    assert seen["lines"]["t3-x (2 seeds)"] == ([250], [265.0])  # mean of 260 and 270
    assert seen["lines"]["gt-y"] == ([250, 500], [255.0, 505.0])


def test_default_width_runs_are_named_apart_and_train_at_the_models_width(tmp_path,
                                                                         monkeypatch):
    import argparse

    from strl_pyg.model.config import StrLPoseConfig
    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    assert spr.run_id("fe", "both", 0) == "fe-both-s0"
    assert spr.run_id("fe", "both", 1, "LP", wide=True) == "fe-LP-both-w128-s1"
    assert spr.run_id("fe", "both", 2, "L", table3=True) == "t3-L-both-s2"
    seen = []

    def fake_run(cmd, **kw):
        seen.append(cmd)
        return argparse.Namespace(returncode=0)

    monkeypatch.setattr(spr.subprocess, "run", fake_run)
    args = argparse.Namespace(row="baseline", root=str(tmp_path), runs=["fe:both:1"],
                              steps=10, ablation_root=str(tmp_path), default_width=True,
                              table3=False)
    assert spr.cmd_train(args) == 0
    cmd = seen[0]
    assert cmd[cmd.index("--out") + 1].endswith("fe-both-w128-s1")
    ap = add_train_arguments(argparse.ArgumentParser())
    cfg = config_from_args(ap.parse_args(cmd[2:]), ap)  # after python and the script
    d = StrLPoseConfig()
    assert cfg.model_overrides == {"hidden": d.hidden, "layers": d.layers, "heads": d.heads,
                                   "inputs": "flow"}
    assert (cfg.steps, cfg.seed, cfg.lr, cfg.beta) == (10, 1, 3e-4, 0.5)  # the study's pins


def test_clip_reads_the_fixed_and_the_relative_threshold(tmp_path, capsys):
    import argparse
    import json

    for name, clip, rows in (
            ("fixed", 10.0, [(1, "grad_norm", 20.0), (1, "clipped", 1.0),
                             (2, "grad_norm", 5.0), (2, "clipped", 0.0)]),
            # the fixed clip of 100 would clip neither step: the logged threshold decides
            ("relative", 100.0, [(1, "grad_norm", 20.0), (1, "grad_clip", 30.0),
                                 (1, "clipped", 0.0), (2, "grad_norm", 5.0),
                                 (2, "grad_clip", 4.0), (2, "clipped", 1.0)])):
        run = tmp_path / name
        run.mkdir()
        (run / "config.json").write_text(json.dumps({"grad_clip": clip}))
        (run / "log.csv").write_text("step,split,key,value\n" + "".join(
            f"{s},train,{k},{v}\n" for s, k, v in rows) + "2,val,rot_err_deg,3.0\n")
    out = tmp_path / "clip.png"
    spr.cmd_clip(argparse.Namespace(runs=[str(tmp_path / "fixed"), str(tmp_path / "relative")],
                                    out=str(out)))
    text = capsys.readouterr().out
    assert "fixed: clipped on 50.0 % of 2 steps (by quarter 100 / 0 %)" in text
    assert "relative: clipped on 50.0 % of 2 steps (by quarter 0 / 100 %)" in text
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(SystemExit, match="expected a run folder with log.csv and config.json"):
        spr.cmd_clip(argparse.Namespace(runs=[str(tmp_path / "none")], out=str(out)))


def _t3_run(val_mean: float, rows: list, step: int = 2000) -> dict:
    hist = [{"step": step, "trans_err_deg": val_mean, "trans_err_med": val_mean / 2,
             "rot_err_deg": 5.0}]
    return {"step": step, "history": hist, "errors": {"driving": rows}}


def _t3_runs() -> dict:
    return {"t3-r-s0": _t3_run(30.0, [[1.0, 4.0], [1.0, 4.0]]),
            "t3-r-s1": _t3_run(40.0, [[3.0, 8.0], [3.0, 8.0]]),
            "t3-LP-r-s0": _t3_run(20.0, [[0.5, 8.0], [0.5, 8.0]]),
            "t3-LP-r-s1": _t3_run(20.0, [[3.0, 8.0], [3.0, 8.0]], step=8000),
            "t3-full-r-s1": _t3_run(10.0, [[3.0, 4.0], [3.0, 4.0]])}


def test_table3_rows_claims_and_figure(tmp_path):
    runs = _t3_runs()
    lines = spr.table3_rows(runs, ["r"])
    # the mean over seeds with the seeds' range; a row without runs (V) is left out; a set
    # the runs were not scored on is '-'
    assert lines[2].startswith("| baseline | `r` | 0, 1 | 2000 | 35.0 (30.0-40.0) | "
                               "17.5 (15.0-20.0) | 5.00 (5.00-5.00) | 2.00 (1.00-3.00) / "
                               "6.0 (4.0-8.0) | - | - |")
    assert [line.split(" | ")[0] for line in lines[2:]] == ["| baseline", "| LP", "| full"]
    assert "| LP | `r` | 0, 1 | 2000 / 8000 |" in lines[3]  # runs of other lengths show
    claims = spr.table3_claims(runs, "r")
    # LP against baseline pooled over seeds 0 and 1: rotation medians 1.75 against 2.0
    assert any(c.startswith("| LP / baseline | 0, 1 | 0.88 [") for c in claims)
    # full against baseline on their common seed 1 only; full / LP: seed 1
    assert any(c.startswith("| full / baseline | 1 | 1.00 [1.00, 1.00] | **0.50") for c in claims)
    assert any(c.startswith("| full / LP | 1 | 1.00 [1.00, 1.00] | **0.50") for c in claims)
    assert not any(c.startswith("| V /") for c in claims)
    out = tmp_path / "t3.png"
    spr.plot_table3(runs, ["r"], out)  # only "driving" scored: the other panels stay empty
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_table3_writes_the_tables_notes_and_figure(tmp_path, monkeypatch):
    monkeypatch.setattr(spr, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(spr, "HERE", tmp_path)
    (tmp_path / "results").mkdir()
    for name, run in _t3_runs().items():
        (tmp_path / "results" / f"{name}.json").write_text(json.dumps(run))
    (tmp_path / "results" / "notes_table3.md").write_text("Findings by hand.")
    out = tmp_path / "t3.md"
    assert spr.main(["table3", "r", "--out", str(out)]) == 0
    text = out.read_text()
    assert "**The paper's claims, recipe `r`**" in text
    assert "| LP / baseline | 0, 1 |" in text and text.rstrip().endswith("Findings by hand.")
    assert (tmp_path / "figures" / "table3_recipe.png").read_bytes()[:4] == b"\x89PNG"


def test_table3_needs_a_scored_baseline(tmp_path, monkeypatch):
    monkeypatch.setattr(spr, "RESULTS", tmp_path)
    with pytest.raises(SystemExit, match="scored baseline runs"):
        spr.main(["table3", "nothing", "--out", str(tmp_path / "t3.md")])


@pytest.mark.slow  # a training run: the slow tier
def test_gradient_shares_use_the_runs_own_loss(tmp_path, monkeypatch):
    """Before: the study built its loss without the run's beta (0.5 for every run, also the
    default recipe's beta 0.25 runs), so their gradient shares were another loss's."""
    import torch

    from strl_pyg.training import TrainConfig, train

    run = tmp_path / "run"
    train(TrainConfig(train_pairs=6, val_pairs=3, batch_size=4, steps=2, val_every=2,
                      num_points=32, num_lines=16, out_dir=str(run), tensorboard=False,
                      scene={"image_size": [96, 256], "max_points": 64, "max_lines": 32},
                      model_overrides={"hidden": 16, "layers": 1, "heads": 2,
                                       "patch_features": 1},
                      beta=0.1, rot_weight=3.0), progress=False)
    seen = []

    def term(loss_fn, out, T, which):
        seen.append((loss_fn.beta, loss_fn.rot_weight, which))
        return out.log_var.sum() * (2.0 if which == "rot" else 1.0)

    monkeypatch.setattr(spr, "_term", term)
    shares = spr.gradient_shares(run, batches=2)
    assert set(seen) == {(0.1, 3.0, "rot"), (0.1, 3.0, "trans")}
    # each share is the norm of its own term's gradient: the rotation's stand-in is twice
    # the translation's
    assert shares["grad_rot"] == pytest.approx(2 * shares["grad_trans"], rel=1e-5)
    assert torch.isfinite(torch.tensor(shares["log_var_rot"]))


def test_table3_runs_are_named_as_table3_reads_them(tmp_path, monkeypatch):
    """Before: train named every run fe-..., and the Table 3 runs were linked by hand as
    t3-... for table3 to read them."""
    import argparse

    seen = []
    monkeypatch.setattr(spr.subprocess, "run",
                        lambda cmd, **kw: seen.append(cmd) or argparse.Namespace(returncode=0))
    args = argparse.Namespace(row="L", root=str(tmp_path), runs=["fe:both:0"], steps=2000,
                              ablation_root=str(tmp_path), default_width=False, table3=True)
    assert spr.cmd_train(args) == 0
    out = seen[0][seen[0].index("--out") + 1]
    assert Path(out).name == "t3-L-both-s0"
    assert spr.split_seed(Path(out).name) == (spr.t3_name("L", "both"), 0)
    args.runs = ["gt:both:0"]
    with pytest.raises(SystemExit, match="front-end matches"):
        spr.cmd_train(args)


def test_add_sets_scores_only_the_sets_a_record_lacks(tmp_path, capsys):
    """score --add-sets (KITTI 06 (i, i+3) came after most runs were scored): the sets a
    record has are kept, the others scored and added; PoseLib's file the same, whole."""
    path = tmp_path / "run.json"
    path.write_text(json.dumps({"run": "r", "errors": {"driving": [[1.0, 2.0]]}}))
    calls = []

    def errors(sets):
        calls.append(sorted(sets))
        return {k: [[9.0, 9.0]] for k in sets}

    sets = {"driving": ["p"], "kitti06_3": ["q"]}
    spr._add_sets(path, sets, errors, key="errors")
    spr._add_sets(path, sets, errors, key="errors")  # nothing left to add: not called
    assert calls == [["kitti06_3"]]
    assert json.loads(path.read_text()) == {
        "run": "r", "errors": {"driving": [[1.0, 2.0]], "kitti06_3": [[9.0, 9.0]]}}
    poselib = tmp_path / "poselib.json"
    spr._add_sets(poselib, sets, errors)
    assert json.loads(poselib.read_text()) == {k: [[9.0, 9.0]] for k in sets}
    assert "kitti06_3" in capsys.readouterr().out
    assert "kitti06_3" in spr.EVAL_SETS


def test_report_header_names_every_scored_set(tmp_path, monkeypatch):
    """Before: the report's header was written by hand for three sets, so a fourth
    (KITTI 06 (i, i+3)) shifted every column after KITTI 06 under the wrong title."""
    monkeypatch.setattr(spr, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(spr, "HERE", tmp_path)
    (tmp_path / "results").mkdir()
    for name, run in _t3_runs().items():
        run = {**run, "grad_rot": 1.0, "grad_trans": 2.0, "clipped_share": 0.5,
               "log_var_rot": -8.0, "log_var_trans": -2.0,
               "errors": {**run["errors"], "kitti06_3": [[0.5, 1.0], [0.7, 2.0]]}}
        (tmp_path / "results" / f"{name}.json").write_text(json.dumps(run))
    (tmp_path / "results" / "poselib.json").write_text(json.dumps({"driving": [[0.1, 1.0]]}))
    out = tmp_path / "report.md"
    assert spr.main(["report", "--out", str(out)]) == 0
    table = [ln for ln in out.read_text().splitlines() if ln.startswith("| ")]
    head = [c.strip() for c in table[0].strip("|").split("|")]
    assert head[4:8] == ["driving rot / trans", "KITTI 06 (i, i+1) rot / trans",
                         "KITTI 06 (i, i+3) rot / trans", "dino rot / trans"]
    assert {ln.count("|") for ln in table} == {table[0].count("|")}
    row = [c.strip() for c in table[1].strip("|").split("|")]
    assert row[head.index("KITTI 06 (i, i+3) rot / trans")] == "0.60 / 1.5"


def test_checkpoints_scores_weights_on_the_study_sets(tmp_path, monkeypatch, capsys):
    """checkpoints: any weights beside PoseLib on the study's pairs; a bad file is one line."""
    import ablation_eval as ae

    from strl_pyg.model import StrLPose, StrLPoseConfig

    monkeypatch.setattr(spr, "RESULTS", tmp_path)
    (tmp_path / "poselib.json").write_text(json.dumps({"kitti06_3": [[0.1, 1.0], [0.3, 2.0]]}))
    monkeypatch.setattr(spr, "eval_sets", lambda root: {"kitti06_3": ["p", "q"]})
    monkeypatch.setattr(ae, "model_errors",
                        lambda model, sets: {k: [[1.0, 10.0], None, [3.0, 30.0]] for k in sets})
    weights = tmp_path / "w.pt"
    StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2)).save(weights)
    assert spr.main(["checkpoints", str(weights)]) == 0
    out = capsys.readouterr().out
    assert "| weights | KITTI 06 (i, i+3) rot / trans |" in out
    assert "| PoseLib (same matches) | 0.20 / 1.5 |" in out
    assert f"| {weights} | 2.00 / 20.0 |" in out  # a pair without a pose is left out
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(SystemExit, match="^error: "):
        spr.main(["checkpoints", str(tmp_path / "bad.pt")])
