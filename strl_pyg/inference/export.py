"""ONNX export of :class:`~strl_pyg.model.StrLPose`'s regression path (``strl-pose export``).

What is exported: the dense (implicit complete-graph) path of one pair at the fixed node counts
of the checkpoint's resampling (``metadata["resample"]``, 384 points and 192 lines for the
shipped models: 768 nodes, 384 endpoints), from the gathered node tensors to the pose head:

    inputs   coords [N, 4] float32 (normalised pos0 || pos1), line_feat [E, 8] float32,
             endpoint_idx [E] int64 (positions of the endpoints among the N nodes),
             line_edges [2, L] int64 (the endpoint-line graph), visual [N, 2P] float32
             (pixel rows only: the patches)
    outputs  quaternion [1, 4], translation [1, 3], log_var [1, k]

Fixed: N, E, L (the resampled sizes: :class:`~strl_pyg.data.FixedSizeResample` draws with
replacement up to them, so every pair with at least one point and one line match has them) and
the batch of one; nothing is dynamic, so a runtime can plan the whole graph once. A pair without
line matches has other sizes and cannot run on the exported graph.

Not exported: graph building (:func:`~strl_pyg.inference.network.prepare_graph`, numpy and
Python), the geometric head (its weighted eight-point solve needs an
SVD and a robust loop, which ONNX does not offer) and the CNN visual encoder (``visual="cnn"``
rows). :func:`onnx_inputs` gives the inputs of a pair in the exported order, and the test
compares onnxruntime's outputs with PyTorch's on it.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn

__all__ = ["DensePoseModule", "onnx_inputs", "export_onnx", "example_graph", "exported_sizes",
           "INPUT_NAMES", "OUTPUT_NAMES"]

INPUT_NAMES = ("coords", "line_feat", "endpoint_idx", "line_edges", "visual")
OUTPUT_NAMES = ("quaternion", "translation", "log_var")


class DensePoseModule(nn.Module):
    """The regression path of a :class:`~strl_pyg.model.StrLPose` on the gathered tensors of one
    graph (module docstring); the same modules, so it equals the model's own forward."""

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        cfg = model.config
        if cfg.visual == "cnn":
            raise ValueError("Expected a model without the CNN visual encoder for the ONNX "
                             "export (got visual='cnn')")
        self.model = model

    def forward(self, coords: Tensor, line_feat: Tensor, endpoint_idx: Tensor,
                line_edges: Tensor, visual: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        from strl_pyg.data import CompleteEdges
        from strl_pyg.nn.layout import DenseLayout

        m = self.model
        layout = DenseLayout.single(coords.shape[0])
        g = m.sce(coords)
        line_full = None
        if m.lse is not None:
            f0 = m.lse(line_feat)
            line_full = f0.new_zeros(g.shape[0], f0.shape[1]).index_copy(0, endpoint_idx, f0)
        v = m.pe(visual) if m.pe is not None else None
        complete = CompleteEdges()
        for layer in m.layers:
            g, v = layer(g, v, self_edges=complete, cross_edges=complete,
                         line_edges=line_edges if line_full is not None else None,
                         line_feat=line_full, layout=layout)
        z = m.fusion(g, v, None, 1)
        return m.pose_head(z)


def onnx_inputs(model: nn.Module, data: Any) -> tuple[Tensor, ...]:
    """The exported inputs (:data:`INPUT_NAMES`) of one pair graph (a ``HeteroData`` of
    :func:`~strl_pyg.inference.network.prepare_graph`), float32 / int64 on the CPU."""
    from torch_geometric.data import Batch

    from strl_pyg.model.gather import gather_inputs

    batch = data if isinstance(data, Batch) else Batch.from_data_list([data])
    inp = gather_inputs(model.config, batch)
    if inp.num_graphs != 1:
        raise ValueError(f"Expected one pair graph (got {inp.num_graphs})")
    n = inp.coords.shape[0]
    want = exported_sizes(model)
    got = {"nodes": n, "endpoints": 0 if inp.endpoint_idx is None else
           int(inp.endpoint_idx.numel())}
    if want is not None and {k: got[k] for k in want} != want:
        raise ValueError(
            f"Expected a pair graph at the exported sizes {want} (got {got}): the ONNX graph "
            "fixes its sizes; resample the pair to the checkpoint's (prepare_graph does), "
            "and a pair without point or without line matches cannot run on it")
    empty = torch.zeros(0, dtype=torch.long)
    out = (inp.coords.float(),
           inp.line_feat.float() if inp.line_feat is not None else torch.zeros(0, 8),
           inp.endpoint_idx if inp.endpoint_idx is not None else empty,
           inp.line_edges if inp.line_edges is not None else empty.reshape(2, 0),
           inp.visual.float() if inp.visual is not None else torch.zeros(n, 0))
    return tuple(x.cpu() for x in out)


def exported_sizes(model: nn.Module) -> dict[str, int] | None:
    """The node counts the exported graph fixes (``nodes``, and ``endpoints`` for models that
    read lines), from the checkpoint's ``metadata["resample"]``; ``None`` when it does not
    resample (the export then fixes the example's sizes)."""
    md = getattr(model, "metadata", None)
    rs = md.get("resample") if isinstance(md, dict) else None
    if rs is None:
        return None
    points, lines = rs
    cfg = model.config
    out = {"nodes": points + (2 * lines if cfg.use_lines else 0)}
    if cfg.line_mp:
        out["endpoints"] = 2 * lines
    return out


def export_onnx(model: nn.Module, path: str | os.PathLike, example: Any = None,
                opset: int = 17) -> Path:
    """Writes the ONNX graph of ``model``'s regression path (module docstring) to ``path``.

    Args:
        model: a :class:`~strl_pyg.model.StrLPose` (put in eval mode; not modified).
        path: the ``.onnx`` file; written to a temporary file first, then moved, so a failed
            export leaves no half-written file.
        example: a pair graph at the checkpoint's resampled size (default: a generated pair
            through :func:`~strl_pyg.inference.network.prepare_graph`); its sizes are the ones
            the export fixes.
        opset: the ONNX opset.
    """
    try:
        import onnx  # noqa: F401
    except ImportError as err:
        raise ImportError("the ONNX export needs the optional dependency onnx: "
                          "pip install 'strl-pyg[onnx]'") from err
    path = Path(path)
    if path.suffix != ".onnx":
        raise ValueError(f"Expected a path ending in .onnx (got {str(path)!r})")
    if example is None:
        example = example_graph(model)
    was_training = model.training
    model.eval()
    tmp = path.with_name(path.name + ".part")
    try:
        module = DensePoseModule(model)
        args = onnx_inputs(model, example)
        path.parent.mkdir(parents=True, exist_ok=True)
        with torch.no_grad(), warnings.catch_warnings():
            # the tracer notes every shape test it freezes: the sizes are fixed by design
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(module, args, str(tmp), input_names=list(INPUT_NAMES),
                              output_names=list(OUTPUT_NAMES), opset_version=opset,
                              dynamo=False)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)  # a failed export leaves no partial file
        model.train(was_training)
    return path


def example_graph(model: nn.Module):
    """A generated pair's graph at the checkpoint's resampled size (the export's example)."""
    from strl_pyg.inference.network import prepare_graph
    from strl_pyg.synthetic import generate_pair

    return prepare_graph(generate_pair(0).matches, model)
