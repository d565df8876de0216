"""Diagnostic (not a fit): how a network's regressed translation depends on the cameras' roll.

Each pair is evaluated as it is and with both cameras rolled about their optical axes by 90,
-90 and 180 degrees (:func:`strl_pyg.data.roll_cameras`: exact in the K-normalised
coordinates, pose rolled with them). A network trained on upright cameras only has learnt the
direction of an orbit from its training data: rolled by 90 degrees, a pair it solves is lost,
and a pair filmed with the camera on its side is solved once it is rolled back.

Sets: 30 held-out generated ``object`` pairs (orbits, focal 5-6 W as the dino's 5.2 W, the
generator's matches), the Middlebury dino's consecutive pairs and KITTI 06 (i, i+1) (front-end
matches, ``--cache``; skipped where the data is absent). Median / mean translation-direction
error (deg) of the regression head, per set and roll.

    python benchmarks/studies/diag_roll.py                  # the shipped weights
    python benchmarks/studies/diag_roll.py --checkpoint RUN/model.pt --label candidate
    python benchmarks/studies/diag_roll.py --report         # the table and figure of all JSONs
    python benchmarks/studies/diag_roll.py --verify         # roll hypotheses, kept by the matches

Writes ``results_roll/<label>.json``; ``--report`` writes ``results_roll.md`` and
``figures/roll.png``. ``--verify`` asks whether the roll can be found at inference time
without retraining: the network is run under four roll hypotheses (0, 90, 180, -90 deg), each
answer rolled back, and the one whose pose has the smallest median Sampson distance on the
pair's point matches is kept (the way a robust estimator scores its candidates), and
separately the one with the smallest predicted translation variance; it writes
``results_roll/verify/<label>.json``, a table in the report.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: shared helpers
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/studies/

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results_roll"
ROLLS = (0, 90, -90, 180)
GENERATED = 30


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def graphs(cache: Path, patch_size: int) -> dict[str, list]:
    import bench_pose as bp

    from strl_pyg import PairMatches
    from strl_pyg.data import build_pair_graph
    from strl_pyg.synthetic import generate_pair
    from strl_pyg.synthetic.distributions import eval_distribution

    dist = eval_distribution("object", object_focal_range=(5.0, 6.0))
    gen = []
    for seed in range(2_000_000, 2_000_000 + GENERATED):
        p = generate_pair(seed, dist.config(seed))
        m = p.matches
        pm = PairMatches(m.points0, m.points1, m.lines0, m.lines1, K0=p.K, K1=p.K,
                         image0=p.image0, image1=p.image1)
        gen.append(build_pair_graph(pm, T_0to1=np.asarray(p.T_0to1), patch_size=patch_size))
    out = {"generated object, f 5-6 W": gen}
    for name, pairs in (("Middlebury dino", bp.dino_pairs(cache)),
                        ("KITTI 06 (i, i+1)", bp.kitti_pairs(1, cache))):
        if pairs:
            out[name] = [build_pair_graph(m, T_0to1=T, patch_size=patch_size)
                         for _, m, T in pairs if m is not None]
    return out


def measure(model, sets: dict[str, list]) -> dict[str, dict[str, list[float]]]:
    import torch

    from strl_pyg.data import keys as K
    from strl_pyg.data import roll_cameras

    res: dict[str, dict[str, list[float]]] = {}
    for name, items in sets.items():
        res[name] = {}
        for roll in ROLLS:
            errs = []
            for g in items:
                h = roll_cameras(g, np.radians(roll))
                with torch.no_grad():
                    out = model(h)
                t = out.translation[0].double().numpy()
                T = h[K.T_0TO1].reshape(4, 4).double().numpy()
                errs.append(_angle(t, T[:3, 3]))
            res[name][str(roll)] = errs
            print(f"{name}, roll {roll:4d}: median {np.median(errs):6.1f}, mean "
                  f"{np.mean(errs):6.1f} deg ({len(errs)} pairs)", flush=True)
    return res


def flow_axis_vertical(x0: np.ndarray, x1: np.ndarray) -> bool:
    """Whether the displacements ``x1 - x0`` (K-normalised) run along the image's y more than
    along its x: the principal axis of their second moment is within 45 deg of vertical. Most
    of the generator's upright orbits move along x, the dino's rolled views along y. No
    displacement (no matches, or none moved): ``False``, the pair is left as it is."""
    u = np.asarray(x1, dtype=float).reshape(-1, 2) - np.asarray(x0, dtype=float).reshape(-1, 2)
    moment = u.T @ u
    if not np.isfinite(moment).all() or np.trace(moment) <= 1e-12:
        return False
    _, vecs = np.linalg.eigh(moment)
    axis = vecs[:, -1]
    return bool(abs(axis[1]) > abs(axis[0]))


def verify(model, sets: dict[str, list]) -> dict[str, dict[str, list]]:
    """Per set: the translation error (deg) of the pair as it is (``as_is``), of the roll
    hypothesis whose pose has the smallest median Sampson distance on the point matches
    (``verified``, its roll in ``picked``), of the hypothesis with the smallest predicted
    translation variance (``by_sigma``, its roll in ``picked_sigma``), of the roll that turns
    the flow's principal axis horizontal (``axis_p90`` / ``axis_m90``: the pair rolled by +90
    or -90 deg where the axis is vertical, the unrolled pair's error where it is horizontal;
    ``vertical`` per pair; the axis does not tell which of the two signs) and of the best
    hypothesis (``best``: an oracle)."""
    import torch

    from strl_pyg.data import keys as K
    from strl_pyg.data import roll_cameras
    from strl_pyg.data.transforms import roll_pose
    from strl_pyg.geometry.epipolar import pose_sampson

    res: dict[str, dict[str, list]] = {}
    for name, items in sets.items():
        r = res[name] = {"as_is": [], "verified": [], "best": [], "picked": [], "by_sigma": [],
                         "picked_sigma": [], "axis_p90": [], "axis_m90": [], "vertical": []}
        for g in items:
            truth = g[K.T_0TO1].reshape(4, 4).double()
            x0 = g[K.POINT][K.POS0].double()
            x1 = g[K.POINT][K.POS1].double()
            errs, costs, sigmas = [], [], []
            for roll in ROLLS:
                with torch.no_grad():
                    out = model(roll_cameras(g, np.radians(roll)))
                T = torch.eye(4, dtype=torch.float64)
                T[:3, :3] = out.R[0].double()
                T[:3, 3] = out.translation[0].double()
                T = roll_pose(T, -np.radians(roll))  # the answer in the pair's own frame
                t = T[:3, 3] / T[:3, 3].norm()
                costs.append(float(pose_sampson(T[:3, :3], t, x0, x1).abs().median()))
                sigmas.append(float(out.log_var[0, 4:].sum()))
                errs.append(_angle(T[:3, 3].numpy(), truth[:3, 3].numpy()))
            k = int(np.argmin(costs))
            r["as_is"].append(errs[0])
            r["verified"].append(errs[k])
            r["best"].append(min(errs))
            r["picked"].append(ROLLS[k])
            j = int(np.argmin(sigmas))
            r["by_sigma"].append(errs[j])
            r["picked_sigma"].append(ROLLS[j])
            vertical = flow_axis_vertical(x0.numpy(), x1.numpy())
            r["vertical"].append(vertical)
            r["axis_p90"].append(errs[ROLLS.index(90)] if vertical else errs[0])
            r["axis_m90"].append(errs[ROLLS.index(-90)] if vertical else errs[0])
        picked = {roll: r["picked"].count(roll) for roll in ROLLS}
        by_sigma = {roll: r["picked_sigma"].count(roll) for roll in ROLLS}
        print(f"{name}: as is {np.median(r['as_is']):.1f}, verified "
              f"{np.median(r['verified']):.1f}, by sigma {np.median(r['by_sigma']):.1f}, best "
              f"{np.median(r['best']):.1f} deg (median; rolls kept {picked}, by sigma "
              f"{by_sigma})", flush=True)
    return res


def verify_table() -> list[str]:
    """The report's lines for the ``--verify`` runs (``results_roll/verify/``); none without."""
    lines: list[str] = []
    verified = {p.stem: json.loads(p.read_text())
                for p in sorted((RESULTS / "verify").glob("*.json"))}
    if verified:
        lines += ["", "**Roll hypotheses kept by the matches** (`--verify`): median / mean "
                  "translation error (deg) as the pair is, of the hypothesis with the smallest "
                  "median Sampson distance, of the hypothesis with the smallest predicted "
                  "translation variance (sum of its three log-variances; '-' where not "
                  "measured), of the roll +90 or -90 deg where the flow's principal axis is "
                  "vertical (the pair as it is elsewhere; the share of vertical pairs), and of "
                  "the best hypothesis (an oracle); rolls kept (0 / 90 / -90 / 180) by the "
                  "Sampson distance, then by the variance.", "",
                  "| weights | set | as is | verified | by variance | +90 if flow vertical | "
                  "-90 if flow vertical | flow vertical | best | rolls kept |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for label, run in verified.items():
            for s, e in run["errors"].items():
                kept = " / ".join(str(e["picked"].count(r)) for r in ROLLS)
                if "picked_sigma" in e:
                    kept += "; " + " / ".join(str(e["picked_sigma"].count(r)) for r in ROLLS)
                cells = [f"{np.median(e[k]):.1f} / {np.mean(e[k]):.1f}" if k in e else "-"
                         for k in ("as_is", "verified", "by_sigma", "axis_p90", "axis_m90")]
                cells.append(f"{100 * np.mean(e['vertical']):.0f} %" if "vertical" in e else "-")
                cells.append(f"{np.median(e['best']):.1f} / {np.mean(e['best']):.1f}")
                lines.append(f"| {label} | {s} ({len(e['as_is'])}) | " + " | ".join(cells)
                             + f" | {kept} |")
    return lines


def report() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from strl_bench_common import banner

    # the measured runs (verify/ holds the --verify ones)
    runs = {p.stem: json.loads(p.read_text()) for p in sorted(RESULTS.glob("*.json"))}
    if not runs:
        raise SystemExit(f"error: expected measured runs in {RESULTS} (got none)")
    lines = ["# The regression's translation under a camera roll", "",
             "`python benchmarks/studies/diag_roll.py --report` (runs measured with `diag_roll.py "
             "--checkpoint ... --label ...`; see its docstring). Median / mean "
             "translation-direction error (deg) of the regression head; both cameras rolled "
             "by the same angle about their optical axes (exact in K-normalised coordinates).",
             ""]
    sets = list(next(iter(runs.values()))["errors"])
    lines += ["| weights | set | " + " | ".join(f"roll {r}" for r in ROLLS) + " |",
              "|---|---|" + "---|" * len(ROLLS)]
    for label, run in runs.items():
        for s in sets:
            e = run["errors"].get(s)
            if e is None:
                continue
            cells = [f"{np.median(e[str(r)]):.1f} / {np.mean(e[str(r)]):.1f}" for r in ROLLS]
            lines.append(f"| {label} | {s} ({len(e['0'])}) | " + " | ".join(cells) + " |")
    lines += verify_table()
    lines += ["", "```", banner().strip(), "```", "", "![roll](figures/roll.png)", ""]
    notes = HERE / "results_roll" / "notes.md"
    if notes.exists():
        lines += [notes.read_text()]
    (HERE / "results_roll.md").write_text("\n".join(lines))
    fig, axes = plt.subplots(1, len(sets), figsize=(4.2 * len(sets), 4.0), squeeze=False)
    width = 0.8 / len(runs)
    for ax, s in zip(axes[0], sets, strict=True):
        for k, (label, run) in enumerate(runs.items()):
            e = run["errors"].get(s)
            if e is None:
                continue
            med = [np.median(e[str(r)]) for r in ROLLS]
            ax.bar(np.arange(len(ROLLS)) + k * width, med, width, label=label)
        ax.set_xticks(np.arange(len(ROLLS)) + 0.4 - width / 2, [f"{r}" for r in ROLLS])
        ax.set_xlabel("roll of both cameras (deg)")
        ax.set_ylabel("median translation error (deg)")
        ax.set_title(s, fontsize=10)
    # one legend for all panels, below them (inside a panel it covered the bars)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.suptitle("Regression head: translation error against the cameras' roll")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    (HERE / "figures").mkdir(exist_ok=True)
    fig.savefig(HERE / "figures" / "roll.png", dpi=110)
    print(f"-> {HERE / 'results_roll.md'}, {HERE / 'figures' / 'roll.png'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoint", default=None, help="model.pt (default: the shipped model)")
    ap.add_argument("--label", default="shipped")
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "strl-pyg" / "eval_cache"))
    ap.add_argument("--report", action="store_true")
    ap.add_argument("--verify", action="store_true",
                    help="roll hypotheses, kept by their Sampson distance on the matches")
    args = ap.parse_args(argv)
    if args.report:
        return report()
    import torch
    from strl_bench_common import banner

    from strl_pyg.model.strl_pose import StrLPose

    torch.set_num_threads(1)
    print(banner())
    model = StrLPose.load(args.checkpoint) if args.checkpoint else StrLPose.from_pretrained()
    model.eval()
    sets = graphs(Path(args.cache), int(model.metadata.get("patch_size") or 1))
    res = verify(model, sets) if args.verify else measure(model, sets)
    path = (RESULTS / "verify" if args.verify else RESULTS) / f"{args.label}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"checkpoint": args.checkpoint or "shipped",
                                "errors": res}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
