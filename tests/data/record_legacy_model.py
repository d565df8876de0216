"""Records ``tests/data/legacy_model.pt``: graphs, checkpoints and outputs of the model as it was
before the dual graph became a list of ``DualGraphLayer`` blocks (commit 3a109d5, state-dict
keys ``geo_self.{i}.*``, ``line_convs.{i}.*``, ``vis_self.{i}.*``, ``vis_cross.{i}.*``,
``fusion.pose_mlp.*``, ``fusion.var_mlp.*``).

It was run once, on a frozen copy of that commit::

    git archive 3a109d5 | tar -x -C /tmp/strl_head
    PYTHONPATH=/tmp/strl_head:/tmp/strl_head/tests python tests/data/record_legacy_model.py

Re-running it on a later tree records that tree's layout instead, which is not the point:
``tests/test_model_compat.py`` compares today's code against these recorded outputs.

The file holds plain tensors, str, int, float, bool and dicts only (loads with
``weights_only=True``):

* ``graphs``: name -> list of graphs, each ``{"node": {type: {key: value}},
  "edge": {"src|rel|dst": {key: value}}, "graph": {key: value}}`` (tensors and ints);
* ``checkpoints``: name -> the payload that ``StrLPose.save`` wrote (version 2) for a tiny
  model initialised with ``torch.manual_seed(0)``;
* ``outputs``: model name -> graph name -> ``{quaternion, translation, log_var}`` (plus
  ``geometric_logits``, ``geometric_E``, ``geometric_status`` for the geometric head).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch
from test_model import make_pair
from torch_geometric.data import Batch

from strl_pyg.data import PairMatches, build_pair_graph
from strl_pyg.model.strl_pose import StrLPose, StrLPoseConfig

OUT = Path(__file__).with_name("legacy_model.pt")
TINY = dict(hidden=8, layers=2, heads=2, line_channels=4)
CONFIGS = {
    "full": StrLPoseConfig.ablation("full", **TINY),
    "full_geometric": StrLPoseConfig.ablation("full", geometric=True, **TINY),
    "baseline": StrLPoseConfig.ablation("baseline", **TINY),
    "V": StrLPoseConfig.ablation("V", **TINY),
    "LP_metric": StrLPoseConfig.ablation("LP", translation="metric", **TINY),
}


def grey_pair(seed: int, n_points: int, n_lines: int, complete: str = "implicit"):
    """A pair with greyscale images (patch_features=1, as the shipped model)."""
    g = make_pair(seed, n_points, n_lines, complete)
    rng = np.random.default_rng(100 + seed)
    H, W = 96, 128
    m = PairMatches(g["point"].kpts0.numpy(), g["point"].kpts1.numpy(),
                    g["endpoint"].kpts0.numpy().reshape(-1, 2, 2) if n_lines else None,
                    g["endpoint"].kpts1.numpy().reshape(-1, 2, 2) if n_lines else None,
                    K0=g.K0[0].numpy(), K1=g.K1[0].numpy(),
                    image0=rng.uniform(0, 1, (H, W)).astype(np.float32),
                    image1=rng.uniform(0, 1, (H, W)).astype(np.float32))
    return build_pair_graph(m, T_0to1=g.T_0to1[0].numpy(), complete_edges=complete)


PLAIN = (torch.Tensor, int, float, bool)  # tensors and num_nodes; pair ids (str) are left out


def to_plain(g) -> dict:
    out = {"node": {}, "edge": {}, "graph": {}}
    for t in g.node_types:
        out["node"][t] = {k: v for k, v in g[t].items() if isinstance(v, PLAIN)}
    for et in g.edge_types:
        out["edge"]["|".join(et)] = {k: v for k, v in g[et].items() if isinstance(v, PLAIN)}
    out["graph"] = {k: v for k, v in g._global_store.items() if isinstance(v, PLAIN)}
    return out


def outputs(model: StrLPose, graphs: list) -> dict:
    data = graphs[0] if len(graphs) == 1 else Batch.from_data_list(graphs)
    with torch.no_grad():
        out = model(data)
    rec = {"quaternion": out.quaternion, "translation": out.translation,
           "log_var": out.log_var}
    if out.geometric is not None:
        rec.update(geometric_logits=out.geometric.logits, geometric_E=out.geometric.E,
                   geometric_status=out.geometric.status)
    return rec


def main() -> None:
    mixed = [(12, 5), (3, 0), (0, 4), (1, 1), (20, 2)]
    rgb = {
        "single": [make_pair(0, 12, 5)],
        "mixed": [make_pair(s, n, nl) for s, (n, nl) in enumerate(mixed)],
        "explicit": [make_pair(s, n, nl, "explicit") for s, (n, nl) in enumerate(mixed[:3])],
    }
    grey = {
        "grey_single": [grey_pair(0, 40, 12)],
        "grey_mixed": [grey_pair(s, n, nl) for s, (n, nl) in enumerate(mixed)],
        "grey_explicit": [grey_pair(s, n, nl, "explicit")
                          for s, (n, nl) in enumerate(mixed[:3])],
    }
    record = {"graphs": {k: [to_plain(g) for g in v] for k, v in {**rgb, **grey}.items()},
              "checkpoints": {}, "outputs": {}}

    shipped = StrLPose.from_pretrained("synthetic")
    record["outputs"]["shipped"] = {k: outputs(shipped, v) for k, v in grey.items()}
    for name, cfg in CONFIGS.items():
        torch.manual_seed(0)
        model = StrLPose(cfg).eval()
        buf = Path("/tmp") / f"legacy_{name}.pt"
        model.save(buf)
        record["checkpoints"][name] = torch.load(buf, weights_only=True)
        record["outputs"][name] = {k: outputs(model, v) for k, v in rgb.items()}
    f = io.BytesIO()
    torch.save(record, f)
    OUT.write_bytes(f.getvalue())
    print(f"wrote {OUT} ({OUT.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
