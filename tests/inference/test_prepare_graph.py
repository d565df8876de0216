"""The network's input graph is built on the resampled rows only: the same graph as building
every match and resampling the graph (:class:`~strl_pyg.data.FixedSizeResample`, the
reference path), for fewer and more matches than the targets, without lines, with and without
image patches, with a seed and with the global generator."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from strl_pyg.inference.network import prepare_graph
from strl_pyg.model import StrLPose, StrLPoseConfig


def _assert_same_graph(fast, ref):
    assert fast.node_types == ref.node_types and fast.edge_types == ref.edge_types
    for store_f, store_r in zip(fast.stores, ref.stores, strict=True):
        assert set(store_f.keys()) == set(store_r.keys())
        for key, value in store_r.items():
            other = store_f[key]
            if isinstance(value, torch.Tensor):
                assert other.shape == value.shape and other.dtype == value.dtype, key
                torch.testing.assert_close(other, value, rtol=1e-6, atol=1e-6, msg=key)
            else:
                assert other == value, key
    for node_type in ref.node_types:
        assert fast[node_type].num_nodes == ref[node_type].num_nodes


@pytest.fixture(scope="module")
def pair(generated_pair):
    return generated_pair(2_000_017).matches


@pytest.fixture(scope="module")
def models():
    torch.manual_seed(0)
    plain = StrLPose(StrLPoseConfig(hidden=16, layers=1, heads=2, patch_features=1))
    return {"shipped": StrLPose.from_pretrained(), "plain": plain}


@pytest.mark.parametrize("model_name", ["shipped", "plain"])
@pytest.mark.parametrize("resample", [(384, 192), (40, 8), (600, 300), (50, 0)])
def test_the_graph_of_the_resampled_rows_is_the_resampled_graph(pair, models, model_name,
                                                                  resample):
    model = models[model_name]
    assert pair.num_points > 40 and 8 < pair.num_lines < 300  # down- and upsampled both
    fast = prepare_graph(pair, model, seed=3, resample=resample)
    ref = prepare_graph(pair, model, seed=3, resample=resample, reference=True)
    _assert_same_graph(fast, ref)
    assert fast["point"].num_nodes == resample[0]


def test_without_lines_and_with_the_global_generator(pair, models):
    m = dataclasses.replace(pair, lines0=None, lines1=None, line_scores=None)
    torch.manual_seed(11)
    fast = prepare_graph(m, models["shipped"], seed=None)
    torch.manual_seed(11)
    ref = prepare_graph(m, models["shipped"], seed=None, reference=True)
    _assert_same_graph(fast, ref)
    assert fast["endpoint"].num_nodes == 0


def test_the_derived_matches_are_not_the_callers(pair):
    """The rows' copy shares no array it changes with the caller's matches, and keeps the
    one rule a selection can break: at least one match."""
    before = pair.points0.copy()
    sub = pair._derived(np.array([0, 0, 1]), np.array([], dtype=np.int64))
    assert sub.num_points == 3 and sub.num_lines == 0 and pair.num_lines > 0
    np.testing.assert_array_equal(sub.points0[:2], pair.points0[[0, 0]])
    sub.points0 += 5.0  # the rows are the copy's own
    np.testing.assert_array_equal(pair.points0, before)
    with pytest.raises(TypeError, match="Expected PairMatches fields"):
        pair._derived(K_0=None)
    with pytest.raises(ValueError, match="at least one point or line match"):
        pair._derived(np.array([], dtype=np.int64), np.array([], dtype=np.int64))
