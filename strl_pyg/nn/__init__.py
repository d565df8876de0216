"""Reusable layers of Str-L Pose: attention and line-endpoint message passing, node encoders,
and the weighted fusion head."""

from strl_pyg.nn.attention import AttentionConv, CompleteEdges
from strl_pyg.nn.encoders import (
    ImageEncoder,
    LineSegmentEncoder,
    PixelEncoder,
    SpatialCoordinateEncoder,
    sample_at_pixels,
)
from strl_pyg.nn.fusion import WeightedFusion
from strl_pyg.nn.line import LineEndpointConv

__all__ = [
    "AttentionConv",
    "CompleteEdges",
    "LineEndpointConv",
    "SpatialCoordinateEncoder",
    "LineSegmentEncoder",
    "PixelEncoder",
    "ImageEncoder",
    "sample_at_pixels",
    "WeightedFusion",
]
