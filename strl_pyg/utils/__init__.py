"""Package-wide helpers that import nothing else of strl_pyg: lazy package faces
(:mod:`.lazy`), strict dataclass-from-dict (:mod:`.dataclass`), atomic writes and safe
``torch.load`` (:mod:`.io`), image checks and decoding (:mod:`.images`), large NumPy products
through PyTorch's BLAS (:mod:`.products`), fork-safe process-wide thread pools
(:mod:`.threads`), one-line command-line errors (:mod:`.commandline`).
"""

from __future__ import annotations

from strl_pyg.utils.lazy import lazy_exports

_EXPORTS = {
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
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
