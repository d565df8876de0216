"""Evaluation on the inference registry: running the methods over pairs and the command
line (:mod:`.run`, also ``python -m strl_pyg.evaluation``), the pairs (:mod:`.pairs`) and
the report (:mod:`.report`: tables, trajectories, files).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
    "SHORT_SEGMENT_LENGTHS": "strl_pyg.evaluation.report",
    "EvalPair": "strl_pyg.evaluation.pairs",
    "PairResult": "strl_pyg.evaluation.report",
    "pair_result": "strl_pyg.evaluation.report",
    "EvalReport": "strl_pyg.evaluation.report",
    "synthetic_eval_pairs": "strl_pyg.evaluation.pairs",
    "demon_eval_pairs": "strl_pyg.evaluation.pairs",
    "kitti_eval_pairs": "strl_pyg.evaluation.pairs",
    "posed_eval_pairs": "strl_pyg.evaluation.pairs",
    "LEGACY_METHOD_NAMES": "strl_pyg.evaluation.run",
    "available_methods": "strl_pyg.evaluation.run",
    "resolve_methods": "strl_pyg.evaluation.run",
    "predict_pose": "strl_pyg.evaluation.run",
    "evaluate_pairs": "strl_pyg.evaluation.run",
    "build_parser": "strl_pyg.evaluation.run",
    "main": "strl_pyg.evaluation.run",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

