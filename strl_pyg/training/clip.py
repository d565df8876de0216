"""The gradient-norm clip of a training run.

A fixed clip (``TrainConfig.grad_clip``) is only as good as its threshold's match with the
loss's scale: with the balanced loss at beta 0.25 the gradient norm's median grows from ~15 to
~24 over a 2000-step run, so a clip at 10 is active on 98 % of steps (it then rescales every
step to the same norm, which Adam mostly undoes) and a clip at 50 misses the spikes of the late
steps (99th percentile ~200). A *relative* clip (``grad_clip_relative``: that many times the
median norm of the last :data:`WINDOW` steps) follows the scale and caps the spikes only.
It is an option, not the default: over three seeds of the study's protocol it was active on
6-7 % of steps and trained a little worse than the fixed clip at 10
(``benchmarks/studies/results_pose_recipe.md``).
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Iterable

__all__ = ["GradientClip", "WINDOW", "MIN_HISTORY"]

#: Steps whose gradient norms the relative clip's median reads.
WINDOW = 200
#: Norms seen before the relative clip takes over from the fixed one (``grad_clip``).
MIN_HISTORY = 20


class GradientClip:
    """The threshold of each step's gradient-norm clip.

    Args:
        fixed: The clip (a maximum norm; ``None``: off) while fewer than
            :data:`MIN_HISTORY` norms are recorded, and always when ``relative`` is 0.
        relative: When > 0, the clip is ``relative`` times the median of the last
            :data:`WINDOW` recorded norms once :data:`MIN_HISTORY` are recorded.
        norms: Norms recorded earlier (a resumed run's checkpoint), oldest first.

    A median of 0 (only zero gradients in the window) leaves the fixed clip in force: a
    threshold of 0 would zero every gradient.
    """

    def __init__(self, fixed: float | None, relative: float = 0.0,
                 norms: Iterable[float] = ()) -> None:
        if not (relative >= 0 and math.isfinite(relative)):
            raise ValueError(f"Expected a finite relative clip >= 0 (got {relative!r})")
        if fixed is not None and not fixed > 0:
            raise ValueError(f"Expected a clip > 0 or None (got {fixed!r})")
        self.fixed = fixed
        self.relative = float(relative)
        self.norms: deque[float] = deque(maxlen=WINDOW)
        for n in norms:
            self.record(n)

    def threshold(self) -> float | None:
        """The maximum gradient norm of the next step (``None``: no clip)."""
        if self.relative > 0 and len(self.norms) >= MIN_HISTORY:
            median = statistics.median(self.norms)
            if median > 0:
                return self.relative * median
        return self.fixed

    def record(self, norm: float) -> None:
        """Adds a step's gradient norm (before clipping); a non-finite one (a skipped step)
        is left out."""
        norm = float(norm)
        if math.isfinite(norm):
            self.norms.append(norm)

    def state(self) -> list[float]:
        """The recorded norms, for a checkpoint (the argument ``norms`` of a resumed run)."""
        return list(self.norms)
