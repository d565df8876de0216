"""The Str-L Pose network: :class:`StrLPose` (:mod:`.strl_pose`: layers wired into the
paper's dual graph), its file I/O (:mod:`.checkpoint`: save / load, pretrained weights), its
configuration and ablation rows (:mod:`.config`), the gathering of its input features
(:mod:`.gather`) and older checkpoints' keys (:mod:`.legacy`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "StrLPoseConfig": "strl_pyg.model.config",
    "PoseOutput": "strl_pyg.model.config",
    "GeometricOutput": "strl_pyg.model.config",
    "ABLATIONS": "strl_pyg.model.config",
    "NO_INTRINSICS": "strl_pyg.model.config",
    "VISUAL_MODES": "strl_pyg.model.config",
    "upgrade_key": "strl_pyg.model.legacy",
    "StrLPose": "strl_pyg.model.strl_pose",
    "ModelInputs": "strl_pyg.model.gather",
    "gather_inputs": "strl_pyg.model.gather",
    "upgrade_legacy_keys": "strl_pyg.model.legacy",
    "what_checkpoint": "strl_pyg.model.legacy",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
