"""Pure rotations made from real photographs: does the recommended pose say ``rotation_only``?

``bench_two_view.py`` warps KITTI, dino and the validation scenes the same way for its
configuration table; this one takes every real_scenes scene, the training scenes included,
and reports the recommended pose's status alone.

A camera that only rotates by ``R`` sees image 0 warped by ``H = K R K^-1`` (no parallax, no
translation to find). For frames spread over each real_scenes scene (``--per-scene``), one
rotation each (angle cycling through ``ANGLES_DEG``, axis drawn from a generator seeded by the
frame's id, so the same in every split), the
photograph and its warp are matched by the default front end and given to ``PoseEstimator()``
(its default order, bootstrap and checks) and to PoseLib called directly.

What is right: ``rotation_only`` with the rotation within 5 deg. What breaks the status's
promise: ``ok`` (a translation direction that does not exist, given as usable), reported with
its translation sigma; a refusal (``unreliable`` / ``failed`` / ``degenerate``) is safe but
gives nothing. The report: per split, the status counts, the rotation error of the answers
(``ok`` and ``rotation_only``), PoseLib's rotation error on the same matches, and the ``ok``
answers with their translation sigma.

    python benchmarks/bench_pure_rotation.py run --out benchmarks/results_real_scenes/pure_rotation
    python benchmarks/bench_pure_rotation.py report \\
        --out benchmarks/results_real_scenes/pure_rotation
"""

from __future__ import annotations

import json
import sys
import zlib
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_matches as bm  # noqa: E402
import bench_pose as bp  # noqa: E402
from strl_bench_common import banner, run_report_parser  # noqa: E402

ANGLES_DEG = (2.0, 5.0, 10.0, 15.0)
RIGHT_DEG = 5.0


def rotation(axis_seed: int, angle_deg: float) -> np.ndarray:
    """A rotation by ``angle_deg`` about an axis drawn uniformly on the sphere (seeded)."""
    import bench_two_view as btv

    return btv._rot(np.random.default_rng(axis_seed).normal(size=3), angle_deg)


def warped_pairs(split: str, per_scene: int, root: Path = bm.DATA):
    """``(pair id, image path, K, R, angle)`` per frame: frames spread evenly over each scene."""
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT

    scenes = (REAL_SCENES_SPLIT["val"] + REAL_SCENES_SPLIT["train"] if split == "all"
              else REAL_SCENES_SPLIT[split])
    out = []
    for scene in scenes:
        if (found := bm.scene_frames(scene, root)) is None:
            continue
        folder, ims = found
        for k, i in enumerate(np.unique(np.linspace(0, len(ims) - 1, per_scene).round()
                                        .astype(int))):
            angle = ANGLES_DEG[k % len(ANGLES_DEG)]
            out.append((f"{scene}/{i}", folder / ims[i]["file"], np.array(ims[i]["K"], float),
                        rotation(zlib.crc32(f"{scene}/{i}".encode()), angle), angle))
    return out


def measure(est, pair) -> dict:
    import cv2

    from strl_pyg.estimation.classical import estimate_relative_pose
    from strl_pyg.frontend import FrontendConfig, NoMatchesError, match_images

    pid, path, K, R, angle = pair
    img = bm.read_gray(path)
    H = K @ R @ np.linalg.inv(K)
    warp = cv2.warpPerspective(img, H, (img.shape[1], img.shape[0]))
    T = np.eye(4)
    T[:3, :3] = R
    row = {"pair": pid, "scene": pid.split("/")[0], "angle": angle}
    try:
        m = match_images(img, warp, K0=K, K1=K, config=FrontendConfig(lines=False))
    except NoMatchesError:
        return {**row, "status": "degenerate", "matches": 0}
    row["matches"] = m.num_points
    pl = estimate_relative_pose(m, "poselib", 1.0, seed=0)
    row["poselib_rot"] = bp.errors(pl.T_0to1.matrix().numpy(), T)[0] if pl.success else None
    e = est.estimate(m)
    pose = e.pose
    row.update(status=pose.status, method=pose.method, configuration=e.configuration)
    if pose.rotation is not None:
        Rm = np.eye(4)
        Rm[:3, :3] = np.asarray(pose.rotation)
        row["rot"] = bp.errors(Rm, T)[0]
    if pose.sigma is not None:
        row["sigma"] = [pose.sigma.get("rotation_deg"), pose.sigma.get("translation_deg")]
    row["reasons"] = [w[:160] for w in pose.info.get("unreliable", pose.warnings)][:3] \
        if pose.status not in ("ok", "rotation_only") else []
    return row


def run(args) -> int:
    from strl_pyg.inference import PoseEstimator

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows_path = out / "rows.jsonl"
    done = set()
    if rows_path.is_file():
        done = {r["pair"] for r in map(json.loads, rows_path.open())}
    print(banner())
    est = PoseEstimator()
    pairs = [p for p in warped_pairs(args.split, args.per_scene) if p[0] not in done]
    with rows_path.open("a") as f:
        for pair in tqdm(pairs, desc=f"warped photographs ({args.split})"):
            f.write(json.dumps(measure(est, pair)) + "\n")
            f.flush()
    return 0


def _median(xs) -> str:
    xs = [x for x in xs if x is not None]
    return f"{np.median(xs):.2f}" if xs else "-"


def report(args) -> int:
    from strl_pyg.datasets.posed import REAL_SCENES_SPLIT

    out = Path(args.out)
    rows = [json.loads(line) for line in (out / "rows.jsonl").open()]
    lines = ["# Pure rotations made from real photographs (`benchmarks/bench_pure_rotation.py`)",
             "", banner(), "",
             f"{len(rows)} photographs, each matched with its own warp by `K R K^-1` "
             f"(rotation {', '.join(f'{a:g}' for a in ANGLES_DEG)} deg in turn, a random axis); "
             "the recommended pose of `PoseEstimator()`. Right: `rotation_only` within "
             f"{RIGHT_DEG:g} deg.", "",
             "| split | pairs | rotation_only (right) | ok | unreliable | failed / degenerate "
             "| rotation error, median deg (answers) | PoseLib's rotation error, median deg |",
             "|---|---|---|---|---|---|---|---|"]
    for split in ("val", "train"):
        rs = [r for r in rows if r["scene"] in REAL_SCENES_SPLIT[split]]
        if not rs:
            continue
        n = {s: sum(r["status"] == s for r in rs) for s in
             ("rotation_only", "ok", "unreliable", "failed", "degenerate")}
        right = sum(r["status"] == "rotation_only" and r.get("rot", 180) <= RIGHT_DEG
                    for r in rs)
        lines.append(f"| {split} | {len(rs)} | {n['rotation_only']} ({right}) | {n['ok']} | "
                     f"{n['unreliable']} | {n['failed'] + n['degenerate']} | "
                     f"{_median(r.get('rot') for r in rs)} | "
                     f"{_median(r.get('poselib_rot') for r in rs)} |")
    oks = [r for r in rows if r["status"] == "ok"]
    lines += ["", f"`ok` answers (a translation given where there is none): {len(oks)}"]
    for r in oks:
        s = r.get("sigma") or [None, None]
        lines.append(f"- {r['pair']} ({r['angle']:g} deg, {r['matches']} matches): rotation "
                     f"error {r.get('rot', float('nan')):.2f} deg, sigma rotation "
                     f"{s[0] if s[0] is None else round(s[0], 2)} / translation "
                     f"{s[1] if s[1] is None else round(s[1], 1)} deg, configuration "
                     f"{r.get('configuration')}")
    refused = [r for r in rows if r["status"] not in ("ok", "rotation_only")]
    lines += ["", f"Refused: {len(refused)}"]
    for r in refused:
        lines.append(f"- {r['pair']} ({r['angle']:g} deg, {r.get('matches')} matches): "
                     f"{r['status']}: {'; '.join(r.get('reasons', []))[:200]}")
    (out / "README.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def main(argv=None) -> int:
    ap = run_report_parser(__doc__, "benchmarks/results_real_scenes/pure_rotation")
    ap.add_argument("--split", choices=("val", "train", "all"), default="all")
    ap.add_argument("--per-scene", type=int, default=8)
    args = ap.parse_args(argv)
    return run(args) if args.what == "run" else report(args)


if __name__ == "__main__":
    raise SystemExit(main())
