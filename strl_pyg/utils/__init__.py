"""Package-wide helpers that import nothing else of strl_pyg: lazy package faces
(:mod:`.lazy`), strict dataclass-from-dict (:mod:`.dataclass`), atomic writes and safe
``torch.load`` (:mod:`.io`), image checks and decoding (:mod:`.images`), large NumPy products
through PyTorch's BLAS (:mod:`.products`), fork-safe process-wide thread pools
(:mod:`.threads`), one-line command-line errors (:mod:`.commandline`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

__all__ = [
    "lazy_exports",
    "strict_from_dict",
    "atomic_open",
    "check_output_file",
    "check_output_dir",
    "safe_torch_load",
    "UnsafeFileError",
    "one_line",
    "decode_image",
    "read_image_file",
    "check_image",
    "to_uint8",
    "FRONTEND_MIN_SIDE",
    "UsageError",
    "OneLineArgumentParser",
]

__getattr__, __dir__ = lazy_exports(__name__, {
    "lazy_exports": "strl_pyg.utils.lazy",
    "strict_from_dict": "strl_pyg.utils.dataclass",
    "atomic_open": "strl_pyg.utils.io",
    "check_output_file": "strl_pyg.utils.io",
    "check_output_dir": "strl_pyg.utils.io",
    "safe_torch_load": "strl_pyg.utils.io",
    "UnsafeFileError": "strl_pyg.utils.io",
    "one_line": "strl_pyg.utils.io",
    "decode_image": "strl_pyg.utils.images",
    "read_image_file": "strl_pyg.utils.images",
    "check_image": "strl_pyg.utils.images",
    "to_uint8": "strl_pyg.utils.images",
    "FRONTEND_MIN_SIDE": "strl_pyg.utils.images",
    "UsageError": "strl_pyg.utils.commandline",
    "OneLineArgumentParser": "strl_pyg.utils.commandline",
}, globals())
