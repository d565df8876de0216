"""Large dense products of NumPy arrays, computed by PyTorch's BLAS.

NumPy's bundled OpenBLAS keeps its worker threads busy-waiting after every threaded product (for
up to about 2^28 cycles, its default thread timeout) before they sleep. In the front end the
next call is an OpenCV detector or LSD on the same cores, and those spinning threads take its
time: on this project's 2-core machine one 8 ms descriptor product made the SIFT detection
that follows it ~40 ms slower on a KITTI pair (1226x370) and ~30 ms on a 640x480 pair, and
``OPENBLAS_NUM_THREADS=1`` removed the gap. PyTorch's intra-op pool goes back to sleep almost
at once (the same product through it cost the next detection ~3 ms), so the front end's
products of more than a few thousand entries go through :func:`matmul`.

In a child process made by ``fork`` the product is NumPy's: PyTorch's OpenMP pool does not
survive a fork (a forked child hung in its first threaded product), OpenBLAS's does.
"""

from __future__ import annotations

import os

import numpy as np
import torch

__all__ = ["matmul"]

_FORKED = False


def _after_fork_in_child() -> None:
    global _FORKED
    _FORKED = True


if hasattr(os, "register_at_fork"):  # not on Windows (no fork there)
    os.register_at_fork(after_in_child=_after_fork_in_child)


def _operand(x: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(x)
    if x.dtype.kind == "f" and not x.dtype.isnative:
        x = x.astype(x.dtype.newbyteorder("="))
    if x.dtype not in (np.float32, np.float64):
        raise ValueError(f"Expected {name} as a float32 or float64 array (got {x.dtype})")
    return x


def _tensor(x: np.ndarray) -> torch.Tensor:
    # torch.from_numpy shares memory; it refuses negative strides and warns on read-only
    # arrays, so those are copied first
    if not x.flags.writeable or any(s < 0 for s in x.strides):
        x = np.array(x, copy=True)
    return torch.from_numpy(x)


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for 2-D arrays ``a [N, K]`` and ``b [K, M]`` of one floating dtype (float32 or
    float64), as a new NumPy array ``[N, M]`` of that dtype.

    The sums may round differently from NumPy's (another BLAS kernel): exact wherever every
    partial sum is exactly representable (e.g. integer-valued SIFT descriptors in float32),
    unless PyTorch is told to compute float32 products in lower precision (e.g.
    ``torch.backends.mkldnn.matmul.fp32_precision = "bf16"``, a process-wide setting).
    """
    a, b = _operand(a, "a"), _operand(b, "b")
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[0]:
        raise ValueError(f"Expected a [N, K] and b [K, M] (got {a.shape} and {b.shape})")
    if a.dtype != b.dtype:
        raise ValueError(f"Expected a and b of one dtype (got {a.dtype} and {b.dtype})")
    if a.size == 0 or b.size == 0:
        return np.zeros((a.shape[0], b.shape[1]), a.dtype)
    if _FORKED:
        return a @ b
    return (_tensor(a) @ _tensor(b)).numpy()
