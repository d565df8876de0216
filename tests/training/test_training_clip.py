"""strl_pyg.training.clip: the gradient clip's threshold (fixed, or relative to the median of
recent norms)."""

from __future__ import annotations

import pytest

from strl_pyg.training.config import TrainConfig


def test_the_relative_clip_follows_the_median_of_recent_norms():
    from strl_pyg.training import clip as clip_

    c = clip_.GradientClip(10.0, relative=3.0)
    for n in range(1, clip_.MIN_HISTORY):  # 19 norms: still the fixed clip
        c.record(float(n))
    assert c.threshold() == 10.0
    c.record(float("nan"))  # a skipped step is not a norm
    c.record(float("inf"))
    assert c.threshold() == 10.0
    c.record(20.0)  # 1..19, 20: median 10.5
    assert c.threshold() == pytest.approx(31.5)
    for _ in range(clip_.WINDOW):  # the window forgets the early norms
        c.record(4.0)
    assert c.threshold() == pytest.approx(12.0) and len(c.state()) == clip_.WINDOW
    # restored from a checkpoint's norms: the same threshold
    assert clip_.GradientClip(10.0, 3.0, c.state()).threshold() == pytest.approx(12.0)
    # relative 0 is the fixed clip whatever was seen; None is no clip
    assert clip_.GradientClip(10.0, 0.0, [1.0] * 50).threshold() == 10.0
    assert clip_.GradientClip(None, 0.0).threshold() is None
    with pytest.raises(ValueError, match="Expected a finite relative clip >= 0"):
        clip_.GradientClip(10.0, -1.0)
    with pytest.raises(ValueError, match=r"Expected a clip > 0 or None \(got -1.0\)"):
        clip_.GradientClip(-1.0, 3.0)
    # a window of zero gradients keeps the fixed clip (a threshold of 0 would zero them all)
    assert clip_.GradientClip(10.0, 3.0, [0.0] * 50).threshold() == 10.0
    with pytest.raises(ValueError, match="Expected grad_clip_relative >= 0"):
        TrainConfig(grad_clip_relative=-0.5)
    # a negative clip reached clip_grad_norm_ and flipped the gradients' sign without a word
    with pytest.raises(ValueError, match=r"Expected grad_clip > 0 or None \(got -1.0\)"):
        TrainConfig(grad_clip=-1.0)
    # a config stored before the setting existed trained with the fixed clip
    assert TrainConfig.from_dict({"loss": "balanced"}).grad_clip_relative == 0.0


def test_the_command_line_turns_the_clip_off_at_0_and_refuses_a_negative_one():
    import argparse

    from strl_pyg.training.commandline import config_from_args
    from strl_pyg.training.config import add_train_arguments

    ap = add_train_arguments(argparse.ArgumentParser())
    assert config_from_args(ap.parse_args(["--grad-clip", "0"]), ap).grad_clip is None
    # a negative clip was read as "off" without a word
    with pytest.raises(ValueError, match=r"Expected grad_clip > 0 or None \(got -1.0\)"):
        config_from_args(ap.parse_args(["--grad-clip", "-1"]), ap)
