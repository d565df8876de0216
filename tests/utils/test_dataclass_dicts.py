"""Configs read from dicts (checkpoints, JSON) refuse unknown keys with one line."""

from __future__ import annotations

import pytest

from strl_pyg.model.config import StrLPoseConfig
from strl_pyg.training.config import TrainConfig


@pytest.mark.parametrize("cls", [StrLPoseConfig, TrainConfig])
def test_round_trip_and_unknown_keys(cls):
    cfg = cls()
    d = cfg.to_dict() if hasattr(cfg, "to_dict") else dict(vars(cfg))
    assert cls.from_dict(d) == cfg
    with pytest.raises(ValueError, match=rf"Expected {cls.__name__} fields \(got unknown keys "
                                         r"\['zz_unknown'\]\)"):
        cls.from_dict({**d, "zz_unknown": 1})
    with pytest.raises(TypeError, match="Expected a dict"):
        cls.from_dict([("hidden", 3)])
