"""The verdict on a pose: its :class:`Status` and the :class:`Verdict` of each rule that spoke.

:class:`Status` is a ``str`` enum whose values are the statuses' names (``Status.OK == "ok"``),
so JSON records, command-line output and comparisons with strings read as they always did.
Every decision about a pose that is not a plain ``"ok"`` (a refusal, a widened sigma, a
configuration reported beside the pose) is a :class:`Verdict` naming its rule
(:mod:`strl_pyg.inference.rules`), kept in :attr:`MethodResult.verdicts
<strl_pyg.inference.record.MethodResult.verdicts>` and in the JSON record's ``"verdicts"``;
the record's ``"rule"`` is the rule that gave it its status (``None`` for ``"ok"``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Status", "Action", "Verdict", "STATUSES"]


class _Named(str, enum.Enum):
    """A str enum that reads, formats and hashes as its value (``Status.OK == "ok"``, and a
    dict keyed by ``"ok"`` finds ``Status.OK``)."""

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)

    __hash__ = str.__hash__


class Status(_Named):
    """What a pose record is (``strl_pyg.inference.record``'s module docstring)."""

    #: a pose to use, with its sigma
    OK = "ok"
    #: the matches show no parallax: a rotation and its sigma, no translation direction
    ROTATION_ONLY = "rotation_only"
    #: a pose was computed but must not be used (the reason names the rule)
    UNRELIABLE = "unreliable"
    #: the input does not determine a pose (too few matches, zero parallax)
    DEGENERATE = "degenerate"
    #: the method found no pose, or the matches do not support it
    FAILED = "failed"
    #: a method's record only: the input lacks what the method reads
    SKIPPED = "skipped"

    @classmethod
    def of(cls, value: Any) -> Status:
        """``value`` (a :class:`Status` or its string) as a :class:`Status`; a one-line
        ``ValueError`` naming the statuses for anything else."""
        try:
            return cls(value)
        except ValueError:
            raise ValueError(f"Expected status in {STATUSES} (got {value!r})") from None

    @property
    def has_pose(self) -> bool:
        """Whether a record of this status carries a pose (``T_0to1`` and ``sigma``)."""
        return self is Status.OK


#: The statuses' values, in order.
STATUSES: tuple[str, ...] = tuple(s.value for s in Status)


class Action(_Named):
    """What a rule's verdict did to the pose."""

    #: the pose was refused: its status is the verdict's (no ``T_0to1``)
    REFUSED = "refused"
    #: the pose stays; its covariance grew by what the rule measured
    WIDENED = "widened"
    #: the pose and its sigma stay; the rule's finding is reported beside them
    REPORTED = "reported"
    #: the pose was replaced by another answer (a pure rotation's rotation)
    REPLACED = "replaced"


@dataclass(frozen=True)
class Verdict:
    """One rule's decision about one pose.

    Attributes:
        rule: the rule's name (:data:`strl_pyg.inference.rules.RULES`, or a method-level rule:
            ``"intrinsics"``, ``"support"``, ``"cheirality"``, ``"solver"``, ...).
        action: what it did (:class:`Action`).
        status: the status the pose has after it (``Status.OK`` for a widening or a report).
        reason: one human-readable sentence (also in the record's ``warnings``).
        evidence: what the rule measured, JSON-ready (counts, angles, ratios).
    """

    rule: str
    action: Action
    status: Status
    reason: str
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"rule": self.rule, "action": self.action.value, "status": self.status.value,
                "reason": self.reason, "evidence": dict(self.evidence)}
