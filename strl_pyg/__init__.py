"""strl-pyg: Str-L Pose relative pose from matched points and line segments, on PyG."""

__version__ = "0.1.0"
