"""The registry of the rules on the recommended pose (:data:`RULES`): the built-in rules, the
rules installed packages declare (:data:`ENTRY_POINT_GROUP`) and those registered at run time,
run by increasing :attr:`~strl_pyg.inference.rules.base.PoseRule.order`."""

from __future__ import annotations

from typing import Any

from strl_pyg.inference.rules.base import PoseRule
from strl_pyg.inference.rules.configuration import Configuration
from strl_pyg.inference.rules.focal import Focal
from strl_pyg.inference.rules.multiple import Multiple
from strl_pyg.inference.rules.sigma_cap import SigmaCap
from strl_pyg.inference.rules.watermark import Watermark

__all__ = ["RULES", "ENTRY_POINT_GROUP", "METHOD_RULES", "builtin_rules", "register_rule",
           "unregister_rule", "ordered_rules", "rules_table"]

#: The entry-point group through which an installed package adds a rule: in its
#: ``pyproject.toml``, ``[project.entry-points."strl-pyg.rules"]`` ``myrule =
#: "mypackage.myrule:MyRule"`` (a :class:`PoseRule` class or instance).
ENTRY_POINT_GROUP = "strl-pyg.rules"

#: The rules applied to each method's own record (not registry entries: they run inside the
#: methods' run), by name: what they decide.
METHOD_RULES = {
    "intrinsics": "intrinsics that fail the input checks: every pose unreliable",
    "no_intrinsics": "no K0, K1: no metric pose (the fundamental matrix instead)",
    "support": "too few point matches within the support band and in front: failed",
    "cheirality": "too many supporting matches behind a camera: unreliable",
    "learned_support": "the network's pose without the matches' support: unreliable",
    "degenerate_input": "zero parallax or normalised coordinates as pixels: degenerate",
    "too_few_matches": "fewer distinct point matches than the method needs: degenerate",
    "no_matches": "the front end found no matches: degenerate",
    "missing_input": "the input lacks what the method reads (images, a skipped method): skipped",
    "raised": "the method raised an exception: failed",
    "solver": "the solver found no pose: failed",
}


def builtin_rules() -> tuple[PoseRule, ...]:
    """New instances of the built-in rules on the recommended pose."""
    return (Watermark(), Multiple(), Configuration(), Focal(), SigmaCap())


def _installed_rules(taken: set[str]) -> list[PoseRule]:
    """The rules installed packages declare (:data:`ENTRY_POINT_GROUP`); one that does not
    load, or whose name is taken, is left out with a one-line warning naming it."""
    from strl_pyg.utils.plugins import load_plugins

    def check(rule: PoseRule, loaded: list) -> None:
        if rule.name in taken or rule.name in METHOD_RULES or \
                any(r.name == rule.name for r in loaded):
            raise ValueError(f"the name {rule.name!r} is taken")

    return load_plugins(ENTRY_POINT_GROUP, PoseRule, "pose rule", check)


def _build() -> dict[str, PoseRule]:
    rules = {r.name: r for r in builtin_rules()}
    rules.update({r.name: r for r in _installed_rules(set(rules))})
    return rules


#: ``name -> PoseRule``: the rules on the recommended pose (module docstring).
RULES: dict[str, PoseRule] = _build()


def ordered_rules() -> list[PoseRule]:
    """The rules of :data:`RULES` by increasing order (registration order among equals)."""
    return sorted(RULES.values(), key=lambda r: r.order)


def register_rule(rule: Any, replace_existing: bool = False) -> PoseRule:
    """Adds ``rule`` (a :class:`PoseRule` class or instance) to :data:`RULES`; a taken name is
    a ``ValueError`` unless ``replace_existing``. Returns the instance."""
    rule = rule() if isinstance(rule, type) else rule
    if not isinstance(rule, PoseRule) or not isinstance(rule.name, str) or not rule.name:
        raise TypeError(f"Expected a PoseRule with a name (got {rule!r})")
    if (rule.name in RULES and not replace_existing) or rule.name in METHOD_RULES:
        raise ValueError(f"Expected a new rule name (got {rule.name!r}, which is taken; "
                         "replace_existing=True replaces a registered rule)")
    RULES[rule.name] = rule
    return rule


def unregister_rule(name: str) -> PoseRule:
    """Removes the rule ``name`` from :data:`RULES` (``KeyError`` naming the rules if absent)."""
    if name not in RULES:
        raise KeyError(f"Expected one of the rules {sorted(RULES)} (got {name!r})")
    return RULES.pop(name)


def rules_table() -> str:
    """A markdown table of every rule: the registry's, then the method-level ones."""
    lines = ["| rule | runs on | decides | what |", "|---|---|---|---|"]
    for r in ordered_rules():
        lines.append(f"| `{r.name}` | the recommended pose | {r.decides} | {r.summary} |")
    for name, what in METHOD_RULES.items():
        lines.append(f"| `{name}` | each method's pose | {what.split(': ')[-1]} | "
                     f"{what.split(': ')[0]} |")
    return "\n".join(lines)
