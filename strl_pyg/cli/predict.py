"""``strl-pose predict``: the pose of one image pair (or of every pair of a list) by the
recommended path or the methods asked for, printed or as JSON lines, with the exit code of its
status (:data:`EXIT_CODES`), and :func:`predict_pair`, the network's pose of one match set."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from strl_pyg.cli.readers import (
    check_input_file,
    frontend_config,
    intrinsics_from_args,
    load_model,
    read_pair,
)
from strl_pyg.inference.status import Status
from strl_pyg.utils import UsageError

__all__ = ["predict_pair", "cmd_predict", "EXIT_CODES", "STATUS_EXIT", "read_pairs_file",
           "format_pose", "pose_errors", "jsonable", "check_file_arg"]


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


def pose_errors(T_est: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    from strl_pyg.metrics.two_view import relative_pose_error

    r, t = relative_pose_error(np.asarray(T_est)[None], np.asarray(T_gt)[None])
    return float(r[0]), float(t[0])


def format_pose(T: np.ndarray) -> str:
    from strl_pyg.geometry import Pose

    p = Pose.from_matrix(np.asarray(T, dtype=np.float64))
    t = p.t.numpy()
    return (f"rotation {float(p.angle_deg()):.3f} deg, q(wxyz) "
            f"{np.array2string(p.quaternion().numpy(), precision=4)}, t "
            f"{np.array2string(t, precision=4)}")


def jsonable(d: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = jsonable(v)
        elif isinstance(v, np.ndarray):
            out[k] = v.tolist()
        elif isinstance(v, (np.floating, np.integer)):
            out[k] = v.item()
        else:
            out[k] = v
    return out


def _label(method: str | None) -> str | None:
    """What a method is in words: its registry entry's label (``PoseMethod.label``)."""
    from strl_pyg.inference import METHODS

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


STATUS_EXIT = {Status.OK: 0, Status.DEGENERATE: 1, Status.FAILED: 1, Status.UNRELIABLE: 3,
               Status.ROTATION_ONLY: 4}


def _print_estimate(est, indent: str = "") -> None:
    """The recommended pose in words: status, method, uncertainty, warnings; then each
    method's own result."""
    pose = est.pose
    if pose.status == Status.UNRELIABLE:
        label = _label(pose.method)
        print(f"{indent}pose: unreliable, no pose given (see the warnings); {pose.method} "
              f"({label}) computed, not to use: {format_pose(pose.info['unreliable_T_0to1'])}")
    elif pose.status == Status.OK:
        label = _label(pose.method)
        print(f"{indent}pose: ok, from {pose.method} ({label}): {format_pose(pose.T_0to1)}")
        if pose.sigma is not None:
            kind = pose.info.get("covariance", "network log-variance")
            cal = ("calibrated" if pose.info.get("calibration_scale") is not None
                   else "uncalibrated")
            print(f"{indent}  sigma ({kind}, {cal}): "
                  f"rotation {pose.sigma['rotation_deg']:.3f} deg, "
                  f"translation direction {pose.sigma['translation_deg']:.3f} deg")
    elif pose.status == Status.ROTATION_ONLY:
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
        detail = format_pose(r.T_0to1) if r.status == Status.OK else "; ".join(r.warnings)
        if r.status == Status.UNRELIABLE:
            detail = "; ".join(r.info["unreliable"])
        extra = f", {r.num_inliers} inliers" if r.num_inliers is not None else ""
        print(f"{indent}  {name:<11} {r.status:<10} {detail}  ({r.time_ms:.1f} ms{extra})")


def check_file_arg(path: str, flag: str, example: str) -> None:
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
    check_input_file(path, "pairs file for --pairs")
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
    bad pair is its error line and the rest go on. Exit 0 when every pair gave a record with
    a pose, 1 when some gave an error or no pose (``"degenerate"`` / ``"failed"``)."""
    from copy import copy

    from tqdm.auto import tqdm

    pairs = read_pairs_file(args.pairs, args.image_dir)
    names = _method_names(methods)
    estimator, errors, no_pose = None, 0, 0
    for a, b in tqdm(pairs, desc="pairs", file=sys.stderr):
        one = copy(args)
        one.image0, one.image1 = a, b
        try:
            inputs = read_pair(one)
            estimator = estimator or _predict_estimator(args, names)
            img0, img1, K0, K1 = inputs
            est = estimator.estimate_images(img0, img1, K0, K1, frontend_config(args),
                                            original=inputs.original_frame)
            record = {"image0": a, "image1": b, **est.to_dict()}
            no_pose += STATUS_EXIT[est.status] == 1
        except (UsageError, OSError, ValueError, TypeError, KeyError) as err:  # as run_guarded
            errors += 1
            record = {"image0": a, "image1": b, "error": str(err)}
        print(json.dumps(record), flush=True)
    return 1 if errors or no_pose else 0


def _draw_estimate(path: str, est, file=None, images=None) -> None:
    """``predict --png``: the matches coloured by the recommended pose's support (inliers
    within its support band and in front of both cameras), on the images as read (colour
    where they are; ``images``) when they have the matches' sizes; an ``"unreliable"`` pose
    shows the support of the pose it refused, and the first reason."""
    from dataclasses import replace

    from strl_pyg.viz.matches import save_matches_png

    m = est.matches
    if m is None or not m.has_images:
        print("note: --png needs the images (a match file without them draws nothing)",
              file=file)
        return
    if images is not None and tuple(np.shape(images[0])[:2]) == tuple(m.image_size0) \
            and tuple(np.shape(images[1])[:2]) == tuple(m.image_size1):
        m = replace(m, image0=images[0], image1=images[1])
    mask = est.inliers_of_matches()
    what = (f"green: {int(mask.sum())} of {m.num_points} point matches support the "
            f"recommended pose ({est.pose.method}, {est.status})" if mask is not None
            else f"recommended pose: {est.status}; no inlier mask (every match drawn grey)")
    if est.status == Status.UNRELIABLE and est.pose.info.get("unreliable"):
        what += f"; unreliable: {est.pose.info['unreliable'][0]}"
    print(f"drawing -> {save_matches_png(path, m, point_inliers=mask, title=what, legend=True)}",
          file=file)


def _draw_explanation(path: str, est, estimator, method: str, file=None, images=None) -> None:
    """``predict --explain``: which point matches and line segments drove the network's pose
    (:func:`strl_pyg.explain.explain_matches`), drawn by importance."""
    from dataclasses import replace

    from strl_pyg.explain import explain_matches
    from strl_pyg.viz.plots import plot_match_importance

    m = est.matches
    if m is None or not m.has_images:
        print("note: --explain needs the images (a match file without them draws nothing)",
              file=file)
        return
    if m.num_lines and not m.line_endpoints_correspond:  # the network reads no such lines
        m = m.select(line_index=np.zeros(0, dtype=np.int64))
    e = explain_matches(m, estimator.model, method)
    if images is not None and tuple(np.shape(images[0])[:2]) == tuple(m.image_size0) \
            and tuple(np.shape(images[1])[:2]) == tuple(m.image_size1):
        m = replace(m, image0=images[0], image1=images[1])
    title = (f"what drove the network's pose ({method}); the recommended pose: "
             f"{est.pose.method}, {est.status}")
    print(f"explanation -> {plot_match_importance(path, m, e.points, e.lines, title)}",
          file=file)


def cmd_predict(args) -> int:
    """Pose of two images: the recommended ``"pose"`` record (:mod:`strl_pyg.inference.estimator`)
    and the own result of each method run (``--methods``; default: only the ones the
    recommended pose needs, :mod:`strl_pyg.inference.recommended`). Exit status (:data:`EXIT_CODES`)
    0 when the pose's status is ``"ok"``, 1 when it is ``"degenerate"`` or ``"failed"``, 3
    when it is ``"unreliable"`` (printed either way)."""
    if args.png:
        check_file_arg(args.png, "--png", "pose.png")  # before any work
    if args.explain:
        check_file_arg(args.explain, "--explain", "explain.png")
        if not args.explain.lower().endswith(".png"):
            raise UsageError(f"Expected a .png path for --explain (got '{args.explain}')")
    if not (np.isfinite(args.threshold_px) and args.threshold_px > 0):
        raise UsageError(f"Expected a positive --threshold-px (got {args.threshold_px})")
    if args.no_baseline:
        from strl_pyg.inference.methods import Regression

        methods = Regression.name
    else:
        methods = args.methods
    if methods.lower() in ("recommended", "all"):
        methods = methods.lower()
    _check_methods(methods)  # before the images and the model are read
    if args.pairs:
        if args.image0 or args.image1:
            raise UsageError(f"Expected either two images or --pairs (got both: "
                             f"{args.image0} and --pairs {args.pairs})")
        if args.png or args.explain:
            raise UsageError(f"Expected --png / --explain with one pair (got --pairs "
                             f"{args.pairs}: run the pair alone to draw it)")
        return _predict_pairs(args, methods)
    # one estimator for both inputs: "recommended" (estimator.RECOMMENDED) walks the
    # recommended order (the images matched once), "all" runs every installed method; torch
    # is imported only once the inputs are read
    names = _method_names(methods)
    if args.matches:
        if args.image0 or args.image1:
            raise UsageError(f"Expected either two images or --matches (got both: "
                             f"{args.image0} and --matches {args.matches})")
        matches = _read_match_file(args)
        K0, images = matches.K0, None
        estimator = _predict_estimator(args, names)
        est = estimator.estimate(matches)
    else:
        if not (args.image0 and args.image1):
            raise UsageError("Expected two images, or --matches FILE (got "
                             f"{'one image' if args.image0 else 'neither'})")
        inputs = read_pair(args)  # fail on bad files before any heavy work
        estimator = _predict_estimator(args, names)
        img0, img1, K0, K1 = inputs
        images = (img0, img1)
        est = estimator.estimate_images(img0, img1, K0, K1, frontend_config(args),
                                        original=inputs.original_frame)
    kind = estimator.model_config.translation  # without building the shipped network
    code = STATUS_EXIT[est.status]
    if args.json:
        print(json.dumps({**est.to_dict(), "translation_kind": kind,
                          "intrinsics": K0 is not None}))
        if args.png:  # stdout is the JSON record: the drawing's line goes to stderr
            _draw_estimate(args.png, est, file=sys.stderr, images=images)
        if args.explain:
            _draw_explanation(args.explain, est, estimator, args.explainer, sys.stderr, images)
        return code
    print(f"matches: {est.num_points} points, {est.num_lines} lines")
    _print_estimate(est)
    if args.png:
        _draw_estimate(args.png, est, images=images)
    if args.explain:
        _draw_explanation(args.explain, est, estimator, args.explainer, images=images)
    if args.checkpoint and methods == "recommended":
        from strl_pyg.inference import METHODS

        if not any(METHODS[n].uses_network for n in est.methods if n in METHODS):
            # a user's own weights that nothing read: say so rather than let them think
            # the printed pose is their network's
            print(f"note: the recommended pose did not need the network, so --checkpoint "
                  f"{args.checkpoint} was not run; --methods all (or regression) shows its pose")
    return code


def _method_names(methods: str) -> tuple[str, ...] | str:
    """``--methods``: :data:`~strl_pyg.inference.RECOMMENDED`, or the names to run (``all``:
    every installed method), parsed by the registry's one parser (any case); a name it does
    not know is one line naming the closest registered name."""
    if methods.strip().lower() == "recommended":  # the default: nothing to import for it
        return "recommended"
    from strl_pyg.inference import checked_method_names  # the registry with its methods

    try:
        return checked_method_names(methods)
    except ValueError as err:
        raise UsageError(str(err).replace("Expected methods from", "Expected --methods from",
                                          1)) from None


def _check_methods(methods: str) -> None:
    """``--methods`` checked before any image or model is read."""
    _method_names(methods)


def _read_match_file(args):
    """``predict --matches``: a match file of this package (``strl-pose match``) or of another
    tool (:func:`~strl_pyg.data.external.load_external_matches`), with ``--K`` / ``--K0`` / ``--K1``
    and, for files without image sizes, the sizes of ``--image-size``."""
    check_input_file(args.matches, "match file (.npz) for --matches")
    K0, K1 = intrinsics_from_args(args)
    from strl_pyg.data.external import load_external_matches

    size = args.image_size
    try:
        return load_external_matches(args.matches, image_size0=size, image_size1=size,
                                     K0=K0, K1=K1)
    except (ValueError, TypeError, OSError) as err:
        raise UsageError(str(err).splitlines()[0]) from None
