"""The rules on the recommended pose, as records: one rule a module, one registry.

:data:`~strl_pyg.inference.rules.registry.RULES` holds the built-in rules (:func:`builtin_rules`),
the rules installed packages
declare (entry-point group ``strl-pyg.rules``) and those registered at run time
(:func:`register_rule`), run by increasing :attr:`PoseRule.order` on the recommended pose of
every pair (:func:`~strl_pyg.inference.rules.base.apply_rules`). Each returns a
:class:`~strl_pyg.inference.status.Verdict` naming itself; the record keeps them all
(``MethodResult.verdicts``, ``"verdicts"`` in the JSON) and ``"rule"`` names the one that gave
the pose its status.

The rules that act on one method's record are named the same way: ``intrinsics`` /
``no_intrinsics`` (:func:`~strl_pyg.inference.pair.pair_rules`), ``support`` and
``cheirality`` (:func:`~strl_pyg.inference.support.check_support`), ``learned_support``
(:func:`~strl_pyg.inference.evidence.learned_pose_evidence`).
"""

from __future__ import annotations

from strl_pyg.inference.rules.base import PoseRule, apply_rules
from strl_pyg.inference.rules.registry import (
    builtin_rules,
    ordered_rules,
    register_rule,
    rules_table,
    unregister_rule,
)

# the registry's tables (RULES, ENTRY_POINT_GROUP, METHOD_RULES) are read from
# strl_pyg.inference.rules.registry
__all__ = ["PoseRule", "builtin_rules", "register_rule", "unregister_rule", "ordered_rules",
           "rules_table", "apply_rules"]
