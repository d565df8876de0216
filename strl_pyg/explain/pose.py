"""Which point matches and line segments drove the network's pose.

PyG's :class:`~torch_geometric.explain.Explainer` calls a model as ``model(x, edge_index,
**kwargs)`` and masks ``x`` (node masks) or the edges of ``edge_index`` (edge masks).
:class:`PoseExplainerModel` gives :class:`~strl_pyg.model.StrLPose` that calling convention
for one pair graph:

* ``x`` is one gate per node ``[N, 1]`` (ones), in the model's order (the graph's point
  matches, then its line endpoints); StrLPose scales each node's encoded features by it
  (``StrLPose.forward(data, node_gate=...)``), so a node mask learned on ``x`` is a soft
  removal of that match;
* ``edge_index`` is the complete edge set ``[2, N^2]`` of the pair (grouped by target node, as
  :func:`~strl_pyg.data.complete_edge_index` orders it). The model itself still runs its
  complete-attention path; :class:`~strl_pyg.nn.AttentionConv` computes the attention of
  every complete edge in that order while an explainer's message hook listens, so PyG's
  ``AttentionExplainer`` reads it;
* the output is the pose ``[1, 7]``: the unit quaternion and the translation direction.

:func:`explain_pose` runs one of PyG's explainers (``"gnn"``: ``GNNExplainer`` learning a
node mask; ``"attention"``: ``AttentionExplainer``, each node scored by the attention the
others pay it; ``"saliency"``: the gradient of the pose with respect to the gates) and returns
a :class:`PoseExplanation`: one importance per point match and per line segment (the mean of
its two endpoints), each set scaled to a maximum of 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from strl_pyg.data import keys as K
from strl_pyg.data.pair_graph import complete_edge_index

__all__ = ["PoseExplainerModel", "PoseExplanation", "explain_pose", "explain_matches", "EXPLAINERS"]

#: The explainers :func:`explain_pose` runs.
EXPLAINERS = ("gnn", "attention", "saliency")


#: Why an explainer's edge mask is refused on the pose model (its layers see other edges)
EDGE_MASK_REFUSED = (
    "Expected a node mask (Explainer(..., node_mask_type='object', edge_mask_type=None), as "
    "strl_pyg.explain.explain_pose does) (got an edge mask: the explainer's mask would be "
    "applied to every layer of the pose model, whose edge sets differ: complete attention has "
    "no explicit edges and the line layer its own)")


def refuse_edge_masks(model: torch.nn.Module) -> None:
    """A one-line ``ValueError`` (:data:`EDGE_MASK_REFUSED`) where an explainer set an edge
    mask on the layers of ``model`` (PyG's ``set_masks``); the masks are cleared first, so the
    model is as it was (PyG's explainer does not clear them when its model raises)."""
    if any(getattr(m, "_edge_mask", None) is not None for m in model.modules()):
        from torch_geometric.explain.algorithm.utils import clear_masks

        clear_masks(model)
        raise ValueError(EDGE_MASK_REFUSED)


class PoseExplainerModel(nn.Module):
    """``StrLPose`` on one pair graph with PyG's explainer calling convention (module
    docstring). ``model(x, edge_index)`` -> ``[1, 7]``."""

    def __init__(self, model: nn.Module, data: Any) -> None:
        super().__init__()
        if getattr(data, "num_graphs", 1) != 1:
            raise ValueError(f"Expected one pair graph (got a batch of {data.num_graphs})")
        self.model = model
        self.data = data
        self.num_points = int(data[K.POINT].num_nodes) if K.POINT in data.node_types else 0
        self.num_endpoints = (int(data[K.ENDPOINT].num_nodes)
                              if K.ENDPOINT in data.node_types else 0)

    @property
    def num_nodes(self) -> int:
        return self.num_points + self.num_endpoints

    def inputs(self) -> tuple[Tensor, Tensor]:
        """``(x, edge_index)`` to explain: all gates open, and the edges the model attends
        over in its own order (the pair's complete edges; a graph with explicit edges: those,
        in the model's node order), so that an edge mask lines up with the attention."""
        from strl_pyg.model.gather import gather_inputs

        device = next(self.model.parameters()).device
        n = self.num_nodes
        explicit = gather_inputs(self.model.config, self.data).self_edges
        if explicit is not None:
            return torch.ones(n, 1, device=device), explicit.to(device)
        ids = torch.zeros(n, dtype=torch.long, device=device)
        return torch.ones(n, 1, device=device), complete_edge_index(ids, ids, 1)

    def forward(self, x: Tensor, edge_index: Tensor | None = None, **_: Any) -> Tensor:
        if x.dim() != 2 or x.shape != (self.num_nodes, 1):
            raise ValueError(f"Expected x as one gate per node, shape [{self.num_nodes}, 1] "
                             f"(got {tuple(x.shape)})")
        refuse_edge_masks(self.model)
        out = self.model(self.data, node_gate=x)
        return torch.cat([out.quaternion, nn.functional.normalize(out.translation, dim=-1)],
                         dim=-1)


@dataclass
class PoseExplanation:
    """What :func:`explain_pose` found.

    Attributes:
        points: importance of each point match ``[Np]`` in ``[0, 1]`` (the graph's order, which
            is the matches' order for a graph built by ``build_pair_graph``).
        lines: importance of each line segment ``[Nl]`` (mean of its endpoints), in ``[0, 1]``.
        method: the explainer (one of :data:`EXPLAINERS`).
    """

    points: np.ndarray
    lines: np.ndarray
    method: str

    def top_points(self, share: float) -> np.ndarray:
        """Indices of the ``share`` most important point matches, most important first."""
        k = int(round(share * len(self.points)))
        return np.argsort(-self.points, kind="stable")[:k]


def _node_scores(explainer_model: PoseExplainerModel, method: str, epochs: int) -> Tensor:
    from torch_geometric.explain import Explainer
    from torch_geometric.explain.algorithm import AttentionExplainer, GNNExplainer

    x, edge_index = explainer_model.inputs()
    config = dict(mode="regression", task_level="graph", return_type="raw")
    if method == "saliency":  # how far the pose moves as each gate closes, to first order
        jac = torch.autograd.functional.jacobian(
            lambda g: explainer_model(g, edge_index).reshape(-1), x)
        return jac.reshape(jac.shape[0], -1).norm(dim=0)
    if method == "gnn":
        explainer = Explainer(explainer_model, GNNExplainer(epochs=epochs),
                              explanation_type="model", node_mask_type="object",
                              edge_mask_type=None, model_config=config)
        return explainer(x, edge_index).node_mask.reshape(-1)
    explainer = Explainer(explainer_model, AttentionExplainer(reduce="mean"),
                          explanation_type="model", node_mask_type=None,
                          edge_mask_type="object", model_config=config)
    edge_mask = explainer(x, edge_index).edge_mask  # [N^2]: attention of each (src, dst)
    n = explainer_model.num_nodes
    return torch.zeros(n, device=edge_mask.device).index_add_(0, edge_index[0], edge_mask) / n


def explain_pose(model: nn.Module, data: Any, method: str = "gnn",
                 epochs: int = 100) -> PoseExplanation:
    """The importance of each point match and line segment of ``data`` (one pair graph) to
    ``model``'s pose, by one of :data:`EXPLAINERS` (module docstring); ``epochs``: the
    GNNExplainer's optimisation steps. The model runs in eval mode (its mode is restored)."""
    if method not in EXPLAINERS:
        raise ValueError(f"Expected method in {EXPLAINERS} (got {method!r})")
    if not (isinstance(epochs, int) and epochs >= 1):
        raise ValueError(f"Expected epochs as an integer >= 1 (got {epochs!r})")
    adapter = PoseExplainerModel(model, data)
    if adapter.num_nodes == 0:
        raise ValueError("Expected at least one point match or line segment (got none)")
    was_training = model.training
    model.eval()
    try:
        scores = _node_scores(adapter, method, epochs).detach().double().cpu().numpy()
    finally:
        model.train(was_training)
    scores = np.nan_to_num(scores, nan=0.0)
    points = scores[:adapter.num_points]
    ends = scores[adapter.num_points:]
    lines = ends.reshape(-1, 2).mean(axis=1) if ends.size else ends
    return PoseExplanation(points=_unit(points), lines=_unit(lines), method=method)


def _unit(v: np.ndarray) -> np.ndarray:
    top = float(v.max()) if v.size else 0.0
    return v / top if top > 0 else v


def explain_matches(matches: Any, model: nn.Module | None = None, method: str = "gnn",
                    epochs: int = 100) -> PoseExplanation:
    """:func:`explain_pose` on the pair graph that the network's methods build from
    ``matches`` (:func:`~strl_pyg.inference.network.prepare_graph`), with every match (not
    resampled), so that importances follow the rows of ``matches``. ``model``: a
    ``StrLPose`` (default: the shipped weights, as ``PoseEstimator().model``)."""
    from strl_pyg.inference.network import prepare_graph

    if model is None:
        from strl_pyg.model.strl_pose import StrLPose

        model = StrLPose.from_pretrained()
    data = prepare_graph(matches, model, resample=None)
    device = next(model.parameters()).device
    return explain_pose(model, data.to(device), method, epochs)
