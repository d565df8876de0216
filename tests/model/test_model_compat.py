"""StrLPose against outputs recorded from the version-1 module layout (before DualGraphLayer).

``tests/fixtures/legacy_model.pt`` was written by ``tests/fixtures/record_legacy_model.py`` on a
frozen
copy of commit 3a109d5: graphs, version-2 checkpoints of tiny seeded models in the old key
layout (``geo_self.{i}.*``, ``line_convs.{i}.*``, ``vis_self.{i}.*``, ``vis_cross.{i}.*``,
``fusion.pose_mlp.*``, ``fusion.var_mlp.*``) and the outputs of those models and of the shipped
weights. Today's code must load them all and reproduce the outputs.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from torch_geometric.data import Batch

from strl_pyg.data import PairGraph
from strl_pyg.model import StrLPoseConfig, upgrade_key
from strl_pyg.model.strl_pose import StrLPose

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "legacy_model.pt"
TINY = ["full", "full_geometric", "baseline", "V", "LP_metric"]
RGB_GRAPHS = ["single", "mixed", "explicit"]


@pytest.fixture(scope="module")
def legacy() -> dict:
    return torch.load(FIXTURE, weights_only=True)


def rebuild(plain: dict) -> PairGraph:
    g = PairGraph()
    for t, store in plain["node"].items():
        for k, v in store.items():
            g[t][k] = v
    for et, store in plain["edge"].items():
        for k, v in store.items():
            g[tuple(et.split("|"))][k] = v
    for k, v in plain["graph"].items():
        g[k] = v
    return g


def graph(legacy: dict, name: str):
    graphs = [rebuild(p) for p in legacy["graphs"][name]]
    return graphs[0] if len(graphs) == 1 else Batch.from_data_list(graphs)


def assert_matches(model: StrLPose, data, rec: dict, atol: float = 1e-5,
                   rtol: float = 1e-5) -> None:
    """Outputs equal the recorded ones to float32 rounding: ``rtol`` matters for the
    log-variances (about 10 in magnitude, where one float32 ulp is ~1e-6 and a machine with
    other SIMD paths or thread counts moved them by 1.9e-6 against ``atol=1e-6, rtol=0``); a
    wrongly mapped or missing weight moves the outputs by orders of magnitude more."""
    with torch.no_grad():
        out = model(data)
    for key in ("quaternion", "translation", "log_var"):
        torch.testing.assert_close(getattr(out, key), rec[key], atol=atol, rtol=rtol)
    if "geometric_logits" in rec:
        torch.testing.assert_close(out.geometric.logits, rec["geometric_logits"], atol=atol,
                                   rtol=rtol)
        assert torch.equal(out.geometric.status, rec["geometric_status"])
        torch.testing.assert_close(out.geometric.E, rec["geometric_E"], atol=1e-5, rtol=0)
    else:
        assert out.geometric is None


def checkpoint_file(legacy, tmp_path, name: str, version: int) -> Path:
    payload = dict(legacy["checkpoints"][name])
    if version == 1:  # version 1 wrote no metadata
        payload.pop("metadata")
        payload["version"] = 1
    path = tmp_path / f"{name}_v{version}.pt"
    torch.save(payload, path)
    return path


def test_the_fixture_is_in_the_old_layout(legacy):
    keys = legacy["checkpoints"]["full"]["state_dict"]
    assert any(k.startswith("geo_self.1.") for k in keys)
    assert any(k.startswith("line_convs.1.") for k in keys)
    assert any(k.startswith("vis_cross.1.") for k in keys)
    assert any(k.startswith("fusion.pose_mlp.") for k in keys)
    assert not any(k.startswith(("layers.", "pose_head.")) for k in keys)


@pytest.mark.parametrize("graphs", ["grey_single", "grey_mixed", "grey_explicit"])
def test_the_shipped_weights_give_the_recorded_outputs(legacy, graphs):
    model = StrLPose.from_pretrained("synthetic")
    assert_matches(model, graph(legacy, graphs), legacy["outputs"]["shipped"][graphs])


@pytest.mark.parametrize("version", [1, 2])
@pytest.mark.parametrize("name", TINY)
def test_old_checkpoints_load_with_identical_outputs(legacy, tmp_path, name, version):
    model = StrLPose.load(checkpoint_file(legacy, tmp_path, name, version)).eval()
    for graphs in RGB_GRAPHS:
        assert_matches(model, graph(legacy, graphs), legacy["outputs"][name][graphs])
    # saved again, it is in today's layout and still gives the same outputs
    again = StrLPose.load(model.save(tmp_path / "again.pt")).eval()
    assert any(k.startswith("layers.1.") for k in again.state_dict())
    assert_matches(again, graph(legacy, "mixed"), legacy["outputs"][name]["mixed"])


@pytest.mark.parametrize("name", TINY)
def test_a_seed_gives_the_initial_weights_of_the_old_layout(legacy, name):
    payload = legacy["checkpoints"][name]
    torch.manual_seed(0)
    model = StrLPose(StrLPoseConfig.from_dict(payload["config"]))
    old = {upgrade_key(k): v for k, v in payload["state_dict"].items()}
    new = model.state_dict()
    assert list(new) != list(payload["state_dict"])  # the names did change
    assert sorted(new) == sorted(old)
    for k, v in new.items():
        assert torch.equal(v, old[k]), k


def test_load_state_dict_takes_old_keys_and_refuses_mixed_ones(legacy):
    payload = legacy["checkpoints"]["full"]
    model = StrLPose(StrLPoseConfig.from_dict(payload["config"]))
    model.load_state_dict(payload["state_dict"])  # old names, strict
    old = payload["state_dict"]
    assert torch.equal(model.layers[1].vis_cross.lin_q.weight, old["vis_cross.1.lin_q.weight"])
    assert torch.equal(model.pose_head.pose_mlp[-1].bias, old["fusion.pose_mlp.6.bias"])
    mixed = dict(model.state_dict())
    mixed["geo_self.0.lin_q.weight"] = old["geo_self.0.lin_q.weight"]
    with pytest.raises(RuntimeError, match="Expected either the old key"):
        model.load_state_dict(mixed)
    # the caller's dict is left as it was
    assert "geo_self.0.lin_q.weight" in mixed and "layers.0.geo_self.lin_q.weight" in mixed


def test_a_regression_only_checkpoint_initialises_a_geometric_model(legacy):
    """The training code starts a geometric model from regression weights (strict=False,
    only inlier_head.* missing): old names must not show up as missing or unexpected."""
    payload = legacy["checkpoints"]["full"]
    cfg = StrLPoseConfig.from_dict({**payload["config"], "geometric": True})
    missing, unexpected = StrLPose(cfg).load_state_dict(payload["state_dict"], strict=False)
    assert not unexpected
    assert missing and all(k.startswith("inlier_head.") for k in missing)


def test_an_old_optimizer_state_is_reindexed_for_the_new_parameter_order(legacy):
    payload = legacy["checkpoints"]["full"]
    old_sd = payload["state_dict"]
    model = StrLPose(StrLPoseConfig.from_dict(payload["config"]))
    model.load_state_dict(old_sd)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    for p in model.parameters():
        p.grad = torch.randn_like(p)
    opt.step()
    state = opt.state_dict()
    # the same state as the old layout indexed it: by position in the old key order
    names = [n for n, _ in model.named_parameters()]
    old_order = [upgrade_key(k) for k in old_sd]
    assert old_order != names
    as_saved = {"state": {old_order.index(names[j]): s for j, s in state["state"].items()},
                "param_groups": state["param_groups"]}
    fixed = model.upgrade_optimizer_state(as_saved, old_sd)
    assert sorted(fixed["state"]) == sorted(state["state"])
    for j, s in state["state"].items():
        for key, value in s.items():
            assert torch.equal(fixed["state"][j][key], value), (names[j], key)
    opt2 = torch.optim.Adam(model.parameters(), lr=1e-3)
    opt2.load_state_dict(fixed)
    # today's layout: unchanged
    assert model.upgrade_optimizer_state(state, model.state_dict()) is state
    with pytest.raises(ValueError, match="one parameter group"):
        model.upgrade_optimizer_state({**as_saved, "param_groups": state["param_groups"] * 2},
                                      old_sd)
