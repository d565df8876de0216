"""``strl-pose export --onnx model.onnx``: the model's regression path as an ONNX graph
(:mod:`strl_pyg.inference.export`: fixed node counts, one pair, no geometric head)."""

from __future__ import annotations

from strl_pyg.cli.readers import load_model
from strl_pyg.utils import UsageError

__all__ = ["cmd_export"]


def cmd_export(args) -> int:
    if not args.onnx.endswith(".onnx"):
        raise UsageError(f"Expected --onnx PATH ending in .onnx (got {args.onnx!r})")
    try:
        import onnx  # noqa: F401
    except ImportError:
        raise UsageError("Expected the optional dependency onnx for the export (got none "
                         "installed): pip install 'strl-pyg[onnx]'") from None
    from strl_pyg.inference.export import INPUT_NAMES, example_graph, export_onnx, onnx_inputs

    model = load_model(args.checkpoint)
    example = example_graph(model)
    path = export_onnx(model, args.onnx, example)
    shapes = ", ".join(f"{n} {list(x.shape)}" for n, x in zip(INPUT_NAMES,
                                                               onnx_inputs(model, example),
                                                               strict=True))
    print(f"wrote {path} (opset 17; fixed inputs: {shapes}; outputs quaternion [1, 4], "
          "translation [1, 3], log_var; the geometric head is not exported)")
    return 0
