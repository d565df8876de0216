"""The prepared GPU check: one script, under 10 minutes, to run first whenever a GPU is lent.

It times on the chosen device (and on the CPU in the same run, for the ratio):

1. the shipped model's forward on a batch of pair graphs (``network_poses``), and forward +
   backward of its loss-free output sum (a stand-in for training's backward pass);
2. a few training steps on generated pairs (``strl_pyg.training.train``, the paper's model at
   the shipped size);
3. ``strl-pose scene`` on a small generated collection (features on the CPU; the network on the
   device where a method runs it).

It writes ``<out>/gpu_check.json`` (device, versions, each timing) and prints it. With
``--quick`` every size is tiny, so that the slow test tier runs it on the CPU and it cannot
rot.

    python benchmarks/gpu_check.py --out gpu_check            # on the lent machine
    python benchmarks/gpu_check.py --quick --device cpu --out /tmp/gpu_check
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _timed(fn, repeat: int, sync) -> dict[str, float]:
    fn()  # warm-up (kernels, caches)
    sync()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        sync()
        times.append(1e3 * (time.perf_counter() - t))
    return {"median_ms": float(np.median(times)), "min_ms": float(np.min(times)),
            "repeat": repeat}


def network(device: str, pairs: int, repeat: int) -> dict:
    import torch

    from strl_pyg.inference.network import forward_pose, prepare_graph
    from strl_pyg.model import StrLPose
    from strl_pyg.synthetic import generate_pair

    model = StrLPose.from_pretrained().to(device).eval()
    matches = [generate_pair(1000 + k).matches for k in range(pairs)]
    from torch_geometric.data import Batch

    batch = Batch.from_data_list([prepare_graph(m, model) for m in matches]).to(device)
    sync = (lambda: torch.cuda.synchronize()) if device.startswith("cuda") else (lambda: None)

    def forward():
        with torch.no_grad():
            forward_pose(model, batch, device)

    def backward():  # the model itself (forward_pose is inference: eval mode, no_grad)
        model.zero_grad(set_to_none=True)
        out = model(batch)
        (out.quaternion.sum() + out.translation.sum() + out.log_var.sum()).backward()

    model.train()
    return {"pairs": pairs, "forward": _timed(forward, repeat, sync),
            "forward_backward": _timed(backward, repeat, sync)}


def training(device: str, steps: int, quick: bool) -> dict:
    from strl_pyg.training import train
    from strl_pyg.training.config import TrainConfig

    with tempfile.TemporaryDirectory() as out:
        small = {"hidden": 16, "layers": 1, "heads": 2, "patch_features": 1} if quick else {}
        cfg = TrainConfig(train_pairs=4 if quick else 32, val_pairs=2 if quick else 8,
                          batch_size=2 if quick else 8, steps=steps, val_every=steps,
                          out_dir=out, tensorboard=False, device=device,
                          model_overrides=small,
                          **({"num_points": 32, "num_lines": 16,
                              "scene": {"image_size": [96, 256], "max_points": 64,
                                        "max_lines": 32}} if quick else {}))
        t = time.perf_counter()
        train(cfg, progress=False)
        seconds = time.perf_counter() - t
    return {"steps": steps, "seconds_incl_data": seconds}


def scene(quick: bool) -> dict:
    import cv2

    from strl_pyg.collection import SceneOptions, exhaustive_pairs, read_collection, run_scene
    from strl_pyg.synthetic import generate_pair

    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / "images"
        folder.mkdir()
        n = 1 if quick else 4
        K = None
        for k in range(n):
            p = generate_pair(2000 + k)
            cv2.imwrite(str(folder / f"{k}a.png"), p.image0)
            cv2.imwrite(str(folder / f"{k}b.png"), p.image1)
            K = p.K
        images = read_collection(folder, K=K)
        pairs = exhaustive_pairs(len(images))
        t = time.perf_counter()
        s = run_scene(images, pairs, Path(d) / "out", SceneOptions(progress=False,
                                                                   database=False))
        return {"images": len(images), "pairs": len(pairs), "seconds": time.perf_counter() - t,
                "statuses": s.statuses}


def main(argv: list[str] | None = None) -> dict:
    import torch

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="gpu_check")
    ap.add_argument("--device", default="auto", help="auto (cuda when present), cpu, cuda")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (the CPU test)")
    args = ap.parse_args(argv)
    device = ("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" \
        else args.device
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise SystemExit(f"Expected a CUDA device for --device {device} (got none)")
    pairs, repeat, steps = (2, 2, 2) if args.quick else (16, 10, 20)
    result = {
        "device": device,
        "device_name": torch.cuda.get_device_name(0) if device.startswith("cuda") else
        platform.processor() or platform.machine(),
        "versions": {"python": platform.python_version(), "torch": torch.__version__},
        "quick": args.quick,
        "network": {device: network(device, pairs, repeat)},
    }
    if device != "cpu":  # the ratio's baseline, in the same run
        result["network"]["cpu"] = network("cpu", pairs, max(2, repeat // 5))
    result["training"] = {device: training(device, steps, args.quick)}
    result["scene"] = scene(args.quick)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "gpu_check.json").write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
