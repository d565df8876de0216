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


def pytest_configure(config):
    """Under pytest-xdist (``-n 2``, the README's test command) each worker runs torch (and
    the subprocesses its tests start) on one thread: the tests' tensors are small, two
    threads per worker were no faster than one, and two workers of two threads on a 2-core
    machine wait on each other."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        os.environ["OMP_NUM_THREADS"] = "1"
        import torch

        torch.set_num_threads(1)


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


# --------------------------------------------------------------------------- scripts' --help
_HELP_RUNNER = r"""
import contextlib, io, json, os, runpy, sys, traceback
repo, plan, dest = sys.argv[1:4]
base_path, base_modules = list(sys.path[1:]), set(sys.modules)
out = {}
for script in json.load(open(plan)):
    stdout, stderr, code = io.StringIO(), io.StringIO(), 0
    sys.argv = [script, "--help"]
    sys.path[:] = [os.path.dirname(script), *base_path]  # as `python SCRIPT`: its folder first
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            runpy.run_path(script, run_name="__main__")
    except SystemExit as err:
        code = err.code if isinstance(err.code, int) else int(err.code is not None)
    except BaseException:
        code = 1
        stderr.write(traceback.format_exc())
    # a script's own helpers leave with it (the next script must find its own); the package,
    # the standard library and installed modules stay imported
    keep = (os.path.join(repo, "strl_pyg") + os.sep, sys.prefix + os.sep,
            sys.base_prefix + os.sep)
    for name in [m for m in sys.modules if m not in base_modules]:
        path = getattr(sys.modules[name], "__file__", None) or ""
        if path and not path.startswith(keep):
            del sys.modules[name]
    out[script] = [code, stdout.getvalue(), stderr.getvalue()]
json.dump(out, open(dest, "w"))
"""


@pytest.fixture(scope="session")
def script_help(tmp_path_factory):
    """``script_help(paths) -> {path: (returncode, stdout, stderr)}`` of ``python PATH --help``
    from the repository root: every script not asked before runs in one process (the imports of
    torch and the package once, not once per script), each with its own folder first on the
    import path as ``python PATH`` has it, and the modules it imported from this checkout
    outside the package dropped before the next (each must find its own helpers)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parent
    known: dict[str, tuple[int, str, str]] = {}
    root = tmp_path_factory.mktemp("help")

    def run(paths) -> dict:
        paths = [str(Path(p).resolve()) for p in paths]
        todo = [p for p in dict.fromkeys(paths) if p not in known]
        if todo:
            n = len(known)
            plan, dest = root / f"plan{n}.json", root / f"out{n}.json"
            plan.write_text(json.dumps(todo))
            (root / "runner.py").write_text(_HELP_RUNNER)
            env = {**os.environ, "PYTHONPATH": str(repo)}
            res = subprocess.run([sys.executable, str(root / "runner.py"), str(repo), str(plan),
                                  str(dest)], cwd=repo, env=env, capture_output=True,
                                 text=True, timeout=900)
            assert res.returncode == 0, f"the --help runner failed:\n{res.stderr[-3000:]}"
            known.update({k: tuple(v) for k, v in json.loads(dest.read_text()).items()})
        return {Path(p): known[p] for p in paths}

    return run
