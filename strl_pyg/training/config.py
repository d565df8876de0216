"""The training configuration and its command-line flags, without importing torch.

:class:`TrainConfig` decides a run (``strl_pyg.training.loop`` re-exports it); the flags of
``examples/train.py`` and ``strl-pose train`` come from :func:`add_train_arguments`. This
module imports only the standard library and numpy (the scene kinds), so ``strl-pose --help``
and argument errors return before torch is loaded.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, fields
from typing import Any

from strl_pyg.synthetic.config import LINE_SCENE_KINDS  # numpy only
from strl_pyg.training.clip import MIN_HISTORY, WINDOW  # standard library only
from strl_pyg.training.options import add_config_arguments, option  # standard library only
from strl_pyg.utils.dataclass import strict_from_dict

__all__ = [
    "DATASETS",
    "DATA_CHANNELS",
    "ABLATION_NAMES",
    "TrainConfig",
    "PAPER_RECIPE",
    "add_train_arguments",
]

DATASETS = ("synthetic", "kitti", "demon", "posed")

#: Image channels of each dataset's graphs: generated scenes are rendered grey, KITTI's
#: ``image_0`` camera is grey, DeMoN is RGB, posed photographs are read grey (the shipped
#: weights' channels; ``--set patch_features=3 --set image_channels=3`` for colour). The default
#: model's ``patch_features`` and
#: ``image_channels`` follow them, so the default model accepts the default data.
DATA_CHANNELS = {"synthetic": 1, "kitti": 1, "demon": 3, "posed": 1}

#: The keys of :data:`strl_pyg.model.ABLATIONS` (a test keeps them equal), for ``--model``.
ABLATION_NAMES = ("baseline", "L", "LP", "R", "V", "LP+R", "LP+V", "V+W", "full")


#: Validation metrics that can keep ``best_model.pt`` (``TrainConfig.best_metric``; lower is
#: better).
BEST_METRICS = ("pose_err_med", "rot_err_med", "trans_err_med", "loss", "inlier_rank_err")

#: Learning-rate schedules (``TrainConfig.lr_schedule``, ``--lr-schedule``).
LR_SCHEDULES = ("constant", "cosine")


#: Float settings where ``inf`` means "never" / "off" (the clip, the checkpoint interval).
_INF_FIELDS = ("grad_clip", "checkpoint_minutes", "budget_minutes")
#: The paper's optimiser settings (Adam at a constant 1e-4, no warm-up); with
#: ``loss="paper"`` and ``model_overrides={"inputs": "paper"}`` the paper's whole recipe.
PAPER_RECIPE = {"lr": 1e-4, "lr_schedule": "constant", "warmup_steps": 0}
#: Settings a stored config may lack because it was written before they existed, with the
#: value every run had then (``TrainConfig.from_dict``): the paper's optimiser and beta 0.5
#: were the defaults until 0.4 made the study's recipe the default.
STORED_BEFORE = {**PAPER_RECIPE, "beta": 0.5, "grad_clip_relative": 0.0}


@dataclass
class TrainConfig:
    """Everything that decides a training run (stored in each checkpoint). Each field declared
    with :func:`~strl_pyg.training.options.option` is one flag of ``examples/train.py`` and
    ``strl-pose train`` (:func:`add_train_arguments`), its help text written here once."""

    dataset: str = option("synthetic", "synthetic | kitti | demon | posed", choices=DATASETS)
    data_root: str | None = option(
        None, "dataset root (kitti: the odometry root; demon: DeepSfM root; posed: a folder of "
        "scene folders, each in a format of strl_pyg.datasets.posed.read_posed_folder, e.g. "
        "real_scenes)")
    cache_dir: str = option("outputs/match_cache", "front-end match cache of real datasets")
    train_scenes: list[str] | None = option(
        None, "posed: training scene folders, comma-separated (default: the real_scenes split, "
        "strl_pyg.datasets.REAL_SCENES_SPLIT)", kind="list")
    val_scenes: list[str] | None = option(
        None, "posed: validation scene folders, comma-separated", kind="list")
    posed_gaps: list[int] = option(default_factory=lambda: [1, 2, 3], kind="int_list",
                                   help="posed: capture-order gaps k of the training pairs "
                                   "(i, i + k)")
    posed_max_rotation: float = option(60.0, "posed: largest relative rotation of a pair",
                                       metavar="DEG")
    matcher: str | None = option(
        None, "photographs (posed, KITTI, DeMoN): the front end's preset, fast | thorough | "
        "adaptive | legacy (default: the FrontendConfig defaults, adaptive); part of the match "
        "caches' key", metavar="PRESET")
    posed_stride: int = option(
        1, "posed: training pairs for every N-th first image, in every scene (thins the pairs "
        "evenly; --limit keeps the first scenes' pairs)", metavar="N")
    posed_min_points: int = option(
        0, "posed: leave out training pairs with fewer than N cached point matches (validation "
        "keeps every pair)", metavar="N")
    posed_min_covisible: float = option(
        0.1, "posed: smallest share of co-visible 3D points of a training pair (COLMAP models "
        "with point tracks; other formats carry none; 0: off)", metavar="SHARE")
    val_gap: int = option(2, "posed: validation pairs (i, i + val_gap)")
    val_stride: int = option(4, "posed: validation pairs for every this many i")
    synthetic_share: float = option(
        0.0, "posed: share of generated pairs mixed into the training set (--scene / "
        "--scene-kinds / --scene-mix, generator's matches), e.g. 0.5 for 1:1; 0: photographs "
        "only")
    synthetic_pairs: int | None = option(
        None, "posed: distinct generated pairs, cycled to reach --synthetic-share (each is "
        "generated once, on first use; default: as many as the share needs)")
    budget_minutes: float = option(
        math.inf, "stop (validated and checkpointed) after this many minutes of training; "
        "--resume with a larger budget or --steps goes on")
    best_metric: str = option(
        "pose_err_med", "validation metric that keeps best_model.pt (lower is better): "
        "pose_err_med (median of max(rotation, translation) error), rot_err_med, "
        "trans_err_med, loss, inlier_rank_err (1 - median per-pair ROC-AUC of the geometric "
        "head's inlier logits)", choices=BEST_METRICS)
    model: str = option("full", "ablation row of the paper (StrLPoseConfig.ablation)",
                        choices=ABLATION_NAMES)
    model_overrides: dict[str, Any] = option(
        default_factory=dict, flag="--set", kind="pairs",
        help="model config override (other StrLPoseConfig fields), e.g. --set hidden=64 "
        "--set layers=3")
    scene: dict[str, Any] = option(default_factory=dict, kind="pairs",
                                   help="SceneConfig field of generated scenes, e.g. --scene "
                                   "noise_px=0.5")
    scene_kinds: list[str] = option(default_factory=lambda: list(LINE_SCENE_KINDS),
                                    kind="list", help="generated scene kinds, comma-separated")
    scene_mix: str | None = option(
        None, "generated scenes drawn per seed from this distribution (e.g. mixed_small, "
        "mixed; strl_pyg.synthetic.distributions); replaces --scene / --scene-kinds; pairs "
        "are split evenly over its configurations")
    matches: str = option(
        "ground_truth", "generated scenes: the generator's matches or front-end matches on "
        "the rendered images (cached in --cache-dir); posed: its generated share always uses "
        "the generator's", choices=("ground_truth", "frontend"))
    loss: str = option(
        "balanced", "pose loss (strl_pyg.training.loss.LOSS_FORMS): balanced (beta-NLL, an "
        "angular translation term) or the paper's aleatoric loss; --loss paper --set "
        "inputs=paper is the paper's recipe; a stored config without it predates it",
        choices=("balanced", "paper"))
    angle_weight: float = option(1.0, "--loss balanced: weight of the angular translation "
                                 "term (radians)")
    beta: float = option(0.25, "--loss balanced: beta of beta-NLL, in [0, 1] (0: the "
                         "aleatoric weighting, 1: the gradient of a plain MSE)")
    rot_weight: float = option(1.0, "weight of the pose loss's rotation terms (both loss "
                               "forms; translation's: 1)")
    grad_clip: float | None = option(10.0, "max gradient norm (0: off); the norm is logged "
                                     "every step", kind="zero_is_none")
    grad_clip_relative: float = option(
        0.0, f"> 0: clip at K x the median norm of the last {WINDOW} steps (--grad-clip for "
        f"the first {MIN_HISTORY}; strl_pyg.training.clip); 0: --grad-clip throughout",
        metavar="K")
    outlier_augment: float = option(0.0, "up to this fraction of point matches shuffled into "
                                    "outliers")
    # Geometric head (--set geometric=true): strl_pyg.training.loss.GeometricLoss
    geo_threshold_px: float = option(2.0, "geometric head: inlier label threshold on the true "
                                     "Sampson distance (px)")
    geo_cls_weight: float = option(1.0, "geometric head: weight of the inlier classification "
                                   "loss")
    pose_weight: float = option(
        1.0, "weight of the pose loss in the total (the geometric head's is added at its own "
        "weights); < 1 lets the inlier classification lead on the shared layers (its gradient "
        "there is 10^2-10^4 times smaller than the pose loss's at 1)")
    geo_ess_weight: float = option(0.5, "geometric head: weight of the essential (epipolar) "
                                   "loss ...")
    geo_ess_start: int = option(200, "... from this step on (the classifier learns first)")
    train_pairs: int = option(2048, "synthetic: pairs in the training set (seeds 0..N-1)")
    val_pairs: int = option(128, "synthetic: held-out pairs (seeds from 1_000_000)")
    kitti_k: int = option(1, "kitti: frame gap of a pair")
    train_sequences: list[str] | None = option(
        None, "kitti: training sequences, comma-separated (default: the standard split 00-08)",
        kind="list")
    val_sequences: list[str] | None = option(
        None, "kitti: validation sequences, comma-separated (default: 09-10)", kind="list")
    limit: int | None = option(
        None, "real datasets, smoke runs: keep only the first N pairs in the order of the "
        "scenes or sequences (posed: of the training pairs; kitti, demon: of the training and "
        "of the validation pairs)", metavar="N")
    lr: float = option(
        1e-3, "Adam's rate, the cosine's peak; the defaults are the study's recipe "
        "(benchmarks/studies/results_pose_recipe.md), the paper's is 1e-4 constant, no "
        "warm-up (PAPER_RECIPE)")
    lr_schedule: str = option("cosine", "cosine (half a cosine from --lr to 0 at --steps, "
                              "after the warm-up) or constant (the paper)",
                              choices=LR_SCHEDULES)
    warmup_steps: int | None = option(None, "linear warm-up steps from lr / warmup to lr "
                                      "(default: min(100, steps / 20); 0: none, the paper)")
    batch_size: int = option(16, "global batch (split over DDP ranks), as the paper")
    steps: int = option(2000, "optimiser steps")
    val_every: int = option(200, "validate and checkpoint every this many steps (and at the "
                            "end)")
    num_points: int = option(384, "points resampled per pair, as the paper")
    num_lines: int = option(192, "line segments resampled per pair, as the paper")
    patch_size: int = option(1, "pixels sampled around each node (1: the paper's single "
                             "pixel)")
    swap_prob: float = option(0.5, "probability of exchanging the two images of a training "
                              "pair")
    roll_augment: float = option(
        0.0, "roll both cameras of a training pair about their optical axes by up to this "
        "many degrees (strl_pyg.data.RandomRoll; 0: off, the paper; 180: any orientation)",
        metavar="DEG")
    init_from: str | None = option(
        None, "start from these weights (model.pt, last.pt, or shipped:synthetic / "
        "shipped:geometric), e.g. to fine-tune; the model is theirs (architecture, inputs; "
        "--model is not read), --set changes fields on top")
    seed: int = option(0, "model initialisation (and the data, unless --data-seed is given)")
    data_seed: int | None = option(
        None, "seed of the training pairs, batch order and resampling (default: --seed); rows "
        "of an ablation share it while --seed varies the initialisation")
    checkpoint_every: int = option(0, "also write last.pt every this many steps (0: off)")
    checkpoint_minutes: float = option(
        10.0, "also write last.pt every this many minutes (0: off); always on Ctrl-C / SIGTERM "
        "and at every validation")
    num_workers: int = option(0, "data-loading processes", flag="--workers")
    device: str = option("cpu", "cpu, cuda, cuda:N or mps")
    out_dir: str = option("runs/default", "run folder (checkpoint, logs, curves)",
                          flag="--out")
    tensorboard: bool = option(True, "do not also log to TensorBoard (it is used when "
                               "installed)", flag="--no-tensorboard", kind="negated")
    in_memory: bool = True  # keep generated / loaded graphs in memory after first access

    def __post_init__(self) -> None:
        import math
        import numbers

        import numpy as np

        # types first: a string from a config file ("1e-3") is named, not compared with 0
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.generic):  # numpy scalars as Python ones: the run's
                value = value.item()           # config.json and last.pt hold plain values
                setattr(self, f.name, value)
            if f.type in ("float", "float | None", "int", "int | None") and value is not None:
                integral = f.type.startswith("int")
                kind = numbers.Integral if integral else numbers.Real
                # +inf is "never" / "off" where these read it so
                bad = not isinstance(value, kind) or isinstance(value, bool) or (
                    not integral and not math.isfinite(value)
                    and not (value == math.inf and f.name in _INF_FIELDS))
                if bad:
                    what = "an integer" if integral else "a finite number"
                    raise ValueError(f"Expected {what} '{f.name}' (got {value!r}, "
                                     f"{type(value).__name__})")
            elif f.type == "bool" and not isinstance(value, bool):
                raise ValueError(f"Expected a bool '{f.name}' (got {value!r}, "
                                 f"{type(value).__name__})")
        if self.dataset not in DATASETS:
            raise ValueError(f"Expected dataset in {DATASETS} (got {self.dataset!r})")
        if self.matches not in ("ground_truth", "frontend"):
            raise ValueError(f"Expected matches in ('ground_truth', 'frontend') "
                             f"(got {self.matches!r})")
        if not 0.0 <= self.outlier_augment < 1.0:
            raise ValueError(f"Expected outlier_augment in [0, 1) (got {self.outlier_augment!r})")
        if self.scene_mix is not None:
            from strl_pyg.synthetic.distributions import DISTRIBUTIONS

            if self.scene_mix not in DISTRIBUTIONS:
                raise ValueError(f"Expected scene_mix in {tuple(DISTRIBUTIONS)} "
                                 f"(got {self.scene_mix!r})")
        if not self.angle_weight >= 0:
            raise ValueError(f"Expected angle_weight >= 0 (got {self.angle_weight!r})")
        if not self.pose_weight >= 0:
            raise ValueError(f"Expected pose_weight >= 0 (got {self.pose_weight!r})")
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"Expected beta in [0, 1] (got {self.beta!r})")
        if self.grad_clip is not None and not self.grad_clip > 0:
            raise ValueError(f"Expected grad_clip > 0 or None (got {self.grad_clip!r})")
        if not self.grad_clip_relative >= 0:
            raise ValueError(f"Expected grad_clip_relative >= 0 (got {self.grad_clip_relative!r})")
        if not self.rot_weight > 0:
            raise ValueError(f"Expected rot_weight > 0 (got {self.rot_weight!r})")
        if self.loss not in ("paper", "balanced"):
            raise ValueError(f"Expected loss in ('paper', 'balanced') (got {self.loss!r})")
        if self.data_seed is not None and (not isinstance(self.data_seed, int)
                                           or self.data_seed < 0):
            raise ValueError(f"Expected a non-negative integer data_seed (got {self.data_seed!r})")
        if not isinstance(self.checkpoint_every, int) or self.checkpoint_every < 0:
            raise ValueError(f"Expected checkpoint_every >= 0 steps "
                             f"(got {self.checkpoint_every!r})")
        if not self.checkpoint_minutes >= 0:
            raise ValueError(f"Expected checkpoint_minutes >= 0 (got {self.checkpoint_minutes!r})")
        for name in ("batch_size", "steps", "val_every", "train_pairs", "val_pairs", "kitti_k",
                     "val_gap", "val_stride"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"Expected a positive integer '{name}' (got {value!r})")
        if not 0.0 <= self.swap_prob <= 1.0:
            raise ValueError(f"Expected swap_prob in [0, 1] (got {self.swap_prob!r})")
        if not 0.0 <= self.roll_augment <= 180.0:
            raise ValueError(f"Expected roll_augment in [0, 180] degrees "
                             f"(got {self.roll_augment!r})")
        if not self.lr > 0:
            raise ValueError(f"Expected a positive learning rate (got {self.lr!r})")
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"Expected lr_schedule in {LR_SCHEDULES} (got {self.lr_schedule!r})")
        if self.warmup_steps is not None and not 0 <= self.warmup_steps < self.steps:
            raise ValueError(f"Expected warmup_steps an integer in [0, steps={self.steps}) "
                             f"or None (got {self.warmup_steps!r})")
        self._check_posed_and_budget()
        if self.dataset != "synthetic" and not self.data_root:
            raise ValueError(f"Expected --data-root for dataset '{self.dataset}' (got none)")

    def _check_posed_and_budget(self) -> None:
        """The posed-photograph settings, the budget and the best-checkpoint metric."""
        if not 0.0 <= self.synthetic_share < 1.0:
            raise ValueError(f"Expected synthetic_share in [0, 1) (got {self.synthetic_share!r})")
        if self.synthetic_share > 0 and self.dataset != "posed":
            raise ValueError(f"Expected synthetic_share 0 unless dataset is 'posed' (got "
                             f"{self.synthetic_share!r} with dataset {self.dataset!r})")
        if self.synthetic_pairs is not None and (not isinstance(self.synthetic_pairs, int)
                                                 or self.synthetic_pairs < 1):
            raise ValueError(f"Expected a positive integer synthetic_pairs or None "
                             f"(got {self.synthetic_pairs!r})")
        if not self.budget_minutes > 0:
            raise ValueError(f"Expected budget_minutes > 0 (got {self.budget_minutes!r})")
        if self.best_metric not in BEST_METRICS:
            raise ValueError(f"Expected best_metric in {BEST_METRICS} (got {self.best_metric!r})")
        if not self.posed_gaps or any(not isinstance(g, int) or isinstance(g, bool) or g < 1
                                      for g in self.posed_gaps):
            raise ValueError(f"Expected posed_gaps as positive integers (got {self.posed_gaps!r})")
        if not isinstance(self.posed_min_points, int) or isinstance(self.posed_min_points, bool) \
                or self.posed_min_points < 0:
            raise ValueError(f"Expected posed_min_points as an integer >= 0 "
                             f"(got {self.posed_min_points!r})")
        if self.dataset == "posed" and self.matches != "ground_truth":
            raise ValueError("Expected matches 'ground_truth' with dataset 'posed' (the "
                             "photographs are matched by the front end, the generated share "
                             f"uses the generator's matches) (got {self.matches!r})")
        if not 0 <= self.posed_min_covisible <= 1:
            raise ValueError(f"Expected posed_min_covisible in [0, 1] "
                             f"(got {self.posed_min_covisible!r})")
        if self.matcher is not None:
            from strl_pyg.frontend.config import PRESETS

            if self.matcher not in PRESETS:
                raise ValueError(f"Expected matcher in {tuple(PRESETS)} or None "
                                 f"(got {self.matcher!r})")
        if not (isinstance(self.posed_stride, int) and self.posed_stride >= 1):
            raise ValueError(f"Expected posed_stride as an integer >= 1 "
                             f"(got {self.posed_stride!r})")
        if not 0 < self.posed_max_rotation <= 180:
            raise ValueError(f"Expected posed_max_rotation in (0, 180] degrees "
                             f"(got {self.posed_max_rotation!r})")

    def learning_rate(self, step: int) -> float:
        """The learning rate of optimiser step ``step`` (0-based): a linear warm-up over
        :attr:`warmup` steps (``lr * (step + 1) / warmup``), then ``lr`` (``constant``) or
        half a cosine from ``lr`` at the warm-up's end to 0 at ``steps`` (``cosine``). A pure
        function of the step, so a resumed run continues the same schedule."""
        warmup = self.warmup
        if step < warmup:
            return self.lr * (step + 1) / warmup
        if self.lr_schedule == "constant":
            return self.lr
        progress = min(1.0, (step - warmup) / (self.steps - warmup))
        return self.lr * 0.5 * (1.0 + math.cos(math.pi * progress))

    @property
    def warmup(self) -> int:
        """The warm-up's length in steps: ``warmup_steps``, or ``min(100, steps // 20)`` when it
        is None (the study's 100 steps of 2000, and none for a run of a few steps)."""
        return min(100, self.steps // 20) if self.warmup_steps is None else self.warmup_steps

    @property
    def resolved_data_seed(self) -> int:
        """The seed of the data (pairs, batch order, resampling)."""
        return self.seed if self.data_seed is None else self.data_seed

    def model_config(self):
        """The :class:`~strl_pyg.StrLPoseConfig` of this run: the ablation row ``model`` with
        ``model_overrides``; unless overridden, metric translation on KITTI and patch / image
        channels of the dataset (:data:`DATA_CHANNELS`, ``patch_features = C * p * p``)."""
        from strl_pyg.model import StrLPoseConfig

        overrides = dict(self.model_overrides)
        known = [f.name for f in fields(StrLPoseConfig)]
        unknown = sorted(set(overrides) - set(known))
        if unknown:
            import difflib

            close = [(k, difflib.get_close_matches(k, known, n=1, cutoff=0.75))
                     for k in unknown]
            hint = "; ".join(f"did you mean {c[0]} for {k}" if len(unknown) > 1
                             else f"did you mean {c[0]}?" for k, c in close if c)
            raise ValueError(f"Expected --set keys among the StrLPoseConfig fields "
                             f"{', '.join(known)} (got {', '.join(unknown)})"
                             f"{'; ' + hint if hint else ''}")
        if self.init_from:
            # fine-tuning continues the architecture and inputs of the weights it starts from
            # (the ablation row is theirs); --set changes fields on top of them
            from strl_pyg.training.checkpoints import saved_model_config

            saved = saved_model_config(self.init_from)
            if saved is not None:
                return StrLPoseConfig.from_dict({**saved, **overrides})
        if self.dataset == "kitti":
            overrides.setdefault("translation", "metric")
        channels = DATA_CHANNELS[self.dataset]
        overrides.setdefault("patch_features", channels * self.patch_size ** 2)
        overrides.setdefault("image_channels", channels)
        return StrLPoseConfig.ablation(self.model, **overrides)

    def ignored_fields(self) -> list[str]:
        """The settings this run's dataset does not read (``config.json`` lists them under
        ``"ignored"`` beside the ``"data"`` actually loaded, so a stored config does not
        describe data the run never saw)."""
        posed = ["train_scenes", "val_scenes", "posed_gaps", "posed_max_rotation",
                 "posed_stride", "posed_min_points", "posed_min_covisible", "val_gap",
                 "val_stride", "synthetic_share", "synthetic_pairs"]
        kitti = ["kitti_k", "train_sequences", "val_sequences"]
        generator = ["scene", "scene_kinds", "scene_mix", "matches"]
        # a named scene mix replaces the scene settings
        per_scene = ["scene", "scene_kinds"] if self.scene_mix is not None else []
        if self.dataset == "posed":
            # the generated share always uses the generator's matches
            out = ["train_pairs", "val_pairs", *kitti, "matches"]
            if self.synthetic_share == 0:
                return [*out, "scene", "scene_kinds", "scene_mix", "synthetic_pairs"]
            return [*out, *per_scene]
        if self.dataset == "synthetic":  # (its front-end matches: the default front end)
            return [*posed, *kitti, "data_root", "limit", "matcher", *per_scene]
        if self.dataset == "kitti":
            return [*posed, *generator, "train_pairs", "val_pairs"]
        return [*posed, *kitti, *generator, "train_pairs", "val_pairs"]

    #: Keys of ``config.json`` that describe the run rather than configure it
    #: (:meth:`from_dict` leaves them out).
    DESCRIPTIVE_KEYS = ("ignored", "data")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """The config of a stored dict; one without ``loss`` was written before the balanced
        loss and the flow inputs existed, and is read as the paper's recipe. A setting the dict
        lacks because it was written before the setting existed takes the value every run had
        then (:data:`STORED_BEFORE`), not today's default: a resumed old run trains on as it
        began."""
        if isinstance(d, dict) and "loss" not in d:
            overrides = {"inputs": "paper", **(d.get("model_overrides") or {})}
            d = {**d, "loss": "paper", "model_overrides": overrides}
        if isinstance(d, dict):
            d = {k: v for k, v in {**STORED_BEFORE, **d}.items()
                 if k not in cls.DESCRIPTIVE_KEYS}
            if d.get("dataset") == "posed":  # stored before it was refused: it had no effect
                d["matches"] = "ground_truth"
        return strict_from_dict(cls, d)


def add_train_arguments(ap: argparse.ArgumentParser,
                        config: type[TrainConfig] = TrainConfig) -> argparse.ArgumentParser:
    """Adds the training flags to ``ap``: one per option field of ``config``
    (:class:`TrainConfig` or a subclass; :mod:`strl_pyg.training.options`), then the run's
    controls (``--resume``, ``--overwrite``, ``--no-progress``)."""
    add_config_arguments(ap, config)
    ap.add_argument("--resume", action="store_true", help="continue from <out>/last.pt")
    ap.add_argument("--overwrite", action="store_true",
                    help="start afresh in an existing run folder (its checkpoint is replaced)")
    ap.add_argument("--no-progress", action="store_true")
    return ap
