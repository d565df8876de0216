"""How many of the true matches each front end finds, and what PoseLib makes of them.

Pairs ``(i, i+g)`` of the real_scenes validation scenes (never trained on), ``g`` in
{1, 2, 4, 8, 16}, ``--per-gap`` pairs per scene and gap spread evenly over each capture,
true relative rotation <= 60 deg; optionally the KITTI 06, dino and DeMoN slices
(``--slices``). For each front end on the same pairs: point matches, true inliers (Sampson
distance < 2 px under the stored pose and intrinsics), their ratio, PoseLib called directly
on the matches (``estimate_relative_pose(m, "poselib", 1.0)``) scored by the AUC of
max(rotation, translation-direction error) at 5 / 10 / 20 deg (a failure counts as 180 deg),
and the wall time per pair of the matching (both images' detection + matching, one process,
nothing else running).

Front ends (points only: lines are scored by ``bench_frontend.py``):

* ``ours:<preset>``: :func:`strl_pyg.frontend.match_images` with
  ``FrontendConfig.preset(<preset>)`` (``legacy`` is the configuration before the presets).
* ``colmap``: COLMAP's SIFT extraction and matching through pycolmap (CPU; its defaults:
  8192 features, first octave -1, peak threshold 0.0067, L1-root descriptors, ratio 0.8,
  distance 0.7, cross-check); skipped where pycolmap is not installed.
* ``opencv-8k`` / ``opencv-8k-up2``: an independent OpenCV set-up written here without the
  package (SIFT 8000, contrast 0.02, RootSIFT, ratio 0.85, no mutual check; the second on
  the image upsampled 2x).

Rows are appended to ``<out>/rows.jsonl`` as they are measured (a rerun skips what is there);
``report`` writes ``<out>/report.md``, ``<out>/report.json`` and ``<out>/gaps.png``.

    python benchmarks/bench_matches.py run --out benchmarks/results_frontend/real \\
        --fronts ours:legacy,ours:fast,ours:thorough,colmap,opencv-8k,opencv-8k-up2
    python benchmarks/bench_matches.py report --out benchmarks/results_frontend/real
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from strl_bench_common import banner, run_report_parser  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
VAL_SCENES = ("drone_hall", "fruit", "ethiopian_head", "office_drink")  # REAL_SCENES_SPLIT
GAPS = (1, 2, 4, 8, 16)
TRUE_PX = 2.0
MAX_ROT_DEG = 60.0


# ----------------------------------------------------------------------------- pairs
def scene_frames(scene: str, root: Path = DATA):
    """``(folder, images)`` of a real_scenes scene (``cameras.json``'s ``images``), or
    ``None`` where the scene is not there."""
    folder = root / "real_scenes" / scene
    if not (folder / "cameras.json").is_file():
        return None
    return folder, json.loads((folder / "cameras.json").read_text())["images"]


def scene_pairs(scenes=VAL_SCENES, gaps=GAPS, per_gap: int = 6, root: Path = DATA):
    """``(pair id, path0, path1, K0, K1, T_0to1, gap)`` of each scene: ``per_gap`` pairs per
    gap with first frames spread evenly over the capture, true rotation <= 60 deg."""
    out = []
    for scene in scenes:
        if (found := scene_frames(scene, root)) is None:
            continue
        folder, ims = found
        for g in gaps:
            if len(ims) <= g:
                continue
            starts = np.unique(np.linspace(0, len(ims) - g - 1, per_gap).round().astype(int))
            for i in starts:
                a, b = ims[i], ims[i + g]
                T = np.linalg.inv(np.array(b["T_cam_to_world"])) @ np.array(a["T_cam_to_world"])
                if rotation_deg(T[:3, :3]) > MAX_ROT_DEG:
                    continue
                out.append((f"{scene}/{i}-{i + g}", folder / a["file"], folder / b["file"],
                            np.array(a["K"], float), np.array(b["K"], float), T, g))
    return out


def slice_pairs(root: Path = DATA):
    """KITTI 06 ``(i, i+1)`` / ``(i, i+3)`` (every 6th ``i``), the dino's consecutive pairs
    and DeMoN's pairs, as ``(pair id, path0, path1, K0, K1, T_0to1, set)``."""
    out = []
    kitti = root / "kitti_odometry"
    if (kitti / "poses" / "06.txt").is_file():
        calib = {}
        for line in (kitti / "sequences/06/calib.txt").read_text().splitlines():
            if ":" in line:
                key, vals = line.split(":", 1)
                calib[key.strip()] = np.array(vals.split(), dtype=np.float64)
        K = calib["P0"].reshape(3, 4)[:, :3]
        poses = np.loadtxt(kitti / "poses/06.txt").reshape(-1, 3, 4)  # camera-to-world
        frames = sorted((kitti / "sequences/06/image_0").glob("*.png"))
        c2w = [np.vstack([poses[int(f.stem)], [0, 0, 0, 1]]) for f in frames]
        for gap in (1, 3):
            for i in range(0, len(frames) - gap, 6):
                j = i + gap
                out.append((f"kitti06/{i}-{j}", frames[i], frames[j], K, K,
                            np.linalg.inv(c2w[j]) @ c2w[i], f"KITTI 06 +{gap}"))
    if (root / "middlebury_dino").is_dir():
        from strl_pyg.datasets.middlebury import middlebury_pairs

        for a, b, T in middlebury_pairs(root / "middlebury_dino"):
            out.append((f"dino/{a.path.stem}-{b.path.stem}", a.path, b.path,
                        np.asarray(a.K, float), np.asarray(b.K, float), np.asarray(T), "dino"))
    for seq in sorted((root / "demon_deepsfm").glob("*/*/poses.txt")):
        d = seq.parent
        K = np.loadtxt(d / "cam.txt").reshape(3, 3)
        P = np.loadtxt(seq).reshape(-1, 3, 4)  # world-to-camera
        T = np.vstack([P[1], [0, 0, 0, 1]]) @ np.linalg.inv(np.vstack([P[0], [0, 0, 0, 1]]))
        out.append((f"demon/{d.name}", d / "0000.jpg", d / "0001.jpg", K, K, T, "DeMoN"))
    return out


def rotation_deg(R: np.ndarray) -> float:
    from strl_pyg.geometry.pose import rotation_angle_deg

    return float(rotation_angle_deg(np.asarray(R, float)))


def read_gray(path) -> np.ndarray:
    if not isinstance(path, (str, Path)):
        img = np.asarray(path)
        return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileNotFoundError(f"Expected an image at {path}")
    return img


# ----------------------------------------------------------------------------- front ends
def ours(spec: str):
    """``<preset>[+field=value...]``: a preset of :class:`FrontendConfig`, fields overridden."""
    from dataclasses import fields

    from strl_pyg.frontend import FrontendConfig, NoMatchesError, match_images

    preset, *over = spec.split("+")
    types = {f.name: f.type for f in fields(FrontendConfig)}
    kw = {}
    for o in over:
        k, v = o.split("=", 1)
        kw[k] = (v not in ("0", "false", "False")) if types[k] in ("bool", bool) else (
            float(v) if types[k] in ("float", float) else int(v))
    lines = kw.pop("lines", False)
    cfg = FrontendConfig.preset(preset, lines=bool(lines), **kw)

    def run(g0, g1):
        try:
            m = match_images(g0, g1, config=cfg)
        except NoMatchesError:
            return np.zeros((0, 2)), np.zeros((0, 2))
        if lines:
            return m.points0, m.points1, m.lines0, m.lines1
        return m.points0, m.points1
    return run


def colmap():
    import pycolmap

    ext = pycolmap.FeatureExtractor.create(pycolmap.FeatureExtractionOptions(),
                                           device=pycolmap.Device.cpu)
    mat = pycolmap.FeatureMatcher.create(pycolmap.FeatureMatchingOptions(),
                                         device=pycolmap.Device.cpu)

    def run(g0, g1):
        k0, d0 = ext.extract_from_uint8_array(np.ascontiguousarray(g0))
        k1, d1 = ext.extract_from_uint8_array(np.ascontiguousarray(g1))
        idx = np.asarray(mat.match(k0, d0, k1, d1), dtype=np.int64).reshape(-1, 2)
        # COLMAP puts the top-left pixel's corner at (0, 0): 0.5 px off OpenCV's centre
        xy0 = np.array([[k.x, k.y] for k in k0]).reshape(-1, 2) - 0.5
        xy1 = np.array([[k.x, k.y] for k in k1]).reshape(-1, 2) - 0.5
        return xy0[idx[:, 0]], xy1[idx[:, 1]]
    return run


def opencv_setup(upsample: bool):
    """The independent set-up: OpenCV only, written here without the package."""
    def detect(g):
        s = 2 if upsample else 1
        img = cv2.resize(g, None, fx=s, fy=s, interpolation=cv2.INTER_LINEAR) if s > 1 else g
        kp, d = cv2.SIFT_create(nfeatures=8000, contrastThreshold=0.02).detectAndCompute(img,
                                                                                        None)
        xy = (np.array([k.pt for k in kp]).reshape(-1, 2) + 0.5) / s - 0.5
        if d is None:
            return xy, None
        d = np.sqrt(d / np.maximum(d.sum(1, keepdims=True), 1e-12)).astype(np.float32)
        return xy, d

    def run(g0, g1):
        (x0, d0), (x1, d1) = detect(g0), detect(g1)
        if d0 is None or d1 is None or len(x0) < 2 or len(x1) < 2:
            return np.zeros((0, 2)), np.zeros((0, 2))
        knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d0, d1, k=2)
        good = [(m[0].queryIdx, m[0].trainIdx) for m in knn
                if len(m) == 2 and m[0].distance < 0.85 * m[1].distance]
        if not good:
            return np.zeros((0, 2)), np.zeros((0, 2))
        i0, i1 = np.array(good).T
        return x0[i0], x1[i1]
    return run


def front_end(name: str):
    if name.startswith("ours:"):
        return ours(name.split(":", 1)[1])
    if name == "colmap":
        return colmap()
    if name in ("opencv-8k", "opencv-8k-up2"):
        return opencv_setup(name.endswith("up2"))
    raise SystemExit(f"Expected a front end ours:<preset>, colmap, opencv-8k or "
                     f"opencv-8k-up2 (got {name!r})")


# ----------------------------------------------------------------------------- scoring
def sampson_px(p0, p1, K0, K1, T) -> np.ndarray:
    """Sampson distances (px) of point matches under the pose: the package's
    :func:`~strl_pyg.geometry.epipolar.epipolar_residuals`."""
    from types import SimpleNamespace

    from strl_pyg.geometry.epipolar import epipolar_residuals

    none = np.zeros((0, 2, 2))
    return epipolar_residuals(SimpleNamespace(points0=p0, points1=p1, lines0=none, lines1=none,
                                              K0=K0, K1=K1, line_endpoints_correspond=True),
                              T)[0]


def poselib_error(p0, p1, K0, K1, T, size0, size1) -> float:
    """max(rotation, translation-direction) error (deg) of PoseLib called directly on the
    matches; 180 where it finds no pose."""
    from strl_pyg.data import PairMatches
    from strl_pyg.estimation.classical import estimate_relative_pose

    if len(p0) < 5:
        return 180.0
    m = PairMatches(p0, p1, K0=K0, K1=K1, image_size0=size0, image_size1=size1)
    r = estimate_relative_pose(m, "poselib", 1.0, seed=0)
    if not r.success:
        return 180.0
    import bench_pose as bp

    rot, tr = bp.errors(r.T_0to1.matrix().numpy(), T)
    return float(max(rot, tr))


def measure(name, fn, pair) -> dict:
    pid, a, b, K0, K1, T, group = pair
    g0, g1 = read_gray(a), read_gray(b)
    t = time.perf_counter()
    p0, p1, *lines = fn(g0, g1)
    ms = 1e3 * (time.perf_counter() - t)
    p0, p1 = np.asarray(p0, float).reshape(-1, 2), np.asarray(p1, float).reshape(-1, 2)
    inl = sampson_px(p0, p1, K0, K1, T) < TRUE_PX if len(p0) else np.zeros(0, bool)
    row = {"front": name, "pair": pid, "group": group, "matches": int(len(p0)),
           "true": int(inl.sum()), "ms": ms,
           "err": poselib_error(p0, p1, K0, K1, T, g0.shape[:2], g1.shape[:2])}
    if lines:  # a line match is right where both endpoints are (Sampson < 2 px)
        l0, l1 = (np.asarray(x, float).reshape(-1, 2, 2) for x in lines)
        ok = np.ones(len(l0), bool)
        for k in range(2):
            if len(l0):
                ok &= sampson_px(l0[:, k], l1[:, k], K0, K1, T) < TRUE_PX
        row.update(lines=int(len(l0)), lines_true=int(ok.sum()))
    return row


# ----------------------------------------------------------------------------- report
def auc(errs, thr) -> float:
    from strl_pyg.metrics.two_view import pose_auc

    return 100.0 * pose_auc(np.asarray(errs, float), (thr,))[0]


def summarise(rows: list[dict], fronts: list[str], baseline: str) -> dict:
    from strl_pyg.metrics.stats import auc_difference_interval

    groups = sorted({r["group"] for r in rows},
                    key=lambda g: (isinstance(g, str), 0 if isinstance(g, str) else g, str(g)))
    by = {(r["front"], r["pair"]): r for r in rows}
    pairs_of = {g: sorted({r["pair"] for r in rows if r["group"] == g}) for g in groups}
    wide = [g for g in groups if g in (4, 8)]
    out = {}
    for g in [*groups, "gaps 4-8", "all gaps"]:
        pids = (pairs_of[g] if g in pairs_of else
                sorted({p for w in (wide if g == "gaps 4-8" else
                                    [x for x in groups if isinstance(x, int)])
                        for p in pairs_of[w]}))
        pids = [p for p in pids if all((f, p) in by for f in fronts)]
        if not pids:
            continue
        row = {}
        for f in fronts:
            rs = [by[(f, p)] for p in pids]
            errs = [r["err"] for r in rs]
            true = np.array([r["true"] for r in rs])
            n = np.array([r["matches"] for r in rs])
            d = {"pairs": len(pids), "matches": float(np.median(n)),
                 "true": float(np.median(true)), "few": int((true < 15).sum()),
                 "ratio": float(np.median(true / np.maximum(n, 1))),
                 "auc5": auc(errs, 5), "auc10": auc(errs, 10), "auc20": auc(errs, 20),
                 "ms": float(np.median([r["ms"] for r in rs]))}
            if all("lines" in r for r in rs):
                nl = sum(r["lines"] for r in rs)
                d["lines"] = float(np.median([r["lines"] for r in rs]))
                d["line_precision"] = sum(r["lines_true"] for r in rs) / max(nl, 1)
            if f != baseline:
                base = [by[(baseline, p)]["err"] for p in pids]
                dd, lo, hi = auc_difference_interval(errs, base, 10.0)
                d["d_auc10"] = [100 * dd, 100 * lo, 100 * hi]
            row[f] = d
        out[str(g)] = row
    return out


def markdown(summary: dict, fronts: list[str], baseline: str, header: str) -> str:
    lines = [header, "",
             "| pairs | front end | matches | true inliers | ratio | < 15 true | "
             "AUC@5 / 10 / 20 | AUC@10 vs " + baseline + " [95 %] | ms / pair |",
             "|---|---|---|---|---|---|---|---|---|"]
    for g, row in summary.items():
        label = f"gap {g}" if g.isdigit() else g
        for f in fronts:
            if f not in row:
                continue
            d = row[f]
            delta = ("" if "d_auc10" not in d else
                     "{:+.1f} [{:+.1f}, {:+.1f}]".format(*d["d_auc10"]))
            lines.append(
                f"| {label} ({d['pairs']}) | {f} | {d['matches']:.0f} | {d['true']:.0f} | "
                f"{d['ratio']:.2f} | {d['few']} | {d['auc5']:.1f} / {d['auc10']:.1f} / "
                f"{d['auc20']:.1f} | {delta} | {d['ms']:.0f} |")
    line_rows = [(g, f, row[f]) for g, row in summary.items() for f in fronts
                 if f in row and "lines" in row[f]]
    if line_rows:
        lines += ["", "Line matches (the epipolar matcher; right: both endpoints within 2 px "
                      "Sampson under the stored pose):", "",
                  "| pairs | front end | median line matches | precision (pooled) |",
                  "|---|---|---|---|"]
        for g, f, d in line_rows:
            label = f"gap {g}" if g.isdigit() else g
            lines.append(f"| {label} ({d['pairs']}) | {f} | {d['lines']:.0f} | "
                         f"{d['line_precision']:.3f} |")
    return "\n".join(lines) + "\n"


def plot(summary: dict, fronts: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gaps = [g for g in summary if g.isdigit()]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for f in [f for f in fronts if "lines=" not in f]:  # the same points as without lines
        xs = [int(g) for g in gaps if f in summary[g]]
        ax[0].plot(xs, [summary[str(g)][f]["true"] for g in xs], "o-", label=f)
        ax[1].plot(xs, [summary[str(g)][f]["auc10"] for g in xs], "o-", label=f)
    for a, t in zip(ax, ("median true inliers (Sampson < 2 px)", "PoseLib AUC@10 (%)"),
                    strict=True):
        a.set_xscale("log", base=2)
        a.set_xlabel("frame gap g of pairs (i, i+g)")
        a.set_ylabel(t)
        a.grid(alpha=0.3)
    ax[0].set_title("True matches found, real_scenes validation")
    ax[1].set_title("PoseLib called directly on each front end's matches")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = run_report_parser(__doc__, "benchmarks/results_frontend/real")
    ap.add_argument("--fronts", default="ours:legacy,ours:fast,ours:thorough,colmap,opencv-8k,"
                                        "opencv-8k-up2")
    ap.add_argument("--per-gap", type=int, default=6, help="pairs per scene and gap")
    ap.add_argument("--slices", action="store_true", help="also KITTI 06, dino and DeMoN")
    ap.add_argument("--baseline", default="ours:legacy")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows_path = out / "rows.jsonl"
    fronts = args.fronts.split(",")
    if args.what == "run":
        cv2.setNumThreads(1)
        pairs = scene_pairs(per_gap=args.per_gap)
        if args.slices:
            pairs += slice_pairs()
        done = set()
        if rows_path.is_file():
            done = {(r["front"], r["pair"]) for r in map(json.loads, rows_path.open())}
        print(banner())
        for name in fronts:
            fn = front_end(name)
            todo = [p for p in pairs if (name, p[0]) not in done]
            with rows_path.open("a") as f:
                for p in tqdm(todo, desc=name):
                    f.write(json.dumps(measure(name, fn, p)) + "\n")
                    f.flush()
        return 0
    rows = [json.loads(x) for x in rows_path.open()]
    fronts = [f for f in fronts if any(r["front"] == f for r in rows)]
    summary = summarise(rows, fronts, args.baseline)
    (out / "report.json").write_text(json.dumps(summary, indent=1))
    header = (f"# Front ends on real pairs\n\n{banner()}\n\nGenerated by `python "
              f"benchmarks/bench_matches.py report --out {out}`; rows measured by `run` with "
              "one OpenCV thread. True inliers: Sampson < 2 px under the stored pose. AUC of "
              "max(rotation, translation direction) of PoseLib called directly on each front "
              "end's matches; intervals: paired bootstrap over pairs.")
    (out / "report.md").write_text(markdown(summary, fronts, args.baseline, header))
    plot(summary, fronts, out / "gaps.png")
    print((out / "report.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
