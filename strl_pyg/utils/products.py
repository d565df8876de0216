"""Large dense products of NumPy arrays, computed by PyTorch's BLAS.

NumPy's bundled OpenBLAS keeps its worker threads busy-waiting after every threaded product (for
up to about 2^28 cycles, its default thread timeout) before they sleep. In the front end the
next call is an OpenCV detector or LSD on the same cores, and those spinning threads take its
time: on this project's 2-core machine one 8 ms descriptor product made the SIFT detection
that follows it ~40 ms slower on a KITTI pair (1226x370) and ~30 ms on a 640x480 pair, and
``OPENBLAS_NUM_THREADS=1`` removed the gap. PyTorch's intra-op pool goes back to sleep almost
at once (the same product through it cost the next detection ~3 ms), so the front end's
products of more than a few thousand entries go through :func:`matmul`.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["matmul"]


def _tensor(x: np.ndarray) -> torch.Tensor:
    # torch.from_numpy shares memory; a read-only array (e.g. a broadcast view) is copied first
    return torch.from_numpy(x if x.flags.writeable else x.copy())


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for 2-D arrays ``a [N, K]`` and ``b [K, M]`` of one floating dtype (float32 or
    float64), as a new NumPy array ``[N, M]`` of that dtype.

    The sums may round differently from NumPy's (another BLAS kernel): exact wherever every
    partial sum is exactly representable (e.g. integer-valued SIFT descriptors in float32).
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[0]:
        raise ValueError(f"Expected a [N, K] and b [K, M] (got {a.shape} and {b.shape})")
    if a.dtype != b.dtype or a.dtype not in (np.float32, np.float64):
        raise ValueError(f"Expected two float32 or two float64 arrays (got {a.dtype} and "
                         f"{b.dtype})")
    if a.size == 0 or b.size == 0:
        return np.zeros((a.shape[0], b.shape[1]), a.dtype)
    return (_tensor(a) @ _tensor(b)).numpy()
