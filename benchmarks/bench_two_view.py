"""Where the classical solvers give up: the two-view configuration, the focal check and the
network's fallback, measured on the same front-end matches.

Sets (all from ``../shared/data``, skipped where absent):

* **general**: real pairs: KITTI 06 ``(i, i+1)`` and ``(i, i+3)``, the dino's consecutive
  pairs, DeMoN, and the real_scenes validation scenes' ``(i, i+2)`` pairs (every 4th ``i``).
* **rotation**: real images and their warp by ``H = K R K^-1`` (R: 3-8 deg about a random
  axis): an exact pure rotation with real texture (every 5th KITTI frame, every 4th
  validation-scene image, every 4th dino view).
* **planar**: the same images warped by a plane's homography ``K (R - t n^T / d) K^-1``
  (random plane facing the camera, baseline 0.05-0.2 d): an exact planar scene.
* **focal**: the general real pairs with both focal lengths x0.5, x2, x10 (principal point
  kept).
* **hard**: the validation scenes' ``(i, i+6)`` pairs (wide baselines, indoor and objects).

For every pair it records the configuration, the focal check, the recommended pose (status,
method, errors, sigma) and the network's own pose with the evidence rule's verdict, and writes
``results_two_view.md`` (the confusion table, the focal table, the fallback table and the
"confident wrong" counts of the issue's targets: status ``ok``, off by more than 10 deg and 3
of its sigma).

    python benchmarks/bench_two_view.py --out benchmarks/results_two_view.md

``--json PATH`` also writes every pair's record (for a before / after comparison run on
another checkout: the script reads only ``PoseEstimator`` and the records' ``to_dict``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_pose as bp  # noqa: E402
from strl_bench_common import banner  # noqa: E402

DATA = bp.DATA
SCALES = (0.5, 2.0, 10.0)


def _rot(axis: np.ndarray, deg: float) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(axis / np.linalg.norm(axis) * math.radians(deg))[0]


def _images():
    """``(name, grey image, K)`` of the warp sets' source images."""
    import json as _json

    import cv2

    out = []
    seq = DATA / "kitti_odometry" / "sequences" / "06"
    if seq.is_dir():
        from strl_pyg.cli.readers import read_intrinsics

        K = read_intrinsics(str(seq / "calib.txt"))
        for p in sorted((seq / "image_0").glob("*.png"))[::5]:
            out.append((f"kitti06/{p.stem}", bp._read(p), K))
    for scene in ("drone_hall", "fruit", "ethiopian_head", "office_drink"):
        cams = DATA / "real_scenes" / scene / "cameras.json"
        if not cams.is_file():
            continue
        ims = _json.loads(cams.read_text())["images"]
        for im in ims[::8]:
            img = cv2.imread(str(cams.parent / im["file"]), cv2.IMREAD_GRAYSCALE)
            out.append((f"{scene}/{Path(im['file']).stem}", img, np.array(im["K"], float)))
    dino = DATA / "middlebury_dino"
    if dino.is_dir():
        from strl_pyg.datasets.middlebury import middlebury_pairs

        for a, _, _ in list(middlebury_pairs(dino))[::6]:
            out.append((f"dino/{a.path.stem}", bp._read(a.path), np.asarray(a.K, float)))
    return out


def warp_pairs(kind: str, cache: Path, seed: int = 0):
    """Real images and their exact pure-rotation or planar warps, matched by the front end."""
    import cv2

    from strl_pyg.frontend import NoMatchesError, match_images

    rng = np.random.default_rng(seed)
    out = []
    for name, img, K in _images():
        R = _rot(rng.normal(size=3), rng.uniform(3.0, 8.0))
        if kind == "rotation":
            H, t = K @ R @ np.linalg.inv(K), np.zeros(3)
        else:
            n = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 1.0])
            n /= np.linalg.norm(n)  # the plane n^T X = d in camera 0, d = 1, facing it
            t = rng.normal(size=3)
            t *= rng.uniform(0.05, 0.2) / np.linalg.norm(t)
            H = K @ (R + np.outer(t, n)) @ np.linalg.inv(K)  # X1 = R X0 + t, n^T X0 = 1
        h, w = img.shape[:2]
        warped = cv2.warpPerspective(img, H, (w, h), flags=cv2.INTER_LINEAR)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        try:
            m = bp._cached(cache, f"warp_{kind}_{seed}_{name}", lambda img=img, warped=warped,
                           K=K: match_images(img, warped, K0=K, K1=K))
        except NoMatchesError:
            continue
        out.append((f"{kind}/{name}", m, T))
    return out


def real_val_pairs(cache: Path, gap: int, stride: int):
    from strl_pyg.frontend import NoMatchesError, match_images

    out = []
    for scene in ("drone_hall", "fruit", "ethiopian_head", "office_drink"):
        folder = DATA / "real_scenes" / scene
        if not (folder / "cameras.json").is_file():
            continue
        ims = json.loads((folder / "cameras.json").read_text())["images"]
        for i in range(0, len(ims) - gap, stride):
            a, b = ims[i], ims[i + gap]
            T = np.linalg.inv(np.array(b["T_cam_to_world"])) @ np.array(a["T_cam_to_world"])
            try:
                m = bp._cached(cache, f"real_{scene}_{i}_{i + gap}", lambda a=a, b=b, folder=folder:
                               match_images(bp._read(folder / a["file"]),
                                            bp._read(folder / b["file"]),
                                            K0=np.array(a["K"]), K1=np.array(b["K"])))
            except NoMatchesError:
                continue
            out.append((f"{scene}/{i}-{i + gap}", m, T))
    return out


def scaled(m, s: float):
    from dataclasses import replace

    K0 = np.asarray(m.K0, float).copy()
    K1 = np.asarray(m.K1, float).copy()
    K0[:2, :2] *= s
    K1[:2, :2] *= s
    return replace(m, K0=K0, K1=K1)


def record(est, T, kind: str, pid: str) -> dict:
    """What the tables read of one estimate."""
    pose = est.pose
    d = est.to_dict()
    row = {"pair": pid, "set": kind, "status": pose.status, "method": pose.method,
           "configuration": (d.get("two_view") or {}).get("configuration"),
           "two_view": d.get("two_view")}
    sig = pose.sigma
    if pose.status == "ok":
        r, t = bp.errors(pose.T_0to1, T)
        row.update(rot=r, trans=t, sigma_rot=sig and sig["rotation_deg"],
                   sigma_trans=sig and sig["translation_deg"])
    if pose.status == "rotation_only":
        from strl_pyg.metrics.two_view import relative_pose_error

        Tr = np.eye(4)
        Tr[:3, :3] = pose.rotation
        r, _ = relative_pose_error(Tr[None], np.asarray(T)[None])
        row.update(rot=float(r[0]), sigma_rot=sig and sig["rotation_deg"])
    reg = est.methods.get("regression")
    if reg is not None and reg.status == "ok":
        r, t = bp.errors(reg.T_0to1, T)
        row["regression"] = {"rot": r, "trans": t}
    return row


def confident_wrong(row: dict) -> bool:
    """Status ``ok`` (or a rotation given) off by more than 10 deg and 3 of its sigma."""
    if row["status"] not in ("ok", "rotation_only"):
        return False
    worst = []
    for err, sig in (("rot", "sigma_rot"), ("trans", "sigma_trans")):
        if err in row and row[err] is not None:
            s = row.get(sig)
            worst.append(row[err] > 10.0 and (s is None or row[err] > 3 * s))
    return any(worst)


def markdown(rows: list[dict], header: str) -> str:
    L = [header, ""]
    sets = list(dict.fromkeys(r["set"] for r in rows))
    configs = ("general", "planar", "rotation", "degenerate", None)
    L += ["## Configuration (rows: what the pair is; columns: what was decided)", "",
          "| set | pairs | " + " | ".join(str(c) for c in configs) + " |",
          "|---|---|" + "---|" * len(configs)]
    for s in sets:
        rs = [r for r in rows if r["set"] == s]
        L.append(f"| {s} | {len(rs)} | " + " | ".join(
            str(sum(r["configuration"] == c for r in rs)) for c in configs) + " |")
    L += ["", "## Recommended pose per set", "",
          "| set | pairs | ok | rotation_only | unreliable | failed/degenerate | confident "
          "wrong | median rot (ok) | median t (ok) |", "|---|---|---|---|---|---|---|---|---|"]
    for s in sets:
        rs = [r for r in rows if r["set"] == s]
        ok = [r for r in rs if r["status"] == "ok"]
        med = lambda k, rr=ok: (f"{np.median([r[k] for r in rr]):.2f}" if rr else "-")  # noqa
        L.append(f"| {s} | {len(rs)} | {len(ok)} | "
                 f"{sum(r['status'] == 'rotation_only' for r in rs)} | "
                 f"{sum(r['status'] == 'unreliable' for r in rs)} | "
                 f"{sum(r['status'] in ('failed', 'degenerate') for r in rs)} | "
                 f"{sum(confident_wrong(r) for r in rs)} | {med('rot')} | {med('trans')} |")
    rot = [r for r in rows if r["set"] == "rotation" and r["status"] == "rotation_only"]
    if rot:
        e = np.array([r["rot"] for r in rot])
        L += ["", f"Pure rotations answered as rotations: {len(rot)}; rotation error median "
              f"{np.median(e):.3f} deg, max {e.max():.3f} deg, within 1 deg: "
              f"{int((e <= 1).sum())} of {len(e)}."]
    foc = [r for r in rows if r["set"].startswith("focal") or r["set"] == "general"]
    if foc:
        L += ["", "## Focal check (ratio s2/s1 of K1^T F K0 on general configurations)", "",
              "| set | pairs checked | ratio median | ratio p10 | ratio p1 | E/F inliers median "
              "| E/F p10 | flagged (< threshold) |",
              "|---|---|---|---|---|---|---|---|"]
        for s in dict.fromkeys(r["set"] for r in foc):
            vals = [((r["two_view"] or {}).get("focal_sv_ratio"),
                     (r["two_view"] or {}).get("focal_inliers", 0))
                    for r in foc if r["set"] == s]
            v = np.array([a for a, n in vals if a is not None and n >= 30])
            ef = np.array([(r["two_view"] or {})["inliers_E"] / (r["two_view"] or {})[
                "focal_inliers"] for r in foc if r["set"] == s and (r["two_view"] or {}).get(
                "focal_inliers", 0) >= 30])
            q = lambda a, p: f"{np.percentile(a, p):.3f}" if len(a) else "-"  # noqa: E731
            flagged = sum(1 for r in foc if r["set"] == s and r["status"] == "unreliable"
                          and "focal lengths do not fit" in json.dumps(r))
            L.append(f"| {s} | {len(v)} | {q(v, 50)} | {q(v, 10)} | {q(v, 1)} | {q(ef, 50)} | "
                     f"{q(ef, 10)} | {flagged} |")
    reg = [r for r in rows if "regression" in r and r["set"] in ("general", "hard")]
    if reg:
        L += ["", "## The network's pose and the evidence rule (general and hard real pairs)",
              "", "The rule is applied to every network pose here, as if the classical "
              "solvers had given up: 'right' is within 10 deg in rotation and 30 deg in "
              "translation.", "", "| verdict | right | wrong |", "|---|---|---|"]
        for verdict in ("kept", "withheld"):
            rr = [r for r in reg if r.get("evidence") == verdict]
            right = sum(r["regression"]["rot"] <= 10 and r["regression"]["trans"] <= 30
                        for r in rr)
            L.append(f"| {verdict} | {right} | {len(rr) - right} |")
    return "\n".join(L) + "\n"


def evidence_verdicts(est, m, threshold_px: float = 1.0) -> str | None:
    """The evidence rule's verdict on the network's pose of this pair (``None`` where the
    checkout has no rule)."""
    try:
        from strl_pyg.inference.evidence import learned_pose_evidence
        from strl_pyg.inference.support import (
            CHEIRALITY_MIN,
            MIN_INLIER_RATIO,
            MIN_SUPPORT_INLIERS,
        )
    except ImportError:
        return None
    reg = est.methods.get("regression")
    if reg is None or reg.status != "ok":
        return None
    out = learned_pose_evidence(reg, est.matches, threshold_px,
                                (MIN_INLIER_RATIO, MIN_SUPPORT_INLIERS, CHEIRALITY_MIN),
                                getattr(est, "geometry", None))
    return "kept" if out.status == "ok" else "withheld"


def _auc(rows: list[dict], t: float) -> float:
    """Pose AUC at ``t`` deg of the recommended pose (max of the two errors; a pose that is
    not ``ok`` counts as failed)."""
    from strl_pyg.metrics.stats import pose_error_stats

    rot = [r.get("rot", np.nan) if r["status"] == "ok" else np.nan for r in rows]
    tr = [r.get("trans", np.nan) if r["status"] == "ok" else np.nan for r in rows]
    ok = [r["status"] == "ok" for r in rows]
    return pose_error_stats(rot, tr, ok, thresholds=(t,))[f"auc{t:g}"]


def compare(before: list[dict], after: list[dict]) -> str:
    """The before / after table of two runs' per-pair records (same pairs)."""
    key = lambda r: (r["set"], r["pair"])  # noqa: E731
    b = {key(r): r for r in before}
    a = {key(r): r for r in after}
    common = [k for k in a if k in b]
    L = ["## Before / after (the same pairs; before: the previous release's code)", "",
         "| set | pairs | ok before | ok after | rotation_only after | confident wrong before | "
         "confident wrong after | from regression before | from regression after |",
         "|---|---|---|---|---|---|---|---|---|"]
    for s in dict.fromkeys(k[0] for k in common):
        ks = [k for k in common if k[0] == s]
        L.append(f"| {s} | {len(ks)} | {sum(b[k]['status'] == 'ok' for k in ks)} | "
                 f"{sum(a[k]['status'] == 'ok' for k in ks)} | "
                 f"{sum(a[k]['status'] == 'rotation_only' for k in ks)} | "
                 f"{sum(confident_wrong(b[k]) for k in ks)} | "
                 f"{sum(confident_wrong(a[k]) for k in ks)} | "
                 f"{sum(b[k]['status'] == 'ok' and b[k]['method'] == 'regression' for k in ks)} | "
                 f"{sum(a[k]['status'] == 'ok' and a[k]['method'] == 'regression' for k in ks)} |")
    L += ["", "Recommended pose AUC@5/10/20 on the real slices (general set), before and after, "
          "with a 95 % bootstrap interval of the difference (after - before) over pairs:", "",
          "| slice | pairs | AUC@5 | AUC@10 | AUC@20 | difference of AUC@10 [95 %] |",
          "|---|---|---|---|---|---|"]
    rng = np.random.default_rng(0)
    gen = [k for k in common if k[0] == "general"]
    for sl in dict.fromkeys(k[1].split("/")[0] for k in gen):
        ks = [k for k in gen if k[1].split("/")[0] == sl]
        rb, ra = [b[k] for k in ks], [a[k] for k in ks]
        cells = [f"{_auc(rb, t):.3f} -> {_auc(ra, t):.3f}" for t in (5, 10, 20)]
        diffs = []
        for _ in range(500):
            idx = rng.integers(0, len(ks), len(ks))
            diffs.append(_auc([ra[i] for i in idx], 10) - _auc([rb[i] for i in idx], 10))
        lo, hi = np.percentile(diffs, [2.5, 97.5])
        L.append(f"| {sl} | {len(ks)} | {' | '.join(cells)} | {_auc(ra, 10) - _auc(rb, 10):+.3f}"
                 f" [{lo:+.3f}, {hi:+.3f}] |")
    changed = [k for k in gen if (a[k]["status"], a[k]["method"]) != (b[k]["status"],
                                                                         b[k]["method"])]
    L += ["", f"Real pairs whose recommended status or method changed: {len(changed)} of "
          f"{len(gen)}" + (": " + "; ".join(
              f"{k[1]} {b[k]['status']}/{b[k]['method']} -> {a[k]['status']}/{a[k]['method']}"
              for k in changed[:20]) if changed else "") + "."]
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=None, help="markdown report")
    ap.add_argument("--json", default=None, help="every pair's record")
    ap.add_argument("--cache", default="outputs/bench_cache")
    ap.add_argument("--sets", default="general,rotation,planar,focal,hard")
    ap.add_argument("--limit", type=int, default=None, help="pairs per set (smoke runs)")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), default=None,
                    help="no run: the before / after table of two --json files")
    args = ap.parse_args(argv)
    if args.compare:
        text = compare(*(json.loads(Path(p).read_text()) for p in args.compare))
        print(text)
        if args.out:
            with open(args.out, "a") as f:
                f.write("\n" + text)
        return 0
    import torch

    from strl_pyg.inference import PoseEstimator

    torch.set_num_threads(1)
    cache = Path(args.cache)
    want = args.sets.split(",")
    est = PoseEstimator(methods=("poselib", "opencv", "regression"))
    sets = {}
    if "general" in want or "focal" in want:
        sets["general"] = (bp.kitti_pairs(1, cache) + bp.kitti_pairs(3, cache)
                           + bp.dino_pairs(cache) + bp.demon_pairs(cache)
                           + real_val_pairs(cache, 2, 4))
    for kind in ("rotation", "planar"):
        if kind in want:
            sets[kind] = warp_pairs(kind, cache)
    if "hard" in want:
        sets["hard"] = real_val_pairs(cache, 6, 4)
    jobs = []
    for name, pairs in sets.items():
        pairs = [p for p in pairs if p[1] is not None][:args.limit]
        if name != "general" or "general" in want:
            jobs += [(name, pid, m, T) for pid, m, T in pairs]
        if name == "general" and "focal" in want:
            for s in SCALES:
                jobs += [(f"focal x{s:g}", pid, scaled(m, s), T) for pid, m, T in pairs]
    rows = []
    t0 = time.perf_counter()
    for kind, pid, m, T in tqdm(jobs, desc="pairs"):
        e = est.estimate(m)
        row = record(e, T, kind, pid)
        row["evidence"] = evidence_verdicts(e, m)
        rows.append(row)
    header = (f"# Where the classical solvers give up\n\n{banner()}"
              f"\n\nCommand: `python benchmarks/bench_two_view.py {' '.join(argv or sys.argv[1:])}`"
              f" ({len(rows)} estimates in {time.perf_counter() - t0:.0f} s; not a timing).")
    text = markdown(rows, header)
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
