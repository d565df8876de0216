"""The 0.2 module paths are gone (0.4); the public paths that did not move keep working, and
the shipped checkpoints load."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_the_0_2_module_paths_are_gone_and_say_where_to_look():
    """0.4 removed the 0.2 paths (docs/changelog.md lists each with its replacement): an old
    path is an ordinary ModuleNotFoundError, and the faces give only their own names."""
    sys.modules.pop("strl_pyg.pose_methods", None)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("strl_pyg.pose_methods")
    import strl_pyg.inference as face

    with pytest.raises(AttributeError, match="has no attribute 'np'"):
        face.np  # noqa: B018  (0.3's fallback face gave every name of a module)
    changelog = (REPO / "docs" / "changelog.md").read_text()
    assert "`strl_pyg.pose_methods` | `strl_pyg.inference.methods`" in changelog


def test_public_paths_that_became_folders_keep_their_names():
    from strl_pyg.cli import main
    from strl_pyg.evaluation import evaluate_pairs
    from strl_pyg.evaluation import main as evaluate_main
    from strl_pyg.inference import POSELIB_MISSING, PoseEstimator
    from strl_pyg.metrics import pose_auc, relative_pose_error
    from strl_pyg.model import StrLPose, StrLPoseConfig
    from strl_pyg.training import TrainConfig, run_from_args, train

    # each public path names the object of its module's home (an import alone cannot fail
    # once it succeeded; the identity can)
    from strl_pyg.cli import commands
    from strl_pyg.evaluation import run
    from strl_pyg.inference import estimator
    from strl_pyg.metrics import stats, two_view
    from strl_pyg.model import strl_pose
    from strl_pyg.training import config, loop

    assert main is commands.main and evaluate_main is run.main
    assert evaluate_pairs is run.evaluate_pairs
    assert run_from_args is loop.run_from_args and train is loop.train
    assert TrainConfig is config.TrainConfig and PoseEstimator is estimator.PoseEstimator
    assert POSELIB_MISSING == estimator.POSELIB_MISSING
    assert StrLPose is strl_pose.StrLPose and StrLPoseConfig is strl_pose.StrLPoseConfig
    assert relative_pose_error is two_view.relative_pose_error
    assert pose_auc([0.0, 0.0], [10.0]) == [1.0] and pose_auc([float("inf")], [10.0]) == [0.0]
    assert stats.pose_error_stats([1.0], [2.0])["n"] == 1


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

    geometric = StrLPose.from_pretrained("geometric")
    assert geometric.metadata["recommended_order"][0] == "poselib"
    assert geometric.config.geometric and not StrLPose.from_pretrained("synthetic").config.geometric
