"""Relative pose from your own match lists, in Python: matches -> graph -> StrLPose.

Examples:
    python examples/pose_from_matches.py                  # uses a generated pair's matches
    # SuperGlue's match_pairs.py output (stores no image sizes): give the images ...
    python examples/pose_from_matches.py --npz a_b_matches.npz --K 718,718,607,185 \\
        --image0 a.png --image1 b.png
    # ... or only their sizes (H W): the model then needs no pixels only if it has no
    # visual branch; otherwise the classical methods run alone, with a note
    python examples/pose_from_matches.py --npz a_b_matches.npz --K calib.txt --size 370 1226

The match file may be any layout `strl_pyg.data.external.load_external_matches` reads: strl-pyg's
own
(`strl-pose match`, PairMatches.save), `mkpts0/mkpts1[/mlines0/mlines1]`, SuperGlue
(`keypoints0/1`, `matches`, `match_confidence`), a LightGlue dict saved with
`np.savez(path, keypoints0=..., keypoints1=..., matches=..., scores=..., image_size0=...)`,
GlueStick or kornia arrays. In Python, LightGlue's three dicts go through
`strl_pyg.data.external.from_lightglue(feats0, feats1, matches01)`.

What each input is for:
  * image sizes (H, W): every layout needs them; they come from the file (strl, matched,
    LightGlue, GlueStick store them), from --image0/--image1, or from --size (both images)
    / --size0 / --size1. SuperGlue's match_pairs.py resizes to 640x480 unless run with
    `--resize -1`: its keypoints are then in the resized frame, so give that size and K.
  * images: the model's visual branch reads pixels at the matches (the shipped model does).
    Without them the model is skipped with a note and the classical methods run alone.
  * intrinsics: --K ('fx,fy,cx,cy', 9 numbers, or a file: a 3x3 matrix such as DeMoN's
    cam.txt, a 3x4 projection, or KITTI's calib.txt), else the file's K0/K1. The classical
    methods (OpenCV, PoseLib) need them; the model runs without, normalising by image size.

Bad input (an unknown layout, a missing size, a wrong path) ends with one error line, exit 2.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np


def _parser() -> argparse.ArgumentParser:
    from strl_pyg.training.checkpoints import default_checkpoint
    from strl_pyg.utils import OneLineArgumentParser

    # a bad command line or file is one `error: ...` line (exit 2), as in `strl-pose`
    ap = OneLineArgumentParser(description=__doc__,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--npz", help="match file (default: a generated pair)")
    ap.add_argument("--K", help="intrinsics of both images: 'fx,fy,cx,cy' or a file")
    ap.add_argument("--image0", help="reference image (sizes and pixels for the model)")
    ap.add_argument("--image1", help="target image")
    ap.add_argument("--size", type=int, nargs=2, metavar=("H", "W"),
                    help="size of both images, when the file stores none and no images are given")
    ap.add_argument("--size0", type=int, nargs=2, metavar=("H", "W"), help="size of image 0")
    ap.add_argument("--size1", type=int, nargs=2, metavar=("H", "W"), help="size of image 1")
    ap.add_argument("--checkpoint", default=str(default_checkpoint()))
    return ap


def _read_file_matches(args, ap):
    """The matches of ``--npz`` with the sizes, images and K of the flags."""
    from strl_pyg.cli.readers import read_image_file, read_intrinsics
    from strl_pyg.data.external import load_external_matches

    if (args.image0 is None) != (args.image1 is None):
        ap.error("Expected both --image0 and --image1 (got only "
                 f"{'--image0' if args.image0 else '--image1'})")
    if args.size is not None and (args.size0 is not None or args.size1 is not None):
        ap.error("Expected --size (both images) or --size0/--size1 (got both)")
    try:
        K = read_intrinsics(args.K) if args.K else None
        images = [read_image_file(p) for p in (args.image0, args.image1)] if args.image0 else None
        sizes = [args.size or s for s in (args.size0, args.size1)]
        if images is not None:
            sizes = [s or img.shape[:2] for s, img in zip(sizes, images, strict=True)]
        matches = load_external_matches(args.npz, image_size0=sizes[0], image_size1=sizes[1],
                                        K0=K, K1=K)
        if images is not None:  # checked against the sizes (flags or file) here
            matches = replace(matches, image0=images[0], image1=images[1])
    except (OSError, ValueError) as err:
        hint = ""
        if "image_size" in str(err) and "got none" in str(err):
            hint = ("; this layout stores no image sizes: give --image0/--image1, or "
                    "--size H W (both images) / --size0 H W --size1 H W")
        ap.error(f"{err}{hint}")
    return matches


def main(argv: list[str] | None = None) -> int:
    from strl_pyg.cli.guard import run_guarded

    ap = _parser()
    return run_guarded(lambda: _run(ap.parse_args(argv), ap))


def _run(args: argparse.Namespace, ap: argparse.ArgumentParser) -> int:
    import torch

    from strl_pyg import StrLPose
    from strl_pyg.estimation.classical import BASELINE_METHODS, estimate_relative_pose
    from strl_pyg.inference import forward_pose, prepare_graph

    if args.npz:
        matches, T_gt = _read_file_matches(args, ap), None
    else:
        from strl_pyg.synthetic import SceneConfig, generate_pair

        pair = generate_pair(2_000_101, SceneConfig(kind="indoor", noise_px=0.5))
        matches, T_gt = pair.matches, pair.T_0to1
    print(matches)

    try:
        model = StrLPose.load(args.checkpoint).eval()
    except (OSError, ValueError, RuntimeError) as err:
        ap.error(f"Expected a model checkpoint at '{args.checkpoint}' ({err})")
    needs_images = model.config.visual is not None
    if needs_images and not matches.has_images and not matches.has_intrinsics:
        ap.error(f"Expected --image0/--image1 for the model (visual={model.config.visual!r}) "
                 "or --K for the classical methods (got neither): nothing can run")

    np.set_printoptions(precision=4, suppress=True)
    if needs_images and not matches.has_images:
        print(f"note: the model reads pixels at the matches (visual={model.config.visual!r}) "
              "and the matches hold no images: Str-L Pose skipped, classical methods only; "
              "give --image0/--image1 to run it")
    else:
        # The graph as the checkpoint was trained: images converted to its patch channels,
        # resampled to its point and line counts.
        graph = prepare_graph(matches, model)
        print(graph)
        out = forward_pose(model, graph)
        print("T_0to1 (Str-L Pose):\n", out.T_0to1[0].numpy())
        print("sigma per component (q_w, q_x, q_y, q_z, t_x, t_y, t_z):",
              torch.exp(0.5 * out.log_var[0]).numpy())

    if not matches.has_intrinsics:
        print("note: no intrinsics (--K, or K0/K1 in the file): classical methods skipped")
    elif matches.num_points < 5:
        print(f"note: {matches.num_points} point matches, the classical methods need 5")
    else:
        for method, label in zip(BASELINE_METHODS, ("OpenCV MAGSAC", "PoseLib"), strict=True):
            try:
                res = estimate_relative_pose(matches, method=method)
            except ImportError as err:
                print(f"note: {label} skipped ({err})")
                continue
            if res.success:
                print(f"T_0to1 ({label}):\n", res.pose.matrix().numpy())
            else:
                print(f"{label}: no pose found")
    if T_gt is not None:
        print("T_0to1 (ground truth):\n", np.asarray(T_gt))
    return 0


if __name__ == "__main__":
    sys.exit(main())
