"""Where a user's K goes: ``strl-pose predict IMG0 IMG1 --K fx,fy,cx,cy`` run in-process with a
profile hook that notes every call of a ``strl_pyg`` function that is handed K, read at run
time rather than from the source.

"Handed K" means: an argument (``self`` included) that is a 3x3 intrinsics matrix proportional
to the user's (the K itself, or K rescaled for a downscaled image), or that holds one one level
down (a ``PairMatches``' ``K0`` / ``K1``, a tuple, a dict such as ``info["original_frame"]``).
For each module the script lists the functions, in the order first reached, and counts the
checks of K (``check_K``: shape and values; ``intrinsics_problems``: plausibility for the
image). Run it on two versions of the package to compare::

    python benchmarks/studies/trace_intrinsics.py
    PYTHONPATH=../before python benchmarks/studies/trace_intrinsics.py

The pair: frames 0 and 1 of KITTI 06 (1241 x 376, downscaled to ``--max-side`` 640), its own K.
"""

from __future__ import annotations

import argparse
import collections
import sys
import threading
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CHECKS = ("check_K", "intrinsics_problems")


def _is_K(obj, ref: np.ndarray) -> bool:
    if not (isinstance(obj, np.ndarray) and obj.shape == (3, 3) and obj.dtype.kind == "f"):
        return False
    if not np.allclose(obj[2], [0.0, 0.0, 1.0]) or abs(obj[0, 0]) < 1e-9:
        return False
    return bool(np.allclose(obj[:2] / obj[0, 0], ref[:2] / ref[0, 0], rtol=2e-2, atol=2e-2))


def _holds_K(obj, ref: np.ndarray, depth: int = 0, objects: bool = True) -> bool:
    """``obj`` is K or holds it one level down (``objects``: also as an attribute, e.g. a
    ``PairMatches``' ``K0``)."""
    if _is_K(obj, ref):
        return True
    if depth > 0:
        return False
    if isinstance(obj, (list, tuple)):
        return any(_holds_K(o, ref, 1) for o in obj[:8])
    if isinstance(obj, dict):
        return any(_holds_K(o, ref, 1) for o in list(obj.values())[:16])
    return objects and any(_is_K(getattr(obj, a, None), ref) for a in ("K0", "K1", "K"))


def trace(argv: list[str], ref: np.ndarray) -> tuple[list, collections.Counter]:
    """Runs ``strl-pose`` with ``argv``; the ``(module, function)`` calls handed K, in order,
    and the check counts."""
    from strl_pyg.cli import main

    package = str(Path(sys.modules["strl_pyg"].__file__).parent)
    seen: list[tuple[str, str, bool]] = []
    checks: collections.Counter = collections.Counter()

    def hook(frame, event, arg):
        if event != "call":
            return
        code = frame.f_code
        if not code.co_filename.startswith(package):
            return
        n = code.co_argcount + code.co_kwonlyargcount
        args = [frame.f_locals.get(v) for v in code.co_varnames[:n]]
        if any(_holds_K(a, ref) for a in args):
            module = Path(code.co_filename).relative_to(Path(package).parent).with_suffix("")
            bare = any(_holds_K(a, ref, objects=False) for a in args)
            seen.append((".".join(module.parts), code.co_name, bare))
            if code.co_name in CHECKS:
                checks[code.co_name] += 1

    sys.setprofile(hook)
    threading.setprofile(hook)  # the focal solves run in a worker thread
    try:
        code = main(argv)
    except SystemExit as err:
        code = err.code
    finally:
        sys.setprofile(None)
        threading.setprofile(None)
    print(f"strl-pose exit code {code}", file=sys.stderr)
    return seen, checks


def report(seen: list, checks: collections.Counter) -> str:
    modules: dict[str, list[str]] = {}
    moves = 0
    last = None
    bare = set()
    for module, fn, itself in seen:
        if module != last:
            moves += 1
            last = module
        fns = modules.setdefault(module, [])
        if fn not in fns:
            fns.append(fn)
        if itself:
            bare.add(module)
    lines = [f"modules handed K: {len(modules)} ({len(bare)} handed K itself, the others the "
             f"matches that hold it); moves between modules: {moves}; calls: {len(seen)}; "
             "checks: " + ", ".join(f"{c} x{checks[c]}" for c in CHECKS), "",
             "handed K itself: " + ", ".join(m for m in modules if m in bare), ""]
    for module, fns in modules.items():
        shown = ", ".join(fns[:8]) + (f", ... (+{len(fns) - 8})" if len(fns) > 8 else "")
        lines.append(f"- {module}: {shown}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--methods", default="recommended")
    ap.add_argument("--max-side", type=int, default=640,
                    help="predict's --max-side: 640 downscales the 1241-px frames (default)")
    args = ap.parse_args()
    seq = Path(args.data) / "kitti_odometry" / "sequences" / "06"
    if not seq.is_dir():
        raise SystemExit(f"Expected KITTI 06 under {seq} (not found)")
    fx, fy, cx, cy = 707.0912, 707.0912, 601.8873, 183.1104
    ref = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    argv = ["predict", str(seq / "image_0" / "000000.png"), str(seq / "image_0" / "000001.png"),
            "--K", f"{fx},{fy},{cx},{cy}", "--methods", args.methods,
            "--max-side", str(args.max_side)]
    import strl_pyg

    print(f"strl_pyg from {Path(strl_pyg.__file__).parent}")
    seen, checks = trace(argv, ref)
    print(report(seen, checks))


if __name__ == "__main__":
    main()
