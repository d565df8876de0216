"""``strl-pose scene`` with one worker process against two, on the same collection, in the same
run (fresh output folders: features and pairs both computed). Nothing else should run.

    python benchmarks/studies/time_scene_workers.py --scene study_room --images 50 --window 2
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from strl_bench_common import banner  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "real_scenes"


def main() -> None:
    from strl_pyg.collection import SceneOptions, read_collection, run_scene, sequential_pairs
    from strl_pyg.datasets.camera_files import read_real_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="study_room")
    ap.add_argument("--images", type=int, default=50)
    ap.add_argument("--window", type=int, default=2)
    args = ap.parse_args()
    print(banner())
    posed = read_real_scene(DATA / args.scene)[:args.images]
    images = read_collection(DATA / args.scene / "images",
                             names=[Path(p.path).name for p in posed], cameras=DATA / args.scene)
    pairs = sequential_pairs(len(images), args.window)
    seconds = {}
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            s = run_scene(images, pairs, d, SceneOptions(workers=workers, progress=False,
                                                         database=False))
            seconds[workers] = time.perf_counter() - t
            print(f"{workers} worker(s): {seconds[workers]:.1f} s, {s.pairs_computed} pairs, "
                  f"features {s.features_computed}", flush=True)
    print(f"{args.scene}, {len(images)} images, {len(pairs)} pairs (sequential:{args.window}): "
          f"two processes {seconds[1] / seconds[2]:.2f}x one")


if __name__ == "__main__":
    main()
