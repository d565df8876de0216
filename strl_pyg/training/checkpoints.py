"""Checkpoint files: where the shipped weights are, and the training checkpoint
(``last.pt``) format next to the model format of :meth:`StrLPose.save
<strl_pyg.model.strl_pose.StrLPose.save>`.

Both formats are read through one loader, :func:`strl_pyg.utils.io.safe_torch_load`
(``torch.load(weights_only=True)``: a file that would run code is refused and never
executed) and checked for their keys and version before use. Model files (``model.pt``, the
shipped weights) hold ``format``, ``version``, ``config``, ``metadata`` and ``state_dict``;
training checkpoints hold ``version`` (:data:`CHECKPOINT_VERSION`), ``train_config``,
``model_config``, ``model``, ``optimizer``, ``step``, ``rng``, ``history`` and ``trivial_T``.
:func:`init_weights` reads either into a model; :func:`load_training_model` builds the model
of a training checkpoint (the run's ``model.pt`` is the same model with its metadata).

Importing this module loads neither torch nor the model (the command line's ``--help`` and
its defaults use :func:`default_checkpoint`).
"""

from __future__ import annotations

import os
import random
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.utils.io import UnsafeFileError, atomic_open, safe_torch_load

__all__ = [
    "WEIGHTS_DIR",
    "DEFAULT_WEIGHTS",
    "CHECKPOINT_VERSION",
    "default_checkpoint",
    "save_checkpoint",
    "load_checkpoint",
    "rng_state",
    "set_rng_state",
    "init_weights",
    "inherit_policy",
    "INHERITED_METADATA",
    "load_training_model",
    "TRAINING_KEYS",
]

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"  # strl_pyg/weights
DEFAULT_WEIGHTS = WEIGHTS_DIR / "strl_pose_geometric.pt"
CHECKPOINT_VERSION = 2  # 2: every value loads with torch.load(weights_only=True)
#: The keys every training checkpoint (``last.pt``) holds.
TRAINING_KEYS = frozenset({"version", "train_config", "model_config", "model", "optimizer",
                           "step"})


def default_checkpoint() -> Path:
    """The shipped checkpoint (``STRL_POSE_WEIGHTS`` overrides it)."""
    return Path(os.environ.get("STRL_POSE_WEIGHTS", DEFAULT_WEIGHTS))


def _check_plain(value: Any, where: str = "state") -> None:
    """Raises ``TypeError`` unless ``value`` holds only what ``torch.load(weights_only=True)``
    reads back: tensors, numbers, strings, ``None`` and lists / tuples / dicts of them."""
    import torch
    from torch import Tensor

    if value is None or isinstance(value, (Tensor, bool, int, float, str, torch.device,
                                           torch.dtype)):
        return
    if isinstance(value, dict):
        for k, v in value.items():
            _check_plain(k, f"{where} key")
            _check_plain(v, f"{where}[{k!r}]")
        return
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_plain(v, f"{where}[{i}]")
        return
    raise TypeError(f"Expected tensors, numbers, strings and plain containers in a checkpoint "
                    f"(got {type(value).__module__}.{type(value).__qualname__} at {where})")


def save_checkpoint(path: str | os.PathLike, state: dict[str, Any]) -> Path:
    """Writes a training checkpoint atomically (temporary file in the same folder, then
    rename). ``state`` must hold only tensors, numbers, strings and plain containers, so that
    :func:`load_checkpoint` reads it back with ``weights_only=True`` (``TypeError`` otherwise,
    before anything is written)."""
    import torch

    _check_plain(state)
    path = Path(path)
    with atomic_open(path) as f:
        torch.save(state, f)
    return path


def load_checkpoint(path: str | os.PathLike) -> dict[str, Any]:
    """Loads a training checkpoint (``last.pt``) safely: ``torch.load(weights_only=True)``,
    so a file that would run code is refused (:class:`~strl_pyg.utils.io.UnsafeFileError`) and never
    executed. Clear one-line errors for missing, corrupt, foreign or old files."""
    path = Path(path)
    try:
        state = safe_torch_load(path, "checkpoint")
    except UnsafeFileError as err:
        if "numpy" in str(err):  # version 1 stored numpy's RNG state as an array
            raise UnsafeFileError(f"{err}; training checkpoints before version "
                                  f"{CHECKPOINT_VERSION} cannot be continued: start from that "
                                  "run's model.pt with --init-from") from None
        raise
    need = TRAINING_KEYS
    if not isinstance(state, dict) or not need <= set(state):
        got = sorted(state) if isinstance(state, dict) else type(state).__name__
        raise ValueError(f"Expected a training checkpoint with keys {sorted(need)} in '{path}' "
                         f"(got {got})")
    if state["version"] != CHECKPOINT_VERSION:
        raise ValueError(f"Expected training checkpoint version {CHECKPOINT_VERSION} in "
                         f"'{path}' (got {state['version']!r})")
    return state


def rng_state() -> dict[str, Any]:
    """The torch, numpy (legacy global) and Python RNG states, as plain values."""
    import torch

    # the legacy global numpy state is what third-party augmentation code draws from; it is
    # stored as a tensor and numbers so the checkpoint loads with weights_only=True
    kind, keys, pos, has_gauss, cached = np.random.get_state()  # noqa: NPY002
    return {"torch": torch.get_rng_state(),
            "numpy": {"kind": str(kind), "keys": torch.from_numpy(keys.astype(np.int64)),
                      "pos": int(pos), "has_gauss": int(has_gauss), "cached": float(cached)},
            "python": random.getstate()}


def set_rng_state(state: dict[str, Any]) -> None:
    """Restores the states of :func:`rng_state`."""
    import torch

    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state((n["kind"], n["keys"].numpy().astype(np.uint32), n["pos"],  # noqa: NPY002
                         n["has_gauss"], n["cached"]))
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))


def load_training_model(path: str | os.PathLike):
    """The :class:`~strl_pyg.model.strl_pose.StrLPose` of a training checkpoint (``last.pt``): its
    ``model_config`` and ``model`` weights, in eval mode, with default metadata (the run's
    ``model.pt``, written when the run finishes, also holds the training metadata)."""
    from strl_pyg.model import StrLPoseConfig
    from strl_pyg.model.strl_pose import StrLPose

    path = Path(path)
    state = load_checkpoint(path)
    model = StrLPose(StrLPoseConfig.from_dict(state["model_config"]))
    problems = _mismatch(model, state["model"], None)
    if problems:
        raise ValueError(f"Expected weights matching the checkpoint's model_config in "
                         f"'{path}' (got {problems})")
    model.load_state_dict(state["model"], strict=True)
    return model.eval()


def _mismatch(model: Any, state: dict[str, Any], saved_config: dict[str, Any] | None,
              allow_missing: tuple[str, ...] = (), shown: int = 3,
              allowed: dict[str, tuple[Any, Any]] | None = None) -> str:
    """What keeps ``state`` out of ``model`` (``""`` when nothing): mis-shaped, missing and
    unexpected keys (the first ``shown`` of each, version-1 names upgraded) and the config
    fields in which ``saved_config`` differs from the model's (but the differences
    ``allowed`` names as ``{field: (file value, model value)}``)."""
    from strl_pyg.model import upgrade_key

    own = model.state_dict()
    given = {upgrade_key(k): v for k, v in state.items()}

    def first(keys: list[str]) -> str:
        return ", ".join(keys[:shown]) + (f", ... ({len(keys)} in all)" if len(keys) > shown
                                          else "")

    shapes = [f"{k} {list(given[k].shape)} vs {list(v.shape)}"
              for k, v in own.items() if k in given and hasattr(given[k], "shape")
              and tuple(given[k].shape) != tuple(v.shape)]
    missing = [k for k in own if k not in given and not k.startswith(allow_missing)]
    unexpected = [k for k in given if k not in own]
    parts = [f"{what} keys {first(keys)}" for what, keys in (
        ("mis-shaped (file vs model)", shapes), ("missing", missing),
        ("unexpected", unexpected)) if keys]
    if parts and isinstance(saved_config, dict):
        mine = model.config.to_dict()
        diff = [f"{k} {saved_config[k]!r} vs {mine[k]!r}" for k in mine
                if k in saved_config and saved_config[k] != mine[k]
                and (allowed or {}).get(k) != (saved_config[k], mine[k])]
        if diff:
            parts.insert(0, "config fields (file vs model) " + ", ".join(diff))
    return "; ".join(parts)


SHIPPED_PREFIX = "shipped:"


def resolve_weights(spec: str | os.PathLike) -> Path:
    """The file of ``--init-from``: a path, or ``shipped:NAME`` for a checkpoint shipped with
    the package (``shipped:synthetic``, ``shipped:geometric``)."""
    text = str(spec)
    if not text.startswith(SHIPPED_PREFIX):
        return Path(text)
    from strl_pyg.model.strl_pose import StrLPose

    name = text[len(SHIPPED_PREFIX):]
    with StrLPose._shipped_path(name) as path:
        return Path(path)


def saved_model_config(spec: str | os.PathLike) -> dict[str, Any] | None:
    """The model config stored with the weights of ``spec`` (:func:`resolve_weights`):
    ``model.pt``'s ``config`` or ``last.pt``'s ``model_config``; ``None`` if it has none."""
    path = resolve_weights(spec)
    payload = safe_torch_load(path, "weights file (model.pt or last.pt)")
    if not isinstance(payload, dict):
        return None
    config = payload.get("config") if "format" in payload else payload.get("model_config")
    return dict(config) if isinstance(config, dict) else None


def init_weights(model: Any, path: str | os.PathLike) -> None:
    """Loads the weights of a model checkpoint (``model.pt``) or training checkpoint
    (``last.pt``) into ``model``; the architectures must match (else a ``ValueError`` naming
    the first mis-shaped, missing and unexpected keys and the config fields that differ).
    Both load with ``weights_only=True`` (a file that would run code is refused)."""
    from strl_pyg.model.strl_pose import StrLPose

    path = resolve_weights(path)
    payload = safe_torch_load(path, "weights file (model.pt or last.pt)")
    if isinstance(payload, dict) and "format" in payload:
        state = StrLPose.load(path).state_dict()
        saved_config = payload.get("config")
    else:
        ckpt = load_checkpoint(path)
        state, saved_config = ckpt["model"], ckpt.get("model_config")
    # A model that adds the geometric head may start from regression-only weights: the new
    # head's parameters are the only ones allowed to be missing.
    problems = _mismatch(model, state, saved_config, allow_missing=("inlier_head.",),
                         allowed={"geometric": (False, True)})  # adding the head only
    if problems:
        raise ValueError(f"Expected weights matching this run's model config in '{path}' "
                         f"(got {problems})")
    try:
        model.load_state_dict(state, strict=False)
    except RuntimeError as err:
        raise ValueError(f"Expected weights matching this run's model config in '{path}' "
                         f"(got {str(err).splitlines()[0]})") from err


#: Metadata of the initial weights that a run started from them keeps: the recommended order
#: of the methods (a policy measured with those weights; the calibration scales are not kept:
#: they describe the initial network's variances).
INHERITED_METADATA = ("recommended_order", "recommended_evidence")


def inherit_policy(model: Any, path: str | os.PathLike) -> None:
    """Copies :data:`INHERITED_METADATA` of the model checkpoint at ``path`` (``model.pt`` or
    shipped weights; a training ``last.pt`` has none) into ``model.metadata``, with
    ``recommended_order_from`` naming ``path``, so that the run's ``model.pt`` and
    ``best_model.pt`` recommend poses as the weights they started from did (not re-measured
    for the new weights: ``benchmarks/bench_pose.py --calibrate`` measures their own)."""
    from strl_pyg.model.strl_pose import StrLPose

    path = resolve_weights(path)
    payload = safe_torch_load(path, "weights file (model.pt or last.pt)")
    if not (isinstance(payload, dict) and "format" in payload):
        return
    md = StrLPose.load(path).metadata
    kept = {k: md[k] for k in INHERITED_METADATA if k in md}
    if kept:
        model.metadata = {**model.metadata, **kept, "recommended_order_from": str(path)}
