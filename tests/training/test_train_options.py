"""One source per training option: a TrainConfig field declared with ``option`` is its flag
(name, type, default, help, choices) and its entry in config.json; a new option is one field."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass, fields

import pytest

from strl_pyg.training.commandline import FLAG_FIELDS, config_from_args
from strl_pyg.training.config import TrainConfig, add_train_arguments
from strl_pyg.training.options import flag_dest, option, option_fields


@dataclass
class KnobConfig(TrainConfig):
    """TrainConfig and one new option, declared once."""

    knob_strength: float = option(0.5, "how hard the new knob turns")


def test_a_new_option_is_one_field(tmp_path):
    ap = add_train_arguments(argparse.ArgumentParser(), KnobConfig)
    text = ap.format_help()
    assert "--knob-strength" in text and "how hard the new knob turns" in text
    args = ap.parse_args(["--knob-strength", "0.75", "--out", str(tmp_path / "run")])
    cfg = config_from_args(args, ap, KnobConfig)
    assert cfg.knob_strength == 0.75 and cfg.out_dir == str(tmp_path / "run")
    assert config_from_args(ap.parse_args([]), ap, KnobConfig).knob_strength == 0.5
    # config.json is written from asdict(cfg) (strl_pyg.training.loop._logger)
    from strl_pyg.training.loop import _logger

    _logger(cfg, tmp_path / "run", 0, 0, [], [])
    assert json.loads((tmp_path / "run" / "config.json").read_text())["knob_strength"] == 0.75


def test_every_setting_but_in_memory_has_a_flag_with_help():
    names = {f.name for f in option_fields(TrainConfig)}
    assert names == {f.name for f in fields(TrainConfig)} - {"in_memory"}
    ap = add_train_arguments(argparse.ArgumentParser())
    helps = {a.dest: a.help for a in ap._actions}
    for f in option_fields(TrainConfig):
        assert helps[flag_dest(f)], f.name
    assert FLAG_FIELDS["out"] == "out_dir" and FLAG_FIELDS["set"] == "model_overrides"


def test_defaults_kinds_and_bad_values():
    ap = add_train_arguments(argparse.ArgumentParser())
    assert asdict(config_from_args(ap.parse_args([]), ap)) == asdict(TrainConfig())
    cfg = config_from_args(ap.parse_args(
        ["--posed-gaps", "1, 4", "--set", "hidden=64", "--set", "visual=null",
         "--grad-clip", "0", "--no-tensorboard", "--train-scenes", "a,b", "--workers", "2"]),
        ap)
    assert cfg.posed_gaps == [1, 4] and cfg.model_overrides == {"hidden": 64, "visual": None}
    assert cfg.grad_clip is None and cfg.tensorboard is False
    assert cfg.train_scenes == ["a", "b"] and cfg.num_workers == 2
    with pytest.raises(SystemExit):  # ap.error: one line
        config_from_args(ap.parse_args(["--posed-gaps", "1,x"]), ap)
    with pytest.raises(SystemExit):
        config_from_args(ap.parse_args(["--set", "hidden"]), ap)
