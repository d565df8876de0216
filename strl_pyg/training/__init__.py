"""Training Str-L Pose: the loop and its command line (:mod:`.loop`), the torch-free config and
flags (:mod:`.config`), datasets and the step sampler (:mod:`.data`), losses (:mod:`.loss`),
validation (:mod:`.validation`), the gradient clip (:mod:`.clip`), checkpoints
(:mod:`.checkpoints`) and logs (:mod:`.log`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "TrainConfig": "strl_pyg.training.config",
    "evaluate_model": "strl_pyg.training.validation",
    "mean_pose": "strl_pyg.training.validation",
    "build_datasets": "strl_pyg.training.data",
    "shuffle_point_matches": "strl_pyg.training.sampling",
    "load_checkpoint": "strl_pyg.training.checkpoints",
    "save_checkpoint": "strl_pyg.training.checkpoints",
    "StepBatchSampler": "strl_pyg.training.sampling",
    "add_train_arguments": "strl_pyg.training.config",
    "plot_history": "strl_pyg.training.log",
    "train": "strl_pyg.training.loop",
    "check_run_folder": "strl_pyg.training.loop",
    "RESUME_FREE_FIELDS": "strl_pyg.training.loop",
    "run_from_args": "strl_pyg.training.commandline",
    "DATASETS": "strl_pyg.training.config",
    "DATA_CHANNELS": "strl_pyg.training.config",
    "ABLATION_NAMES": "strl_pyg.training.config",
    "PAPER_RECIPE": "strl_pyg.training.config",
    "check_sources": "strl_pyg.training.data",
    "check_graph_channels": "strl_pyg.training.data",
    "model_input_channels": "strl_pyg.training.data",
    "unaugmented_poses": "strl_pyg.training.data",
    "aleatoric_loss": "strl_pyg.training.loss",
    "pose_targets": "strl_pyg.training.loss",
    "PoseLoss": "strl_pyg.training.loss",
    "GeometricLoss": "strl_pyg.training.loss",
    "WEIGHTS_DIR": "strl_pyg.training.checkpoints",
    "DEFAULT_WEIGHTS": "strl_pyg.training.checkpoints",
    "CHECKPOINT_VERSION": "strl_pyg.training.checkpoints",
    "default_checkpoint": "strl_pyg.training.checkpoints",
    "rng_state": "strl_pyg.training.checkpoints",
    "set_rng_state": "strl_pyg.training.checkpoints",
    "init_weights": "strl_pyg.training.checkpoints",
    "load_training_model": "strl_pyg.training.checkpoints",
    "TRAINING_KEYS": "strl_pyg.training.checkpoints",
    "TrainLogger": "strl_pyg.training.log",
    "read_log": "strl_pyg.training.log",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
