import numpy as np
import pytest
import torch
from torch_geometric.loader import DataLoader

from strl_pyg.data import (
    FixedSizeResample,
    MaterializeCompleteEdges,
    PairMatches,
    build_pair_graph,
    complete_edge_index,
    has_implicit_complete_edges,
    load_graph,
    materialize_complete_edges,
    save_graph,
)
from strl_pyg.data import keys as K
from strl_pyg.data.build import normalize_coords, sample_patches

H, W = 48, 64


def make(num_points=10, num_lines=4, seed=0, images=True, K_mat=None, rgb=False):
    rng = np.random.default_rng(seed)
    pts = lambda n: rng.uniform([0, 0], [W - 1, H - 1], (n, 2))  # noqa: E731
    shape = (H, W, 3) if rgb else (H, W)
    kw = dict(image_size0=(H, W), image_size1=(H, W))
    if images:
        kw.update(
            image0=rng.integers(0, 256, shape, dtype=np.uint8),
            image1=rng.integers(0, 256, shape, dtype=np.uint8),
        )
    if K_mat is not None:
        kw.update(K0=K_mat, K1=K_mat)
    return PairMatches(
        pts(num_points),
        pts(num_points),
        pts(2 * num_lines).reshape(-1, 2, 2),
        pts(2 * num_lines).reshape(-1, 2, 2),
        **kw,
    )


def test_shapes_dtypes_and_validate():
    m = make(10, 4)
    g = build_pair_graph(m, patch_size=3, T_0to1=np.eye(4))
    assert g.validate()
    assert set(g.node_types) == set(K.NODE_TYPES)
    assert set(g.edge_types) == set(K.EDGE_TYPES)
    assert g[K.POINT].num_nodes == 10 and g[K.ENDPOINT].num_nodes == 8
    for nt in K.NODE_TYPES:
        n = g[nt].num_nodes
        for key in (K.POS0, K.POS1, K.KPTS0, K.KPTS1):
            assert g[nt][key].shape == (n, 2) and g[nt][key].dtype == torch.float32
        assert g[nt][K.PATCH0].shape == (n, 9)
    assert g[K.ENDPOINT][K.LINE_FEAT].shape == (8, 8)
    assert g[K.T_0TO1].shape == (1, 4, 4)
    torch.testing.assert_close(
        g[K.POINT][K.KPTS0].double(), torch.from_numpy(m.points0), rtol=0, atol=1e-4
    )
    # endpoints 2i, 2i+1 are line i's endpoints; line edges connect them both ways
    torch.testing.assert_close(
        g[K.ENDPOINT][K.KPTS1][2:4].double(), torch.from_numpy(m.lines1[1]), rtol=0, atol=1e-4
    )
    assert g[K.LINE_EDGE].edge_index.tolist() == [list(range(8)), [1, 0, 3, 2, 5, 4, 7, 6]]


def test_line_features_are_endpoint_and_delta():
    g = build_pair_graph(make(3, 2))
    ep = g[K.ENDPOINT]
    lf = ep[K.LINE_FEAT]
    torch.testing.assert_close(lf[0, :2], ep[K.POS0][0])
    torch.testing.assert_close(lf[0, 2:4], ep[K.POS0][1] - ep[K.POS0][0])
    torch.testing.assert_close(lf[1, 6:8], ep[K.POS1][0] - ep[K.POS1][1])


def test_normalisation_by_image_size_and_intrinsics():
    xy = torch.tensor([[(W - 1) / 2, (H - 1) / 2], [W - 1 + 0.5, (H - 1) / 2]])
    out = normalize_coords(xy, (H, W))
    torch.testing.assert_close(out, torch.tensor([[0.0, 0.0], [1.0, 0.0]]))
    Km = np.array([[50.0, 0, 30], [0, 40, 20], [0, 0, 1]])
    g = build_pair_graph(make(4, 0, K_mat=Km))
    kp = g[K.POINT][K.KPTS0]
    expect = torch.stack([(kp[:, 0] - 30) / 50, (kp[:, 1] - 20) / 40], -1)
    torch.testing.assert_close(g[K.POINT][K.POS0], expect)
    g2 = build_pair_graph(make(4, 0, K_mat=Km), normalization="image_size")
    torch.testing.assert_close(g2[K.POINT][K.POS0], normalize_coords(kp, (H, W)))


def test_patch_sampling_matches_integer_pixels():
    img = torch.arange(H * W, dtype=torch.float32).view(1, H, W)
    xy = torch.tensor([[5.0, 7.0], [0.0, 0.0], [2.5, 3.0]])
    p1 = sample_patches(img, xy, 1)
    close = lambda a, b: torch.testing.assert_close(a, torch.tensor(b), rtol=0, atol=1e-3)  # noqa: E731
    close(p1[:, 0], [7.0 * W + 5, 0.0, 3.0 * W + 2.5])
    p3 = sample_patches(img, xy[:1], 3)
    close(p3.view(3, 3)[0], [6.0 * W + 4, 6.0 * W + 5, 6.0 * W + 6])
    g = build_pair_graph(make(4, 1, rgb=True), patch_size=5)
    assert g[K.POINT][K.PATCH0].shape == (4, 3 * 25)


def test_points_only_and_lines_only():
    g = build_pair_graph(make(5, 0))
    assert g[K.ENDPOINT].num_nodes == 0 and g[K.LINE_EDGE].edge_index.shape == (2, 0)
    assert g.validate()
    g = build_pair_graph(make(0, 3))
    assert g[K.POINT].num_nodes == 0 and g[K.ENDPOINT].num_nodes == 6
    assert g.validate()


def test_batching_offsets_every_edge_type():
    graphs = [
        build_pair_graph(make(n, m, seed=n), complete_edges="explicit")
        for n, m in [(3, 2), (5, 0), (1, 3)]
    ]
    batch = next(iter(DataLoader(graphs, batch_size=3)))
    assert batch.num_graphs == 3
    for et in K.EDGE_TYPES:
        src, _, dst = et
        ei = batch[et].edge_index
        assert ei.shape[1] == sum(g[et].edge_index.shape[1] for g in graphs)
        bs, bd = batch[src].batch[ei[0]], batch[dst].batch[ei[1]]
        assert torch.equal(bs, bd), et  # never crosses graphs
    # implicit batch materialised after collation equals explicit collated
    implicit = [build_pair_graph(make(n, m, seed=n)) for n, m in [(3, 2), (5, 0), (1, 3)]]
    b2 = next(iter(DataLoader(implicit, batch_size=3)))
    assert has_implicit_complete_edges(b2) and b2[K.SELF_EDGE_TYPES[0]][K.DENSE].shape == (3,)
    b2 = materialize_complete_edges(b2)
    for et in K.COMPLETE_EDGE_TYPES:
        a = batch[et].edge_index
        b = b2[et].edge_index
        assert sorted(map(tuple, a.T.tolist())) == sorted(map(tuple, b.T.tolist()))


def test_complete_edge_index_counts_and_self_loops():
    bs = torch.tensor([0, 0, 1, 1, 1])
    ei = complete_edge_index(bs, bs)
    assert ei.shape[1] == 4 + 9
    assert (ei[0] == ei[1]).sum() == 5
    ei = complete_edge_index(torch.tensor([1, 1]), torch.tensor([0, 1, 1]), num_graphs=2)
    assert ei.shape[1] == 4 and set(ei[1].tolist()) == {1, 2}


def test_implicit_memory_is_linear():
    def edge_bytes(g):
        return sum(v.numel() * v.element_size() for et in g.edge_types for v in g[et].values())

    small, big = build_pair_graph(make(20, 10)), build_pair_graph(make(200, 100))
    assert edge_bytes(big) <= 10 * edge_bytes(small) + 64
    explicit = MaterializeCompleteEdges()(build_pair_graph(make(200, 100)))
    assert edge_bytes(explicit) > 100 * edge_bytes(big)


def test_save_load_roundtrip(tmp_path):
    g = build_pair_graph(make(7, 3), T_0to1=np.eye(4), patch_size=3)
    r = load_graph(save_graph(g, tmp_path / "g.pt"))
    assert set(r.edge_types) == set(g.edge_types)
    for store_r, store_g in zip(r.stores, g.stores, strict=True):
        for key, value in store_g.items():
            assert (
                torch.equal(store_r[key], value)
                if torch.is_tensor(value)
                else store_r[key] == value
            )
    with pytest.raises(FileNotFoundError):
        load_graph(tmp_path / "nope.pt")
    (tmp_path / "bad.pt").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="save_graph"):
        load_graph(tmp_path / "bad.pt")


def test_resample_counts_determinism_and_pairs():
    g = build_pair_graph(make(50, 30), T_0to1=np.eye(4))
    a = FixedSizeResample(16, 8, seed=3)(g)
    b = FixedSizeResample(16, 8, seed=3)(g)
    c = FixedSizeResample(16, 8, seed=4)(g)
    assert a[K.POINT].num_nodes == 16 and a[K.ENDPOINT].num_nodes == 16
    assert torch.equal(a[K.POINT][K.KPTS0], b[K.POINT][K.KPTS0])
    assert not torch.equal(a[K.POINT][K.KPTS0], c[K.POINT][K.KPTS0])
    # endpoints stay paired: line features of 2i and 2i+1 describe the same segment
    lf = a[K.ENDPOINT][K.LINE_FEAT].view(-1, 2, 8)
    torch.testing.assert_close(lf[:, 0, :2] + lf[:, 0, 2:4], lf[:, 1, :2])
    # upsampling repeats: every original point is kept
    up = FixedSizeResample(80, 40, seed=0)(g)
    assert up[K.POINT].num_nodes == 80 and up[K.ENDPOINT].num_nodes == 80
    assert len(torch.unique(up[K.POINT][K.KPTS0], dim=0)) == 50
    assert up.validate() and torch.equal(up[K.T_0TO1], g[K.T_0TO1])
    # no resampling when not asked: the builder keeps every match
    assert g[K.POINT].num_nodes == 50
    # zero lines stays zero lines; explicit edges are rebuilt
    z = FixedSizeResample(8, 4, seed=0)(build_pair_graph(make(5, 0), complete_edges="explicit"))
    assert z[K.ENDPOINT].num_nodes == 0 and z[K.SELF_EDGE_TYPES[0]].edge_index.shape[1] == 64


@pytest.mark.parametrize(
    "kw, err, match",
    [
        (dict(patch_size=2), ValueError, "odd positive"),
        (dict(complete_edges="sparse"), ValueError, "complete_edges"),
        (dict(T_0to1=np.eye(3)), ValueError, r"\(4, 4\)"),
        (dict(T_0to1=np.diag([1.0, 1, -1, 1])), ValueError, "rotation"),
        (dict(normalization="intrinsics"), ValueError, "K0 and K1"),
    ],
)
def test_builder_bad_arguments(kw, err, match):
    with pytest.raises(err, match=match):
        build_pair_graph(make(4, 1), **kw)


def test_builder_rejects_non_matches():
    with pytest.raises(TypeError, match="PairMatches"):
        build_pair_graph({"points0": np.zeros((3, 2))})


def swapped_matches(m):
    from dataclasses import replace

    return replace(m, points0=m.points1, points1=m.points0, lines0=m.lines1, lines1=m.lines0,
                   image_size0=m.image_size1, image_size1=m.image_size0, K0=m.K1, K1=m.K0,
                   image0=m.image1, image1=m.image0)


def test_swap_images_equals_building_from_swapped_matches():
    from strl_pyg.data import RandomSwap, swap_images
    from strl_pyg.geometry import Pose

    Km = np.array([[50.0, 0, 30], [0, 40, 20], [0, 0, 1]])
    m = make(6, 3, K_mat=Km)
    T = Pose.from_quaternion(torch.tensor([0.9, 0.1, -0.2, 0.3]), torch.tensor([0.1, 0.2, 1.0]))
    T = T.matrix().numpy()
    a = swap_images(build_pair_graph(m, T_0to1=T, patch_size=3))
    b = build_pair_graph(swapped_matches(m), T_0to1=np.linalg.inv(T), patch_size=3)
    for store_a, store_b in zip(a.stores, b.stores, strict=True):
        for key, value in store_b.items():
            if torch.is_tensor(value) and value.is_floating_point():
                torch.testing.assert_close(store_a[key], value, atol=1e-5, rtol=1e-5)
            elif torch.is_tensor(value):
                assert torch.equal(store_a[key], value), key
    twice = swap_images(a)
    g = build_pair_graph(m, T_0to1=T, patch_size=3)
    torch.testing.assert_close(twice[K.T_0TO1], g[K.T_0TO1], atol=1e-6, rtol=0)
    assert torch.equal(twice[K.ENDPOINT][K.LINE_FEAT], g[K.ENDPOINT][K.LINE_FEAT])
    # the random transform swaps about half of the time, deterministically by seed
    t = RandomSwap(0.5, seed=0)
    flips = [not torch.equal(t(g)[K.POINT][K.KPTS0], g[K.POINT][K.KPTS0]) for _ in range(200)]
    assert 70 < sum(flips) < 130
    with pytest.raises(ValueError, match="probability"):
        RandomSwap(1.5)


def test_swap_flag_collates_and_undoes():
    from strl_pyg.data import RandomSwap

    g = build_pair_graph(make(4, 2), T_0to1=np.eye(4))
    t = RandomSwap(0.5, seed=1)
    graphs = [t(g) for _ in range(8)]
    batch = next(iter(DataLoader(graphs, batch_size=8)))
    assert batch[K.SWAPPED].shape == (8,) and 0 < int(batch[K.SWAPPED].sum()) < 8


def test_transforms_leave_their_input_untouched():
    from strl_pyg.data import RandomSwap, swap_images

    g = build_pair_graph(make(30, 10), T_0to1=np.eye(4), patch_size=3)
    before = {(nt, k): v.clone() for nt in K.NODE_TYPES for k, v in g[nt].items()
              if torch.is_tensor(v)}
    T = g[K.T_0TO1].clone()
    for t in (FixedSizeResample(8, 4, seed=0), swap_images, RandomSwap(0.0, seed=0)):
        out = t(g)
        assert out is not g
    assert all(torch.equal(g[nt][k], v) for (nt, k), v in before.items())
    assert torch.equal(g[K.T_0TO1], T) and K.SWAPPED not in g
    assert g[K.LINE_EDGE].edge_index.shape[1] == 20


def _scene_pair(seed=0, n=40, lines=6, size=96, f=60.0):
    """Matches of a real two-view scene (points and segments in front of both cameras, inside
    a disk about the principal point so that any roll keeps them in the image) and its pose."""
    from strl_pyg.geometry import Pose

    rng = np.random.default_rng(seed)
    c = size / 2
    Km = np.array([[f, 0, c], [0, f, c], [0, 0, 1.0]])
    T = Pose.from_quaternion(torch.tensor([0.99, 0.03, -0.05, 0.04]),
                             torch.tensor([0.3, -0.2, 0.1])).matrix().double().numpy()

    def project(X, Tm):
        Xc = X @ Tm[:3, :3].T + Tm[:3, 3]
        return Xc[:, :2] / Xc[:, 2:] * f + c

    X = []
    while len(X) < n + 2 * lines:
        cand = rng.uniform([-1, -1, 4], [1, 1, 6], (3,))
        ok = all(np.hypot(*(project(cand[None], Tm)[0] - c)) < 0.45 * size
                 for Tm in (np.eye(4), T))
        if ok:
            X.append(cand)
    X = np.array(X)
    p0, p1 = project(X, np.eye(4)), project(X, T)
    m = PairMatches(p0[:n], p1[:n], p0[n:].reshape(-1, 2, 2), p1[n:].reshape(-1, 2, 2),
                    image_size0=(size, size), image_size1=(size, size), K0=Km, K1=Km)
    return m, T, c


def _rotate_pixels(xy, angle, c):
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return (np.asarray(xy) - c) @ R.T + c


def test_roll_cameras_equals_building_from_rolled_images():
    """A roll of both cameras by 0.7 rad is the graph of the images rotated about the principal
    point (square pixels), with the pose (Rz R Rz^T, Rz t); the appearance stays."""
    from dataclasses import replace

    from strl_pyg.data import roll_cameras

    m, T, c = _scene_pair()
    a = 0.7
    g = build_pair_graph(m, T_0to1=T)
    rolled = roll_cameras(g, a)
    rot = {k: _rotate_pixels(getattr(m, k), a, c) for k in ("points0", "points1",
                                                            "lines0", "lines1")}
    ref = build_pair_graph(replace(m, **rot), T_0to1=T)
    for nt in K.NODE_TYPES:
        for key in (K.POS0, K.POS1):
            torch.testing.assert_close(rolled[nt][key], ref[nt][key], atol=1e-5, rtol=0)
        assert torch.equal(rolled[nt][K.KPTS0], g[nt][K.KPTS0])  # appearance: unchanged
    torch.testing.assert_close(rolled[K.ENDPOINT][K.LINE_FEAT], ref[K.ENDPOINT][K.LINE_FEAT],
                               atol=1e-5, rtol=0)
    Rz = torch.tensor([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    T0 = g[K.T_0TO1].reshape(4, 4).double()
    T1 = rolled[K.T_0TO1].reshape(4, 4).double()
    torch.testing.assert_close(T1[:3, :3], Rz @ T0[:3, :3] @ Rz.T, atol=1e-6, rtol=0)
    torch.testing.assert_close(T1[:3, 3], Rz @ T0[:3, 3], atol=1e-6, rtol=0)
    # the rolled pose explains the rolled coordinates: the epipolar residual stays ~0 ...
    def residual(graph, pose):
        x0 = torch.cat([graph[K.POINT][K.POS0].double(), torch.ones(40, 1)], 1)
        x1 = torch.cat([graph[K.POINT][K.POS1].double(), torch.ones(40, 1)], 1)
        t = pose[:3, 3]
        tx = torch.tensor([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
        return ((x1 @ (tx @ pose[:3, :3])) * x0).sum(1).abs().max()

    assert residual(rolled, T1) < 1e-5
    assert residual(rolled, T0) > 1e-2  # ... which the unrolled pose does not
    # roll and unroll: the graph back
    back = roll_cameras(rolled, -a)
    torch.testing.assert_close(back[K.POINT][K.POS1], g[K.POINT][K.POS1], atol=1e-6, rtol=0)
    torch.testing.assert_close(back[K.T_0TO1], g[K.T_0TO1], atol=1e-6, rtol=0)
    assert K.ROLL not in g and float(rolled[K.ROLL]) == a and abs(float(back[K.ROLL])) < 1e-12


def test_roll_cameras_refuses_what_it_cannot_roll():
    from torch_geometric.data import Batch

    from strl_pyg.data import RandomRoll, roll_cameras

    no_K = build_pair_graph(make(6, 2), T_0to1=np.eye(4))
    with pytest.raises(ValueError, match="intrinsics K0 and K1"):
        roll_cameras(no_K, 0.1)
    m, T, _ = _scene_pair()
    g = build_pair_graph(m, T_0to1=T)
    with pytest.raises(ValueError, match="Batch"):
        roll_cameras(Batch.from_data_list([g, g]), 0.1)
    with pytest.raises(ValueError, match="finite roll angle"):
        roll_cameras(g, float("nan"))
    with pytest.raises(ValueError, match=r"max_degrees in \[0, 180\]"):
        RandomRoll(200)


def test_roll_cameras_of_a_pair_without_lines():
    """A pair with no line matches (no endpoint nodes) rolls; it used to raise in reshape
    (a training pair of the Table 3 cache has none)."""
    from dataclasses import replace

    from strl_pyg.data import roll_cameras

    m, T, _ = _scene_pair()
    m = replace(m, lines0=np.zeros((0, 2, 2)), lines1=np.zeros((0, 2, 2)))
    g = build_pair_graph(m, T_0to1=T)
    assert g[K.ENDPOINT][K.POS0].shape == (0, 2)
    out = roll_cameras(g, 0.5)
    assert out[K.ENDPOINT][K.POS0].shape == (0, 2)
    assert out[K.ENDPOINT][K.LINE_FEAT].shape == (0, 8)
    assert not torch.allclose(out[K.POINT][K.POS0], g[K.POINT][K.POS0])


def test_random_roll_draws_within_its_range_by_seed():
    from strl_pyg.data import RandomRoll

    m, T, _ = _scene_pair()
    g = build_pair_graph(m, T_0to1=T)
    p = g[K.POINT][K.POS0][0].double()

    def angles(t, n=200):
        out = []
        for _ in range(n):
            q = t(g)[K.POINT][K.POS0][0].double()
            out.append(np.degrees(float(torch.atan2(p[0] * q[1] - p[1] * q[0], p @ q))))
        return np.array(out)

    a = angles(RandomRoll(30, seed=4))
    assert np.abs(a).max() <= 30 + 1e-3 and a.min() < -20 and a.max() > 20
    np.testing.assert_array_equal(a, angles(RandomRoll(30, seed=4)))
    full = angles(RandomRoll(180, seed=5))
    assert full.min() < -150 and full.max() > 150
    assert np.abs(angles(RandomRoll(0, seed=0), 5)).max() < 1e-4
    assert K.T_0TO1 in g and torch.equal(build_pair_graph(m, T_0to1=T)[K.T_0TO1], g[K.T_0TO1])


def test_roll_pose_per_pose_angles_equal_one_at_a_time_and_undo():
    from strl_pyg.data import roll_pose
    from strl_pyg.geometry import Pose

    T = torch.stack([Pose.from_quaternion(torch.tensor(q), torch.tensor(t)).matrix()
                     for q, t in (([0.9, 0.1, -0.2, 0.3], [0.1, 0.2, 1.0]),
                                  ([0.8, -0.3, 0.1, 0.2], [1.0, -0.5, 0.2]))]).double()
    a = torch.tensor([0.4, -2.0], dtype=torch.float64)
    both = roll_pose(T, a)
    for i in range(2):
        torch.testing.assert_close(both[i], roll_pose(T[i], float(a[i])), atol=1e-12, rtol=0)
    torch.testing.assert_close(roll_pose(both, -a), T, atol=1e-12, rtol=0)
    # a quarter turn sends the translation's x to y
    quarter = roll_pose(T[1], np.pi / 2)
    torch.testing.assert_close(quarter[:3, 3], torch.stack([-T[1, 1, 3], T[1, 0, 3], T[1, 2, 3]]),
                               atol=1e-12, rtol=0)
