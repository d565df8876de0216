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
