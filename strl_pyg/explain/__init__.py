"""Which point matches and line segments drove the network's pose: PyG's explainers
(``GNNExplainer``, ``AttentionExplainer``) and gradients on :class:`~strl_pyg.model.StrLPose`'s
complete-attention path (:mod:`strl_pyg.explain.pose`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "EXPLAINERS": "strl_pyg.explain.pose",
    "PoseExplainerModel": "strl_pyg.explain.pose",
    "PoseExplanation": "strl_pyg.explain.pose",
    "explain_pose": "strl_pyg.explain.pose",
    "explain_matches": "strl_pyg.explain.pose",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

if TYPE_CHECKING:  # for type checkers and IDEs; never executed
    from strl_pyg.explain.pose import (
        EXPLAINERS,
        PoseExplainerModel,
        PoseExplanation,
        explain_matches,
        explain_pose,
    )
