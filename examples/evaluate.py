"""Evaluates a Str-L Pose checkpoint against the classical baselines and the fused pose.

Examples::

    python examples/evaluate.py --checkpoint strl_pyg/weights/strl_pose_geometric.pt \\
        --dataset synthetic --num-pairs 60 --noise-px 1 --outlier-fraction 0.3 --out out/syn
    python examples/evaluate.py --checkpoint ckpt.pt --dataset demon --data-root DEMON_ROOT
    python examples/evaluate.py --checkpoint ckpt.pt --dataset kitti --data-root KITTI_ROOT \\
        --sequences 09 10 --out out/kitti

Writes ``results.md``, ``results.json`` and trajectory PNGs (KITTI) to ``--out`` and prints
the table. All logic lives in :mod:`strl_pyg.evaluation`.
"""

from __future__ import annotations

import sys

from strl_pyg.evaluation import main

if __name__ == "__main__":
    sys.exit(main())
