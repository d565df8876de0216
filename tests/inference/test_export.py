"""ONNX export of the regression path: the wrapper equals the model's forward exactly,
onnxruntime equals PyTorch within 1e-4 on a pair, the file is never half-written, and the CLI
says what it needs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from strl_pyg.inference.export import (
    INPUT_NAMES,
    DensePoseModule,
    export_onnx,
    onnx_inputs,
)
from strl_pyg.inference.network import forward_pose, prepare_graph
from strl_pyg.model.strl_pose import StrLPose


@pytest.fixture(scope="module")
def graph(model, generated_pair):
    return prepare_graph(generated_pair(7).matches, model)


def test_wrapper_equals_the_model_forward(model, graph):
    ref = forward_pose(model, graph)
    with torch.no_grad():
        q, t, lv = DensePoseModule(model)(*onnx_inputs(model, graph))
    for a, b in ((q, ref.quaternion), (t, ref.translation), (lv, ref.log_var)):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)


def test_inputs_have_the_resampled_sizes(model, graph):
    pts, lines = model.metadata.get("resample") or [384, 192]
    shapes = [tuple(x.shape) for x in onnx_inputs(model, graph)]
    assert shapes[0] == (pts + 2 * lines, 4) and shapes[1] == (2 * lines, 8)
    assert shapes[2] == (2 * lines,) and shapes[3][0] == 2


def test_onnxruntime_equals_pytorch(model, graph, tmp_path, generated_pair):
    ort = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    path = export_onnx(model, tmp_path / "m.onnx", example=graph)
    assert path.is_file() and not list(tmp_path.glob("*.part"))
    # another pair than the example: the graph is not specialised to the traced values
    other = prepare_graph(generated_pair(11).matches, model)
    ref = forward_pose(model, other)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    outs = sess.run(None, {n: x.numpy() for n, x in zip(INPUT_NAMES, onnx_inputs(model, other),
                                                        strict=True)})
    for o, r in zip(outs, (ref.quaternion, ref.translation, ref.log_var), strict=True):
        np.testing.assert_allclose(o, r.numpy(), atol=1e-4)
    assert float(np.abs(outs[1] - forward_pose(model, prepare_graph(
        generated_pair(7).matches, model)).translation.numpy()).max()) > 1e-3  # inputs matter


def test_bad_path_and_cnn_rows_are_refused(model, tmp_path):
    with pytest.raises(ValueError, match=r"Expected a path ending in \.onnx"):
        export_onnx(model, tmp_path / "m.txt")
    from strl_pyg.model.config import StrLPoseConfig

    with pytest.raises(ValueError, match=r"visual='cnn'"):
        DensePoseModule(StrLPose(StrLPoseConfig.ablation("R", hidden=16, layers=1)))


def test_cli_export(tmp_path, capsys):
    pytest.importorskip("onnx")
    from strl_pyg.cli.commands import main

    assert main(["export", "--onnx", str(tmp_path / "x.onnx")]) == 0
    assert (tmp_path / "x.onnx").stat().st_size > 1000
    assert "fixed inputs: coords [768, 4]" in capsys.readouterr().out
    assert main(["export", "--onnx", str(tmp_path / "x.txt")]) == 2
    assert "Expected --onnx PATH ending in .onnx" in capsys.readouterr().err


def test_a_failed_export_leaves_no_file(model, graph, tmp_path, monkeypatch):
    pytest.importorskip("onnx")

    def broken(module, args, f, **kw):
        with open(f, "wb") as fh:  # the exporter had started writing
            fh.write(b"partial")
        raise RuntimeError("exporter failed")

    monkeypatch.setattr(torch.onnx, "export", broken)
    with pytest.raises(RuntimeError, match="exporter failed"):
        export_onnx(model, tmp_path / "m.onnx", example=graph)
    assert list(tmp_path.iterdir()) == []
    assert not model.training


@pytest.mark.parametrize("inputs", ["flow", "flow2", "parallax"])
def test_onnxruntime_equals_pytorch_for_the_flow_inputs(inputs, tmp_path, generated_pair):
    """The flow inputs' products and standardisation are part of the exported graph."""
    ort = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    from strl_pyg.model import StrLPoseConfig

    torch.manual_seed(0)
    m = StrLPose(StrLPoseConfig.ablation("full", hidden=16, layers=1, heads=2, inputs=inputs,
                                         patch_features=1)).eval()
    g = prepare_graph(generated_pair(7).matches, m)
    path = export_onnx(m, tmp_path / "m.onnx", example=g)
    other = prepare_graph(generated_pair(11).matches, m)
    ref = forward_pose(m, other)
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    outs = sess.run(None, {n: x.numpy() for n, x in zip(INPUT_NAMES, onnx_inputs(m, other),
                                                        strict=True)})
    for o, r in zip(outs, (ref.quaternion, ref.translation, ref.log_var), strict=True):
        np.testing.assert_allclose(o, r.numpy(), atol=1e-4)


def test_onnx_inputs_of_a_pair_without_lines_fail_before_the_runtime(held_out_pair):
    from strl_pyg.inference.export import onnx_inputs
    from strl_pyg.inference.network import prepare_graph
    from strl_pyg.model import StrLPose

    model = StrLPose.from_pretrained()
    no_lines = replace(held_out_pair.matches, lines0=None, lines1=None)
    with pytest.raises(ValueError, match=r"Expected a pair graph at the exported sizes .*"
                                         r"'endpoints': 0"):
        onnx_inputs(model, prepare_graph(no_lines, model))

