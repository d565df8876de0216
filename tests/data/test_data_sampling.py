"""The one bilinear sampler (strl_pyg.data.sampling): the OpenCV pixel convention at known
answers, equality with a direct interpolation, and the three callers (graph patches, +R
feature maps, front-end line descriptors) on it with the model's inputs unchanged."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from strl_pyg.data.build import sample_patches
from strl_pyg.data.sampling import sample_bilinear
from strl_pyg.nn import sample_at_pixels

H, W = 7, 11


def ramps(dtype=torch.float64) -> torch.Tensor:
    """``(1, 2, H, W)``: channel 0 holds each pixel's x, channel 1 its y (OpenCV pixels)."""
    y, x = torch.meshgrid(torch.arange(H, dtype=dtype), torch.arange(W, dtype=dtype),
                          indexing="ij")
    return torch.stack([x, y])[None]


def reference(img: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
    """Direct bilinear interpolation of ``(h, w)`` at ``(L, 2)`` pixels, border repeated."""
    h, w = img.shape
    x, y = xy[:, 0].clamp(0, w - 1), xy[:, 1].clamp(0, h - 1)
    x0, y0 = x.floor().clamp(max=w - 2).long(), y.floor().clamp(max=h - 2).long()
    fx, fy = x - x0, y - y0
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bottom = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def test_pixel_centres_give_their_coordinates_exactly():
    xy = torch.tensor([[[0.0, 0.0], [W - 1, H - 1], [3.25, 2.5], [W - 1, 0.0], [0.5, H - 1]]],
                      dtype=torch.float64)
    out = sample_bilinear(ramps(), xy)[0]  # [2, L]
    torch.testing.assert_close(out.T, xy[0], rtol=0, atol=1e-12)


def test_border_padding_repeats_and_zeros_padding_fades():
    xy = torch.tensor([[[-3.0, 2.0], [W + 4.0, 2.0], [2.0, -0.5]]], dtype=torch.float64)
    border = sample_bilinear(ramps(), xy)[0]
    torch.testing.assert_close(border[0], torch.tensor([0.0, W - 1, 2.0], dtype=torch.float64))
    zeros = sample_bilinear(ramps() + 1.0, xy, padding="zeros")[0]
    torch.testing.assert_close(zeros[:, :2], torch.zeros(2, 2, dtype=torch.float64))
    # half a pixel above the top row: half of the row's value, half of the zero outside
    torch.testing.assert_close(zeros[1, 2], torch.tensor(0.5, dtype=torch.float64))


def test_equals_direct_interpolation_at_random_points():
    g = torch.Generator().manual_seed(0)
    img = torch.rand(H, W, generator=g, dtype=torch.float64)
    xy = torch.rand(200, 2, generator=g, dtype=torch.float64) * torch.tensor([W + 4, H + 4]) - 2
    out = sample_bilinear(img[None, None], xy[None])[0, 0]
    torch.testing.assert_close(out, reference(img, xy), rtol=0, atol=1e-12)


def test_lower_resolution_map_covers_the_image_field_of_view():
    """A 2x2 average-pooled x ramp holds, at map pixel j, the mean of image pixels 2j and
    2j + 1, i.e. the value at image x = 2j + 0.5: sampled at image pixels it gives x."""
    pooled = F.avg_pool2d(ramps()[:, :1, :6, :10], 2)  # [1, 1, 3, 5] of a 6x10 image
    xy = torch.tensor([[[0.5, 1.0], [2.5, 3.0], [4.0, 2.2], [8.5, 0.7]]], dtype=torch.float64)
    out = sample_bilinear(pooled, xy, image_size=(6, 10))[0, 0]
    torch.testing.assert_close(out, xy[0, :, 0], rtol=0, atol=1e-12)


def test_bad_arguments():
    with pytest.raises(ValueError, match=r"Expected maps \(B, C, h, w\) and xy \(B, L, 2\)"):
        sample_bilinear(torch.zeros(1, H, W), torch.zeros(1, 3, 2))
    with pytest.raises(ValueError, match="Expected padding in"):
        sample_bilinear(torch.zeros(1, 1, H, W), torch.zeros(1, 3, 2), padding="reflect")


def test_sample_patches_bit_identical_to_its_former_grid_sample():
    """The graph's patches (shipped checkpoints were trained on them) are unchanged."""
    g = torch.Generator().manual_seed(1)
    img = torch.rand(3, 40, 57, generator=g)
    xy = torch.rand(30, 2, generator=g) * torch.tensor([60.0, 44.0]) - 1.5
    for p in (1, 3):
        r = p // 2
        off = torch.arange(-r, r + 1, dtype=xy.dtype)
        oy, ox = torch.meshgrid(off, off, indexing="ij")
        pts = xy[:, None, :] + torch.stack([ox, oy], dim=-1).reshape(1, -1, 2)
        scale = xy.new_tensor([2.0 / 56, 2.0 / 39])
        former = F.grid_sample(img[None], (pts * scale - 1.0)[None], mode="bilinear",
                               padding_mode="border", align_corners=True)
        former = former[0].permute(1, 0, 2).reshape(30, 3 * p * p)
        assert torch.equal(sample_patches(img, xy, p), former)


def test_sample_at_pixels_bit_identical_to_its_former_grid_sample():
    g = torch.Generator().manual_seed(2)
    fmap = torch.rand(2, 4, 5, 8, generator=g)
    kpts = torch.rand(9, 2, generator=g) * torch.tensor([64.0, 40.0])
    batch = torch.tensor([0, 0, 0, 0, 1, 1, 1, 1, 1])
    grid = (kpts + 0.5) * kpts.new_tensor([2.0 / 64, 2.0 / 40]) - 1.0
    former = torch.cat([
        F.grid_sample(fmap[b:b + 1], grid[batch == b][None, None], mode="bilinear",
                      padding_mode="zeros", align_corners=False)[0, :, 0].T for b in (0, 1)])
    assert torch.equal(sample_at_pixels(fmap, kpts, batch, (40, 64)), former)


def test_frontend_sampler_is_exact_on_the_last_row_and_column():
    """Bug reproduced: the front end's former numpy sampler clipped x to ``W - 1.001``, so the
    last column of an x ramp read ``W - 1.001`` (and beyond it, too) instead of ``W - 1``."""
    from strl_pyg.frontend.line_descriptors import sample_image

    ramp = np.tile(np.arange(W, dtype=np.float32), (H, 1))
    xy = np.array([[W - 1.0, 3.0], [W + 2.0, 3.0], [4.5, H - 1.0], [0.0, 0.0]])
    np.testing.assert_array_equal(sample_image(ramp, xy), [W - 1.0, W - 1.0, 4.5, 0.0])
    assert sample_image(ramp, xy[None]).shape == (1, 4)
