"""Shared fixtures. Real-data tests find ``../shared/data`` from the repository root, or the
folder named by ``STRL_PYG_DATA``, and skip with a reason where it is absent."""

from __future__ import annotations

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


@pytest.fixture(scope="module")
def held_out_pair():
    """The generated pair of seed 2_000_017 (held out from training; ``pair`` in
    tests/inference/test_inference.py), for the other modules' tests that run on it."""
    from strl_pyg.synthetic import generate_pair

    return generate_pair(2_000_017)
