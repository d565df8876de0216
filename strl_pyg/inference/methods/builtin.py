"""The built-in methods, in the order they run (:mod:`strl_pyg.inference.estimator`
registers them)."""

from __future__ import annotations

from strl_pyg.inference.methods.classical import Classical
from strl_pyg.inference.methods.fused import Fused
from strl_pyg.inference.methods.geometric import Geometric, Guided
from strl_pyg.inference.methods.regression import Regression
from strl_pyg.inference.methods.vanishing_point import VanishingPoint, VanishingPointChecked
from strl_pyg.inference.registry import PoseMethod

__all__ = ["builtin_methods"]


def builtin_methods() -> tuple[PoseMethod, ...]:
    """New instances of the built-in methods, in the order they run."""
    return (Regression(), Classical("opencv"), Classical("poselib"), Fused(), Geometric(),
            Guided(), VanishingPoint(), VanishingPointChecked())
