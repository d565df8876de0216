"""The built-in methods, in the order they run (the first entries of
:data:`~strl_pyg.inference.registry.METHODS`, which reads them itself)."""

from __future__ import annotations

from strl_pyg.inference.methods.base import PoseMethod
from strl_pyg.inference.methods.classical import OpenCV, PoseLib
from strl_pyg.inference.methods.fused import Fused
from strl_pyg.inference.methods.geometric import Geometric, Guided
from strl_pyg.inference.methods.regression import Regression
from strl_pyg.inference.methods.vanishing_point import VanishingPoint, VanishingPointChecked

__all__ = ["builtin_methods"]


def builtin_methods() -> tuple[PoseMethod, ...]:
    """New instances of the built-in methods, in the order they run."""
    return (Regression(), OpenCV(), PoseLib(), Fused(), Geometric(),
            Guided(), VanishingPoint(), VanishingPointChecked())
