"""The one bilinear pixel sampler of the package.

Pixel convention (OpenCV, as everywhere in the package): the centre of the top-left pixel of
the image is ``(0, 0)``, so pixel ``(i, j)`` (row, column) covers ``[j - 0.5, j + 0.5] x
[i - 0.5, i + 0.5]`` and the image spans ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``.

:func:`sample_bilinear` samples maps that cover the field of view of an ``H x W`` image at
image pixel coordinates. A map at the image's own resolution (the image itself: the pixel
patches of :func:`~strl_pyg.data.build.sample_patches`, the line descriptors of the front end)
is sampled at pixel centres ``x``; a map of another resolution ``h x w`` (the strided feature
maps of :func:`~strl_pyg.nn.sample_at_pixels`) at ``(x + 0.5) w / W - 0.5`` of its own pixels.
The two are one convention: at ``w = W`` the second is the first. They reach ``grid_sample`` by
two normalisations (``align_corners=True`` for the image's resolution, so that border pixel
centres map exactly to ``-1`` and ``1``; ``align_corners=False`` for another resolution), which
are the ones the shipped checkpoints were trained with, so their inputs stay bit-identical.

Outside the map, ``padding="border"`` repeats the border pixels, ``padding="zeros"`` gives 0.
Needs torch only.
"""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor

__all__ = ["sample_bilinear", "PADDINGS"]

PADDINGS = ("border", "zeros")


def sample_bilinear(maps: Tensor, xy: Tensor, image_size: tuple[int, int] | None = None,
                    padding: str = "border") -> Tensor:
    """Bilinear samples of ``maps`` at image pixel coordinates ``xy`` (module docstring).

    Args:
        maps: ``(B, C, h, w)`` float maps covering the image's field of view.
        xy: ``(B, L, 2)`` pixel coordinates ``(x, y)`` in the image, OpenCV convention.
        image_size: ``(H, W)`` of the image ``xy`` refers to (default: ``(h, w)``, the map is
            the image).
        padding: ``"border"`` (repeat the border pixels) or ``"zeros"``.

    Returns:
        ``(B, C, L)`` samples in the dtype of ``maps``.
    """
    if maps.dim() != 4 or xy.dim() != 3 or xy.shape[-1] != 2 or xy.shape[0] != maps.shape[0]:
        raise ValueError(f"Expected maps (B, C, h, w) and xy (B, L, 2) (got {tuple(maps.shape)} "
                         f"and {tuple(xy.shape)})")
    if padding not in PADDINGS:
        raise ValueError(f"Expected padding in {PADDINGS} (got {padding!r})")
    h, w = maps.shape[-2:]
    H, W = (h, w) if image_size is None else (int(image_size[0]), int(image_size[1]))
    if (H, W) == (h, w):  # pixel centres 0 and W - 1 at grid -1 and 1
        scale = xy.new_tensor([2.0 / max(w - 1, 1), 2.0 / max(h - 1, 1)])
        grid, corners = xy * scale - 1.0, True
    else:  # the map covers [-0.5, W - 0.5]: image edges at grid -1 and 1
        scale = xy.new_tensor([2.0 / W, 2.0 / H])
        grid, corners = (xy + 0.5) * scale - 1.0, False
    out = F.grid_sample(maps, grid.to(maps.dtype).unsqueeze(1), mode="bilinear",
                        padding_mode=padding, align_corners=corners)  # [B, C, 1, L]
    return out.squeeze(2)

