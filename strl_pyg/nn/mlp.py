"""Small building blocks shared by the layers of :mod:`strl_pyg.nn`: the MLP used by every
encoder, update and head, its re-initialisation, and the ``(source, target)`` pair helper."""

from __future__ import annotations

from typing import Any

from torch import nn

__all__ = ["mlp", "reset_mlp", "as_pair"]


def mlp(channels: list[int]) -> nn.Sequential:
    """``Linear -> LayerNorm -> GELU`` blocks between ``channels``, a plain ``Linear`` last.

    ``mlp([a, b, c])`` is ``Linear(a, b), LayerNorm(b), GELU(), Linear(b, c)``; the state-dict
    keys of its layers are ``0.*``, ``1.*``, ``3.*`` (every checkpoint relies on this layout).
    """
    if len(channels) < 2:
        raise ValueError(f"Expected at least two channel sizes (got {channels!r})")
    layers: list[nn.Module] = []
    for i in range(len(channels) - 1):
        layers.append(nn.Linear(channels[i], channels[i + 1]))
        if i < len(channels) - 2:
            layers += [nn.LayerNorm(channels[i + 1]), nn.GELU()]
    return nn.Sequential(*layers)


def reset_mlp(module: nn.Module) -> None:
    """Re-initialises every descendant of ``module`` that has ``reset_parameters``, in
    registration order (so a seed gives the same weights every time)."""
    for child in module.modules():
        reset = getattr(child, "reset_parameters", None)
        if child is not module and callable(reset):
            reset()


def as_pair(x: Any) -> tuple[Any, Any]:
    """``(source, target)`` from a pair, or ``(x, x)`` from a single value."""
    return tuple(x) if isinstance(x, (tuple, list)) else (x, x)


def as_index(edge_index: Any) -> Any:
    """An integer ``edge_index`` (a tensor or PyG's ``EdgeIndex``) of another integer type
    (``int32`` from numpy or another tool) as ``int64``, which PyG's scatter needs; a
    floating one is a one-line ``ValueError``; anything else (a sparse adjacency) as given."""
    import torch

    if (isinstance(edge_index, torch.Tensor) and edge_index.layout == torch.strided
            and edge_index.dtype != torch.long):
        if edge_index.is_floating_point() or edge_index.is_complex() \
                or edge_index.dtype == torch.bool:
            raise ValueError(f"Expected an integer edge_index (got {edge_index.dtype})")
        return edge_index.long()
    return edge_index
