"""brdfgan.core.filtering: the shared Gaussian and binomial blurs and the box mean."""

from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.filtering import binomial_blur, box_mean, gaussian_blur


def test_reflect_keeps_a_constant_and_zeros_darkens_the_border() -> None:
    image = torch.full((1, 2, 12, 12), 0.7)
    assert torch.allclose(gaussian_blur(image, 2.0, "reflect"), image, atol=1e-6)
    zeros = gaussian_blur(image, 2.0, "zeros")
    assert zeros[..., 0, 0].max() < 0.7 * 0.6
    assert torch.allclose(zeros[..., 6, 6], torch.tensor(0.7), atol=0.02)


def test_an_impulse_spreads_into_the_normal_density() -> None:
    image = torch.zeros(1, 1, 41, 41)
    image[..., 20, 20] = 1.0
    sigma = 2.5
    out = gaussian_blur(image, sigma)
    assert float(out.sum()) == pytest.approx(1.0, abs=1e-5)
    # Three pixels along one axis: the normal density ratio exp(-3²/2σ²).
    ratio = float(out[0, 0, 20, 23] / out[0, 0, 20, 20])
    assert ratio == pytest.approx(math.exp(-9 / (2 * sigma**2)), rel=1e-4)
    with pytest.raises(ValueError, match="sigma"):
        gaussian_blur(image, 0.0)


def test_the_binomial_blur_flattens_every_period_2_pattern_and_keeps_smooth_images() -> None:
    rows, columns = torch.meshgrid(torch.arange(9.0), torch.arange(12.0), indexing="ij")
    for pattern in ((-1) ** columns, (-1) ** rows, (-1) ** (rows + columns)):
        image = (0.5 + 0.25 * pattern).expand(2, 3, 9, 12)
        torch.testing.assert_close(binomial_blur(image), torch.full_like(image, 0.5))  # borders too
    ramp = (0.1 * rows + 0.05 * columns).expand(1, 1, 9, 12)  # linear: kept inside the borders
    torch.testing.assert_close(binomial_blur(ramp)[..., 1:-1, 1:-1], ramp[..., 1:-1, 1:-1])
    with pytest.raises(ValueError, match="H, W >= 2"):
        binomial_blur(torch.zeros(1, 3, 1, 8))


def test_box_mean_is_the_mean_over_each_window_cut_at_the_border() -> None:
    image = torch.rand(2, 3, 9, 13, generator=torch.Generator().manual_seed(0))
    for radius in (1, 3):
        _check_box_mean(image, radius)
    assert torch.equal(box_mean(image, 0), image)
    with pytest.raises(ValueError, match="radius"):
        box_mean(image, -1)


def _check_box_mean(image: torch.Tensor, radius: int) -> None:
    expected = torch.empty_like(image)
    height, width = image.shape[-2:]
    for row in range(height):
        for column in range(width):
            window = image[
                ..., max(row - radius, 0) : row + radius + 1, max(column - radius, 0) : column + radius + 1
            ]
            expected[..., row, column] = window.mean(dim=(-2, -1))
    assert torch.allclose(box_mean(image, radius), expected, atol=1e-6)
