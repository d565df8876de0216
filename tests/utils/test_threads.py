"""The process-wide thread pools (strl_pyg.utils.threads) and their users."""

from __future__ import annotations

import multiprocessing as mp
import os

import pytest

from strl_pyg.frontend.points import on_both
from strl_pyg.utils.threads import available_cores, shared_pool


def _child(queue) -> None:
    import numpy as np

    from strl_pyg.utils.products import matmul
    from strl_pyg.utils.threads import shared_pool

    a = np.ones((600, 600), np.float32)
    queue.put((on_both(lambda x: 10 * x, 1, 2),
               shared_pool("bootstrap", 2).submit(lambda: "solved").result(),
               float(matmul(a, a)[0, 0])))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
def test_pools_work_in_a_forked_child():
    # the child inherits the pool objects but not their threads: before the fix a task
    # submitted there waited forever (a DataLoader worker calling the front end hung)
    import numpy as np

    from strl_pyg.utils.products import matmul

    assert on_both(lambda x: x + 1, 1, 2) == (2, 3)  # the parent's pools exist
    assert shared_pool("bootstrap", 2).submit(lambda: 1).result() == 1
    a = np.ones((600, 600), np.float32)  # and torch's OpenMP threads (with >1 core), which a
    assert float(matmul(a, a)[0, 0]) == 600.0  # forked child cannot use: NumPy's product there
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(queue,))
    proc.start()
    proc.join(60)
    hung = proc.is_alive()
    if hung:
        proc.kill()
    assert not hung, "a forked child's pool never ran its task"
    assert proc.exitcode == 0 and queue.get(timeout=5) == ((10, 20), "solved", 600.0)


def test_shared_pool_grows_and_refuses_bad_sizes():
    small = shared_pool("test-grow", 1)
    assert shared_pool("test-grow", 1) is small
    big = shared_pool("test-grow", 3)
    assert big is not small and shared_pool("test-grow", 2) is big
    assert sorted(big.map(lambda x: x * x, range(5))) == [0, 1, 4, 9, 16]
    with pytest.raises(ValueError, match=r"Expected a pool size as an integer >= 1 \(got 0\)"):
        shared_pool("test-grow", 0)
    assert available_cores() >= 1
