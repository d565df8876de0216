"""Building the posed-photo training cache with each image's features computed once per
process (``strl_pyg.datasets.base.image_features``) against detecting them again for every
pair (``FEATURE_CACHE_IMAGES = 0``), on one real_scenes scene with gaps 1-8, in one process,
in the same run. Nothing else should run.

    python benchmarks/studies/time_posed_cache.py --scene robot_table --images 24
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


def build(scene: str, images: int, gaps: tuple[int, ...], cached: int) -> tuple[float, int]:
    import strl_pyg.datasets.base as base
    from strl_pyg.datasets.camera_files import read_real_scene
    from strl_pyg.datasets.posed import PosedImagePairs, PosedPairOptions

    base.FEATURE_CACHE_IMAGES = cached
    base._FEATURES.clear()
    posed = read_real_scene(DATA / scene)[:images]
    with tempfile.TemporaryDirectory() as d:
        ds = PosedImagePairs([(scene, posed)], cache_dir=d,
                             pairs=PosedPairOptions(gaps=gaps, min_covisible=0.0,
                                                    max_rotation_deg=180.0,
                                                    max_axis_angle_deg=180.0))
        t = time.perf_counter()
        report = ds.build_cache(progress=False)
        return time.perf_counter() - t, report.computed + report.failed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="robot_table")
    ap.add_argument("--images", type=int, default=24)
    ap.add_argument("--gaps", default="1,2,3,4,5,6,7,8")
    args = ap.parse_args()
    gaps = tuple(int(g) for g in args.gaps.split(","))
    print(banner())
    per_pair, n = build(args.scene, args.images, gaps, 0)
    once, m = build(args.scene, args.images, gaps, 48)
    assert n == m
    print(f"{args.scene}, first {args.images} images, gaps {args.gaps}: {n} pairs; "
          f"features per pair {per_pair:.1f} s, once per image {once:.1f} s: "
          f"{per_pair / once:.2f}x faster")


if __name__ == "__main__":
    main()
