r"""Checkpoints of older versions: version-1 state-dict keys (parallel ``ModuleList``\ s and the
head inside the fusion) renamed to today's on load, and what a file that is not a model
checkpoint holds (for :meth:`StrLPose.load <strl_pyg.model.StrLPose.load>`'s error)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["upgrade_key", "upgrade_legacy_keys", "what_checkpoint"]


# ----------------------------------------------------------------------------- legacy keys
#: Version-1 module names (parallel ``ModuleList``\ s and the head inside the fusion) ->
#: today's. Checkpoints of both versions store the old names; they load unchanged.
_LEGACY_LAYER_KEYS = {"geo_self": "geo_self", "line_convs": "line_conv",
                      "vis_self": "vis_self", "vis_cross": "vis_cross"}
_LEGACY_PREFIXES = {"fusion.pose_mlp.": "pose_head.pose_mlp.",
                    "fusion.var_mlp.": "pose_head.var_mlp."}


def upgrade_key(key: str) -> str:
    """Today's name of a state-dict key of :class:`StrLPose` (``key`` itself when current):
    ``geo_self.{i}.*`` -> ``layers.{i}.geo_self.*``, ``line_convs.{i}.*`` ->
    ``layers.{i}.line_conv.*``, ``vis_self.{i}.*`` / ``vis_cross.{i}.*`` ->
    ``layers.{i}.vis_self.*`` / ``layers.{i}.vis_cross.*``, ``fusion.pose_mlp.*`` /
    ``fusion.var_mlp.*`` -> ``pose_head.pose_mlp.*`` / ``pose_head.var_mlp.*``."""
    head, _, rest = key.partition(".")
    if head in _LEGACY_LAYER_KEYS:
        i, _, tail = rest.partition(".")
        if i.isdigit() and tail:
            return f"layers.{i}.{_LEGACY_LAYER_KEYS[head]}.{tail}"
    for old, new in _LEGACY_PREFIXES.items():
        if key.startswith(old):
            return new + key[len(old):]
    return key


def what_checkpoint(payload: Any, path: Path) -> str:
    """What a file that is not a model checkpoint holds, for :meth:`StrLPose.load`'s error:
    a training checkpoint gets the way to its model."""
    if not isinstance(payload, dict):
        return type(payload).__name__
    if "format" in payload:
        return f"format {payload['format']!r}"
    # a few of strl_pyg.training.TRAINING_KEYS (not imported: that layer is above this one)
    if {"model_config", "model", "optimizer", "step"} <= set(payload):
        model_pt = path.parent / "model.pt"
        where = (f"'{model_pt}' (the same run's model)" if model_pt.is_file()
                 else "the run's model.pt (written when training finishes)")
        return (f"a training checkpoint (last.pt format, step {payload.get('step')!r}): pass "
                f"{where}, or build its model with "
                f"strl_pyg.training.checkpoints.load_training_model('{path}')")
    keys = sorted(str(k) for k in payload)
    return f"a dict with keys {keys[:8]}" + (" ..." if len(keys) > 8 else "")


def upgrade_legacy_keys(module, state_dict, prefix, local_metadata, strict, missing_keys,
                         unexpected_keys, error_msgs) -> None:
    """``load_state_dict`` pre-hook of :class:`StrLPose`: renames version-1 keys in place
    (``state_dict`` is the loader's own copy)."""
    for key in [k for k in state_dict if k.startswith(prefix)]:
        new = prefix + upgrade_key(key[len(prefix):])
        if new == key:
            continue
        if new in state_dict:
            error_msgs.append(f"Expected either the old key {key!r} or the new key {new!r} "
                              "(got both)")
            continue
        state_dict[new] = state_dict.pop(key)
