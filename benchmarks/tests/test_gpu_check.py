"""``gpu_check.py``, the script run first whenever a GPU is lent, runs end to end on the CPU
with tiny sizes, so that it cannot rot between loans."""

from __future__ import annotations

import json

import gpu_check
import pytest


@pytest.mark.slow
def test_the_gpu_check_runs_on_the_cpu_and_writes_its_results(tmp_path):
    result = gpu_check.main(["--quick", "--device", "cpu", "--out", str(tmp_path)])
    saved = json.loads((tmp_path / "gpu_check.json").read_text())
    assert saved["device"] == result["device"] == "cpu"
    net = saved["network"]["cpu"]
    assert net["pairs"] == 2 and net["forward"]["median_ms"] > 0
    assert net["forward_backward"]["median_ms"] > 0
    assert saved["training"]["cpu"]["steps"] == 2
    assert saved["scene"]["pairs"] == 1 and sum(saved["scene"]["statuses"].values()) == 1


def test_a_missing_cuda_device_is_one_line(tmp_path):
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("a CUDA device is present")
    with pytest.raises(SystemExit, match="Expected a CUDA device"):
        gpu_check.main(["--device", "cuda", "--out", str(tmp_path)])
