"""inputs="parallax": each node's motion parallax against its image neighbours, and the
products whose mean is the epipole's least-squares system (issue 30: the handheld pairs)."""

from __future__ import annotations

import math

import pytest
import torch
from torch_geometric.data import Batch

from strl_pyg.inference.network import prepare_graph
from strl_pyg.model import StrLPose, StrLPoseConfig
from strl_pyg.nn import SpatialCoordinateEncoder, flow_features, parallax_features


def _small_motion(t, w, n=300, seed=0):
    """Normalised ``[x0, y0, x1, y1]`` of ``n`` points at inverse depths 1/6..1/2 under the
    small-motion flow ``rho (x t_z - t_xy) + A(x) w``."""
    g = torch.Generator().manual_seed(seed)
    X = (torch.rand(n, 2, generator=g, dtype=torch.float64) - 0.5) * 0.8
    rho = 1.0 / (2.0 + 4.0 * torch.rand(n, generator=g, dtype=torch.float64))
    x, y = X[:, 0], X[:, 1]
    A = torch.stack([torch.stack([x * y, -(1 + x * x), y], -1),
                     torch.stack([1 + y * y, -x * y, -x], -1)], 1)
    u = rho[:, None] * (X * t[2] - t[:2]) + A @ w
    return torch.cat([X, X + u], -1)


def _epipole(f):
    """The smallest eigenvector of the summed products (features 2..7)."""
    M = torch.zeros(3, 3, dtype=f.dtype)
    i, j = torch.triu_indices(3, 3)
    s = f[:, 2:].sum(0)
    M[i, j] = s
    M[j, i] = s
    return torch.linalg.eigh(M).eigenvectors[:, 0]


def _angle(a, b):
    c = abs(float(a @ b) / float(a.norm() * b.norm()))
    return math.degrees(math.acos(min(1.0, c)))


@pytest.mark.parametrize("t", [(0.3, -0.2, 0.5), (1.0, 0.0, 0.0), (0.0, 0.1, 1.0)])
def test_parallax_products_give_the_translation_whatever_the_rotation(t):
    """A known answer: the summed products' smallest eigenvector is the translation's axis,
    within a few degrees, beside a rotation whose flow is larger than the translation's;
    the mean displacement alone (what "flow" pools) is dominated by the rotation."""
    t = torch.nn.functional.normalize(torch.tensor(t, dtype=torch.float64), dim=0) * 0.03
    w = torch.tensor([0.01, -0.02, 0.005], dtype=torch.float64)
    c = _small_motion(t, w)
    f = parallax_features(c)
    assert f.shape == (300, 8) and f.dtype == torch.float64
    assert _angle(_epipole(f), t) < 8.0
    # the same points without the rotation: closer (what is left comes from the neighbours
    # sitting elsewhere in the image)
    assert _angle(_epipole(parallax_features(_small_motion(t, 0 * w))), t) < 3.0
    # the rotation's flow is larger than the translation's, so the flow inputs' mean
    # displacement does not point along the translation's image part
    u = flow_features(c)[:, 4:6].mean(0)
    if float(t[:2].norm()) > 0.5 * float(t.norm()):
        assert _angle(torch.cat([u, u.new_zeros(1)]), torch.cat([t[:2], t.new_zeros(1)])) > 20


def test_parallax_is_per_graph_and_follows_the_node_order():
    """Batched equals one call per graph (neighbours never cross graphs), and permuting a
    graph's nodes permutes its features."""
    t = torch.tensor([0.02, 0.0, 0.01], dtype=torch.float64)
    w = torch.tensor([0.0, 0.01, 0.0], dtype=torch.float64)
    a, b = _small_motion(t, w, n=50, seed=1), _small_motion(-t, w, n=70, seed=2)
    batched = parallax_features(torch.cat([a, b]),
                                torch.cat([torch.zeros(50), torch.ones(70)]).long())
    torch.testing.assert_close(batched, torch.cat([parallax_features(a),
                                                   parallax_features(b)]))
    perm = torch.randperm(50, generator=torch.Generator().manual_seed(3))
    torch.testing.assert_close(parallax_features(a[perm]), parallax_features(a)[perm])


def test_repeated_nodes_are_not_their_own_neighbours():
    """The fixed-size resampling repeats matches of a sparse pair: with every node twice, each
    copy's 8 neighbours are 4 other positions twice, so the features equal those of the
    single graph with k = 4 (a copy among its own neighbours would pull d towards 0)."""
    c = _small_motion(torch.tensor([0.02, 0.01, 0.01], dtype=torch.float64),
                      torch.tensor([0.0, 0.01, 0.0], dtype=torch.float64), n=40, seed=6)
    doubled = parallax_features(torch.cat([c, c]), k=8)
    torch.testing.assert_close(doubled[:40], parallax_features(c, k=4))
    torch.testing.assert_close(doubled[40:], doubled[:40])
    assert float(doubled[:, :2].abs().min(1).values.max()) > 0


def test_parallax_on_tiny_graphs():
    """A graph of k or fewer nodes uses all its other nodes; a single node gets zeros, also
    inside a batch; bad shapes are refused."""
    c = torch.tensor([[0.0, 0.0, 0.1, 0.0], [0.2, 0.0, 0.2, 0.0], [0.0, 0.2, 0.0, 0.2]])
    f = parallax_features(c)
    # node 0: u = (0.1, 0); its two neighbours' u are (0, 0): median (0, 0), d = (0.1, 0)
    torch.testing.assert_close(f[0, :2], torch.tensor([0.1, 0.0]))
    torch.testing.assert_close(parallax_features(c[:1]), torch.zeros(1, 8))
    out = parallax_features(torch.cat([c, c[:1]]), torch.tensor([0, 0, 0, 1]))
    torch.testing.assert_close(out[:3], f)
    torch.testing.assert_close(out[3], torch.zeros(8))
    with pytest.raises(ValueError, match=r"Expected \[N, 4\] coordinates \(got \(3, 2\)\)"):
        parallax_features(c[:, :2])


def test_parallax_encoder_fits_sixteen_features_per_pair_and_round_trips(tmp_path):
    enc = SpatialCoordinateEncoder(16, inputs="parallax")
    assert enc.feature_mean.shape == (16,)
    t = torch.tensor([0.02, 0.01, 0.02], dtype=torch.float64)
    w = torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64)
    coords = torch.cat([_small_motion(t, w, 80, 4), _small_motion(t, -w, 90, 5)]).float()
    batch = torch.cat([torch.zeros(80), torch.ones(90)]).long()
    enc.fit_standardisation(coords, symmetric=True, batch=batch)
    both = torch.cat([coords, coords[:, [2, 3, 0, 1]]])
    z = (enc.features(both, torch.cat([batch, batch + 2])) - enc.feature_mean) / enc.feature_std
    torch.testing.assert_close(z.mean(0), torch.zeros(16), atol=1e-5, rtol=0)
    assert enc(coords, batch).shape == (170, 16)
    with pytest.raises(ValueError, match="Expected a batch vector of 170 entries"):
        enc.fit_standardisation(coords, batch=batch[:3])
    model = StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1, inputs="parallax"))
    model.sce.feature_std.mul_(3.0)
    back = StrLPose.load(model.save(tmp_path / "m.pt"))
    assert back.config.inputs == "parallax"
    torch.testing.assert_close(back.sce.feature_std, model.sce.feature_std)


def test_parallax_model_batched_equals_one_graph_at_a_time(generated_pair):
    """The full model (points and line endpoints) on a batch of two pairs gives each pair's
    own pose: the parallax neighbours stay inside a pair."""
    torch.manual_seed(0)
    m = StrLPose(StrLPoseConfig.ablation("full", hidden=16, layers=1, heads=2,
                                         inputs="parallax", patch_features=1)).eval()
    g1 = prepare_graph(generated_pair(7).matches, m)
    g2 = prepare_graph(generated_pair(11).matches, m)
    with torch.no_grad():
        one = [m(g) for g in (g1, g2)]
        both = m(Batch.from_data_list([g1, g2]))
    for k, o in enumerate(one):
        torch.testing.assert_close(both.translation[k], o.translation[0], atol=1e-5, rtol=0)
        torch.testing.assert_close(both.quaternion[k], o.quaternion[0], atol=1e-5, rtol=0)


def test_training_fits_the_parallax_statistics_on_pairs_resampled_as_it_trains(generated_pair):
    """A neighbour's distance depends on the density, so the fit resamples each pair to the
    training size first and reads only the nodes the model reads (parallax only: the flow
    inputs' fit is unchanged)."""
    from strl_pyg.data import keys
    from strl_pyg.data.transforms import FixedSizeResample
    from strl_pyg.training.data import fit_input_statistics

    m = StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1, inputs="parallax"))
    pairs = [prepare_graph(generated_pair(s).matches, m) for s in (1, 2)]
    fit_input_statistics(m, pairs, symmetric=False, resample=(64, 16))
    coords, batch = [], []
    for i, g in enumerate(pairs):
        g = FixedSizeResample(64, 16, seed=i)(g)
        for t in (keys.POINT,):  # the points-only row reads no line endpoints
            if t in g.node_types and g[t][keys.POS0].shape[0]:
                coords.append(torch.cat([g[t][keys.POS0], g[t][keys.POS1]], -1))
                batch.append(torch.full((coords[-1].shape[0],), i))
    ref = SpatialCoordinateEncoder(16, inputs="parallax")
    ref.fit_standardisation(torch.cat(coords), symmetric=False, batch=torch.cat(batch))
    torch.testing.assert_close(m.sce.feature_std, ref.feature_std)
    fit_input_statistics(m, pairs, symmetric=False)  # without: all nodes, another density
    assert not torch.allclose(m.sce.feature_std[8:], ref.feature_std[8:])


def _reference(c, batch, k=8):
    """One node at a time, in numpy: the median displacement of the k nearest other
    positions (copies of the node itself excluded), then the products."""
    import numpy as np

    c = c.numpy()
    out = np.zeros((len(c), 8))
    for i in range(len(c)):
        others = [j for j in range(len(c)) if batch[j] == batch[i] and not (c[j] == c[i]).all()]
        if not others:
            continue
        dist = np.array([np.hypot(*(c[j, :2] - c[i, :2])) for j in others])
        near = [others[j] for j in np.argsort(dist, kind="stable")[:k]]
        u = c[near, 2:] - c[near, :2]
        d = (c[i, 2:] - c[i, :2]) - np.median(u, axis=0)
        x, y = c[i, :2]
        a = np.array([d[1], -d[0], y * d[0] - x * d[1]])
        out[i] = np.r_[d, [a[p] * a[q] for p in range(3) for q in range(p, 3)]]
    return torch.from_numpy(out)


def test_parallax_equals_a_node_by_node_reference():
    """The dense gather / masked median path against a plain loop: uneven graphs of 1-13
    nodes, with copies of a node and a distinct match sharing its image-0 point."""
    g = torch.Generator().manual_seed(8)
    sizes = [1, 5, 13, 9, 2]
    c = torch.rand(sum(sizes), 4, generator=g, dtype=torch.float64)
    c[5] = c[4]  # a copy inside graph 1
    c[2, :2] = c[3, :2]  # distinct matches sharing an image-0 point: still neighbours
    # (in graph 1, which has fewer than k others: where such a tie fell at the k-th place,
    # which of the two is kept is topk's choice)
    batch = torch.repeat_interleave(torch.arange(len(sizes)), torch.tensor(sizes))
    torch.testing.assert_close(parallax_features(c, batch), _reference(c, batch))


def test_parallax_reads_nodes_in_any_order_and_refuses_what_it_cannot_answer():
    """Nodes of a batch need not be sorted by graph (the model's layout allows any order);
    graph ids that are not long integers, or a fit without them, are refused."""
    g = torch.Generator().manual_seed(10)
    c = torch.rand(12, 4, generator=g, dtype=torch.float64)
    batch = torch.tensor([0] * 5 + [1] * 7)
    perm = torch.randperm(12, generator=g)
    torch.testing.assert_close(parallax_features(c[perm], batch[perm]),
                               parallax_features(c, batch)[perm])
    with pytest.raises(TypeError, match="Expected graph ids as a 1-D long tensor"):
        parallax_features(c, batch.float())
    enc = SpatialCoordinateEncoder(16, inputs="parallax")
    with pytest.raises(ValueError, match=r"Expected the pair \(batch vector\) of each node"):
        enc.fit_standardisation(c.float())


def test_parallax_in_half_precision_is_computed_in_float32(generated_pair):
    c = _small_motion(torch.tensor([0.02, 0.0, 0.01], dtype=torch.float64),
                      torch.tensor([0.0, 0.01, 0.0], dtype=torch.float64), n=60, seed=9)
    half = c.float().to(torch.bfloat16)
    out = parallax_features(half)
    assert out.dtype == torch.bfloat16
    # float32 arithmetic on the rounded inputs (bfloat16's 8 bits already blur a displacement
    # of ~0.01 at coordinates of ~0.3: the mode is not meant for half precision)
    torch.testing.assert_close(out, parallax_features(half.float()).to(torch.bfloat16))
    m = StrLPose(StrLPoseConfig.ablation("baseline", hidden=16, layers=1, inputs="parallax"))
    g = prepare_graph(generated_pair(7).matches, m)
    with torch.no_grad():
        assert torch.isfinite(m.to(torch.bfloat16)(g).translation.float()).all()
