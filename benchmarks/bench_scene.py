"""Photo collections into COLMAP's mappers: our ``strl-pose scene`` database against COLMAP's
own pipeline (pycolmap's SIFT extraction, exhaustive matching and two-view verification), both
with the scene's known intrinsics, each reconstructed by pycolmap's incremental mapper and
GLOMAP's global mapper.

Per scene (``N`` images spread evenly over the capture order, every pair of them): registered
images; relative rotation and translation errors over all image pairs after reconstruction
against the verified poses (a pair with an unregistered image counts as a failure), AUC at
3 / 5 / 10 deg of ``max(rotation, translation)``, as IMC and GLOMAP report them; wall time of
the front end (features, matching, verification or our poses) and of each mapper; our statuses
against COLMAP's configurations on the same pairs.

The training scenes choose (``--verified``: which statuses become verified geometries); the
validation scenes are scored once with the choice. Both pipelines use the same cores: ours with
``--workers`` processes, COLMAP's with its own threads (all cores). Nothing else should run.

    python benchmarks/bench_scene.py run --split train \
        --out benchmarks/results_real_scenes/scene/train_ok
    python benchmarks/bench_scene.py run --split val --out benchmarks/results_real_scenes/scene/val
    python benchmarks/bench_scene.py report --out benchmarks/results_real_scenes/scene/val
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from strl_bench_common import banner  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real_scenes"
SPLITS = {
    "val": ["drone_hall", "fruit", "ethiopian_head", "office_drink"],
    "train": ["robot_table", "study_room", "beer_can"],
}
THRESHOLDS = (3.0, 5.0, 10.0)


def subset(scene: str, n: int):
    from strl_pyg.datasets.camera_files import read_real_scene

    posed = read_real_scene(DATA / scene)
    keep = np.unique(np.linspace(0, len(posed) - 1, n).round().astype(int))
    return [posed[k] for k in keep]


def ours(scene: str, posed, work: Path, workers: int, verified: tuple[str, ...],
         matcher: str | None = None):
    from strl_pyg.collection import SceneOptions, exhaustive_pairs, read_collection, run_scene
    from strl_pyg.frontend import FrontendConfig

    names = [Path(p.path).name for p in posed]
    images = read_collection(DATA / scene / "images", names=names, cameras=DATA / scene)
    t = time.perf_counter()
    summary = run_scene(images, exhaustive_pairs(len(images)), work / "ours",
                        SceneOptions(workers=workers, verified=verified, progress=False,
                                     frontend=FrontendConfig.preset(matcher) if matcher
                                     else FrontendConfig()))
    seconds = time.perf_counter() - t
    rows = [json.loads(line) for line in (work / "ours" / "pairs.jsonl").read_text()
            .splitlines()]
    return summary.outputs["database"], seconds, {(r["image0"], r["image1"]): r.get("status")
                                                  for r in rows}


def colmap(scene: str, posed, work: Path):
    import pycolmap

    names = [Path(p.path).name for p in posed]
    db = work / "colmap.db"
    K = np.asarray(posed[0].K)
    same_K = all(np.allclose(p.K, K) for p in posed)
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    reader.camera_params = ",".join(str(v) for v in (K[0, 0], K[1, 1], K[0, 2] + 0.5,
                                                       K[1, 2] + 0.5))
    t = time.perf_counter()
    pycolmap.extract_features(str(db), str(DATA / scene / "images"), image_names=names,
                              camera_mode=pycolmap.CameraMode.SINGLE if same_K
                              else pycolmap.CameraMode.PER_IMAGE, reader_options=reader,
                              device=pycolmap.Device.cpu)
    if not same_K:  # each image its own K
        with pycolmap.Database.open(str(db)) as d:
            by = {Path(p.path).name: p for p in posed}
            for im in d.read_all_images():
                cam = d.read_camera(im.camera_id)
                Ki = np.asarray(by[im.name].K)
                cam.params = [Ki[0, 0], Ki[1, 1], Ki[0, 2] + 0.5, Ki[1, 2] + 0.5]
                d.update_camera(cam)
    pycolmap.match_exhaustive(str(db), device=pycolmap.Device.cpu)
    seconds = time.perf_counter() - t
    configs = {}
    order = {n: k for k, n in enumerate(names)}  # our pairs list image0 before image1
    with pycolmap.Database.open(str(db)) as d:
        ids = {im.image_id: im.name for im in d.read_all_images()}
        pairs, geos = d.read_two_view_geometries()
        for pid, g in zip(pairs, geos, strict=True):
            a, b = pycolmap.pair_id_to_image_pair(pid)
            key = tuple(sorted((ids[a], ids[b]), key=order.get))
            configs[key] = pycolmap.TwoViewGeometryConfiguration(g.config).name
    return str(db), seconds, configs


def reconstruct(db: str, scene: str, work: Path, posed) -> dict:
    """Both mappers on ``db``: registered images, pairwise errors, seconds."""
    import pycolmap

    gt = {Path(p.path).name: np.asarray(p.T_c2w) for p in posed}
    out = {}
    for name, fn in (("incremental", pycolmap.incremental_mapping),
                     ("global", pycolmap.global_mapping)):
        folder = work / f"{Path(db).stem}_{name}"
        folder.mkdir()
        t = time.perf_counter()
        try:
            recs = fn(db, str(DATA / scene / "images"), str(folder))
        except Exception as err:  # a mapper that fails registers nothing
            print(f"  {name} on {Path(db).name} failed: {err}", file=sys.stderr)
            recs = {}
        seconds = time.perf_counter() - t
        best = max(recs.values(), key=lambda r: r.num_reg_images(), default=None)
        poses = {} if best is None else {
            im.name: np.linalg.inv(np.r_[im.cam_from_world().matrix(), [[0, 0, 0, 1]]])
            for im in best.images.values() if im.has_pose}
        out[name] = {"registered": len(poses), "seconds": seconds,
                     "errors": pair_errors(poses, gt)}
    return out


def pair_errors(poses: dict, gt: dict) -> list[float]:
    """``max(rotation, translation direction)`` error in degrees of every image pair (in
    ``gt``'s order; ``inf`` where an image is not registered)."""
    from strl_pyg.metrics.two_view import relative_pose_error

    names = list(gt)
    errs = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            na, nb = names[a], names[b]
            if na not in poses or nb not in poses:
                errs.append(float("inf"))
                continue
            T = np.linalg.inv(poses[nb]) @ poses[na]
            T_gt = np.linalg.inv(gt[nb]) @ gt[na]
            r, t = relative_pose_error(T, T_gt)
            errs.append(float(max(r, t)) if np.isfinite(float(t)) else float(r))
    return errs


def run(args) -> None:
    from tqdm.auto import tqdm

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows_path = out / "rows.jsonl"
    done = set()
    if rows_path.exists():
        done = {json.loads(line)["scene"] for line in rows_path.read_text().splitlines()}
    verified = tuple(args.verified.split(","))
    (out / "banner.txt").write_text(banner() + f"\npycolmap {__import__('pycolmap').__version__}"
                                    f"; ours with {args.workers} worker processes\n")
    for scene in tqdm(args.scenes or SPLITS[args.split], desc="scenes"):
        if scene in done:
            continue
        posed = subset(scene, args.images)
        work = Path(tempfile.mkdtemp(prefix=f"scene_{scene}_"))
        try:
            db_ours, t_ours, statuses = ours(scene, posed, work, args.workers, verified,
                                             args.matcher)
            db_colmap, t_colmap, configs = colmap(scene, posed, work)
            row = {"scene": scene, "images": len(posed), "verified": list(verified),
                   "matcher": args.matcher or "default (adaptive)",
                   "frontend_seconds": {"ours": t_ours, "colmap": t_colmap},
                   "ours": reconstruct(db_ours, scene, work, posed),
                   "colmap": reconstruct(db_colmap, scene, work, posed),
                   "status_vs_config": [[statuses.get(k), configs.get(k)] for k in
                                        sorted(set(statuses) | set(configs))]}
        finally:
            shutil.rmtree(work, ignore_errors=True)
        with open(rows_path, "a") as f:
            f.write(json.dumps(row) + "\n")


def report(args) -> None:
    from strl_pyg.metrics.stats import auc_difference_interval
    from strl_pyg.metrics.two_view import pose_auc

    out = Path(args.out)
    rows = [json.loads(line) for line in (out / "rows.jsonl").read_text().splitlines()]
    lines = [f"# Photo collections: ours vs COLMAP's pipeline ({out.name})", "",
             "```", (out / "banner.txt").read_text().strip(), "```", "",
             "| scene | images | mapper | registered ours / COLMAP | AUC@3 ours / COLMAP | "
             "AUC@5 ours / COLMAP | AUC@10 ours / COLMAP | front end s ours / COLMAP | "
             "mapper s ours / COLMAP |", "|---|---|---|---|---|---|---|---|---|"]
    pooled: dict[str, dict[str, list]] = {}
    for r in rows:
        for m in ("incremental", "global"):
            o, c = r["ours"][m], r["colmap"][m]
            ao, ac = pose_auc(o["errors"], THRESHOLDS), pose_auc(c["errors"], THRESHOLDS)
            pooled.setdefault(m, {"ours": [], "colmap": []})
            pooled[m]["ours"] += o["errors"]
            pooled[m]["colmap"] += c["errors"]
            lines.append(
                f"| {r['scene']} | {r['images']} | {m} | {o['registered']} / {c['registered']} | "
                + " | ".join(f"{100 * a:.1f} / {100 * b:.1f}" for a, b in zip(ao, ac,
                                                                                strict=True))
                + f" | {r['frontend_seconds']['ours']:.0f} / "
                  f"{r['frontend_seconds']['colmap']:.0f} | {o['seconds']:.1f} / "
                  f"{c['seconds']:.1f} |")
    lines += ["", "Pooled over the scenes' image pairs (AUC@5 ours - COLMAP, paired bootstrap "
              "over pairs, 95 %; pairs of one scene are not independent, so the interval is "
              "narrower than a scene-level one):", ""]
    for m, d in pooled.items():
        diff, lo, hi = auc_difference_interval(d["ours"], d["colmap"], threshold=5.0)
        ao = pose_auc(d["ours"], (5.0,))[0]
        ac = pose_auc(d["colmap"], (5.0,))[0]
        lines.append(f"- {m}: AUC@5 ours {100 * ao:.1f}, COLMAP {100 * ac:.1f}, difference "
                     f"{100 * diff:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] over "
                     f"{len(d['ours'])} pairs")
    t_o = sum(r["frontend_seconds"]["ours"] for r in rows)
    t_c = sum(r["frontend_seconds"]["colmap"] for r in rows)
    lines += ["", f"Front end wall time, all scenes: ours {t_o:.0f} s, COLMAP {t_c:.0f} s "
              f"(ours / COLMAP {t_o / t_c:.2f}x).", "",
              "Our status against COLMAP's two-view configuration on the same pairs:", "",
              "| our status | COLMAP configuration | pairs |", "|---|---|---|"]
    table: dict[tuple, int] = {}
    for r in rows:
        for s, c in r["status_vs_config"]:
            table[(str(s), str(c))] = table.get((str(s), str(c)), 0) + 1
    lines += [f"| {s} | {c} | {n} |" for (s, c), n in sorted(table.items())]
    (out / "README.md").write_text("\n".join(lines) + "\n")
    _plot(rows, out)
    print("\n".join(lines))


def _plot(rows: list[dict], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from strl_pyg.metrics.two_view import pose_auc

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    x = np.arange(len(rows))
    for ax, m in zip(axes, ("incremental", "global"), strict=True):
        for k, (who, label) in enumerate((("ours", "strl-pose scene"),
                                          ("colmap", "COLMAP SIFT + verification"))):
            auc = [100 * pose_auc(r[who][m]["errors"], (5.0,))[0] for r in rows]
            ax.bar(x + (k - 0.5) * 0.4, auc, 0.4, label=label)
        ax.set_xticks(x, [r["scene"] for r in rows], rotation=20)
        ax.set_title(f"{m} mapper")
        ax.set_xlabel("scene")
    axes[0].set_ylabel("pairwise AUC@5 after reconstruction (%)")
    axes[0].legend()
    fig.suptitle(f"Relative poses after reconstruction ({out.name})")
    fig.tight_layout()
    fig.savefig(out / "auc5.png", dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("run", "report"))
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results_real_scenes" / "scene"
                                         / "val"))
    ap.add_argument("--split", choices=tuple(SPLITS), default="val")
    ap.add_argument("--scenes", nargs="*", help="instead of the split's scenes")
    ap.add_argument("--images", type=int, default=16, help="images per scene (default 16)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--verified", default="ok", help="statuses written as verified geometries")
    ap.add_argument("--matcher", default=None, choices=("fast", "thorough", "adaptive", "legacy"),
                    help="our front-end preset (default: FrontendConfig(), adaptive)")
    args = ap.parse_args()
    if args.what == "run":
        run(args)
    report(args)


if __name__ == "__main__":
    main()
