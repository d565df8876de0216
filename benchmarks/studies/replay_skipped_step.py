"""Replays a training step that was skipped for a non-finite loss or gradient.

The training loop keeps the first skipped steps of a run as ``<run>/skipped/stepN.pt`` (the
run's config, the weights before the step, the batch). This script runs that step's forward
and backward pass again under autograd's anomaly mode and prints the losses, the operation
whose backward first returned a non-finite value (with the line of our code that built it),
and the gradient norm::

    python benchmarks/studies/replay_skipped_step.py runs/ship_balanced_3000/skipped/step000569.pt

The replay runs on the CPU in float32, whatever device the run trained on: a non-finite value
that only a GPU's arithmetic produces (TF32, other kernels) may not show here.

It is how the NaN of issue 30's phase-2 run (step 569) was traced to the float32 Sampson
division of the geometric head's essential loss (``benchmarks/training.md``).
"""

from __future__ import annotations

import argparse
import sys
import traceback

import torch


def replay(path: str) -> dict:
    from strl_pyg.data import keys
    from strl_pyg.training import loop
    from strl_pyg.training.skipped import load_skipped_step

    step, cfg, model, batch = load_skipped_step(path)
    loss_fn, geo_fn = loop.losses_for(cfg, model.config)
    model.train()
    report: dict = {"step": step, "anomaly": None}
    T = batch[keys.T_0TO1]
    with torch.autograd.detect_anomaly(check_nan=True):
        out = model(batch)
        logs = loss_fn(out, T)
        loss = logs["loss"]
        report["pose_loss"] = float(loss.detach())
        if geo_fn is not None:
            # the essential term as the loop weighs it at this step (steps count from 1)
            geo_fn.ess_weight = cfg.geo_ess_weight if step - 1 >= cfg.geo_ess_start else 0.0
            geo = geo_fn(out, T)
            report["geometric_loss"] = float(geo["loss"].detach())
            report["geometric_status"] = out.geometric.status.tolist()
            loss = loss + geo["loss"]
        report["loss"] = float(loss.detach())
        try:
            loss.backward()
        except RuntimeError as err:
            report["anomaly"] = str(err).splitlines()[0]
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    report["grad_norm"] = float(torch.cat([g.flatten() for g in grads]).norm()) if grads \
        else float("nan")
    return report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("path", help="a skipped/stepN.pt file of a training run")
    args = ap.parse_args(argv)
    try:
        r = replay(args.path)
    except (FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except Exception:  # a replay that fails elsewhere is itself the finding: show it whole
        traceback.print_exc()
        return 1
    print(f"step {r['step']}: loss {r['loss']:.6g} (pose {r['pose_loss']:.6g}"
          + (f", geometric {r['geometric_loss']:.6g}" if "geometric_loss" in r else "") + ")")
    if "geometric_status" in r:
        print(f"geometric head status per pair (0 ok): {r['geometric_status']}")
    print(f"first non-finite backward: {r['anomaly'] or 'none'}")
    print(f"gradient norm: {r['grad_norm']:.6g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
