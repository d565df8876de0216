"""Relative pose from your own match lists, in Python: matches -> graph -> StrLPose.

Example:
    python examples/pose_from_matches.py                  # uses a generated pair's matches
    python examples/pose_from_matches.py --npz m.npz      # a file from `strl-pose match` or
                                                          # PairMatches.save / GlueStick arrays

The match file may be any layout `strl_pyg.data.load_external_matches` reads (strl-pyg's own,
`mkpts0/mkpts1[/mlines0/mlines1]`, or raw GlueStick/LightGlue output); give --K and --size
when the file holds no intrinsics or image sizes.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

from strl_pyg import StrLPose, build_pair_graph
from strl_pyg.baselines import estimate_relative_pose
from strl_pyg.cli import default_checkpoint, read_intrinsics
from strl_pyg.data import FixedSizeResample, load_external_matches
from strl_pyg.evaluation import prepare_matches


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--npz", help="match file (default: a generated pair)")
    ap.add_argument("--K", help="intrinsics of both images: 'fx,fy,cx,cy' or a file")
    ap.add_argument("--size", type=int, nargs=2, metavar=("H", "W"), help="image size")
    ap.add_argument("--checkpoint", default=str(default_checkpoint()))
    args = ap.parse_args(argv)

    if args.npz:
        K = read_intrinsics(args.K) if args.K else None
        matches = load_external_matches(args.npz, image_size0=args.size, image_size1=args.size,
                                        K0=K, K1=K)
        T_gt = None
    else:
        from strl_pyg.synthetic import SceneConfig, generate_pair

        pair = generate_pair(2_000_101, SceneConfig(kind="indoor", noise_px=0.5))
        matches, T_gt = pair.matches, pair.T_0to1
    print(matches)

    model = StrLPose.load(args.checkpoint).eval()
    # Images (if any) converted to what the model's pixel encoder expects.
    matches, patch = prepare_matches(matches, model)
    graph = build_pair_graph(matches, patch_size=patch)
    graph = FixedSizeResample(384, 192, seed=0)(graph)  # the counts the model was trained on
    print(graph)
    with torch.no_grad():
        out = model(graph)
    np.set_printoptions(precision=4, suppress=True)
    print("T_0to1 (Str-L Pose):\n", out.T_0to1[0].numpy())
    print("sigma per component (q_w, q_x, q_y, q_z, t_x, t_y, t_z):",
          torch.exp(0.5 * out.log_var[0]).numpy())
    if matches.has_intrinsics and matches.num_points >= 5:
        res = estimate_relative_pose(matches, method="opencv")
        print("T_0to1 (OpenCV MAGSAC):\n", res.pose.matrix().numpy())
    if T_gt is not None:
        print("T_0to1 (ground truth):\n", np.asarray(T_gt))
    return 0


if __name__ == "__main__":
    sys.exit(main())
