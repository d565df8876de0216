"""benchmarks/diag_roll.py: a network's translation error with both cameras rolled (the
Middlebury dino's cameras are rolled by 90 deg against the generator's upright ones)."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import diag_roll  # noqa: E402

from strl_pyg.data import PairMatches, build_pair_graph  # noqa: E402
from strl_pyg.data import keys as K  # noqa: E402


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
