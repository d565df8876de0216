"""The ``strl-pose`` command line.

Subcommands: ``demo`` (the main job on an embedded default: a generated pair goes through
matching, graph and model), ``match``, ``predict``, ``train``, ``evaluate``, ``bench`` and
``export``.
Every error in the user's input ends with a one-line ``error: Expected ... (got ...)`` on
stderr and exit code 2 (no traceback): bad flags and values, missing files, folders given as
files, undecodable images, bad intrinsics, empty or foreign match files, checkpoints that are
corrupt or would need code to load (refused: all checkpoints load with ``weights_only=True``),
and outputs that cannot be written (checked before any work). ``predict`` exits with 0 for a
pose with status ``ok``, 1 for no pose, 3 for an ``unreliable`` one (computed, not to use:
see ``strl-pose predict --help``); output cut short by a closed stdout (``| head``) ends
quietly with 141.

Large images are downscaled for matching so that their longer side is at most ``--max-side``
pixels (default :data:`MAX_SIDE`; ``0`` keeps the full resolution), with the intrinsics scaled
by the same factors under the package's pixel-centre convention (centre of the top-left pixel
at ``(0, 0)``: ``x' = (x + 0.5) s - 0.5``). Saved matches are mapped back to the original
pixel frame; the relative pose does not depend on the image scale.

``strl-pose --help`` and argument errors return without importing torch: the parser is built
from torch-free modules and every command imports its heavy modules when it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from strl_pyg.cli.guard import run_guarded
from strl_pyg.cli.predict import (
    EXIT_CODES,
    check_file_arg,
    cmd_predict,
    format_pose,
    jsonable,
    pose_errors,
    predict_pair,
)
from strl_pyg.cli.readers import (
    DEMO_SEED,
    MATCHER_PRESETS,
    MAX_SIDE,
    bootstrap_count,
    check_input_file,
    frontend_config,
    load_model,
    non_negative_int,
    read_pair,
)
from strl_pyg.inference.status import Status
from strl_pyg.synthetic.config import LINE_SCENE_KINDS
from strl_pyg.utils import OneLineArgumentParser, UsageError

__all__ = ["main", "check_train_files", "build_parser"]


# ----------------------------------------------------------------------------- subcommands
def cmd_demo(args) -> int:
    from strl_pyg.utils.io import check_output_dir

    check_output_dir(args.out, "a folder for --out")  # before any work
    from strl_pyg.frontend import match_images
    from strl_pyg.geometry import epipolar_residuals
    from strl_pyg.synthetic import SceneConfig, generate_pair
    from strl_pyg.viz.matches import save_matches_png

    model = load_model(args.checkpoint)
    pair = generate_pair(args.seed, SceneConfig(kind=args.kind))
    print(f"generated pair: kind={args.kind}, seed={args.seed}, "
          f"{pair.image0.shape[0]}x{pair.image0.shape[1]} px (H x W; held out from training)")
    matches = match_images(pair.image0, pair.image1, K0=pair.K, K1=pair.K)
    tm = matches.info.get("timings_ms", {})
    print(f"front end: {matches.num_points} points, {matches.num_lines} lines "
          f"in {tm.get('total', float('nan')):.0f} ms")
    pred = predict_pair(model, matches, warmup=True)  # warm-up: steady-state times below
    from strl_pyg.inference.estimator import PoseEstimator

    est = PoseEstimator(model).estimate(matches)  # every method
    T_gt = pair.T_0to1
    print(f"\n{'method':<14} {'status':<10} {'rot err':>8} {'t err':>8} {'ms':>7}   pose")
    print(f"{'ground truth':<14} {'':<10} {0.0:8.3f} {0.0:8.3f} {'-':>7}   {format_pose(T_gt)}")
    report = {}
    for name, r in est.methods.items():  # registry names: one method, one name
        if r.T_0to1 is None:
            print(f"{name:<14} {r.status:<10} {'-':>8} {'-':>8} {r.time_ms:7.1f}   "
                  f"{'; '.join(r.warnings)}")
            continue
        rot, tr = pose_errors(r.T_0to1, T_gt)
        print(f"{name:<14} {r.status:<10} {rot:8.3f} {tr:8.3f} {r.time_ms:7.1f}   "
              f"{format_pose(r.T_0to1)}")
        report[name] = {"rot_err_deg": rot, "trans_err_deg": tr, "status": r.status}
    s = pred["sigma"]
    print(f"\npredicted sigma (regression): quaternion {np.array2string(s[:4], precision=4)}, "
          f"translation {np.array2string(s[4:], precision=4)}")
    print(f"recommended pose: {est.status}" + (f", from {est.pose.method}" if est.pose.method
                                               else "")
          + "".join(f"\nwarning: {w}" for w in est.warnings))
    if est.pose.sigma is not None and est.status == Status.OK:
        kind = est.pose.info.get("covariance", "network log-variance")
        print(f"recommended pose's sigma ({kind}): rotation "
              f"{est.pose.sigma['rotation_deg']:.3f} deg, translation direction "
              f"{est.pose.sigma['translation_deg']:.3f} deg")
    p_err, l_err = epipolar_residuals(matches, T_gt)
    out = Path(args.out)
    png = save_matches_png(
        out / "demo_matches.png", matches, point_inliers=p_err < 2.0, line_inliers=l_err < 2.0,
        layout="horizontal", max_points=200, max_lines=60, max_connectors=25, legend=True,
        title=f"strl-pose demo ({args.kind}, seed {args.seed}): matches; inlier = epipolar "
              "error < 2 px under the true pose")
    print(f"matches drawn (green: epipolar error < 2 px under the true pose): {png}")
    if args.json:
        print(json.dumps({**est.to_dict(), "prediction": jsonable(pred), "errors": report}))
    return 0


def _match(inputs, args):
    from strl_pyg.frontend import match_images

    img0, img1, K0, K1 = inputs
    return match_images(img0, img1, K0=K0, K1=K1, config=frontend_config(args))


def cmd_match(args) -> int:
    check_file_arg(args.out, "--out", "matches.npz")  # before any work
    if args.png:
        check_file_arg(args.png, "--png", "matches.png")
    inputs = read_pair(args)
    from strl_pyg.viz.matches import save_matches_png

    matches = inputs.to_original_frame(_match(inputs, args))
    path = matches.save(args.out)
    print(f"{matches.num_points} points, {matches.num_lines} lines -> {path}")
    if args.png:
        inliers = fundamental_inliers(matches)
        title = ("no fundamental matrix found: every match drawn as an outlier" if inliers is None
                 else f"green: {int(inliers.sum())} of {matches.num_points} point matches fit "
                      "the pair's fundamental matrix (MAGSAC, 1 px)")
        mask = inliers if inliers is not None else np.zeros(matches.num_points, bool)
        png = save_matches_png(args.png, matches, point_inliers=mask, title=title, legend=True)
        print(f"drawing -> {png}")
    return 0


def fundamental_inliers(matches) -> np.ndarray | None:
    """The point matches within 1 px of the pair's fundamental matrix
    (:func:`~strl_pyg.estimation.classical.fundamental_matrix`), as ``match --png`` colours
    them; ``None`` with too few matches or no F."""
    from strl_pyg.estimation.classical import fundamental_matrix

    found = fundamental_matrix(matches)
    return None if found is None else found[1]


def cmd_methods(args) -> int:
    """The registered pose methods as a Markdown table (docs/methods.md holds the built-in
    ones'), and those not installed here."""
    from strl_pyg.inference.registry import METHODS, methods_table

    print(methods_table())
    missing = [n for n, m in METHODS.items() if not m.available()]
    if missing:
        print(f"not installed here: {', '.join(missing)}")
    return 0


def cmd_rules(args) -> int:
    """The rules on a pose as a Markdown table (docs/rules.md holds the built-in ones')."""
    from strl_pyg.inference.rules import rules_table

    print(rules_table())
    return 0


def cmd_train(args, parser, argv: list[str] | None = None) -> int:
    check_train_files(args)  # before torch is imported
    from strl_pyg.training import run_from_args

    return run_from_args(args, parser, argv)


def check_train_files(args) -> None:
    """Checks the files a training run needs (``--out`` writable, ``--init-from`` present,
    ``<out>/last.pt`` for ``--resume``) before torch is imported; raises ``UsageError`` /
    ``OSError`` with one-line messages."""
    from strl_pyg.utils.io import check_output_dir

    check_output_dir(args.out, "a run folder for --out")
    if args.init_from and not args.init_from.startswith("shipped:"):
        check_input_file(args.init_from, "weights file for --init-from")
    if args.resume:
        check_input_file(Path(args.out) / "last.pt", "training checkpoint for --resume")


def cmd_evaluate(argv: list[str]) -> int:
    pre = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    pre.add_argument("--out", nargs="?", default=None)  # a missing value is the real
    pre.add_argument("--checkpoint", nargs="?", default=None)  # parser's to report
    known, _ = pre.parse_known_args(argv)
    if known.out:
        from strl_pyg.utils.io import check_output_dir

        check_output_dir(known.out, "a folder for --out")  # before any work
    if known.checkpoint:
        check_input_file(known.checkpoint, "model checkpoint for --checkpoint")
    try:
        from strl_pyg.evaluation.run import main as evaluate_main
    except ImportError as err:
        raise UsageError(f"Expected strl_pyg.evaluation.run to be importable (got {err})") from err
    return int(evaluate_main(argv, prog="strl-pose evaluate") or 0)


# ----------------------------------------------------------------------------- parser
def _image_size(text: str) -> tuple[int, int]:
    """argparse type of ``--image-size``: ``H,W`` in pixels."""
    try:
        h, w = (int(v) for v in text.replace("x", ",").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"Expected H,W in pixels (got {text!r})") from None
    if h < 1 or w < 1:
        raise argparse.ArgumentTypeError(f"Expected H,W >= 1 (got {text!r})")
    return h, w


def _add_pair_args(p: argparse.ArgumentParser, optional_images: bool = False) -> None:
    nargs = "?" if optional_images else None
    p.add_argument("image0", nargs=nargs, help="reference image")
    p.add_argument("image1", nargs=nargs, help="target image")
    p.add_argument("--K", help="intrinsics of both images: 'fx,fy,cx,cy', 9 numbers or a file "
                               "(3x3, 3x4, KITTI calib.txt, COLMAP cameras.txt, Strecha "
                               ".camera); or a posed scene's cameras, each image's K found "
                               "by its path, else its file name (transforms.json, "
                               "real_scenes cameras.json, a COLMAP / LLFF scene folder)")
    p.add_argument("--K0", help="intrinsics of image 0 (same formats)")
    p.add_argument("--K1", help="intrinsics of image 1 (default: --K0)")
    p.add_argument("--detector", choices=("sift", "orb"), default="sift")
    p.add_argument("--matcher", choices=MATCHER_PRESETS, default=None,
                   help="front-end preset: 'fast', 'thorough' (more, smaller features: "
                        "wide pairs), 'adaptive' (fast, thorough where the first pass has "
                        "few inliers) or 'legacy' (default: the FrontendConfig defaults)")
    p.add_argument("--max-side", type=non_negative_int, default=MAX_SIDE, metavar="PX",
                   help=f"downscale images whose longer side exceeds PX for matching, K scaled "
                        f"alike (default {MAX_SIDE}; 0: full resolution)")


def build_parser() -> argparse.ArgumentParser:
    """The ``strl-pose`` parser; building it imports neither torch nor the training code."""
    from strl_pyg.training.config import add_train_arguments

    ap = OneLineArgumentParser(prog="strl-pose", description=__doc__,
                               formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="the main job on a generated pair (no downloads)")
    p.add_argument("--seed", type=non_negative_int, default=DEMO_SEED)
    p.add_argument("--kind", choices=LINE_SCENE_KINDS, default="street")
    p.add_argument("--checkpoint", default=None, help="default: the shipped weights")
    p.add_argument("--out", default="outputs/demo", help="folder for the match drawing")
    p.add_argument("--json", action="store_true", help="also print the result as JSON")
    p = sub.add_parser("match", help="match points and lines of two images into a .npz")
    _add_pair_args(p)
    p.add_argument("--out", required=True, help="output .npz (PairMatches.save keys)")
    p.add_argument("--png", default=None, help="also draw the matches to this PNG")
    p = sub.add_parser("predict", help="relative pose of two images, or of a match file",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="exit codes:\n" + "\n".join(
                           f"  {k:<4} {v}" for k, v in EXIT_CODES.items()))
    _add_pair_args(p, optional_images=True)
    p.add_argument("--matches", default=None, metavar="FILE",
                   help="estimate from this match file instead of two images: 'strl-pose "
                        "match' output, or SuperGlue / LightGlue / GlueStick / kornia / mkpts "
                        ".npz (docs/match_formats.md)")
    p.add_argument("--image-size", default=None, type=_image_size, metavar="H,W",
                   help="with --matches: the images' size when the file holds none")
    p.add_argument("--checkpoint", default=None, help="default: the shipped weights")
    p.add_argument("--json", action="store_true", help="print JSON only")
    p.add_argument("--no-baseline", action="store_true", help="the network's regression only")
    p.add_argument("--methods", default="recommended", metavar="M",
                   help="'recommended' (default: the checkpoint's recommended order, stopping "
                        "at the first 'ok' method), 'all', or names, e.g. 'regression,opencv'")
    p.add_argument("--pairs", default=None, metavar="FILE",
                   help="many pairs: a text file of 'image0 image1' lines (hloc's pairs "
                        "format), names relative to --image-dir; one JSON line per pair")
    p.add_argument("--image-dir", default=".", metavar="DIR",
                   help="with --pairs: the folder the names are relative to")
    p.add_argument("--png", default=None,
                   help="also draw the matches, coloured by the recommended pose's support")
    p.add_argument("--explain", default=None, metavar="PNG",
                   help="also draw which matches and lines drove the network's pose "
                        "(strl_pyg.explain), coloured by importance")
    p.add_argument("--explainer", default="saliency", choices=("saliency", "attention", "gnn"),
                   help="with --explain: the pose's gradient per match (default), the "
                        "attention the network pays each match, or PyG's GNNExplainer")
    p.add_argument("--threshold-px", type=float, default=1.0, metavar="PX",
                   help="inlier threshold of the solvers and the support check (default 1)")
    p.add_argument("--bootstrap", type=bootstrap_count, default=8, metavar="N",
                   help="resamples behind the PoseLib/OpenCV covariance (default 8, the "
                        "calibrated setting; 0: first-order covariance only, faster)")
    sub.add_parser("methods", help="the pose methods predict --methods takes, with what each "
                                   "needs (installed packages' methods included)")
    sub.add_parser("rules", help="the rules that decide a pose's status and widen its sigma, "
                                 "in the order they run (installed packages' rules included)")
    p = sub.add_parser("train", help="train a model (see examples/train.py)")
    add_train_arguments(p)
    sub.add_parser("evaluate", help="evaluate a checkpoint (see examples/evaluate.py)",
                   add_help=False)
    p = sub.add_parser("scene", help="a photo collection: a pose per pair, a table and a COLMAP "
                                     "database for COLMAP's / GLOMAP's mappers")
    from strl_pyg.cli.scene import add_scene_arguments

    add_scene_arguments(p)
    p = sub.add_parser("bench", help="time the pipeline stages on this machine")
    p.add_argument("--checkpoint", default=None)
    p.add_argument("--repeat", type=int, default=20)
    p = sub.add_parser("export", help="the model's regression path as ONNX (needs [onnx])")
    p.add_argument("--onnx", required=True, metavar="PATH", help="output .onnx file")
    p.add_argument("--checkpoint", default=None, help="default: the shipped weights")
    return ap


#: Options whose value may begin with '-' (a negative number leads an intrinsics list).
_SIGNED_VALUE_OPTIONS = ("--K", "--K0", "--K1")


def _join_signed_values(argv: list[str]) -> list[str]:
    """``--K -293,...`` as ``--K=-293,...``: argparse reads a value that begins with '-'
    and is not a plain number as an option ('expected one argument')."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in _SIGNED_VALUE_OPTIONS and i + 1 < len(argv) and \
                len(argv[i + 1]) > 1 and argv[i + 1][0] == "-" and argv[i + 1][1] in "0123456789.":
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def _dispatch(argv: list[str]) -> int:
    if argv[:1] == ["evaluate"]:
        return cmd_evaluate(argv[1:])
    argv = _join_signed_values(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "train":
        return cmd_train(args, parser, argv)
    if args.command == "methods":
        return cmd_methods(args)
    if args.command == "rules":
        return cmd_rules(args)
    if args.command == "bench":
        from strl_pyg.cli.bench import cmd_bench

        return cmd_bench(args)
    if args.command == "scene":
        from strl_pyg.cli.scene import cmd_scene

        return cmd_scene(args)
    if args.command == "export":
        from strl_pyg.cli.export import cmd_export

        return cmd_export(args)
    return {"demo": cmd_demo, "match": cmd_match, "predict": cmd_predict}[args.command](args)


def main(argv: list[str] | None = None) -> int:
    """The ``strl-pose`` entry point; returns the exit code (0, or 2 for a user error)."""
    return run_guarded(_dispatch, list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
