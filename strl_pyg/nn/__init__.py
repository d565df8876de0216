"""Reusable layers of Str-L Pose (Figure 1 of the paper, left to right): node encoders, the
attention and line-endpoint layers and the dual-graph layer that combines them, the weighted
fusion and the output heads."""

from strl_pyg.nn.attention import AttentionConv
from strl_pyg.nn.dual_graph import DualGraphLayer
from strl_pyg.nn.encoders import (
    INPUT_MODES,
    ImageEncoder,
    LineSegmentEncoder,
    PixelEncoder,
    SpatialCoordinateEncoder,
    flow_features,
    parallax_features,
    sample_at_pixels,
)
from strl_pyg.nn.feature_fusion import WeightedFusion
from strl_pyg.nn.heads import InlierHead, PoseHead
from strl_pyg.nn.layout import DenseLayout
from strl_pyg.nn.line import LineEndpointConv
from strl_pyg.nn.mlp import mlp, reset_mlp

__all__ = [
    "AttentionConv",
    "DenseLayout",
    "LineEndpointConv",
    "DualGraphLayer",
    "SpatialCoordinateEncoder",
    "flow_features",
    "parallax_features",
    "INPUT_MODES",
    "LineSegmentEncoder",
    "PixelEncoder",
    "ImageEncoder",
    "sample_at_pixels",
    "WeightedFusion",
    "PoseHead",
    "InlierHead",
    "mlp",
    "reset_mlp",
]
