"""Training on posed photographs (``dataset="posed"``) mixed with generated pairs: the
flags, what config.json records, the best checkpoint kept by validation, the wall-clock
budget, fine-tuning the shipped weights, and the summary line of an interrupted run."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, replace

import cv2
import numpy as np
import pytest

from strl_pyg.synthetic import SceneConfig
from strl_pyg.training.config import TrainConfig
from strl_pyg.training.data import build_datasets, posed_scenes
from strl_pyg.training.loop import best_value, train


@pytest.fixture(scope="module")
def posed_root(tmp_path_factory, generated_pair):
    """Three scenes in the real_scenes format, each two generated views of a street."""
    root = tmp_path_factory.mktemp("posed")
    for k, name in enumerate(("a", "b", "c")):
        p = generated_pair(40 + k, SceneConfig(kind="street", image_size=(96, 256)))
        d = root / name
        (d / "images").mkdir(parents=True)
        T1 = np.linalg.inv(np.asarray(p.T_0to1, dtype=np.float64))  # camera 1 to camera 0
        ims = []
        for i, (img, T) in enumerate(((p.image0, np.eye(4)), (p.image1, T1))):
            colour = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img
            cv2.imwrite(str(d / "images" / f"{i}.png"), colour)  # photographs are in colour
            ims.append({"file": f"images/{i}.png", "K": np.asarray(p.K).tolist(),
                        "T_cam_to_world": T.tolist(), "width": 256, "height": 96})
        (d / "cameras.json").write_text(json.dumps({"images": ims}))
    return root


def posed_config(root, out_dir, **kw) -> TrainConfig:
    base = TrainConfig(
        dataset="posed", data_root=str(root), cache_dir=str(out_dir / "cache"),
        train_scenes=["a", "b"], val_scenes=["c"], posed_gaps=[1], val_gap=1, val_stride=1,
        batch_size=2, steps=2, val_every=1, num_points=32, num_lines=16,
        out_dir=str(out_dir / "run"), tensorboard=False, seed=1,
        scene={"image_size": [96, 256], "max_points": 64, "max_lines": 32},
        model_overrides={"hidden": 16, "layers": 1, "heads": 2, "patch_features": 1},
        lr=1e-4, lr_schedule="constant")
    return replace(base, **kw)


@pytest.mark.slow
def test_posed_and_generated_pairs_train_together(posed_root, tmp_path):
    cfg = posed_config(posed_root, tmp_path, synthetic_share=0.5)
    train_ds, val_ds = build_datasets(cfg, progress=False)
    assert len(train_ds) == 4 and len(val_ds) == 1  # 2 photograph pairs + 2 generated
    assert val_ds.subsets() == ["c"]
    result = train(cfg, progress=False)
    run = tmp_path / "run"
    stored = json.loads((run / "config.json").read_text())
    assert stored["dataset"] == "posed" and stored["synthetic_share"] == 0.5
    assert stored["train_scenes"] == ["a", "b"] and stored["val_scenes"] == ["c"]
    # what the run loaded, per source, and the settings it did not read: a posed run's
    # config.json recorded train_pairs 2048 and the generator's scene kinds as if they applied
    assert stored["data"] == {"training": {"a": 1, "b": 1, "generated": 2},
                              "validation": {"c": 1}}
    assert "train_pairs" in stored["ignored"] and "kitti_k" in stored["ignored"]
    assert "scene_kinds" not in stored["ignored"]  # the generated share reads it
    # the descriptive keys are left out (warmup_steps is stored resolved)
    assert TrainConfig.from_dict(stored) == replace(cfg, warmup_steps=cfg.warmup)
    assert (run / "best_model.pt").is_file() and len(result["history"]) == 2
    assert all("pose_err_med" in h for h in result["history"])


@pytest.mark.slow
def test_generated_pairs_can_be_cycled_to_the_share(posed_root, tmp_path):
    cfg = posed_config(posed_root, tmp_path, synthetic_share=0.75, synthetic_pairs=2)
    train_ds, _ = build_datasets(cfg, progress=False)
    assert len(train_ds) == 2 + 6  # 6 generated items for the 3:1 share, 2 distinct
    a, b = train_ds[2], train_ds[4]
    assert np.array_equal(a["point"]["pos0"].numpy(), b["point"]["pos0"].numpy())


@pytest.mark.slow
def test_the_budget_stops_a_run_with_its_checkpoint(posed_root, tmp_path):
    cfg = posed_config(posed_root, tmp_path, steps=50, val_every=25, budget_minutes=1e-9)
    result = train(cfg, progress=False)
    assert result["step"] == 1 and result["budget_reached"]
    assert (tmp_path / "run" / "last.pt").is_file() and len(result["history"]) == 1
    with pytest.raises(ValueError, match="Expected budget_minutes > 0"):
        replace(cfg, budget_minutes=0.0)


def test_scenes_without_pairs_are_named_with_the_rules(posed_root, tmp_path):
    """A scene whose pairs the options all drop (a COLMAP model without point tracks did)
    was reported as 'pairs the front end can match (got none of 0)'."""
    cfg = posed_config(posed_root, tmp_path, posed_max_rotation=1e-6)
    with pytest.warns(UserWarning, match="Expected pairs from scene 'a'"), \
            pytest.raises(ValueError, match=r"Expected training pairs from the scenes \(got "
                                            r"none: a: 0 pairs of 2 images, b: 0 pairs of 2 "
                                            r"images; the pair options keep pairs"):
        build_datasets(cfg, progress=False)


def test_posed_settings_on_the_command_line():
    import argparse

    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ap = add_train_arguments(argparse.ArgumentParser())
    args = ap.parse_args(["--dataset", "posed", "--data-root", "x", "--posed-min-covisible", "0"])
    cfg = config_from_args(args, ap)
    assert cfg.posed_min_covisible == 0.0
    # what each dataset reads (strl_pyg.training.data): the rest is listed as ignored
    posed = TrainConfig(dataset="posed", data_root="x")
    assert {"train_pairs", "val_pairs", "matches", "scene_kinds", "kitti_k"} \
        <= set(posed.ignored_fields())
    mixed = replace(posed, synthetic_share=0.5)
    assert "matches" in mixed.ignored_fields()  # the generated share: generator's matches
    assert not {"scene", "scene_kinds", "synthetic_pairs"} & set(mixed.ignored_fields())
    assert {"scene", "scene_kinds"} <= set(replace(mixed, scene_mix="lines_small").ignored_fields())
    generated = TrainConfig()
    assert {"posed_gaps", "data_root", "limit"} <= set(generated.ignored_fields())
    assert not {"scene", "scene_kinds", "matches", "train_pairs"} & set(generated.ignored_fields())
    assert {"scene", "scene_kinds"} <= set(TrainConfig(scene_mix="lines_small").ignored_fields())
    kitti = TrainConfig(dataset="kitti", data_root="x")
    assert "kitti_k" not in kitti.ignored_fields() and "matches" in kitti.ignored_fields()
    assert "kitti_k" in TrainConfig(dataset="demon", data_root="x").ignored_fields()
    # a posed run stored with --matches frontend (then accepted and ignored) still resumes
    stored = {**asdict(posed), "matches": "frontend"}
    assert TrainConfig.from_dict(stored).matches == "ground_truth"
    with pytest.raises(ValueError, match="Expected posed_min_covisible in"):
        TrainConfig(posed_min_covisible=1.5)
    with pytest.raises(ValueError, match="Expected matches 'ground_truth' with dataset 'posed'"):
        TrainConfig(dataset="posed", data_root="x", matches="frontend")


def test_best_value_reads_the_history():
    hist = [{"step": 1, "pose_err_med": 9.0}, {"step": 2, "pose_err_med": math.nan},
            {"step": 3, "pose_err_med": 4.0}, {"step": 4}]
    assert best_value(hist, "pose_err_med") == 4.0
    assert best_value([], "pose_err_med") == math.inf
    with pytest.raises(ValueError, match="Expected best_metric in"):
        TrainConfig(best_metric="auc")


def test_scenes_must_exist_and_stay_apart(posed_root, tmp_path):
    with pytest.raises(ValueError, match="Expected training and validation scenes apart"):
        posed_scenes(posed_config(posed_root, tmp_path, val_scenes=["a"]))
    with pytest.raises(ValueError, match=r"Expected --val-scenes scenes under .* \(got zz"):
        posed_scenes(posed_config(posed_root, tmp_path, val_scenes=["zz"]))
    with pytest.raises(ValueError, match="Expected synthetic_share 0 unless dataset is"):
        TrainConfig(synthetic_share=0.5)


def test_the_real_scenes_split_is_the_default(shared_data, tmp_path):
    root = shared_data / "real_scenes"
    if not root.is_dir():
        pytest.skip("real_scenes not found")
    train_names, val_names = posed_scenes(TrainConfig(dataset="posed", data_root=str(root)))
    assert "fruit" in val_names and "fruit" not in train_names and len(train_names) == 11


def test_init_from_shipped_weights_takes_their_model():
    """Before: the shipped weights could not be continued with today's defaults (flow
    inputs, a bigger model): --init-from named 176 mis-shaped keys."""
    from strl_pyg.model.strl_pose import StrLPose

    shipped, _ = StrLPose.pretrained_header("synthetic")
    cfg = TrainConfig(init_from="shipped:synthetic")
    assert cfg.model_config() == shipped and cfg.model_config().inputs == "paper"
    tuned = TrainConfig(init_from="shipped:synthetic", model_overrides={"dropout": 0.1})
    assert tuned.model_config().dropout == 0.1 and tuned.model_config().hidden == shipped.hidden
    with pytest.raises(ValueError, match="Expected a pretrained name"):
        TrainConfig(init_from="shipped:nope").model_config()


def test_an_interrupted_run_prints_no_summary_line(monkeypatch, tmp_path, capsys):
    """Before: a stray '{"step": 32}' line on stdout after Ctrl-C."""
    import argparse

    from strl_pyg.training import commandline
    from strl_pyg.training.config import add_train_arguments

    def interrupted(cfg, **kw):
        return {"step": 32, "history": [], "interrupted": "SIGINT"}

    monkeypatch.setattr(commandline, "train", interrupted)
    ap = add_train_arguments(argparse.ArgumentParser())
    args = ap.parse_args(["--out", str(tmp_path / "run"), "--no-tensorboard"])
    assert commandline.run_from_args(args, ap, []) == 130
    out, err = capsys.readouterr()
    assert out == "" and "stopped by SIGINT at step 32" in err
    monkeypatch.setattr(commandline, "train", lambda cfg, **kw: {"step": 4, "history": []})
    assert commandline.run_from_args(args, ap, []) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1]) == {"step": 4}


def test_posed_min_points_is_a_flag_recorded_in_the_config():
    import argparse

    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ap = argparse.ArgumentParser()
    add_train_arguments(ap)
    cfg = config_from_args(ap.parse_args(["--posed-min-points", "40"]), ap)
    assert cfg.posed_min_points == 40 and TrainConfig().posed_min_points == 0
    with pytest.raises(ValueError, match="Expected posed_min_points as an integer >= 0"):
        TrainConfig(posed_min_points=-1)


@pytest.mark.slow
def test_posed_min_points_leaves_out_training_pairs_with_few_matches(posed_root, tmp_path):
    cfg = posed_config(posed_root, tmp_path)
    train_ds, val_ds = build_datasets(cfg, progress=False)
    counts = sorted(train_ds.load_matches(i).num_points for i in range(len(train_ds)))
    assert len(counts) == 2
    cut = replace(cfg, posed_min_points=counts[1])  # the pair with fewer matches goes
    with pytest.warns(UserWarning, match=f"fewer than min_points={counts[1]}"):
        train_ds, val_ds = build_datasets(cut, progress=False)
    assert len(train_ds) == 1 and train_ds.load_matches(0).num_points == counts[1]
    assert len(val_ds) == 1  # validation keeps every pair
    with pytest.raises(ValueError, match=r"with >= 100000 point matches \(got none of 2"):
        build_datasets(replace(cfg, posed_min_points=100_000), progress=False)


@pytest.mark.slow
def test_photographs_and_generated_pairs_collate_for_a_model_without_pixels(posed_root, tmp_path):
    """Before: with ``--model baseline`` (no visual branch) the photographs' graphs carried
    RGB patches and the generated ones grey patches, and the first mixed batch failed in
    torch.cat with a traceback."""
    from strl_pyg.training.data import collater

    cfg = posed_config(posed_root, tmp_path, synthetic_share=0.5, model="baseline")
    train_ds, _ = build_datasets(cfg, progress=False)
    batch = collater(cfg.model_config())([train_ds[i] for i in range(len(train_ds))])
    assert batch.num_graphs == len(train_ds) == 4


@pytest.mark.slow
def test_posed_stride_thins_every_scene(posed_root, tmp_path, monkeypatch):
    """Training pairs could only be thinned by --limit, which keeps the first scenes' pairs;
    --posed-stride takes every N-th first image in every scene."""
    import argparse

    from strl_pyg.datasets import posed as posed_mod
    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ap = argparse.ArgumentParser()
    add_train_arguments(ap)
    args = ap.parse_args(["--dataset", "posed", "--data-root", str(posed_root),
                          "--posed-stride", "3"])
    assert config_from_args(args, ap).posed_stride == 3
    with pytest.raises(ValueError, match=r"Expected posed_stride as an integer >= 1 \(got 0"):
        TrainConfig(posed_stride=0)
    seen = []
    real = posed_mod.PosedImagePairs

    def spy(scenes, **kw):
        seen.append(kw["pairs"].stride)
        return real(scenes, **kw)

    monkeypatch.setattr(posed_mod, "PosedImagePairs", spy)
    build_datasets(posed_config(posed_root, tmp_path, posed_stride=3), progress=False)
    assert seen[0] == 3  # the training pairs; validation keeps its own --val-stride


def test_matcher_reaches_the_photographs_front_end(posed_root, tmp_path, monkeypatch):
    """`--matcher` on `train`, as on `predict` and `match`: the posed datasets match with the
    preset (its settings are in the match caches' key); a name that is no preset is refused."""
    import argparse

    from strl_pyg.datasets import posed as posed_mod
    from strl_pyg.frontend import FrontendConfig
    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments
    from strl_pyg.training.data import frontend_of

    ap = argparse.ArgumentParser()
    add_train_arguments(ap)
    args = ap.parse_args(["--dataset", "posed", "--data-root", str(posed_root),
                          "--matcher", "thorough"])
    cfg = config_from_args(args, ap)
    assert cfg.matcher == "thorough" and frontend_of(cfg) == FrontendConfig.preset("thorough")
    assert frontend_of(TrainConfig()) is None
    assert "matcher" in TrainConfig(dataset="synthetic").ignored_fields()
    with pytest.raises(ValueError, match=r"Expected matcher in \('fast', 'thorough'"):
        TrainConfig(matcher="best")
    seen = []
    monkeypatch.setattr(posed_mod, "PosedImagePairs",
                        lambda scenes, **kw: seen.append(kw["frontend_config"]) or
                        (_ for _ in ()).throw(RuntimeError("stop")))
    with pytest.raises(RuntimeError, match="stop"):
        build_datasets(posed_config(posed_root, tmp_path, matcher="fast"), progress=False)
    assert seen == [FrontendConfig.preset("fast")]
