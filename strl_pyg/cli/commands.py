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
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.cli.guard import OneLineArgumentParser, run_guarded
from strl_pyg.cli.readers import (  # noqa: F401  (re-exported: the readers' public home)
    DEMO_SEED,
    MAX_SIDE,
    PairInputs,
    UsageError,
    _check_input_file,
    _intrinsics,
    load_model,
    bootstrap_count,
    downscale_for_matching,
    non_negative_int,
    read_image_file,
    read_intrinsics,
    read_pair,
)
from strl_pyg.synthetic.config import LINE_SCENE_KINDS
from strl_pyg.training.checkpoints import DEFAULT_WEIGHTS, WEIGHTS_DIR, default_checkpoint  # noqa: F401

__all__ = ["main", "run_guarded", "check_train_files", "build_parser", "read_intrinsics",
           "read_image_file", "default_checkpoint", "predict_pair", "downscale_for_matching",
           "PairInputs", "MAX_SIDE"]

def _predict_model(args):
    """``predict``'s model: the ``--checkpoint`` (or ``STRL_POSE_WEIGHTS``) file, loaded now
    so that a bad file is one line before any work; ``None`` for the shipped weights, which
    the estimator builds only when a method needs the network (the default recommended pose
    of a pair with enough points does not)."""
    if args.checkpoint or os.environ.get("STRL_POSE_WEIGHTS"):
        return load_model(args.checkpoint)
    return None


def _predict_estimator(args, names):
    """``predict``'s one estimator (``names``: "recommended", ``None`` for all, or names),
    made once the inputs are read (torch is imported here)."""
    from strl_pyg.inference.estimator import PoseEstimator

    return PoseEstimator(_predict_model(args), methods=names, bootstrap=args.bootstrap,
                         threshold_px=args.threshold_px)


# ----------------------------------------------------------------------------- the pipeline
def predict_pair(model, matches, resample_seed: int | None = 0,
                 warmup: bool = False) -> dict[str, Any]:
    """Runs the network alone on one pair's matches; returns its pose and uncertainty.

    The graph is built and resampled as the checkpoint stores (:attr:`StrLPose.metadata
    <strl_pyg.model.StrLPose.metadata>`; 384 points, 192 lines for old checkpoints) with seed
    ``resample_seed``, or not resampled when it is None. With ``warmup``, one untimed forward
    pass runs first, so ``time_ms`` is the steady-state time. For the recommended pose of all
    methods use :class:`strl_pyg.inference.estimator.PoseEstimator`.
    """
    import torch

    from strl_pyg.inference.network import network_pose

    def run():
        return network_pose(model, matches, resample_seed or 0,
                            "model" if resample_seed is not None else None)

    if warmup:
        run()
    t0 = time.perf_counter()
    out = run()
    ms = (time.perf_counter() - t0) * 1e3
    q, t, lv = (x[0].detach().cpu().double() for x in (out.quaternion, out.translation,
                                                       out.log_var))
    from strl_pyg.geometry import Pose

    return {
        "T_0to1": Pose.from_quaternion(q, t).matrix().numpy(),
        "quaternion": q.numpy(),
        "translation": t.numpy(),
        "sigma": torch.exp(0.5 * lv).numpy(),
        "log_var": lv.numpy(),
        "time_ms": ms,
    }


def _pose_errors(T_est: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    from strl_pyg.metrics.two_view import relative_pose_error

    r, t = relative_pose_error(np.asarray(T_est)[None], np.asarray(T_gt)[None])
    return float(r[0]), float(t[0])


def _fmt_pose(T: np.ndarray) -> str:
    from strl_pyg.geometry import Pose

    p = Pose.from_matrix(np.asarray(T, dtype=np.float64))
    t = p.t.numpy()
    return (f"rotation {float(p.angle_deg()):.3f} deg, q(wxyz) "
            f"{np.array2string(p.quaternion().numpy(), precision=4)}, t "
            f"{np.array2string(t, precision=4)}")


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = _jsonable(v)
        elif isinstance(v, np.ndarray):
            out[k] = v.tolist()
        elif isinstance(v, (np.floating, np.integer)):
            out[k] = v.item()
        else:
            out[k] = v
    return out


def _label(method: str | None) -> str | None:
    """What a method is in words: its registry entry's label (``MethodSpec.label``)."""
    from strl_pyg.inference.estimator import METHODS

    return METHODS[method].label if method in METHODS else method

#: ``strl-pose predict``'s exit codes (also in its ``--help``).
EXIT_CODES = {0: "a pose: status 'ok'",
              1: "no pose: status 'degenerate' or 'failed'",
              2: "an error in the input (one 'error: Expected ...' line on stderr)",
              3: "no pose to use: status 'unreliable' (a pose was computed, but the "
                 "intrinsics fail the input checks or its matches lie behind a camera: see the "
                 "warnings; T_0to1 and sigma are null)",
              4: "a rotation only: status 'rotation_only' (the matches show no parallax, a "
                 "pure rotation: 'rotation' and sigma.rotation_deg are given, T_0to1 is null)",
              130: "interrupted",
              141: "stdout closed early (e.g. '| head'): output stopped quietly"}
STATUS_EXIT = {"ok": 0, "degenerate": 1, "failed": 1, "unreliable": 3, "rotation_only": 4}


def _print_estimate(est, indent: str = "") -> None:
    """The recommended pose in words: status, method, uncertainty, warnings; then each
    method's own result."""
    pose = est.pose
    if pose.status == "unreliable":
        label = _label(pose.method)
        print(f"{indent}pose: unreliable, no pose given (see the warnings); {pose.method} "
              f"({label}) computed, not to use: {_fmt_pose(pose.info['unreliable_T_0to1'])}")
    elif pose.status == "ok":
        label = _label(pose.method)
        print(f"{indent}pose: ok, from {pose.method} ({label}): {_fmt_pose(pose.T_0to1)}")
        if pose.sigma is not None:
            kind = pose.info.get("covariance", "network log-variance")
            cal = ("calibrated" if pose.info.get("calibration_scale") is not None
                   else "uncalibrated")
            print(f"{indent}  sigma ({kind}, {cal}): "
                  f"rotation {pose.sigma['rotation_deg']:.3f} deg, "
                  f"translation direction {pose.sigma['translation_deg']:.3f} deg")
    elif pose.status == "rotation_only":
        R = "; ".join(" ".join(f"{v:+.5f}" for v in row) for row in pose.rotation)
        sig = pose.sigma["rotation_deg"] if pose.sigma is not None else float("nan")
        print(f"{indent}pose: rotation_only (a pure rotation: no translation direction), "
              f"R = [{R}], sigma rotation {sig:.3f} deg")
    else:
        print(f"{indent}pose: {pose.status}, no pose given")
    if est.geometry is not None:
        g = est.geometry
        print(f"{indent}two-view configuration: {g.configuration} (inliers: essential "
              f"{g.inliers_E}, homography {g.inliers_H}, rotation alone {g.inliers_R} of "
              f"{g.num_points})")
    if "fundamental_matrix" in pose.info:  # the route without intrinsics
        F = pose.info["fundamental_matrix"]
        if F is None:
            print(f"{indent}fundamental matrix (no intrinsics): none found")
        else:
            rows = "; ".join(" ".join(f"{v:+.4e}" for v in row) for row in np.asarray(F))
            print(f"{indent}fundamental matrix (no intrinsics; x1^T F x0 = 0, pixels, "
                  f"{pose.info['fundamental_inliers']} inliers): [{rows}]")
    for w in pose.warnings:
        print(f"{indent}warning: {w}")
    print(f"{indent}methods:")
    for name, r in est.methods.items():
        detail = _fmt_pose(r.T_0to1) if r.status == "ok" else "; ".join(r.warnings)
        if r.status == "unreliable":
            detail = "; ".join(r.info["unreliable"])
        extra = f", {r.num_inliers} inliers" if r.num_inliers is not None else ""
        print(f"{indent}  {name:<11} {r.status:<10} {detail}  ({r.time_ms:.1f} ms{extra})")


# ----------------------------------------------------------------------------- subcommands
def cmd_demo(args) -> int:
    from strl_pyg.utils.io import check_output_dir

    check_output_dir(args.out, "a folder for --out")  # before any work
    from strl_pyg.frontend import epipolar_residuals, match_images
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
    print(f"{'ground truth':<14} {'':<10} {0.0:8.3f} {0.0:8.3f} {'-':>7}   {_fmt_pose(T_gt)}")
    report = {}
    for name, r in est.methods.items():  # registry names: one method, one name
        if r.T_0to1 is None:
            print(f"{name:<14} {r.status:<10} {'-':>8} {'-':>8} {r.time_ms:7.1f}   "
                  f"{'; '.join(r.warnings)}")
            continue
        rot, tr = _pose_errors(r.T_0to1, T_gt)
        print(f"{name:<14} {r.status:<10} {rot:8.3f} {tr:8.3f} {r.time_ms:7.1f}   "
              f"{_fmt_pose(r.T_0to1)}")
        report[name] = {"rot_err_deg": rot, "trans_err_deg": tr, "status": r.status}
    s = pred["sigma"]
    print(f"\npredicted sigma (regression): quaternion {np.array2string(s[:4], precision=4)}, "
          f"translation {np.array2string(s[4:], precision=4)}")
    print(f"recommended pose: {est.status}" + (f", from {est.pose.method}" if est.pose.method
                                               else "")
          + "".join(f"\nwarning: {w}" for w in est.warnings))
    if est.pose.sigma is not None and est.status == "ok":
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
        print(json.dumps({**est.to_dict(), "prediction": _jsonable(pred), "errors": report}))
    return 0


def _match(inputs, args):
    from strl_pyg.frontend import FrontendConfig, match_images

    img0, img1, K0, K1 = inputs
    return match_images(img0, img1, K0=K0, K1=K1, config=FrontendConfig(detector=args.detector))


def _check_file_arg(path: str, flag: str, example: str) -> None:
    """An output file flag's value: a folder (existing, or ending in '/') is refused with the
    file name to add (``Path('out/')`` is ``out``: it used to become a file named ``out``)."""
    from strl_pyg.utils.io import check_output_file

    if path.endswith(("/", os.sep)) or Path(path).is_dir():
        name = str(Path(path) / example)
        raise UsageError(f"Expected a file path for {flag} (got '{path}', which names a folder; "
                         f"e.g. '{name}')")
    check_output_file(path, f"a file path for {flag}")


def read_pairs_file(path: str, image_dir: str) -> list[tuple[str, str]]:
    """The pairs of a pairs file: one ``name0 name1`` line each (extra columns ignored, blank
    lines and ``#`` comments skipped), names joined to ``image_dir``."""
    from strl_pyg.cli.readers import _check_input_file

    _check_input_file(path, "pairs file for --pairs")
    out = []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) < 2:
            raise UsageError(f"Expected 'image0 image1' on line {n} of '{path}' (got "
                             f"{line.strip()!r})")
        out.append((str(Path(image_dir) / fields[0]), str(Path(image_dir) / fields[1])))
    if not out:
        raise UsageError(f"Expected at least one 'image0 image1' line in '{path}' (got none)")
    return out


def _predict_pairs(args, methods: str) -> int:
    """``predict --pairs``: every pair of the file with one estimator, one JSON line each on
    stdout (``{"image0", "image1", ...the record}`` or ``{"image0", "image1", "error"}``); a
    bad pair is its error line and the rest go on. Exit 0 when every pair gave a record, 1
    when some gave an error."""
    from copy import copy

    from tqdm.auto import tqdm

    from strl_pyg.frontend import FrontendConfig

    pairs = read_pairs_file(args.pairs, args.image_dir)
    names = (methods if methods == "recommended" else None if methods == "all"
             else _method_names(methods))
    estimator, errors = None, 0
    for a, b in tqdm(pairs, desc="pairs", file=sys.stderr):
        one = copy(args)
        one.image0, one.image1 = a, b
        try:
            inputs = read_pair(one)
            estimator = estimator or _predict_estimator(args, names)
            img0, img1, K0, K1 = inputs
            est = estimator.estimate_images(img0, img1, K0, K1,
                                            FrontendConfig(detector=args.detector))
            if inputs.downscaled:
                _intrinsics_in_original_frame(est, inputs)
            record = {"image0": a, "image1": b, **est.to_dict()}
        except (UsageError, OSError, ValueError, TypeError, KeyError) as err:  # as run_guarded
            errors += 1
            record = {"image0": a, "image1": b, "error": str(err)}
        print(json.dumps(record), flush=True)
    return 1 if errors else 0


def _draw_estimate(path: str, est) -> None:
    """``predict --png``: the matches coloured by the recommended pose's support (inliers
    within its support band and in front of both cameras)."""
    from strl_pyg.viz.matches import save_matches_png

    m = est.matches
    if m is None or not m.has_images:
        print("note: --png needs the images (a match file without them draws nothing)")
        return
    mask = est.inliers_of_matches()
    what = (f"green: {int(mask.sum())} of {m.num_points} point matches support the "
            f"recommended pose ({est.pose.method}, {est.status})" if mask is not None
            else f"recommended pose: {est.status}; no inlier mask (every match drawn grey)")
    print(f"drawing -> {save_matches_png(path, m, point_inliers=mask, title=what, legend=True)}")


def cmd_match(args) -> int:
    _check_file_arg(args.out, "--out", "matches.npz")  # before any work
    if args.png:
        _check_file_arg(args.png, "--png", "matches.png")
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


def cmd_predict(args) -> int:
    """Pose of two images: the recommended ``"pose"`` record (:mod:`strl_pyg.inference.estimator`)
    and the own result of each method run (``--methods``; default: only the ones the
    recommended pose needs, :mod:`strl_pyg.inference.recommended`). Exit status (:data:`EXIT_CODES`)
    0 when the pose's status is ``"ok"``, 1 when it is ``"degenerate"`` or ``"failed"``, 3
    when it is ``"unreliable"`` (printed either way)."""
    if args.png:
        _check_file_arg(args.png, "--png", "pose.png")  # before any work
    if not (np.isfinite(args.threshold_px) and args.threshold_px > 0):
        raise UsageError(f"Expected a positive --threshold-px (got {args.threshold_px})")
    methods = "regression" if args.no_baseline else args.methods
    if methods.lower() in ("recommended", "all"):
        methods = methods.lower()
    _check_methods(methods)  # before the images and the model are read
    if args.pairs:
        return _predict_pairs(args, methods)
    # one estimator for both inputs: "recommended" (estimator.RECOMMENDED) walks the
    # recommended order (the images matched once), "all" runs every installed method; torch
    # is imported only once the inputs are read
    names = (methods if methods == "recommended" else None if methods == "all"
             else _method_names(methods))
    if args.matches:
        if args.image0 or args.image1:
            raise UsageError(f"Expected either two images or --matches (got both: "
                             f"{args.image0} and --matches {args.matches})")
        matches = _read_match_file(args)
        K0 = matches.K0
        estimator = _predict_estimator(args, names)
        est = estimator.estimate(matches)
    else:
        if not (args.image0 and args.image1):
            raise UsageError("Expected two images, or --matches FILE (got "
                             f"{'one image' if args.image0 else 'neither'})")
        inputs = read_pair(args)  # fail on bad files before any heavy work
        estimator = _predict_estimator(args, names)
        from strl_pyg.frontend import FrontendConfig

        img0, img1, K0, K1 = inputs
        est = estimator.estimate_images(img0, img1, K0, K1,
                                        FrontendConfig(detector=args.detector))
        if inputs.downscaled:
            _intrinsics_in_original_frame(est, inputs)
    kind = estimator.model_config.translation  # without building the shipped network
    code = STATUS_EXIT[est.status]
    if args.json:
        print(json.dumps({**est.to_dict(), "translation_kind": kind,
                          "intrinsics": K0 is not None}))
        return code
    print(f"matches: {est.num_points} points, {est.num_lines} lines")
    _print_estimate(est)
    if args.png:
        _draw_estimate(args.png, est)
    if args.checkpoint and methods == "recommended":
        from strl_pyg.inference.estimator import METHODS

        if not any(METHODS[n].uses_network for n in est.methods if n in METHODS):
            # a user's own weights that nothing read: say so rather than let them think
            # the printed pose is their network's
            print(f"note: the recommended pose did not need the network, so --checkpoint "
                  f"{args.checkpoint} was not run; --methods all (or regression) shows its pose")
    return code


def _intrinsics_in_original_frame(est, inputs) -> None:
    """The intrinsics warnings of a pair matched downscaled (``--max-side``) quote the sizes
    and K the user gave, not the downscaled ones (a 6000 px image's fx=4615 was quoted as
    fx=153.8 at 1600 px)."""
    from strl_pyg.inference.checks import intrinsics_problems

    (s0, s1, sK0, sK1), (o0, o1, oK0, oK1) = tuple(inputs), inputs.original
    small = intrinsics_problems(s0.shape[:2], s1.shape[:2], sK0, sK1)
    original = intrinsics_problems(o0.shape[:2], o1.shape[:2], oK0, oK1)
    if not small or len(small) != len(original):
        return
    swap = dict(zip(small, original, strict=True))

    def fix(text: str) -> str:
        for a, b in swap.items():
            text = text.replace(a, b)
        return text

    for rec in (est.pose, *est.methods.values()):
        rec.warnings = [fix(w) for w in rec.warnings]
        if "unreliable" in rec.info:
            rec.info["unreliable"] = [fix(w) for w in rec.info["unreliable"]]


def _method_names(methods: str) -> tuple[str, ...]:
    """The names of ``--methods``, matched to the registered ones without regard to case
    (``OpenCV`` is ``opencv``)."""
    from strl_pyg.inference.estimator import METHODS

    by_lower = {m.lower(): m for m in METHODS}
    return tuple(by_lower.get(m.strip().lower(), m.strip()) for m in methods.split(",")
                 if m.strip())


def _check_methods(methods: str) -> None:
    """``--methods``: 'recommended', 'all' or registered names; one line naming the closest
    registered name otherwise (checked before any image or model is read)."""
    if methods.lower() in ("recommended", "all"):
        return
    import difflib

    from strl_pyg.inference.estimator import METHODS

    names = _method_names(methods)
    unknown = [m for m in names if m not in METHODS]
    if unknown or not names:
        close = difflib.get_close_matches(unknown[0], list(METHODS), n=1) if unknown else []
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise UsageError(f"Expected --methods 'recommended', 'all' or names from "
                         f"{', '.join(METHODS)} (got {methods!r}){hint}")


def _read_match_file(args):
    """``predict --matches``: a match file of this package (``strl-pose match``) or of another
    tool (:func:`~strl_pyg.data.load_external_matches`), with ``--K`` / ``--K0`` / ``--K1``
    and, for files without image sizes, the sizes of ``--image-size``."""
    from strl_pyg.cli.readers import _check_input_file

    _check_input_file(args.matches, "match file (.npz) for --matches")
    K0, K1 = _intrinsics(args)
    from strl_pyg.data.external import load_external_matches

    size = args.image_size
    try:
        return load_external_matches(args.matches, image_size0=size, image_size1=size,
                                     K0=K0, K1=K1)
    except (ValueError, TypeError, OSError) as err:
        raise UsageError(str(err).splitlines()[0]) from None


def cmd_train(args, parser, argv: list[str] | None = None) -> int:
    check_train_files(args)  # before torch is imported
    from strl_pyg.training.loop import run_from_args

    return run_from_args(args, parser, argv)


def check_train_files(args) -> None:
    """Checks the files a training run needs (``--out`` writable, ``--init-from`` present,
    ``<out>/last.pt`` for ``--resume``) before torch is imported; raises ``UsageError`` /
    ``OSError`` with one-line messages."""
    from strl_pyg.utils.io import check_output_dir

    check_output_dir(args.out, "a run folder for --out")
    if args.init_from and not args.init_from.startswith("shipped:"):
        _check_input_file(args.init_from, "weights file for --init-from")
    if args.resume:
        _check_input_file(Path(args.out) / "last.pt", "training checkpoint for --resume")


def cmd_evaluate(argv: list[str]) -> int:
    pre = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    pre.add_argument("--out", nargs="?", default=None)  # a missing value is the real
    pre.add_argument("--checkpoint", nargs="?", default=None)  # parser's to report
    known, _ = pre.parse_known_args(argv)
    if known.out:
        from strl_pyg.utils.io import check_output_dir

        check_output_dir(known.out, "a folder for --out")  # before any work
    if known.checkpoint:
        _check_input_file(known.checkpoint, "model checkpoint for --checkpoint")
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
                               ".camera)")
    p.add_argument("--K0", help="intrinsics of image 0 (same formats)")
    p.add_argument("--K1", help="intrinsics of image 1 (default: --K0)")
    p.add_argument("--detector", choices=("sift", "orb"), default="sift")
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
    p.add_argument("--threshold-px", type=float, default=1.0, metavar="PX",
                   help="inlier threshold of the solvers and the support check (default 1)")
    p.add_argument("--bootstrap", type=bootstrap_count, default=8, metavar="N",
                   help="resamples behind the PoseLib/OpenCV covariance (default 8, the "
                        "calibrated setting; 0: first-order covariance only, faster)")
    p = sub.add_parser("train", help="train a model (see examples/train.py)")
    add_train_arguments(p)
    sub.add_parser("evaluate", help="evaluate a checkpoint (see examples/evaluate.py)",
                   add_help=False)
    p = sub.add_parser("bench", help="time the pipeline stages on this machine")
    p.add_argument("--checkpoint", default=None)
    p.add_argument("--repeat", type=int, default=20)
    p = sub.add_parser("export", help="the model's regression path as ONNX (needs [onnx])")
    p.add_argument("--onnx", required=True, metavar="PATH", help="output .onnx file")
    p.add_argument("--checkpoint", default=None, help="default: the shipped weights")
    return ap


def _dispatch(argv: list[str]) -> int:
    if argv[:1] == ["evaluate"]:
        return cmd_evaluate(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "train":
        return cmd_train(args, parser, argv)
    if args.command == "bench":
        from strl_pyg.cli.bench import cmd_bench

        return cmd_bench(args)
    if args.command == "export":
        from strl_pyg.cli.export import cmd_export

        return cmd_export(args)
    return {"demo": cmd_demo, "match": cmd_match, "predict": cmd_predict}[args.command](args)


def main(argv: list[str] | None = None) -> int:
    """The ``strl-pose`` entry point; returns the exit code (0, or 2 for a user error)."""
    return run_guarded(_dispatch, list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
