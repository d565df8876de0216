"""Evaluation of a Str-L Pose checkpoint against the classical baselines and the fused pose,
on the same matches, with the paper's tables; also the ``strl-pose evaluate`` command line.

Per pair (:class:`~strl_pyg.evaluation.pairs.EvalPair`: matches, ground-truth ``T_0to1``,
subset, id) the methods of :class:`~strl_pyg.inference.PoseEstimator`, by the registry's names
(:data:`~strl_pyg.inference.METHODS`, the registry: ``regression``, ``opencv``, ``poselib``,
``fused``,
``geometric``, ``guided``, ``vp``, ``vp_checked``), estimate ``T_0to1`` (``X1 = R X0 + t``)
with the estimator's support checks and statuses: a method's pose counts only with status
``"ok"``. The 0.2 names (``strl``, ``fused_opencv``, ``fused_poselib``) are refused with their
registry name (:data:`LEGACY_METHOD_NAMES`).

The job is in three modules: the pairs (:mod:`strl_pyg.evaluation.pairs`: generated, DeMoN,
KITTI),
running the methods over them (this module: :func:`evaluate_pairs`, and :func:`main`, the
command line), and the report (:mod:`strl_pyg.evaluation.report`: errors, the tables, KITTI
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
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from strl_pyg.data.matches import PairMatches
from strl_pyg.evaluation.pairs import (
    EvalPair,
    demon_eval_pairs,
    kitti_eval_pairs,
    posed_eval_pairs,
    synthetic_eval_pairs,
)
from strl_pyg.evaluation.report import EvalReport, PairResult, pair_result
from strl_pyg.geometry import Pose
from strl_pyg.inference.network import network_pose
from strl_pyg.inference.status import Status
from strl_pyg.synthetic.config import LINE_SCENE_KINDS, SCENE_KINDS
from strl_pyg.utils.commandline import OneLineArgumentParser, UsageError
from strl_pyg.utils.io import one_line

__all__ = ["LEGACY_METHOD_NAMES", "registered_methods", "available_methods", "resolve_methods",
           "predict_pose", "evaluate_pairs", "build_parser", "main"]

def registered_methods() -> tuple[str, ...]:
    """The methods ``evaluate`` scores: the registry of
    :class:`~strl_pyg.inference.PoseEstimator` by the same names, a method registered later
    included."""
    from strl_pyg.inference import METHODS as REGISTRY

    return tuple(REGISTRY)


def _network_methods() -> tuple[str, ...]:
    from strl_pyg.inference import methods_where

    return methods_where(uses_network=True)


#: Names of the 0.2 runner -> registry names, named in the error that refuses them (0.4
#: removed them). The former ``fused_opencv`` / ``fused_poselib`` are the registry's
#: ``fused``, which fuses with the first ``"ok"`` classical pose (PoseLib when installed).
LEGACY_METHOD_NAMES = {"strl": "regression", "fused_poselib": "fused", "fused_opencv": "fused"}



def available_methods() -> tuple[str, ...]:
    """:data:`~strl_pyg.inference.METHODS` whose dependencies are installed (PoseLib's only when
    importable)."""
    from strl_pyg.inference import METHODS as REGISTRY

    return tuple(m for m in REGISTRY if REGISTRY[m].available())


def resolve_methods(methods: Iterable[str] | None, model: Any) -> tuple[str, ...]:
    """Registry names of ``methods`` (comma-separated items allowed; a 0.2 name is refused
    with its registry name); ``None``: :func:`available_methods`, without the network
    methods when ``model`` is ``None`` and without those that need the geometric head when
    ``model`` has none (asked for by name, they run and say why they fail)."""
    from strl_pyg.inference import METHODS as REGISTRY

    head = bool(getattr(getattr(model, "config", None), "geometric", False))
    if methods is None:
        names = available_methods()
        if model is None:
            return tuple(m for m in names if m not in _network_methods())
        # what the model cannot run is left out, not scored "fail 60/60"
        return tuple(m for m in names if head or not REGISTRY[m].needs_geometric_head)
    from strl_pyg.inference.registry import checked_method_names

    items = [methods] if isinstance(methods, str) else list(methods)
    names = [n.strip() for item in items for n in str(item).split(",") if n.strip()]
    for name in names:
        if name.lower() in LEGACY_METHOD_NAMES:
            raise ValueError(f"Expected methods from {registered_methods()} (got {name!r}: "
                             f"0.2's '{name}' is '{LEGACY_METHOD_NAMES[name.lower()]}')")
    if len(names) == 1 and names[0].lower() in ("all", "recommended"):
        raise ValueError(f"Expected method names from {registered_methods()} (got "
                         f"{names[0]!r}: evaluate scores every available method when "
                         "--methods is left out)")
    # the registry's one parser: any case, a suggestion for a misspelt name (its words
    # 'all' and 'recommended' are not evaluate's)
    try:
        return tuple(dict.fromkeys(checked_method_names(tuple(names))))
    except ValueError as err:
        text = str(err).replace(", 'all' or 'recommended'", "")
        raise ValueError(text) from None


# ----------------------------------------------------------------------------- model
def predict_pose(model: torch.nn.Module, matches: PairMatches,
                 resample: tuple[int, int] | None = (384, 192), seed: int = 0,
                 device: str | torch.device = "cpu") -> Any:
    """The model's ``PoseOutput`` (one pair): :func:`strl_pyg.inference.network_pose` with
    this module's former defaults (``resample=(384, 192)``; ``"model"`` takes the counts the
    checkpoint stores)."""
    return network_pose(model, matches, seed, resample, device)


# ----------------------------------------------------------------------------- evaluation
def evaluate_pairs(
    model: torch.nn.Module | None,
    pairs: Iterable[EvalPair],
    methods: Sequence[str] | None = None,
    resample: Any = "model",
    seed: int = 0,
    threshold_px: float = 1.0,
    device: str | torch.device = "cpu",
    progress: bool = True,
    meta: dict[str, Any] | None = None,
) -> EvalReport:
    """Runs the methods of :class:`~strl_pyg.inference.PoseEstimator` (the same registry, the
    same names, the same support checks and statuses) on every pair and scores them.

    Args:
        model: a :class:`~strl_pyg.model.StrLPose` (``None``: classical methods only).
        pairs: :class:`EvalPair` s.
        methods: names from :data:`~strl_pyg.inference.METHODS` (old names of
        :data:`LEGACY_METHOD_NAMES` are
            accepted with a warning; default: :func:`available_methods`, without the network
            methods when ``model`` is ``None``).
        resample: the regression's input graph (``"model"``: the checkpoint's counts,
            ``(points, lines)`` or ``None``), seeded by ``seed``.
        seed: the estimator's seed (resampling and RANSAC): a pair's result does not depend
            on the other pairs or their order.
        threshold_px: inlier threshold of the classical estimators, pixels.
        device: where the network runs.
        progress: show a tqdm bar.
        meta: extra metadata stored in the report.

    A method's pose counts only with status ``"ok"``; any other status (``"failed"``,
    ``"unreliable"``, ``"degenerate"``) is a failure of that method on that pair.

    Returns:
        :class:`EvalReport`.
    """
    from strl_pyg.inference.estimator import PoseEstimator

    methods = resolve_methods(methods, model)
    needs_model = any(m in _network_methods() for m in methods)
    if needs_model and model is None:
        raise ValueError(f"Expected a model for methods {list(methods)} (got None)")
    if model is not None:
        model = model.to(device).eval()
    estimator = PoseEstimator(model, methods=list(methods), seed=seed, threshold_px=threshold_px,
                              device=device if model is not None else None, bootstrap=0,
                              resample=resample)
    results: list[PairResult] = []
    truth: dict[str, tuple[str, np.ndarray, tuple[int, int] | None]] = {}
    for pair in tqdm(list(pairs), desc="evaluate", disable=not progress):
        if not isinstance(pair, EvalPair):
            raise TypeError(f"Expected EvalPair items (got {type(pair).__name__})")
        if pair.pair_id in truth:
            raise ValueError(f"Expected unique pair ids (got '{pair.pair_id}' twice)")
        truth[pair.pair_id] = (pair.subset, pair.T_0to1, pair.frames)
        est = estimator.estimate(pair.matches)
        for name in methods:
            r = est.methods[name]
            ok = r.status == Status.OK
            pose = Pose.from_matrix(torch.as_tensor(r.T_0to1)) if ok else Pose.identity()
            results.append(pair_result(pair, name, pose, r.time_ms, ok))
    return EvalReport(results, methods, truth, dict(meta or {}))


# ----------------------------------------------------------------------------- command line
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
    p = OneLineArgumentParser(prog=prog, description=(
        "Evaluates a Str-L Pose checkpoint against the classical baselines and the fused pose."),
                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    from strl_pyg.training.checkpoints import default_checkpoint

    p.add_argument("--checkpoint", default=str(default_checkpoint()),
                   help="StrLPose checkpoint (StrLPose.save); default: the shipped weights")
    p.add_argument("--dataset", choices=("synthetic", "demon", "kitti", "posed"),
                   default="synthetic")
    p.add_argument("--data-root", help="DeMoN DeepSfM root, KITTI odometry root or a folder "
                                       "of posed scenes (COLMAP, NeRF, LLFF, real_scenes)")
    p.add_argument("--scenes", default=None,
                   help="posed: scene folders under --data-root, comma-separated (default: "
                        "the real_scenes validation scenes where there, else every folder)")
    p.add_argument("--stride", type=_POSITIVE_INT, default=4,
                   help="posed: pairs (i, i + --frame-gap) for every this many i")
    p.add_argument("--sequences", nargs="+", default=["09", "10"],
                   help="KITTI test sequences, space- or comma-separated (as --train-sequences)")
    p.add_argument("--frame-gap", type=_POSITIVE_INT, default=None,
                   help="KITTI / posed pair (i, i + gap) (default: 1 for KITTI, 2 for posed)")
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
    p.add_argument("--methods", nargs="+", default=None,
                   help=f"names of PoseEstimator's registry, space- or comma-separated, from "
                        f"{', '.join(registered_methods())} (default: all available; "
                        f"PoseLib's only if importable)")
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
    # "06,07" as train.py's --train-sequences takes it, or "06 07"
    args.sequences = [q.strip() for item in args.sequences for q in item.split(",")
                      if q.strip()]
    ckpt = Path(args.checkpoint)
    if not ckpt.is_file():
        raise UsageError(f"Expected a checkpoint file at '{ckpt}' (got none)")
    if args.dataset != "synthetic":
        if not args.data_root:
            raise UsageError(f"Expected --data-root for --dataset {args.dataset} (got none)")
        if not Path(args.data_root).is_dir():
            raise UsageError(f"Expected a data folder at '{args.data_root}' (got none)")
    if args.methods is not None:
        try:
            args.methods = list(resolve_methods(args.methods, True))
        except ValueError as err:
            raise UsageError(one_line(err)) from None
        missing = sorted(set(args.methods) - set(available_methods()))
        if missing:
            raise UsageError(f"Expected available methods (got {missing}: is PoseLib "
                             "installed?)")
    try:
        torch.device(args.device)
    except RuntimeError:
        raise UsageError(f"Expected a torch device such as 'cpu' or 'cuda' for --device "
                         f"(got {args.device!r})") from None
    from strl_pyg.training.commandline import check_device

    try:  # before the checkpoint is mapped onto it (an absent device blamed the checkpoint)
        check_device(args.device)
    except ValueError as err:
        raise UsageError(one_line(err)) from None
    if args.out:
        from strl_pyg.utils.io import check_output_dir

        try:
            check_output_dir(args.out, "a folder for --out")  # before any work
        except OSError as err:
            raise UsageError(one_line(err)) from None
    return ckpt


def _run(argv: list[str] | None, prog: str | None) -> int:
    args = build_parser(prog).parse_args(argv)
    ckpt = _checked(args)
    from strl_pyg.model.strl_pose import StrLPose

    try:
        model = StrLPose.load(ckpt, map_location=args.device)
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as err:
        text = one_line(err)
        raise UsageError(text if text.startswith("Expected") else (
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
        elif args.dataset == "posed":
            pairs = posed_eval_pairs(args.data_root, args.cache_dir,
                                     [s.strip() for s in (args.scenes or "").split(",")
                                      if s.strip()], args.frame_gap or 2, args.stride,
                                     limit=args.limit, num_workers=args.workers,
                                     progress=progress)
        else:
            pairs = kitti_eval_pairs(args.data_root, args.cache_dir, args.sequences,
                                     args.frame_gap or 1, limit=args.limit,
                                     num_workers=args.workers, progress=progress,
                                     on_missing="skip")
    except (FileNotFoundError, ValueError) as err:
        raise UsageError(one_line(err)) from None
    if not pairs:
        raise UsageError(f"Expected pairs to evaluate in {args.dataset} (got none)")
    meta = {"checkpoint": str(ckpt), "dataset": args.dataset, "pairs": len(pairs),
            "resample": "none" if args.no_resample else f"checkpoint's counts, seed "
                                                              f"{args.resample_seed}"}
    if args.dataset == "synthetic":
        meta.update(matches=args.matches, noise_px=args.noise_px,
                    outliers=args.outlier_fraction, seed=args.seed)
    report = evaluate_pairs(
        model, pairs, args.methods, None if args.no_resample else "model",
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
    except UsageError as err:
        print(f"error: {one_line(err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
