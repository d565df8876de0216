"""Checkpoint I/O of :class:`~strl_pyg.model.strl_pose.StrLPose` (a mixin it inherits):
training metadata, ``save`` / ``load`` (safe loading only), the shipped weights
(``from_pretrained``) and the re-indexing of a version-1 optimizer state. Keys of older
checkpoints are upgraded by :mod:`strl_pyg.model.legacy`."""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import torch

from strl_pyg.model.config import StrLPoseConfig
from strl_pyg.model.legacy import upgrade_key, what_checkpoint
from strl_pyg.utils.io import atomic_open, safe_torch_load

__all__ = ["CheckpointIO"]


class CheckpointIO:
    """What a :class:`~strl_pyg.model.strl_pose.StrLPose` knows about files: the methods below
    are the model's (``model.save(path)``, ``StrLPose.load(path)``, ...)."""

    _FORMAT = "strl_pyg.StrLPose"
    _VERSION = 2  # 2 added "metadata"; version 1 files load with default_metadata()
    _READABLE_VERSIONS = (1, 2)
    #: Checkpoints shipped in the package (``strl_pyg/weights/``), for :meth:`from_pretrained`:
    #: ``name -> (file, metadata used when the file stores none)``.
    #: ``"geometric"`` (the default): regression + geometric head, calibrated; ``"synthetic"``:
    #: the paper's model alone (regression head), the first shipped weights.
    PRETRAINED: dict[str, tuple[str, dict[str, Any]]] = {
        "geometric": ("strl_pose_geometric.pt", {}),
        "synthetic": ("strl_pose_synthetic.pt", {"training_data": (
            "generated street/indoor/boxes scenes only: 3000 pairs, ground-truth matches with "
            "0.7 px noise and 10% outliers, 4000 steps of batch 16, swap augmentation")}),
    }

    @staticmethod
    def default_metadata(config: StrLPoseConfig) -> dict[str, Any]:
        """What a checkpoint without metadata (version 1) is assumed to be trained with:
        ``resample`` ``[384, 192]`` (points, lines of :class:`~strl_pyg.data.FixedSizeResample`,
        ``None`` = not resampled); ``patch_channels`` the channels images are converted to
        before sampling (1 grey, 3 RGB; ``image_channels`` for ``visual="cnn"``, ``None``
        without visual input) and ``patch_size`` (odd ``p`` with ``patch_features =
        channels * p * p``; ``None`` unless ``visual="pixel"``), both from the config;
        ``training_data`` ``None`` (unknown)."""
        channels = size = None
        if config.visual == "cnn":
            channels = config.image_channels
        elif config.visual == "pixel":
            for c in (1, 3):
                p = math.isqrt(config.patch_features // c)
                if c * p * p == config.patch_features and p % 2:
                    channels, size = c, p
                    break
            else:
                raise ValueError(f"Expected patch_features = C * p * p with C in (1, 3) and odd "
                                 f"p (got {config.patch_features})")
        return {"resample": [384, 192], "patch_channels": channels, "patch_size": size,
                "training_data": None}

    @staticmethod
    def _check_metadata(md: Any, config: StrLPoseConfig) -> dict[str, Any]:
        if not isinstance(md, dict) or not all(isinstance(k, str) for k in md):
            raise ValueError(f"Expected metadata as a dict with str keys (got {type(md).__name__})")
        out = {**CheckpointIO.default_metadata(config), **md}
        rs = out["resample"]
        if rs is not None:
            rs = list(rs) if isinstance(rs, (list, tuple)) else rs
            if not (isinstance(rs, list) and len(rs) == 2 and all(
                    isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in rs)):
                raise ValueError(f"Expected metadata 'resample' as [points, lines] >= 0 or None "
                                 f"(got {out['resample']!r})")
            out["resample"] = rs
        default = CheckpointIO.default_metadata(config)
        for key in ("patch_channels", "patch_size"):
            if out[key] != default[key]:
                raise ValueError(f"Expected metadata '{key}' {default[key]!r} for this config "
                                 f"(visual={config.visual!r}, patch_features="
                                 f"{config.patch_features}) (got {out[key]!r})")
        if out["training_data"] is not None and not isinstance(out["training_data"], str):
            raise ValueError(f"Expected metadata 'training_data' as a str or None "
                             f"(got {type(out['training_data']).__name__})")
        return out

    @property
    def metadata(self) -> dict[str, Any]:
        """Training metadata (:meth:`default_metadata` keys plus any free-form ones) stored in
        the checkpoint; the defaults when none was stored or set."""
        md = self.__dict__.get("_metadata")
        return dict(md) if md is not None else self.default_metadata(self.config)

    @metadata.setter
    def metadata(self, value: dict[str, Any]) -> None:
        self._metadata = self._check_metadata(value, self.config)

    def save(self, path: str | os.PathLike, metadata: dict[str, Any] | None = None) -> Path:
        """Writes the config, the weights and the training metadata (:attr:`metadata` updated
        with ``metadata``; plain str/int/float/bool/None/list/dict values) to ``path``
        atomically (temp file + rename)."""
        path = Path(path)
        md = self._check_metadata({**self.metadata, **(metadata or {})}, self.config)
        payload = {
            "format": self._FORMAT,
            "version": self._VERSION,
            "config": self.config.to_dict(),
            "metadata": md,
            "state_dict": {k: v.detach().cpu() for k, v in self.state_dict().items()},
        }
        with atomic_open(path) as f:
            torch.save(payload, f)
        return path

    @classmethod
    def _read_payload(cls, path: Path, map_location: Any = "cpu") -> dict[str, Any]:
        """The checked contents of a checkpoint file (format and version)."""
        # weights_only=True: a file that would run code is refused (io.UnsafeFileError)
        payload = safe_torch_load(path, "StrLPose checkpoint", map_location)
        if not isinstance(payload, dict) or payload.get("format") != cls._FORMAT:
            raise ValueError(f"Expected a '{cls._FORMAT}' checkpoint at {path} (got "
                             f"{what_checkpoint(payload, path)})")
        if payload.get("version") not in cls._READABLE_VERSIONS:
            raise ValueError(f"Expected checkpoint version in {cls._READABLE_VERSIONS} "
                             f"(got {payload.get('version')!r})")
        return payload

    @classmethod
    def load(cls, path: str | os.PathLike, map_location: Any = "cpu") -> Any:
        """Rebuilds a model saved with :meth:`save`; raises ``ValueError`` on a corrupt,
        foreign or mismatched checkpoint. Checkpoints of the version-1 module layout load
        unchanged (:func:`upgrade_key`, applied by every ``load_state_dict`` of the model)."""
        path = Path(path)
        payload = cls._read_payload(path, map_location)
        model = cls(StrLPoseConfig.from_dict(payload["config"]))
        try:
            model.load_state_dict(payload["state_dict"], strict=True)
        except RuntimeError as err:
            raise ValueError(
                f"Expected weights matching the checkpoint's config at {path} (got {err})"
            ) from err
        if payload.get("metadata") is not None:
            model.metadata = payload["metadata"]
        return model

    def upgrade_optimizer_state(self, optimizer_state: dict[str, Any],
                                model_state: dict[str, Any]) -> dict[str, Any]:
        """Re-indexes an optimizer state saved next to ``model_state`` for this model's
        parameter order.

        An optimizer indexes its state by parameter position; the version-1 module layout
        listed the parameters in another order (all GCG self-attentions, then all line
        convolutions, ...), so the state of a version-1 training checkpoint must be permuted
        before ``optimizer.load_state_dict`` (else Adam moments land on other parameters).
        A state saved with today's layout is returned unchanged.

        Args:
            optimizer_state: ``optimizer.state_dict()`` of an optimizer over
                ``model.parameters()`` (one parameter group).
            model_state: the model state dict saved with it (its key order is the
                parameter order of that model).
        """
        keys = list(model_state)
        if all(upgrade_key(k) == k for k in keys):
            return optimizer_state
        names = [n for n, _ in self.named_parameters()]
        known = set(names)
        old_order = [upgrade_key(k) for k in keys if upgrade_key(k) in known]
        if sorted(old_order) != sorted(names):
            raise ValueError(f"Expected a model state with this model's {len(names)} "
                             f"parameters (got {len(old_order)} of them)")
        groups = optimizer_state.get("param_groups")
        if not (isinstance(groups, list) and len(groups) == 1
                and list(groups[0].get("params", [])) == list(range(len(names)))):
            raise ValueError("Expected the state of an optimizer over model.parameters() in "
                             f"one parameter group of {len(names)} (got "
                             f"{len(groups) if isinstance(groups, list) else groups!r} groups)")
        position = {n: j for j, n in enumerate(names)}
        new_index = [position[n] for n in old_order]  # old position -> new position
        group = {**groups[0], "params": list(range(len(names)))}
        if "param_names" in group:
            group["param_names"] = names
        state = {new_index[int(i)]: v for i, v in optimizer_state.get("state", {}).items()}
        return {**optimizer_state, "state": state, "param_groups": [group]}

    @classmethod
    def from_pretrained(cls, name: str = "geometric", map_location: Any = "cpu") -> Any:
        """A shipped checkpoint (:attr:`PRETRAINED`), read from the installed package (not the
        working directory), in eval mode."""
        fallback = cls._shipped_entry(name)[1]
        with cls._shipped_path(name) as path:
            model = cls.load(path, map_location)
        if "_metadata" not in model.__dict__:
            model.metadata = fallback
        return model.eval()

    @classmethod
    def _shipped_entry(cls, name: str) -> tuple[str, dict[str, Any]]:
        """``(file name, fallback metadata)`` of a shipped checkpoint, or a one-line error."""
        if name not in cls.PRETRAINED:
            raise ValueError(f"Expected a pretrained name in {tuple(cls.PRETRAINED)} "
                             f"(got {name!r})")
        return cls.PRETRAINED[name]

    @classmethod
    @contextmanager
    def _shipped_path(cls, name: str) -> Iterator[Path]:
        """The path of a shipped checkpoint inside the installed package (not the working
        directory), checked to exist."""
        from importlib.resources import as_file, files

        file = cls._shipped_entry(name)[0]
        with as_file(files("strl_pyg") / "weights" / file) as path:
            if not Path(path).is_file():
                raise FileNotFoundError(f"Expected the shipped checkpoint '{file}' in the "
                                        f"strl_pyg package at {path} (got none)")
            yield Path(path)

    @classmethod
    def pretrained_header(cls, name: str = "geometric") -> tuple[StrLPoseConfig, dict[str, Any]]:
        """The config and the training metadata (calibration, recommended order, ...) of a
        shipped checkpoint, checked as :meth:`from_pretrained` checks the file, without
        building the network."""
        fallback = cls._shipped_entry(name)[1]
        with cls._shipped_path(name) as path:
            payload = cls._read_payload(path)
        config = StrLPoseConfig.from_dict(payload["config"])
        md = payload.get("metadata")
        return config, cls._check_metadata(fallback if md is None else md, config)

    @classmethod
    def pretrained_metadata(cls, name: str = "geometric") -> dict[str, Any]:
        """The training metadata of a shipped checkpoint (:meth:`pretrained_header`)."""
        return cls.pretrained_header(name)[1]

