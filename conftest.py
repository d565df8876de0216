"""The test tiers, for both test folders (``tests/`` and ``benchmarks/tests/``, pytest's
``testpaths``): a conftest here at the root is read whatever path pytest is given, so
``pytest benchmarks/tests --runslow`` knows the option too.

Two tiers, as kornia (--runslow) and PyG (FULL_TEST) do it: the default run is the fast tier
(every module, in-process); the slow tier (training runs, torchrun, torch.compile,
subprocesses, real-data end-to-end, CLI fuzzing) runs with --runslow or STRL_FULL_TEST=1,
and .ci/run runs it after the fast tier. Fixtures are in ``tests/conftest.py``."""

from __future__ import annotations

import os

import pytest


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False,
                     help="also run the slow tier (tests marked 'slow')")


def _full_test(config) -> bool:
    return bool(config.getoption("--runslow")) or os.environ.get("STRL_FULL_TEST") == "1"


def pytest_collection_modifyitems(config, items):
    if _full_test(config):
        return
    skip = pytest.mark.skip(reason="slow tier: run with --runslow (or STRL_FULL_TEST=1)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def plant_nan_gradients(monkeypatch):
    """``plant(calls)``: the training loss gets a term whose value is 0 and whose gradient is
    NaN on the ``calls``-th calls (1-based; -1: every call): sqrt(0 * x) has 0 * inf as its
    derivative."""
    from strl_pyg.training import loop

    real = loop.losses_for

    def plant(calls: set) -> None:
        count = [0]

        def losses(cfg, model_cfg):
            pose, geo = real(cfg, model_cfg)

            def planted(out, T):
                logs = pose(out, T)
                count[0] += 1
                if count[0] in calls or -1 in calls:
                    logs["loss"] = logs["loss"] + (0.0 * out.quaternion.sum()).sqrt()
                return logs

            return planted, geo

        monkeypatch.setattr(loop, "losses_for", losses)

    return plant
