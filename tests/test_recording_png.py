"""The posterior's indexed PNG (:mod:`recording.png`) holds exactly the pixels of the raw RGBA image."""

from __future__ import annotations

import numpy as np
import pytest

from recording.png import alpha_png, decode_png
from recording.style import C_POSTERIOR, posterior_alpha, posterior_image


@pytest.mark.parametrize("shape", [(1, 1), (3, 7), (229, 187)])
def test_alpha_png_decodes_to_the_same_rgba(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    p = rng.random(shape) ** 8  # mostly near 0, like a posterior
    p[rng.random(shape) < 0.8] = 0.0
    rgba = posterior_image(p)
    got = decode_png(alpha_png(posterior_alpha(p), C_POSTERIOR))
    assert got.shape == rgba.shape and got.dtype == np.uint8
    np.testing.assert_array_equal(got, rgba)


def test_alpha_png_rejects_an_empty_grid() -> None:
    with pytest.raises(ValueError, match="2D"):
        alpha_png(np.zeros((0, 3), dtype=np.uint8), C_POSTERIOR)


def test_rgba_png_decodes_to_the_same_rgba() -> None:
    from recording.png import rgba_png

    rng = np.random.default_rng(3)
    rgba = rng.integers(0, 256, size=(13, 9, 4), dtype=np.uint8)
    rgba[2:6, 3:7] = (150, 140, 125, 110)  # a block of one colour, as the buildings' footprints
    np.testing.assert_array_equal(decode_png(rgba_png(rgba)), rgba)
    with pytest.raises(ValueError, match="H x W x 4"):
        rgba_png(rgba[..., :3])
