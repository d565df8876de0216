"""Profile of the predict path against a plain SIFT + MAGSAC pipeline on the same images.

One run, the same decoded images for both sides (real pairs: KITTI 06 frames 0-1, 370x1226;
DeMoN mvs_test_00000 0-1, 480x640; Middlebury dino 1-2 where present; and a generated
point-poor pair, :data:`POINT_POOR_SEED` of the ``point_poor`` set, 640x480, written to PNG files
first: at most 30 point matches, so ``--methods recommended`` puts the line solver ``vp`` first
and matches the points twice, once without lines to count them and once with lines). Every
figure is the median of ``--repeat`` runs after one warm-up; the ratios compare figures of this
run only (the machine is shared and noisy).

* **baseline**: ``cv2.SIFT_create()`` (OpenCV defaults) on both grey images, ``BFMatcher``
  kNN with Lowe's ratio test (0.8), ``cv2.findEssentialMat(USAC_MAGSAC, 0.999, 1 px)`` and
  ``cv2.recoverPose``.
* **stages** of ``strl-pose predict`` (the same calls :class:`~strl_pyg.inference.PoseEstimator`
  makes): image check and grey conversion, point detection, point matching, F fit, LSD, line
  candidates (epipolar overlap + guidance) and line descriptors (NCC), graph builds (resampled for
  the regression, full for the geometric head), network forwards, each pose method; the
  forward at batch 1 against the per-pair time at batch 16 (the same resampled graph,
  ``torch.inference_mode``); LSD at ``lsd_scale=0.5`` beside the default (a lever measured, not
  taken: it changes the lines the model reads).
* **end to end** ``PoseEstimator.estimate_images`` as ``strl-pose predict`` calls it: the
  default (``--methods recommended``: the checkpoint's recommended order, stopping at the first
  ``"ok"`` method, lines only when a method that reads them runs) and ``--methods all``
  (every installed method). Model loading (once per process) and reading the files are listed
  apart.

    MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=67108864 \\
        .venv/bin/python benchmarks/bench_predict.py --repeat 9

See :data:`MALLOC_NOTE` for why the malloc thresholds are pinned.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

from strl_bench_common import banner  # noqa: E402

from strl_pyg import frontend as fe  # noqa: E402
from strl_pyg.utils.images import read_image_file  # noqa: E402

MALLOC_ENV = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")
MALLOC_NOTE = (
    "glibc's malloc decides whether OpenCV's image buffers are reused or returned to the OS and "
    "faulted in again on every call; its thresholds move up during a process's life (after a "
    "large block is freed), and one SIFT detection of a 640x480 image then takes ~25 ms instead "
    "of ~39 ms: the baseline's time halves on those pairs. Unset, the figures depend on what ran "
    "before. Run it pinned, e.g. `MALLOC_MMAP_THRESHOLD_=131072 MALLOC_TRIM_THRESHOLD_=131072` "
    "(a fresh process) or `MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=67108864` "
    "(a long-running one).")


#: The generated point-poor pair (the first pair of the ``point_poor`` set of
#: ``benchmarks/ablation_eval.py``: 23 point and 34 line matches from our front end).
POINT_POOR_SEED = 2_100_000


#: Runs of the millisecond stages (the graph builds; a tenth of it for the batch-16 forward).
QUICK_REPEAT = 200


def _median_ms(fn, repeat: int) -> tuple[float, object]:
    out = fn()  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times), out


def baseline(img0: np.ndarray, img1: np.ndarray, K: np.ndarray):
    """Plain SIFT + ratio test + MAGSAC essential matrix + recoverPose; ``(R, t, inliers)``."""
    cv2.setRNGSeed(0)
    g0 = cv2.cvtColor(img0, cv2.COLOR_RGB2GRAY) if img0.ndim == 3 else img0
    g1 = cv2.cvtColor(img1, cv2.COLOR_RGB2GRAY) if img1.ndim == 3 else img1
    sift = cv2.SIFT_create()
    k0, d0 = sift.detectAndCompute(g0, None)
    k1, d1 = sift.detectAndCompute(g1, None)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d0, d1, k=2)
    good = [m[0] for m in knn if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
    p0 = np.float64([k0[m.queryIdx].pt for m in good])
    p1 = np.float64([k1[m.trainIdx].pt for m in good])
    if len(good) < 5:
        return None, None, 0
    E, mask = cv2.findEssentialMat(p0, p1, K, method=cv2.USAC_MAGSAC, prob=0.999, threshold=1.0)
    if E is None:  # no model found (few or degenerate matches): the baseline's time still counts
        return None, None, 0
    _, R, t, mask = cv2.recoverPose(E[:3], p0, p1, K, mask=mask)
    return R, t, int(mask.sum())


def _point_poor_pair(folder: Path):
    """The generated point-poor pair written to two PNG files in ``folder``."""
    from ablation_eval import point_poor_distribution

    from strl_pyg.synthetic import generate_pair

    p = generate_pair(POINT_POOR_SEED, point_poor_distribution().config(POINT_POOR_SEED))
    paths = [folder / f"point_poor_{POINT_POOR_SEED}_{i}.png" for i in (0, 1)]
    for path, img in zip(paths, (p.image0, p.image1), strict=True):
        if not cv2.imwrite(str(path), img):
            raise OSError(f"Expected to write '{path}' (cv2.imwrite failed)")
    return (f"generated point-poor {POINT_POOR_SEED}", paths,
            np.ascontiguousarray(np.asarray(p.K, dtype=np.float64)))


def _pairs(data: Path):
    out = []
    kitti = data / "kitti_odometry"
    if (kitti / "sequences/06").is_dir():
        seq = kitti / "sequences/06"
        P0 = next(ln for ln in (seq / "calib.txt").read_text().splitlines()
                  if ln.startswith("P0:"))
        # contiguous: OpenCV 5's USAC silently finds no model with a strided camera matrix
        K = np.ascontiguousarray(np.array(P0.split()[1:], dtype=np.float64).reshape(3, 4)[:, :3])
        out.append(("KITTI 06 0-1", [seq / f"image_0/{i:06d}.png" for i in (0, 1)], K))
    demon = data / "demon_deepsfm/test/mvs_test_00000"
    if demon.is_dir():
        K = np.loadtxt(demon / "cam.txt").reshape(3, 3)
        out.append(("DeMoN mvs_test_00000 0-1", [demon / f"{i:04d}.jpg" for i in (0, 1)], K))
    dino = data / "middlebury_dino"
    if (dino / "dino_par.txt").is_file():
        row = (dino / "dino_par.txt").read_text().split("\n")[1].split()
        K = np.array(row[1:10], dtype=np.float64).reshape(3, 3)
        out.append(("Middlebury dino 1-2", [dino / f"dino000{i}.png" for i in (1, 2)], K))
    return out


def _stages(img0, img1, K, model, repeat: int) -> dict[str, float]:
    """Median ms of each stage of the predict path, called one by one."""
    from strl_pyg.frontend import line_descriptor_scores
    from strl_pyg.frontend.lines import candidate_pairs
    from strl_pyg.inference import PoseEstimator, forward_pose, prepare_graph

    cfg = fe.FrontendConfig()
    t = {}
    t["image check + grey"], (g0, g1) = _median_ms(
        lambda: (fe.check_frontend_image(img0, "image0"), fe.check_frontend_image(img1, "image1")),
        repeat)
    both = fe.points.on_both  # the two images at once, as match_images does
    t["points: SIFT detect (2 images)"], ((k0, d0), (k1, d1)) = _median_ms(
        lambda: both(lambda g: fe.points._detector(cfg)[0].detectAndCompute(g, None), g0, g1,
                     cfg.concurrent), repeat)
    t["points: detect + match"], (p0, p1, _, _) = _median_ms(
        lambda: fe.match_points(g0, g1, cfg), repeat)
    t["points: match"] = t["points: detect + match"] - t["points: SIFT detect (2 images)"]
    t["F fit (MAGSAC)"], (F, inl) = _median_ms(lambda: fe.fit_fundamental(p0, p1, cfg),
                                                repeat)
    t["lines: LSD (2 images)"], (s0, s1) = _median_ms(
        lambda: both(lambda g: fe.detect_lines(g, cfg), g0, g1, cfg.concurrent), repeat)
    # LSD at a smaller scale: a lever measured, not taken (it changes the model's input)
    for scale in (0.5,):
        c = fe.FrontendConfig(lsd_scale=scale)
        ms, (r0, r1) = _median_ms(lambda c=c: both(lambda g: fe.detect_lines(g, c), g0, g1,
                                                   c.concurrent), repeat)
        t[f"(lines: LSD at lsd_scale {scale}, not the default: {len(r0)}+{len(r1)} segments "
          f"against {len(s0)}+{len(s1)})"] = ms
    guide = (p0[inl], p1[inl])
    t["lines: candidates"], cand = _median_ms(
        lambda: candidate_pairs(s0, s1, F, g1.shape, cfg, guide), repeat)
    t["lines: descriptors + NCC"], _ = _median_ms(
        lambda: line_descriptor_scores(cand[2], cand[3], cand[4], g0, g1, cfg), repeat)
    t["lines: match (total)"], _ = _median_ms(
        lambda: fe.match_lines(s0, s1, g0, g1, F, cfg, guide=guide), repeat)
    t["front end: match_images"], m = _median_ms(
        lambda: fe.match_images(img0, img1, K, K, cfg), repeat)
    # the graph stages take about a millisecond: a median of a few runs is mostly noise, so
    # they (and the batch-16 forward they are compared with) get many more runs
    quick = max(repeat, QUICK_REPEAT)
    t["graph: resampled"], g_small = _median_ms(lambda: prepare_graph(m, model, 0), quick)
    t["graph: full"], g_full = _median_ms(lambda: prepare_graph(m, model, 0, resample=None),
                                          quick)
    t["network: forward (resampled)"], _ = _median_ms(lambda: forward_pose(model, g_small),
                                                      repeat)
    t["network: forward (full, geometric head)"], _ = _median_ms(
        lambda: forward_pose(model, g_full), repeat)
    # the third target: batch 1 <= 1.5x the per-pair time at batch 16 (same graph)
    import torch
    from torch_geometric.loader.dataloader import Collater

    b16 = Collater(None)([g_small] * 16)
    with torch.inference_mode():
        t["network: model(graph), batch 1 (resampled)"], _ = _median_ms(
            lambda: model(g_small), max(repeat, QUICK_REPEAT // 10))
        ms16, _ = _median_ms(lambda: model(b16), max(repeat, QUICK_REPEAT // 10))
    t["network: model(graph), batch 16, per pair (resampled)"] = ms16 / 16
    est_all = PoseEstimator(model)
    runs = [est_all.estimate(m) for _ in range(max(repeat, 1) + 1)][1:]
    for name in est_all.method_names:
        t[f"method: {name} (own time_ms)"] = statistics.median(r.methods[name].time_ms
                                                              for r in runs)
    return t


def _end_to_end(img0, img1, K, model, repeat: int) -> dict[str, float]:
    from strl_pyg.frontend import FrontendConfig
    from strl_pyg.inference.recommended import estimate_methods

    out = {}
    for label, methods, boot in (
            ("predict (default: --methods recommended)", "recommended", 8),
            ("predict --bootstrap 0 (first-order covariance only)", "recommended", 0),
            ("predict --methods regression,poselib,fused (the network path)",
             "regression,poselib,fused", 8),
            ("predict --methods all", "all", 8)):
        out[label], res = _median_ms(
            lambda m=methods, b=boot: estimate_methods(model, img0, img1, K, K,
                                                       FrontendConfig(), m, bootstrap=b),
            repeat)
        out[f"{label}: method"] = f"{res.pose.method}; ran {', '.join(res.methods)}"
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results_predict.md"))
    args = ap.parse_args()
    import torch

    from strl_pyg.model.strl_pose import StrLPose

    lines = ["# Predict-path profile (`benchmarks/bench_predict.py`)", "",
             "    " + " ".join(f"{k}={os.environ[k]}" for k in MALLOC_ENV if k in os.environ)
             + " .venv/bin/python benchmarks/bench_predict.py "
             f"--repeat {args.repeat} --out {Path(args.out).name}", "", *banner().splitlines(),
             f"cv2 threads {cv2.getNumThreads()}, torch threads {torch.get_num_threads()}",
             "malloc: " + ", ".join(f"{k}={os.environ.get(k, 'unset')}" for k in MALLOC_ENV),
             "", MALLOC_NOTE, "",
             "Medians of the repeats after one warm-up, ms (the graph builds: at least "
             f"{QUICK_REPEAT} runs; the batch-1 and batch-16 forwards: at least "
             f"{QUICK_REPEAT // 10}). Ratios: to the baseline of the same "
             "pair in this run. Targets (issue 'The learned path at CPU speed'): the network "
             "path (front end with lines, graph, forward, PoseLib, fused) <= 1.0x, the default "
             "predict <= 0.8x. The figures before that issue's work: "
             "`benchmarks/studies/results_predict_before.md`. Run it on a quiet machine.", ""]
    t0 = time.perf_counter()
    model = StrLPose.from_pretrained()
    load_ms = 1e3 * (time.perf_counter() - t0)
    pairs = _pairs(Path(args.data))
    if not pairs:
        raise SystemExit(f"Expected the real data slices under {args.data} (got none)")
    tmp = tempfile.TemporaryDirectory()
    pairs.append(_point_poor_pair(Path(tmp.name)))
    for name, paths, K in pairs:
        t_read, (img0, img1) = _median_ms(lambda p=paths: [read_image_file(x) for x in p],
                                          args.repeat)
        base_ms, (_, _, n_inl) = _median_ms(lambda a=img0, b=img1, k=K: baseline(a, b, k),
                                            args.repeat)
        stages = _stages(img0, img1, K, model, args.repeat)
        e2e = _end_to_end(img0, img1, K, model, args.repeat)
        lines += [f"## {name} ({img0.shape[1]}x{img0.shape[0]})", "",
                  "| stage | ms | / baseline |", "|---|---|---|",
                  f"| **baseline: SIFT + ratio + MAGSAC E + recoverPose** ({n_inl} inliers) | "
                  f"{base_ms:.1f} | 1.00 |"]
        for k, v in stages.items():
            lines.append(f"| {k} | {v:.1f} | {v / base_ms:.2f} |")
        for k, v in e2e.items():
            if isinstance(v, float):
                lines.append(f"| **end to end: {k}** (pose from {e2e[k + ': method']}) | "
                             f"{v:.1f} | **{v / base_ms:.2f}** |")
        b1 = stages["network: model(graph), batch 1 (resampled)"]
        per16 = stages["network: model(graph), batch 16, per pair (resampled)"]
        lines += [f"| **forward at batch 1 / per pair at batch 16** (target <= 1.5) | - | "
                  f"**{b1 / per16:.2f}** |",
                  f"| (read both files) | {t_read:.1f} | {t_read / base_ms:.2f} |",
                  f"| (model load, once per process) | {load_ms:.1f} | - |", ""]
        print("\n".join(lines[-(len(stages) + 10):]), flush=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
