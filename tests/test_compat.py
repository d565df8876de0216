"""Old module paths of 0.2 resolve to the new ones with a DeprecationWarning naming the new
path, and the public paths that did not move keep working."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from strl_pyg._compat import OLD_PATHS

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("old", sorted(OLD_PATHS))
def test_every_old_path_imports_the_new_module_with_a_warning(old):
    new = OLD_PATHS[old]
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=rf"{old} is deprecated .*import {new} instead"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    assert sys.modules[old] is sys.modules[new]


def test_old_from_imports_give_the_same_objects():
    with pytest.warns(DeprecationWarning):
        sys.modules.pop("strl_pyg.pose_methods", None)
        from strl_pyg.pose_methods import MethodContext
    import strl_pyg.data

    sys.modules.pop("strl_pyg.data.datasets", None)
    vars(strl_pyg.data).pop("datasets", None)  # set by an earlier import of the submodule
    with pytest.warns(DeprecationWarning, match="import strl_pyg.datasets instead"):
        from strl_pyg.data import datasets
    from strl_pyg.datasets import KITTIOdometry
    from strl_pyg.inference.methods import MethodContext as new

    assert MethodContext is new and datasets.KITTIOdometry is KITTIOdometry


def test_public_paths_that_became_folders_keep_their_names():
    from strl_pyg.cli import main
    from strl_pyg.evaluation import evaluate_pairs
    from strl_pyg.evaluation import main as evaluate_main
    from strl_pyg.inference import POSELIB_MISSING, PoseEstimator
    from strl_pyg.metrics import pose_auc, relative_pose_error
    from strl_pyg.model import StrLPose, StrLPoseConfig
    from strl_pyg.training import TrainConfig, run_from_args, train

    assert callable(main) and callable(evaluate_main) and callable(evaluate_pairs)
    assert callable(run_from_args) and callable(train) and TrainConfig().steps > 0
    assert PoseEstimator and POSELIB_MISSING and StrLPose and StrLPoseConfig
    assert callable(pose_auc) and callable(relative_pose_error)


@pytest.mark.slow
def test_python_dash_m_evaluation_and_the_console_script_entry_point():
    res = subprocess.run([sys.executable, "-m", "strl_pyg.evaluation", "--help"],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert res.returncode == 0 and "--methods" in res.stdout, res.stderr[-1000:]
    res = subprocess.run([sys.executable, "-c", "from strl_pyg.cli import main; "
                          "raise SystemExit(main(['--help']))"],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert res.returncode == 0 and "predict" in res.stdout, res.stderr[-1000:]


def test_shipped_checkpoints_load_unchanged():
    from strl_pyg.model import StrLPose

    for name in ("geometric", "synthetic"):
        model = StrLPose.from_pretrained(name)
        assert model.metadata["recommended_order"] if name == "geometric" else model
