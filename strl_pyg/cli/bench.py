"""``strl-pose bench``: a quick profile of the front end, graph building and the model
forward at batch 1 and 16 on a generated pair."""

from __future__ import annotations

import os
import time

from strl_pyg.cli.readers import DEMO_SEED, load_model
from strl_pyg.utils import UsageError

__all__ = ["cmd_bench"]


def cmd_bench(args) -> int:
    import platform

    import torch
    from torch_geometric.loader.dataloader import Collater

    from strl_pyg.data import FixedSizeResample, build_pair_graph
    from strl_pyg.frontend import match_images
    from strl_pyg.synthetic import SceneConfig, generate_pair

    model = load_model(args.checkpoint)
    print(f"python {platform.python_version()}, torch {torch.__version__}, "
          f"{os.cpu_count()} cores, {torch.get_num_threads()} threads; model {model!r}")
    pair = generate_pair(DEMO_SEED, SceneConfig())

    def timed(fn, n):
        fn()
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        return (time.perf_counter() - t0) / n * 1e3

    n = args.repeat
    if n < 1:
        raise UsageError(f"Expected a positive --repeat (got {n})")
    ms_match = timed(lambda: match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K),
                     max(1, n // 5))
    m = pair.matches
    ms_graph = timed(lambda: FixedSizeResample(seed=0)(build_pair_graph(m)), n)
    g = FixedSizeResample(seed=0)(build_pair_graph(m))
    b16 = Collater(None)([g] * 16)
    with torch.no_grad():
        ms_b1 = timed(lambda: model(g), n)
        ms_b16 = timed(lambda: model(b16), max(1, n // 4))
    print("\n| stage (192x640, 384 points + 192 lines) | ms |\n|---|---|")
    print(f"| front end (SIFT + LSD + line matching) | {ms_match:.1f} |")
    print(f"| graph build + resample | {ms_graph:.2f} |")
    print(f"| model forward, batch 1 | {ms_b1:.2f} |")
    print(f"| model forward, batch 16 (per pair) | {ms_b16 / 16:.2f} |")
    return 0
