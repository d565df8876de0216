"""Evaluation on the inference registry: running the methods over pairs and the command
line (:mod:`.run`, also ``python -m strl_pyg.evaluation``), the pairs (:mod:`.pairs`) and
the report (:mod:`.report`: tables, trajectories, files).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

__all__ = [
    "AUC_THRESHOLDS",
    "SHORT_SEGMENT_LENGTHS",
    "EvalPair",
    "PairResult",
    "pair_result",
    "EvalReport",
    "prepare_matches",
    "synthetic_eval_pairs",
    "demon_eval_pairs",
    "kitti_eval_pairs",
    "METHODS",
    "LEGACY_METHOD_NAMES",
    "NETWORK_METHODS",
    "available_methods",
    "resolve_methods",
    "predict_pose",
    "evaluate_pairs",
    "build_parser",
    "main",
]

# 0.2 code read other names of the module this folder was: they resolve too
_lazy_getattr, __dir__ = lazy_exports(__name__, {
    "AUC_THRESHOLDS": "strl_pyg.evaluation.run",
    "SHORT_SEGMENT_LENGTHS": "strl_pyg.evaluation.report",
    "EvalPair": "strl_pyg.evaluation.pairs",
    "PairResult": "strl_pyg.evaluation.report",
    "pair_result": "strl_pyg.evaluation.report",
    "EvalReport": "strl_pyg.evaluation.report",
    "prepare_matches": "strl_pyg.evaluation.run",
    "synthetic_eval_pairs": "strl_pyg.evaluation.pairs",
    "demon_eval_pairs": "strl_pyg.evaluation.pairs",
    "kitti_eval_pairs": "strl_pyg.evaluation.pairs",
    "LEGACY_METHOD_NAMES": "strl_pyg.evaluation.run",
    "available_methods": "strl_pyg.evaluation.run",
    "resolve_methods": "strl_pyg.evaluation.run",
    "predict_pose": "strl_pyg.evaluation.run",
    "evaluate_pairs": "strl_pyg.evaluation.run",
    "build_parser": "strl_pyg.evaluation.run",
    "main": "strl_pyg.evaluation.run",
}, globals())


def __getattr__(name: str):
    if name in ("METHODS", "NETWORK_METHODS"):  # the registry's, never cached on the face
        from strl_pyg.evaluation import run

        return getattr(run, name)
    return _lazy_getattr(name)
