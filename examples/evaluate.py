"""Evaluates a Str-L Pose checkpoint against the classical baselines and the fused pose.

Examples::

    # held-out generated pairs, front-end matches on the rendered images (the default)
    python examples/evaluate.py --dataset synthetic --num-pairs 60 --out out/syn
    # the generator's exact matches, noised (without noise the classical methods score 0 deg)
    python examples/evaluate.py --checkpoint strl_pyg/weights/strl_pose_geometric.pt \\
        --matches ground_truth --noise-px 1 --outlier-fraction 0.3 --out out/syn_gt
    python examples/evaluate.py --checkpoint ckpt.pt --dataset demon --data-root DEMON_ROOT
    python examples/evaluate.py --checkpoint ckpt.pt --dataset kitti --data-root KITTI_ROOT \\
        --sequences 09 10 --out out/kitti

Writes ``results.md``, ``results.json`` and trajectory PNGs (KITTI) to ``--out`` and prints
the table. All logic lives in :mod:`strl_pyg.evaluation.run`.
"""

from __future__ import annotations

import sys

from strl_pyg.evaluation.run import main

if __name__ == "__main__":
    sys.exit(main())
