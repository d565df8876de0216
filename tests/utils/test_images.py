"""Image files as users have them (strl_pyg.utils.images): 12-bit data in a 16-bit PNG."""

from __future__ import annotations

import numpy as np

from strl_pyg.inference.estimator import PoseEstimator


def test_twelve_bit_data_in_a_sixteen_bit_png_is_not_dark(tmp_path, held_out_pair):
    """Before: v // 257 made 4095 into 15: 'degenerate', 'featureless'."""
    import cv2

    from strl_pyg.utils.images import read_image_file

    twelve = [(img.astype(np.uint32) * 4095 // 255).astype(np.uint16)
              for img in (held_out_pair.image0, held_out_pair.image1)]
    cv2.imwrite(str(tmp_path / "a.png"), twelve[0])
    back = read_image_file(tmp_path / "a.png")
    assert back.dtype == np.uint8 and np.abs(back.astype(int) - held_out_pair.image0).max() <= 1
    est = PoseEstimator(methods="opencv").estimate_images(*twelve, K0=held_out_pair.K)
    assert est.status == "ok"

