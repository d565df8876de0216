"""Old module paths of strl_pyg (0.2.x) and where each lives now.

``import strl_pyg.<old path>`` (and ``from strl_pyg.<old path> import name``) still works for
one release: the finder that ``strl_pyg/__init__.py`` installs imports the new module under
the old name and says so with a :class:`DeprecationWarning` naming the new path. Paths that
are folders now (``strl_pyg.inference``, ``.training``, ``.evaluation``, ``.metrics``,
``.model``, ``.cli``, ``.data.external``) keep their public names on the folder's face and
need no entry.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

__all__ = ["OLD_PATHS", "REMOVAL", "install"]

#: old module path -> new module path
OLD_PATHS: dict[str, str] = {
    "strl_pyg._dataclass": "strl_pyg.utils.dataclass",
    "strl_pyg._lazy": "strl_pyg.utils.lazy",
    "strl_pyg.baselines": "strl_pyg.estimation.classical",
    "strl_pyg.checkpoints": "strl_pyg.training.checkpoints",
    "strl_pyg.cli_inputs": "strl_pyg.cli.inputs",
    "strl_pyg.data.datasets": "strl_pyg.datasets",
    "strl_pyg.data.datasets.base": "strl_pyg.datasets.base",
    "strl_pyg.data.datasets.cache": "strl_pyg.datasets.cache",
    "strl_pyg.data.datasets.demon": "strl_pyg.datasets.demon",
    "strl_pyg.data.datasets.files": "strl_pyg.datasets.files",
    "strl_pyg.data.datasets.kitti": "strl_pyg.datasets.kitti",
    "strl_pyg.data.datasets.middlebury": "strl_pyg.datasets.middlebury",
    "strl_pyg.data.datasets.synthetic": "strl_pyg.datasets.synthetic",
    "strl_pyg.data.external_checks": "strl_pyg.data.external.checks",
    "strl_pyg.data.external_hloc": "strl_pyg.data.external.hloc",
    "strl_pyg.data.external_readers": "strl_pyg.data.external.readers",
    "strl_pyg.essential": "strl_pyg.geometry.essential",
    "strl_pyg.eval_pairs": "strl_pyg.evaluation.pairs",
    "strl_pyg.eval_report": "strl_pyg.evaluation.report",
    "strl_pyg.fusion": "strl_pyg.estimation.fusion",
    "strl_pyg.guided": "strl_pyg.estimation.guided",
    "strl_pyg.images": "strl_pyg.utils.images",
    "strl_pyg.io": "strl_pyg.utils.io",
    "strl_pyg.loss": "strl_pyg.training.loss",
    "strl_pyg.model_config": "strl_pyg.model.config",
    "strl_pyg.model_inputs": "strl_pyg.model.inputs",
    "strl_pyg.odometry": "strl_pyg.metrics.odometry",
    "strl_pyg.pose_fusion": "strl_pyg.estimation.fusion",
    "strl_pyg.pose_input": "strl_pyg.inference.inputs",
    "strl_pyg.pose_methods": "strl_pyg.inference.methods",
    "strl_pyg.pose_record": "strl_pyg.inference.record",
    "strl_pyg.pose_stats": "strl_pyg.metrics.stats",
    "strl_pyg.pose_uncertainty": "strl_pyg.estimation.uncertainty",
    "strl_pyg.recommended": "strl_pyg.inference.recommended",
    "strl_pyg.train_config": "strl_pyg.training.config",
    "strl_pyg.train_data": "strl_pyg.training.data",
    "strl_pyg.train_log": "strl_pyg.training.log",
    "strl_pyg.trajectory": "strl_pyg.metrics.trajectory",
    "strl_pyg.validation": "strl_pyg.training.validation",
}

#: the release that drops the old paths
REMOVAL = "0.4.0"


class _Redirect(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Serves an old path with the module of its new path (the same module object)."""

    def find_spec(self, name, path=None, target=None):
        if name in OLD_PATHS:
            return importlib.machinery.ModuleSpec(name, self)
        return None

    def create_module(self, spec):
        new = OLD_PATHS[spec.name]
        warnings.warn(f"{spec.name} is deprecated and goes in strl-pyg {REMOVAL}: import "
                      f"{new} instead", DeprecationWarning, stacklevel=2)
        return importlib.import_module(new)

    def exec_module(self, module) -> None:  # the new module is executed already
        return None


def install() -> None:
    """Puts the redirecting finder first on ``sys.meta_path`` (once): an old submodule path
    such as ``strl_pyg.data.datasets.base`` would otherwise be found by the path finder in the
    redirected parent's folder and loaded a second time, as another module object."""
    if not any(isinstance(f, _Redirect) for f in sys.meta_path):
        sys.meta_path.insert(0, _Redirect())
