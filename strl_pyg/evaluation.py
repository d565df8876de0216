"""Evaluation of a Str-L Pose checkpoint against the classical baselines and the fused pose,
on the same matches, with the paper's tables; also the ``strl-pose evaluate`` command line.

Per pair (:class:`~strl_pyg.eval_pairs.EvalPair`: matches, ground-truth ``T_0to1``, subset,
id) every method in :data:`METHODS` estimates ``T_0to1`` (``X1 = R X0 + t``):

* ``"strl"``: the network, on the graph of :func:`~strl_pyg.data.build_pair_graph` built from
  the matches (patches greyscale when the model's ``patch_features`` is 1, grey replicated to
  RGB when it is 3), resampled to ``(384, 192)`` points/lines with
  :class:`~strl_pyg.data.transforms.FixedSizeResample` seeded by ``seed + pair index`` (so a
  pair's graph does not depend on the order or the other pairs), or not resampled with
  ``resample=None``;
* ``"opencv"``, ``"poselib"``: :func:`~strl_pyg.baselines.estimate_relative_pose`;
* ``"fused_opencv"``, ``"fused_poselib"``: :func:`~strl_pyg.pose_fusion.fuse_poses` of the
  network with that baseline.

The job is in three modules: the pairs (:mod:`strl_pyg.eval_pairs`: generated, DeMoN, KITTI),
running the methods over them (this module: :func:`evaluate_pairs`, and :func:`main`, the
command line), and the report (:mod:`strl_pyg.eval_report`: errors, the tables, KITTI
trajectories and drift, markdown / JSON / PNG files). Every public name of the other two is
re-exported here.

Command-line errors (a bad flag or value, a missing checkpoint or data folder, no pairs) are
one ``error: Expected ... (got ...)`` line on stderr and exit code 2, as in every other
``strl-pose`` command.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from strl_pyg.baselines import MIN_POINTS, estimate_relative_pose
from strl_pyg.data.matches import PairMatches
from strl_pyg.eval_pairs import (
    EvalPair,
    demon_eval_pairs,
    kitti_eval_pairs,
    synthetic_eval_pairs,
)
from strl_pyg.eval_report import (
    AUC_THRESHOLDS,
    SHORT_SEGMENT_LENGTHS,
    EvalReport,
    PairResult,
    pair_result,
)
from strl_pyg.geometry import Pose
from strl_pyg.inference import forward_pose, prepare_graph, prepare_matches
from strl_pyg.io import one_line
from strl_pyg.metrics import (  # noqa: F401  (names this module had before the 0.2 split)
    integrate_relative_poses,
    kitti_odometry_errors,
    kitti_odometry_summary,
    pose_auc,
    relative_pose_error,
)
from strl_pyg.pose_fusion import fuse_poses
from strl_pyg.synthetic.config import LINE_SCENE_KINDS, SCENE_KINDS

__all__ = [
    "METHODS",
    "AUC_THRESHOLDS",
    "SHORT_SEGMENT_LENGTHS",
    "EvalPair",
    "PairResult",
    "pair_result",
    "EvalReport",
    "available_methods",
    "prepare_matches",
    "predict_pose",
    "evaluate_pairs",
    "synthetic_eval_pairs",
    "demon_eval_pairs",
    "kitti_eval_pairs",
    "build_parser",
    "main",
]

METHODS = ("strl", "opencv", "poselib", "fused_opencv", "fused_poselib")


def _have_poselib() -> bool:
    try:
        import poselib  # noqa: F401
    except ImportError:
        return False
    return True


def available_methods() -> tuple[str, ...]:
    """:data:`METHODS` without the PoseLib ones when PoseLib is not importable."""
    return METHODS if _have_poselib() else tuple(m for m in METHODS if "poselib" not in m)



# ----------------------------------------------------------------------------- model
def predict_pose(model: torch.nn.Module, matches: PairMatches,
                 resample: tuple[int, int] | None = (384, 192), seed: int = 0,
                 device: str | torch.device = "cpu") -> Any:
    """The model's ``PoseOutput`` (one pair) on the graph of ``matches`` (module docstring):
    :func:`strl_pyg.inference.prepare_graph` then :func:`strl_pyg.inference.forward_pose`
    (``no_grad``, eval mode, the graph cast to the model's dtype); ``resample="model"``
    takes the counts the checkpoint stores."""
    return forward_pose(model, prepare_graph(matches, model, seed, resample), device)



# ----------------------------------------------------------------------------- evaluation
def evaluate_pairs(
    model: torch.nn.Module | None,
    pairs: Iterable[EvalPair],
    methods: Sequence[str] | None = None,
    resample: tuple[int, int] | None = (384, 192),
    seed: int = 0,
    threshold_px: float = 1.0,
    device: str | torch.device = "cpu",
    progress: bool = True,
    meta: dict[str, Any] | None = None,
) -> EvalReport:
    """Runs every method on every pair (module docstring).

    Args:
        model: a :class:`~strl_pyg.model.StrLPose` (``None``: classical methods only).
        pairs: :class:`EvalPair` s.
        methods: subset of :data:`METHODS` (default: :func:`available_methods`, without the
            model's methods when ``model`` is ``None``).
        resample: ``(points, lines)`` for the network's graph, or ``None``.
        seed: resampling seed of pair ``i`` is ``seed + i``; also the RANSAC seed.
        threshold_px: inlier threshold of the classical estimators, pixels.

    Returns:
        :class:`EvalReport`.
    """
    if methods is None:
        methods = available_methods()
        if model is None:
            methods = tuple(m for m in methods if m in ("opencv", "poselib"))
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(f"Expected methods from {METHODS} (got {list(methods)})")
    needs_model = any(m == "strl" or m.startswith("fused") for m in methods)
    if needs_model and model is None:
        raise ValueError(f"Expected a model for methods {list(methods)} (got None)")
    if resample is not None and (len(resample) != 2 or min(resample) < 0):
        raise ValueError(f"Expected resample as (points, lines) >= 0 or None (got {resample!r})")
    if model is not None:
        model = model.to(device).eval()
    classical = [m for m in ("opencv", "poselib")
                 if m in methods or f"fused_{m}" in methods]
    results: list[PairResult] = []
    truth: dict[str, tuple[str, np.ndarray, tuple[int, int] | None]] = {}
    for i, pair in enumerate(tqdm(list(pairs), desc="evaluate", disable=not progress)):
        if not isinstance(pair, EvalPair):
            raise TypeError(f"Expected EvalPair items (got {type(pair).__name__})")
        if pair.pair_id in truth:
            raise ValueError(f"Expected unique pair ids (got '{pair.pair_id}' twice)")
        truth[pair.pair_id] = (pair.subset, pair.T_0to1, pair.frames)
        out = None
        if needs_model:
            start = time.perf_counter()
            out = predict_pose(model, pair.matches, resample, seed + i, device)
            net_ms = (time.perf_counter() - start) * 1e3
            out.quaternion, out.translation, out.log_var = (
                x.detach().cpu().double() for x in (out.quaternion, out.translation, out.log_var))
            if "strl" in methods:
                results.append(pair_result(pair, "strl", out.pose[0], net_ms, True))
        est = {}
        for c in classical:
            if pair.matches.num_points < MIN_POINTS:
                from strl_pyg.baselines import BaselineResult

                est[c] = BaselineResult(Pose.identity(), np.zeros(pair.matches.num_points, bool),
                                        0.0, c, False)
            else:
                est[c] = estimate_relative_pose(pair.matches, c, threshold_px, seed=seed)
            if c in methods:
                results.append(pair_result(pair, c, est[c].pose, est[c].time_ms, est[c].success))
            if f"fused_{c}" in methods:
                start = time.perf_counter()
                fused = fuse_poses(out, None, est[c], pair.matches)
                ms = (time.perf_counter() - start) * 1e3 + net_ms + est[c].time_ms
                results.append(pair_result(pair, f"fused_{c}", fused.pose, ms, True))
    order = tuple(m for m in METHODS if m in methods)
    return EvalReport(results, order, truth, dict(meta or {}))


# ----------------------------------------------------------------------------- command line
class _UsageError(ValueError):
    """A bad evaluation command line; :func:`main` prints it as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """Reports a bad flag or value as one :class:`_UsageError` line, not a usage block."""

    def error(self, message: str):
        if not message.startswith("Expected"):
            message = f"Expected valid arguments (got {message}); see '{self.prog} --help'"
        raise _UsageError(one_line(message))


def _number(kind: type, low: float, what: str, high: float = math.inf):
    """An argparse ``type``: a finite ``kind`` in ``[low, high)`` or a one-line error."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not (math.isfinite(value) and low <= value < high):
            raise argparse.ArgumentTypeError(f"Expected {what} (got {text!r})")
        return value

    return parse


_POSITIVE_INT = _number(int, 1, "an integer >= 1")
_NON_NEGATIVE_INT = _number(int, 0, "an integer >= 0")


def build_parser(prog: str | None = None) -> argparse.ArgumentParser:
    """The flags of ``examples/evaluate.py`` and ``strl-pose evaluate``; a bad flag or value
    raises a one-line ``ValueError`` ("Expected ... (got ...)") instead of exiting."""
    p = _Parser(prog=prog, description=(
        "Evaluates a Str-L Pose checkpoint against the classical baselines and the fused pose."),
                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    from strl_pyg.checkpoints import default_checkpoint

    p.add_argument("--checkpoint", default=str(default_checkpoint()),
                   help="StrLPose checkpoint (StrLPose.save); default: the shipped weights")
    p.add_argument("--dataset", choices=("synthetic", "demon", "kitti"), default="synthetic")
    p.add_argument("--data-root", help="DeMoN DeepSfM root or KITTI odometry root")
    p.add_argument("--sequences", nargs="+", default=["09", "10"], help="KITTI test sequences")
    p.add_argument("--frame-gap", type=_POSITIVE_INT, default=1, help="KITTI pair (i, i + gap)")
    p.add_argument("--split", default="test", help="DeMoN split folder")
    p.add_argument("--limit", type=_POSITIVE_INT, default=None,
                   help="real data: first N pairs only")
    p.add_argument("--cache-dir", default="outputs/match_cache", help="front-end match cache")
    p.add_argument("--workers", type=_NON_NEGATIVE_INT, default=1,
                   help="front-end matching processes")
    p.add_argument("--num-pairs", type=_POSITIVE_INT, default=30,
                   help="synthetic: number of pairs")
    p.add_argument("--seed", type=_NON_NEGATIVE_INT, default=2_000_000,
                   help="synthetic: first held-out seed")
    p.add_argument("--kinds", nargs="+", default=list(LINE_SCENE_KINDS), choices=SCENE_KINDS)
    p.add_argument("--matches", choices=("frontend", "ground_truth"), default="frontend",
                   help="synthetic: front-end matches on the rendered images (as on real "
                        "data) or the generator's exact matches (the classical methods then "
                        "score ~0 deg without --noise-px / --outlier-fraction)")
    p.add_argument("--noise-px", type=_number(float, 0.0, "a finite number >= 0"), default=0.0,
                   help="synthetic match noise")
    p.add_argument("--outlier-fraction", type=_number(float, 0.0, "a fraction in [0, 1)", 1.0),
                   default=0.0, help="synthetic outliers")
    p.add_argument("--methods", nargs="+", choices=METHODS, default=None,
                   help="default: all available (PoseLib ones only if importable)")
    p.add_argument("--no-resample", action="store_true",
                   help="feed all matches instead of resampling to 384 points / 192 lines")
    p.add_argument("--resample-seed", type=_NON_NEGATIVE_INT, default=0)
    p.add_argument("--threshold-px", type=_number(float, 1e-12, "a finite number > 0"),
                   default=1.0, help="classical inlier threshold")
    p.add_argument("--device", default="cpu")
    p.add_argument("--out", default=None, help="output folder (results.md, .json, PNGs)")
    p.add_argument("--no-progress", action="store_true")
    return p


def _checked(args: argparse.Namespace) -> Path:
    """Checks the paths, methods and device of parsed flags; returns the checkpoint path."""
    ckpt = Path(args.checkpoint)
    if not ckpt.is_file():
        raise _UsageError(f"Expected a checkpoint file at '{ckpt}' (got none)")
    if args.dataset != "synthetic":
        if not args.data_root:
            raise _UsageError(f"Expected --data-root for --dataset {args.dataset} (got none)")
        if not Path(args.data_root).is_dir():
            raise _UsageError(f"Expected a data folder at '{args.data_root}' (got none)")
    if args.methods is not None:
        missing = sorted(set(args.methods) - set(available_methods()))
        if missing:
            raise _UsageError(f"Expected available methods (got {missing}: is PoseLib "
                              "installed?)")
    try:
        torch.device(args.device)
    except RuntimeError:
        raise _UsageError(f"Expected a torch device such as 'cpu' or 'cuda' for --device "
                          f"(got {args.device!r})") from None
    from strl_pyg.training import check_device

    try:  # before the checkpoint is mapped onto it (an absent device blamed the checkpoint)
        check_device(args.device)
    except ValueError as err:
        raise _UsageError(one_line(err)) from None
    if args.out:
        from strl_pyg.io import check_output_dir

        try:
            check_output_dir(args.out, "a folder for --out")  # before any work
        except OSError as err:
            raise _UsageError(one_line(err)) from None
    return ckpt


def _run(argv: list[str] | None, prog: str | None) -> int:
    args = build_parser(prog).parse_args(argv)
    ckpt = _checked(args)
    from strl_pyg.model import StrLPose

    try:
        model = StrLPose.load(ckpt, map_location=args.device)
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as err:
        text = one_line(err)
        raise _UsageError(text if text.startswith("Expected") else (
            f"Expected a StrLPose checkpoint at '{ckpt}' (got {text})")) from None
    progress = not args.no_progress
    try:
        if args.dataset == "synthetic":
            pairs = synthetic_eval_pairs(
                args.num_pairs, args.seed, args.kinds, args.matches,
                scene={"noise_px": args.noise_px, "outlier_fraction": args.outlier_fraction},
                progress=progress)
        elif args.dataset == "demon":
            pairs = demon_eval_pairs(args.data_root, args.cache_dir, split=args.split,
                                     limit=args.limit, num_workers=args.workers,
                                     progress=progress, on_missing="skip")
        else:
            pairs = kitti_eval_pairs(args.data_root, args.cache_dir, args.sequences,
                                     args.frame_gap, limit=args.limit, num_workers=args.workers,
                                     progress=progress, on_missing="skip")
    except (FileNotFoundError, ValueError) as err:
        raise _UsageError(one_line(err)) from None
    if not pairs:
        raise _UsageError(f"Expected pairs to evaluate in {args.dataset} (got none)")
    meta = {"checkpoint": str(ckpt), "dataset": args.dataset, "pairs": len(pairs),
            "resample": "none" if args.no_resample else f"384/192 seed {args.resample_seed}"}
    if args.dataset == "synthetic":
        meta.update(matches=args.matches, noise_px=args.noise_px,
                    outliers=args.outlier_fraction, seed=args.seed)
    report = evaluate_pairs(
        model, pairs, args.methods, None if args.no_resample else (384, 192),
        seed=args.resample_seed, threshold_px=args.threshold_px, device=args.device,
        progress=progress, meta=meta)
    print(report.to_markdown())
    if args.out:
        for path in report.save(args.out):
            print(f"wrote {path}")
    return 0


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """Runs an evaluation from command-line flags (:func:`build_parser`); returns the exit
    code: 0, or 2 after one ``error: Expected ... (got ...)`` line on stderr for a bad flag or
    value, a missing checkpoint, data folder or pairs, or an unwritable ``--out``."""
    try:
        return _run(argv, prog)
    except _UsageError as err:
        print(f"error: {one_line(err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
