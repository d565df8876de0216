"""Every method's estimate on seven fixed pairs, as JSON, to show that a refactoring changed no
estimate: run it on two versions of the package and compare.

    PYTHONPATH=../before python benchmarks/studies/dump_estimates.py --out before.json
    python benchmarks/studies/dump_estimates.py --out after.json --compare before.json

The pairs: generated street, indoor, boxes and object scenes; the street pair cut to 20 point
matches (point-poor), without intrinsics, and with a one-pixel focal length. Per pair: every
method's record (status, pose to 1e-9, sigma to 1e-6, warnings), the recommended pose of an
all-methods estimate and of the recommended path.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np


def pairs():
    from strl_pyg.synthetic import SceneConfig, generate_pair

    out = []
    for seed, kind in ((2_000_017, "street"), (11, "indoor"), (12, "boxes"), (13, "object")):
        out.append((f"{kind}-{seed}", generate_pair(seed, SceneConfig(kind=kind)).matches))
    m = generate_pair(2_000_017).matches
    out.append(("point-poor", m.select(np.arange(20))))
    out.append(("no-K", dataclasses.replace(m, K0=None, K1=None)))
    bad = m.K0.copy()
    bad[0, 0] = bad[1, 1] = 1.0
    out.append(("bad-K", dataclasses.replace(m, K0=bad, K1=bad)))
    return out


#: record the focal-inclusive sigma where a record has one (``--sigma-with-focal``): the sigma
#: an earlier version carried when the focal length's spread was added to the pose's own
WITH_FOCAL = False


def record(r) -> dict:
    sig = r.sigma
    if WITH_FOCAL and getattr(r, "sigma_with_focal", None) is not None:
        sig = r.sigma_with_focal
    sigma = None if sig is None else {k: None if v is None else round(v, 6)
                                      for k, v in sig.items()}
    return {"method": r.method, "status": str(r.status), "sigma": sigma,
            "warnings": list(r.warnings),
            "T": None if r.T_0to1 is None else np.round(r.T_0to1, 9).tolist()}


def dump() -> dict:
    from strl_pyg.inference import PoseEstimator

    out = {}
    for name, m in pairs():
        est = PoseEstimator(seed=0).estimate(m)
        out[name] = {"all": {k: record(v) for k, v in est.methods.items()},
                     "pose": record(est.pose),
                     "recommended": record(PoseEstimator(seed=0).estimate(
                         m, methods="recommended").pose)}
    return out


def differences(a: dict, b: dict) -> list[str]:
    out = []
    for pair in sorted(set(a) | set(b)):
        if pair not in a or pair not in b:
            out.append(f"{pair}: only in one dump")
            continue
        for part in ("all", "pose", "recommended"):
            x, y = a[pair][part], b[pair][part]
            if part == "all":
                out += [f"{pair} {m}" for m in sorted(set(x) | set(y)) if x.get(m) != y.get(m)]
            elif x != y:
                out.append(f"{pair} {part}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="the JSON dump to write")
    ap.add_argument("--compare", default=None, help="a dump to compare this one with")
    ap.add_argument("--sigma-with-focal", action="store_true",
                    help="record sigma_with_focal where a record has one (to compare with a "
                         "version whose sigma held the focal length's spread)")
    args = ap.parse_args(argv)
    global WITH_FOCAL
    WITH_FOCAL = args.sigma_with_focal
    result = dump()
    Path(args.out).write_text(json.dumps(result, indent=1, sort_keys=True))
    records = sum(len(v["all"]) + 2 for v in result.values())
    print(f"wrote {args.out}: {len(result)} pairs, {records} records")
    if args.compare:
        diff = differences(json.loads(Path(args.compare).read_text()), result)
        print(f"{len(diff)} records differ from {args.compare}" + "".join(
            f"\n  {d}" for d in diff))
        return 1 if diff else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
