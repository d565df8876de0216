"""Each thing said once per pose: the classical bootstrap's warning is the same sentence in
every record that reuses that bootstrap, so the recommended pose lists it once."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from strl_pyg.inference.methods.context import _add_bootstrap
from strl_pyg.inference.record import MethodResult


def test_a_reused_bootstrap_warns_in_one_sentence():
    """Before: 'poselib: 3 of 16 bootstrap resamples ...', then the same for guided and
    fused, three times in one pose's warnings."""
    boot = SimpleNamespace(covariance=np.eye(5) * 1e-6, far=3, resamples=16)
    own = _add_bootstrap(MethodResult("poselib", "ok", np.eye(4), np.eye(5)), boot, 16,
                         "first-order")
    fused = _add_bootstrap(MethodResult("fused", "ok", np.eye(4), np.eye(5)), boot, 16,
                           "information form", "poselib ")
    assert own.warnings == fused.warnings and len(own.warnings) == 1
    assert own.warnings[0].startswith("poselib bootstrap: 3 of 16 resamples found another")
    assert fused.info["covariance"] == "information form + poselib bootstrap (16)"

