"""Explanations of the network's pose: PyG's explainers on the complete-attention path, the
node gate they mask, and the gradient explanation against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch_geometric.explain import Explainer
from torch_geometric.explain.algorithm import AttentionExplainer

from strl_pyg.data import PairMatches, build_pair_graph, materialize_complete_edges
from strl_pyg.explain import EXPLAINERS, PoseExplainerModel, explain_pose
from strl_pyg.model import StrLPose, StrLPoseConfig


def small_model(seed: int = 0) -> StrLPose:
    torch.manual_seed(seed)
    return StrLPose(StrLPoseConfig(hidden=32, layers=2, heads=4, visual=None,
                                   visual_graph=False)).eval()


def pair(points: int = 24, lines: int = 3, seed: int = 0):
    rng = np.random.default_rng(seed)
    return build_pair_graph(PairMatches(
        points0=rng.uniform(0, 100, (points, 2)), points1=rng.uniform(0, 100, (points, 2)),
        lines0=rng.uniform(0, 100, (lines, 4)), lines1=rng.uniform(0, 100, (lines, 4)),
        image_size0=(120, 120), image_size1=(120, 120)))


def test_open_gates_equal_the_plain_forward_and_bad_gates_refuse():
    model, g = small_model(), pair()
    n = 24 + 2 * 3
    a, b = model(g), model(g, node_gate=torch.ones(n))
    torch.testing.assert_close(a.quaternion, b.quaternion)
    torch.testing.assert_close(a.translation, b.translation)
    with pytest.raises(ValueError, match=rf"Expected node_gate of shape \[{n}\]"):
        model(g, node_gate=torch.ones(n - 1))
    closed = model(g, node_gate=torch.cat([torch.zeros(5), torch.ones(n - 5)]))
    assert not torch.allclose(closed.quaternion, a.quaternion)  # the gate reaches the pose


@pytest.mark.parametrize("method", EXPLAINERS)
def test_every_explainer_runs_on_the_complete_attention_path(method):
    model, g = small_model(), pair()
    e = explain_pose(model, g, method, epochs=5)
    assert e.points.shape == (24,) and e.lines.shape == (3,) and e.method == method
    assert np.all(np.isfinite(e.points)) and e.points.min() >= 0
    assert e.points.max() == pytest.approx(1.0) and e.lines.max() <= 1.0
    assert len(e.top_points(0.25)) == 6
    model.train()
    explain_pose(model, g, method, epochs=2)
    assert model.training  # the caller's mode is restored


def test_attention_explainer_reads_the_same_attention_on_both_paths():
    """AttentionExplainer needs message hooks; the complete path runs the reference
    (explicit) attention while one listens, so implicit and explicit graphs agree."""
    model = small_model()
    g = pair()
    masks = []
    for data in (g, materialize_complete_edges(g)):
        adapter = PoseExplainerModel(model, data)
        x, ei = adapter.inputs()
        explainer = Explainer(adapter, AttentionExplainer(), explanation_type="model",
                              edge_mask_type="object",
                              model_config=dict(mode="regression", task_level="graph",
                                                return_type="raw"))
        mask = explainer(x, ei).edge_mask
        assert mask.shape == (30 * 30,)
        order = torch.argsort(ei[0] * 30 + ei[1])  # the same edges, by (source, target)
        masks.append(mask[order])
    torch.testing.assert_close(masks[0], masks[1], atol=1e-5, rtol=1e-4)


def test_saliency_is_the_gradient_of_the_pose():
    model, g = small_model(), pair(points=10, lines=0)
    adapter = PoseExplainerModel(model, g)
    x, ei = adapter.inputs()
    x = x.double()
    model.double()
    e = explain_pose(model, g, "saliency")
    h, raw = 1e-6, []
    for i in range(adapter.num_nodes):  # central differences of each gate
        up, dn = x.clone(), x.clone()
        up[i] += h
        dn[i] -= h
        raw.append(((adapter(up, ei) - adapter(dn, ei)) / (2 * h)).norm().item())
    raw = np.array(raw)
    np.testing.assert_allclose(e.points, raw / raw.max(), atol=1e-5)


def test_bad_calls_refuse_in_one_line():
    model, g = small_model(), pair()
    with pytest.raises(ValueError, match="Expected method in"):
        explain_pose(model, g, "shap")
    with pytest.raises(ValueError, match="Expected epochs"):
        explain_pose(model, g, "gnn", epochs=0)
    with pytest.raises(ValueError, match="one gate per node"):
        PoseExplainerModel(model, g)(torch.ones(3, 1))


def test_an_edge_mask_on_the_pose_model_is_refused_in_one_line():
    """Before: GNNExplainer with an edge mask met a bare AssertionError inside PyG (its one mask
    was applied to the line layer's edges too), or "Could not compute gradients for edges" on
    complete attention. The node-mask path is the one that works; the refusal names it."""
    from torch_geometric.explain.algorithm import GNNExplainer

    model, g = small_model(), pair()
    adapter = PoseExplainerModel(model, g)
    x, ei = adapter.inputs()
    explainer = Explainer(adapter, GNNExplainer(epochs=2), explanation_type="model",
                          edge_mask_type="object", node_mask_type=None,
                          model_config=dict(mode="regression", task_level="graph",
                                            return_type="raw"))
    with pytest.raises(ValueError, match="Expected a node mask .*node_mask_type='object'"):
        explainer(x, ei)
    # the masks are cleared with the refusal: the node path works afterwards
    assert explain_pose(model, g, "gnn", epochs=2).points.shape == (24,)


def test_an_edge_mask_on_complete_attention_is_refused_by_the_layer():
    from torch_geometric.explain.algorithm.utils import clear_masks, set_masks

    from strl_pyg.data import CompleteEdges
    from strl_pyg.nn.attention import AttentionConv

    conv = AttentionConv(8, heads=2)
    x = torch.randn(5, 8)
    set_masks(conv, torch.ones(25, requires_grad=True), torch.zeros(2, 25, dtype=torch.long),
              apply_sigmoid=True)
    try:
        with pytest.raises(ValueError, match="Expected explicit edges for an explainer's edge"):
            conv(x, CompleteEdges())
    finally:
        clear_masks(conv)
    assert conv(x, CompleteEdges()).shape == (5, 8)
