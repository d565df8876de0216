"""benchmarks/studies/diag_roll.py: a network's translation error with both cameras rolled (the
Middlebury dino's cameras are rolled by 90 deg against the generator's upright ones)."""

from __future__ import annotations

from types import SimpleNamespace

import diag_roll
import numpy as np
import torch

from strl_pyg.data import PairMatches, build_pair_graph
from strl_pyg.data import keys as K


def _graph():
    rng = np.random.default_rng(0)
    Km = np.array([[100.0, 0, 64], [0, 100, 64], [0, 0, 1]])
    p = rng.uniform(20, 100, (12, 2))
    m = PairMatches(p, p + 1.0, np.zeros((0, 2, 2)), np.zeros((0, 2, 2)),
                    image_size0=(128, 128), image_size1=(128, 128), K0=Km, K1=Km)
    T = np.eye(4)
    T[:3, 3] = [1.0, 0.0, 0.0]  # sideways, along the camera's x
    return build_pair_graph(m, T_0to1=T)


class _Fixed:
    """Always answers +x (an upright-only network's orbit)."""

    def __call__(self, g):
        return SimpleNamespace(translation=torch.tensor([[1.0, 0.0, 0.0]]))


class _Oracle:
    """Answers the (rolled) graph's own translation."""

    def __call__(self, g):
        return SimpleNamespace(translation=g[K.T_0TO1].reshape(4, 4)[:3, 3][None])


def test_a_fixed_answer_is_lost_by_the_roll_and_the_truth_is_not():
    sets = {"one": [_graph()]}
    fixed = diag_roll.measure(_Fixed(), sets)["one"]
    assert fixed["0"] == [0.0]
    np.testing.assert_allclose([fixed["90"][0], fixed["-90"][0], fixed["180"][0]],
                               [90.0, 90.0, 180.0], atol=1e-4)
    oracle = diag_roll.measure(_Oracle(), sets)["one"]
    assert max(max(v) for v in oracle.values()) < 1e-3


def _consistent_graph(t=(0.6, 0.1, 0.05)):
    """Matches that are exact projections under the pair's pose (by default a sideways move
    and a small yaw), so the true pose has zero Sampson distance."""
    rng = np.random.default_rng(1)
    Km = np.array([[100.0, 0, 64], [0, 100, 64], [0, 0, 1]])
    X = np.c_[rng.uniform(-1, 1, (20, 2)), rng.uniform(3, 6, 20)]
    a = np.radians(5.0)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t = np.asarray(t, dtype=float)
    X1 = X @ R.T + t
    p0 = (X[:, :2] / X[:, 2:]) * 100 + 64
    p1 = (X1[:, :2] / X1[:, 2:]) * 100 + 64
    m = PairMatches(p0, p1, np.zeros((0, 2, 2)), np.zeros((0, 2, 2)),
                    image_size0=(128, 128), image_size1=(128, 128), K0=Km, K1=Km)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return build_pair_graph(m, T_0to1=T)


class _RightOnlyRolled:
    """The truth when the graph was rolled by 90 deg, a wrong pose (another translation, no
    rotation) under every other roll: a network that knows only one camera orientation. Its
    translation log-variances are ``right_var`` on the right answer, 0 on the wrong ones; its
    quaternion's are the opposite (``-right_var``), so that reading the wrong columns picks
    another roll."""

    def __init__(self, right_var: float = 0.0):
        self.right_var = right_var

    def __call__(self, g):
        T = g[K.T_0TO1].reshape(4, 4).double()
        if abs(float(g[K.ROLL].reshape(-1)[0]) - np.pi / 2) < 1e-9:
            return SimpleNamespace(R=T[:3, :3][None], translation=T[:3, 3][None],
                                   log_var=torch.tensor([[-self.right_var] * 4
                                                         + [self.right_var] * 3]))
        return SimpleNamespace(R=torch.eye(3, dtype=torch.float64)[None],
                               translation=torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64),
                               log_var=torch.zeros(1, 7))


def test_verify_keeps_the_roll_whose_pose_fits_the_matches():
    res = diag_roll.verify(_RightOnlyRolled(), {"one": [_consistent_graph()]})["one"]
    assert res["picked"] == [90]
    assert res["verified"][0] < 1e-4 and res["best"][0] < 1e-4
    assert res["as_is"][0] > 30.0  # unrolled, the wrong answer


def test_verify_by_variance_keeps_the_least_uncertain_roll():
    graph = {"one": [_consistent_graph()]}
    sure = diag_roll.verify(_RightOnlyRolled(right_var=-2.0), graph)["one"]
    assert sure["picked_sigma"] == [90] and sure["by_sigma"][0] < 1e-4
    unsure = diag_roll.verify(_RightOnlyRolled(right_var=2.0), graph)["one"]
    assert unsure["picked_sigma"][0] != 90 and unsure["by_sigma"][0] > 30.0
    assert unsure["picked"] == [90]  # the Sampson distance does not read the variance


def test_report_writes_the_table_and_figure(tmp_path, monkeypatch):
    monkeypatch.setattr(diag_roll, "HERE", tmp_path)
    monkeypatch.setattr(diag_roll, "RESULTS", tmp_path / "results_roll")
    (tmp_path / "results_roll").mkdir()
    errs = {str(r): [float(abs(r)), float(abs(r)) + 2.0] for r in diag_roll.ROLLS}
    (tmp_path / "results_roll" / "a.json").write_text(
        __import__("json").dumps({"checkpoint": "x", "errors": {"set": errs}}))
    assert diag_roll.main(["--report"]) == 0
    text = (tmp_path / "results_roll.md").read_text()
    assert "| a | set (2) | 1.0 / 1.0 | 91.0 / 91.0 | 91.0 / 91.0 | 181.0 / 181.0 |" in text
    assert (tmp_path / "figures" / "roll.png").read_bytes()[:4] == b"\x89PNG"
    assert "Roll hypotheses" not in text
    (tmp_path / "results_roll" / "verify").mkdir()
    ver = {"as_is": [90.0, 92.0], "verified": [10.0, 14.0], "best": [9.0, 11.0],
           "picked": [90, -90]}
    (tmp_path / "results_roll" / "verify" / "a.json").write_text(
        __import__("json").dumps({"checkpoint": "x", "errors": {"set": ver}}))
    assert diag_roll.main(["--report"]) == 0
    text = (tmp_path / "results_roll.md").read_text()
    assert ("| a | set (2) | 91.0 / 91.0 | 12.0 / 12.0 | - | - | - | - | 10.0 / 10.0 | "
            "0 / 1 / 1 / 0 |") in text
    ver.update(by_sigma=[30.0, 50.0], picked_sigma=[0, 0])
    (tmp_path / "results_roll" / "verify" / "a.json").write_text(
        __import__("json").dumps({"checkpoint": "x", "errors": {"set": ver}}))
    assert diag_roll.main(["--report"]) == 0
    text = (tmp_path / "results_roll.md").read_text()
    assert ("| a | set (2) | 91.0 / 91.0 | 12.0 / 12.0 | 40.0 / 40.0 | - | - | - | 10.0 / 10.0 | "
            "0 / 1 / 1 / 0; 2 / 0 / 0 / 0 |") in text
    ver.update(axis_p90=[20.0, 22.0], axis_m90=[90.0, 92.0], vertical=[True, False])
    (tmp_path / "results_roll" / "verify" / "a.json").write_text(
        __import__("json").dumps({"checkpoint": "x", "errors": {"set": ver}}))
    assert diag_roll.main(["--report"]) == 0
    text = (tmp_path / "results_roll.md").read_text()
    assert ("| a | set (2) | 91.0 / 91.0 | 12.0 / 12.0 | 40.0 / 40.0 | 21.0 / 21.0 | "
            "91.0 / 91.0 | 50 % | 10.0 / 10.0 |") in text


def test_flow_axis_tells_vertical_from_horizontal_motion():
    rng = np.random.default_rng(3)
    x0 = rng.uniform(-0.5, 0.5, (50, 2))
    along = np.c_[rng.normal(0.1, 0.02, 50), rng.normal(0.0, 0.02, 50)]
    assert not diag_roll.flow_axis_vertical(x0, x0 + along)
    assert diag_roll.flow_axis_vertical(x0, x0 + along[:, ::-1])
    assert diag_roll.flow_axis_vertical(x0, x0 - along[:, ::-1])  # the sign does not matter
    # no displacement to read: left as it is (eigh of a zero moment would say "vertical")
    assert not diag_roll.flow_axis_vertical(x0, x0)
    assert not diag_roll.flow_axis_vertical(np.zeros((0, 2)), np.zeros((0, 2)))


def test_verify_by_flow_axis_rolls_only_vertical_flow():
    sideways = diag_roll.verify(_RightOnlyRolled(), {"one": [_consistent_graph()]})["one"]
    assert sideways["vertical"] == [False]
    assert sideways["axis_p90"] == sideways["axis_m90"] == sideways["as_is"]
    upward = diag_roll.verify(_RightOnlyRolled(), {"one": [_consistent_graph((0.1, 0.6, 0.05))]})
    upward = upward["one"]
    assert upward["vertical"] == [True]
    assert upward["axis_p90"][0] < 1e-4  # the network is right under +90 only
    assert upward["axis_m90"][0] > 30.0
