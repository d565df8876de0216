"""Shared fixtures. Real-data tests find ``../shared/data`` from the repository root, or the
folder named by ``STRL_PYG_DATA``, and skip with a reason where it is absent."""

from __future__ import annotations

import copy
import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path | None:
    env = os.environ.get("STRL_PYG_DATA")
    path = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    return path if path.is_dir() else None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    path = shared_data_dir()
    if path is None:
        pytest.skip("real data slices not found (set STRL_PYG_DATA or place ../shared/data)")
    return path


@pytest.fixture(scope="session")
def kitti_root(shared_data) -> Path:
    root = shared_data / "kitti_odometry"
    if not (root / "sequences" / "06").is_dir():
        pytest.skip(f"KITTI slice not found under {root}")
    return root


@pytest.fixture(scope="session")
def demon_root(shared_data) -> Path:
    root = shared_data / "demon_deepsfm"
    if not root.is_dir():
        pytest.skip(f"DeMoN slice not found under {root}")
    return root


# The test tiers (--runslow, STRL_FULL_TEST=1) are in the repository's root conftest.py, which
# benchmarks/tests/ shares.


@pytest.fixture(scope="module")
def model():
    """The shipped model in eval mode, once per test module (a module's own ``model`` fixture,
    e.g. a tiny one, takes its place there)."""
    from strl_pyg.model.strl_pose import StrLPose

    return StrLPose.from_pretrained().eval()


@pytest.fixture
def method_registry():
    """The method registry (``strl_pyg.inference.registry``), restored after the test: a test
    may register or replace methods in it."""
    from strl_pyg.inference import registry

    saved = dict(registry.METHODS)
    yield registry
    registry.METHODS.clear()
    registry.METHODS.update(saved)


@pytest.fixture(scope="session")
def generated_pair():
    """``generated_pair(seed, config=None)``: ``generate_pair(seed, config)``, generated once per
    test session for each seed and config (a street pair takes ~0.8 s; many modules run on the
    same ones). Every call returns its own deep copy, so a test may change what it gets. Tests
    of the generator itself call ``generate_pair``."""
    from strl_pyg.synthetic import SceneConfig, generate_pair

    made: dict = {}

    def get(seed: int, config=None):
        # SceneConfig is a plain (unhashable) dataclass; None is its defaults
        key = (seed, repr(SceneConfig() if config is None else config))
        if key not in made:
            made[key] = generate_pair(seed, config)
        return copy.deepcopy(made[key])

    return get


@pytest.fixture(scope="module")
def held_out_pair(generated_pair):
    """The generated pair of seed 2_000_017 (held out from training; ``pair`` in
    tests/inference/test_inference.py), for the other modules' tests that run on it."""
    return generated_pair(2_000_017)


@pytest.fixture
def plugin_cli(tmp_path):
    """``plugin_cli(module, source, group, entry)``: a one-module package declaring ``entry``
    (``name = module:Object``) in the entry-point ``group``, installed in ``tmp_path``; returns
    ``cli(*argv, code=0)``, which runs ``python -m strl_pyg.cli`` with it on the path and
    returns its stdout, asserting the exit code."""
    import subprocess
    import sys

    def install(module: str, source: str, group: str, entry: str):
        (tmp_path / f"{module}.py").write_text(source)
        info = tmp_path / f"{module}-0.1.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(
            f"Metadata-Version: 2.1\nName: {module.replace('_', '-')}\nVersion: 0.1\n")
        (info / "entry_points.txt").write_text(f"[{group}]\n{entry}\n")
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [str(tmp_path), os.environ.get("PYTHONPATH", "")])}

        def cli(*argv, code=0):
            out = subprocess.run([sys.executable, "-m", "strl_pyg.cli", *argv], env=env,
                                 capture_output=True, text=True, timeout=300)
            assert out.returncode == code, out.stderr[-800:]
            return out.stdout

        return cli

    return install
