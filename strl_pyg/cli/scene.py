"""``strl-pose scene``: a photo collection to a relative pose per pair, a table and a COLMAP
database (:func:`strl_pyg.collection.run_scene`)."""

from __future__ import annotations

import argparse
import json
import os

from strl_pyg.utils import UsageError

__all__ = ["add_scene_arguments", "cmd_scene"]

_PAIRS_HELP = ("'exhaustive' (every pair), 'sequential:N' (each image with its next N), or a "
               "pairs file: hloc's 'name0 name1' lines or SuperGlue's pairs_with_gt lines (a K "
               "per pair)")


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    from strl_pyg.cli.readers import MATCHER_PRESETS

    p.add_argument("images", help="the image folder (images found recursively)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created; rerun the same command to resume it)")
    p.add_argument("--pairs", default="exhaustive", help=_PAIRS_HELP + " (default exhaustive)")
    cams = p.add_mutually_exclusive_group()
    cams.add_argument("--K", help="one K for every image: 'fx,fy,cx,cy', 9 numbers or a file "
                                  "(as predict --K)")
    cams.add_argument("--cameras", metavar="PATH",
                      help="each image's camera: a COLMAP database (.db), or a folder with a "
                           "COLMAP model (sparse/0), transforms.json or cameras.json (lens "
                           "distortion of SIMPLE_RADIAL, RADIAL, OPENCV is undistorted)")
    p.add_argument("--images-list", metavar="FILE",
                   help="only these image names (one per line; default: every image)")
    p.add_argument("--workers", type=int, default=1,
                   help="worker processes, each one thread (default 1; under torchrun each "
                        "rank is one)")
    p.add_argument("--matcher", choices=MATCHER_PRESETS, default=None,
                   help="front-end preset (default: the FrontendConfig defaults, adaptive)")
    p.add_argument("--detector", choices=("sift", "orb"), default="sift")
    from strl_pyg.inference.status import Status

    p.add_argument("--verified", default=Status.OK.value,
                   help="comma-separated statuses written to the database as verified "
                        "two-view geometries (default 'ok'; e.g. 'ok,unreliable')")
    p.add_argument("--no-database", action="store_true",
                   help="skip the COLMAP database (no pycolmap needed)")
    p.add_argument("--checkpoint", default=None, help="default: the shipped weights")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def _pairs(args, names: list[str]):
    from strl_pyg.collection import exhaustive_pairs, read_pairs_file, sequential_pairs

    spec = args.pairs
    if spec == "exhaustive":
        return exhaustive_pairs(len(names))
    if spec.startswith("sequential"):
        _, _, n = spec.partition(":")
        try:
            return sequential_pairs(len(names), int(n or 5))
        except ValueError as err:
            raise UsageError(f"Expected --pairs sequential:N with N >= 1 (got {spec!r}: "
                             f"{err})") from None
    return read_pairs_file(spec, names)


def cmd_scene(args) -> int:
    """Runs the scene; prints the summary as JSON. Exit 0 (1 when some pair gave an error)."""
    from strl_pyg.cli.readers import frontend_config, read_intrinsics
    from strl_pyg.collection import SceneOptions, read_collection, run_scene
    from strl_pyg.inference.status import STATUSES

    verified = tuple(s.strip() for s in args.verified.split(",") if s.strip())
    bad = [s for s in verified if s not in STATUSES]
    if bad or not verified:
        raise UsageError(f"Expected --verified statuses among {list(STATUSES)} (got "
                         f"{args.verified!r})")
    if args.workers < 1:
        raise UsageError(f"Expected --workers >= 1 (got {args.workers})")
    try:
        names = None
        if args.images_list:
            with open(args.images_list) as f:
                names = [ln.strip() for ln in f if ln.strip() and not ln.startswith("#")]
        K = read_intrinsics(args.K) if args.K else None
        images = read_collection(args.images, names=names, K=K, cameras=args.cameras)
        pairs = _pairs(args, [im.name for im in images])
    except (OSError, ValueError) as err:
        raise UsageError(str(err).splitlines()[0]) from None
    if not args.no_database:
        try:
            import pycolmap  # noqa: F401
        except ImportError:
            raise UsageError("Expected pycolmap for the COLMAP database (got none installed): "
                             "pip install 'strl-pyg[collection]', or pass --no-database") from None
    model = None
    if args.checkpoint:
        from strl_pyg.cli.readers import load_model

        model = load_model(args.checkpoint)
    options = SceneOptions(frontend=frontend_config(args), model=model, workers=args.workers,
                           verified=verified, database=not args.no_database,
                           progress=not args.quiet)
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        from strl_pyg.collection.distributed import run_scene_distributed

        summary = run_scene_distributed(images, pairs, args.out, options)
    else:
        summary = run_scene(images, pairs, args.out, options)
    if summary is not None:
        print(json.dumps(summary.to_dict(), indent=1))
        return 1 if summary.statuses.get("error") else 0
    return 0

