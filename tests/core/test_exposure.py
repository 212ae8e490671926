from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.exposure import (
    auto_expose,
    auto_exposure_scale,
    ev100_to_scale,
    exposure_value_100,
    luminance,
    saturation_luminance,
)


def _hdr(seed: int = 0, batch: int = 2) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand((batch, 3, 16, 16), generator=g, dtype=torch.float64) ** 4 * 50


@pytest.mark.parametrize("factor", [1e-4, 0.37, 1.0, 12.0, 5e5])
def test_ldr_is_invariant_to_hdr_scaling(factor: float) -> None:
    hdr = _hdr()
    ldr, _ = auto_expose(hdr)
    scaled, _ = auto_expose(hdr * factor)
    torch.testing.assert_close(scaled, ldr, rtol=1e-9, atol=1e-12)


def test_golden_values() -> None:
    # EV100 = log2(L·100/12.5); L_max = 1.2·2^EV100 = 9.6·L: a uniform grey maps to 1/9.6.
    assert saturation_luminance(torch.tensor(0.0)).item() == pytest.approx(1.2)
    assert exposure_value_100(torch.tensor(0.125)).item() == pytest.approx(0.0)
    hdr = torch.full((1, 3, 4, 4), 7.0, dtype=torch.float64)
    ldr, scale = auto_expose(hdr)
    torch.testing.assert_close(ldr, torch.full_like(ldr, 1 / 9.6))
    assert scale.item() == pytest.approx(1 / (9.6 * 7.0))
    assert ev100_to_scale(0.0) == pytest.approx(1 / 1.2)


def test_output_is_linear_and_clipped() -> None:
    hdr = _hdr(batch=1)
    hdr[..., :2, :2] = 1e3  # a flash hotspot
    ldr, scale = auto_expose(hdr)
    assert ldr.min() >= 0 and ldr.max() == 1.0  # bright pixels clip
    unclipped = hdr * scale.view(-1, 1, 1, 1) < 1
    torch.testing.assert_close(ldr[unclipped], (hdr * scale.view(-1, 1, 1, 1))[unclipped])


def test_each_image_is_exposed_on_its_own() -> None:
    hdr = _hdr(batch=3)
    hdr[1] *= 1000
    ldr, _ = auto_expose(hdr)
    for i in range(3):
        torch.testing.assert_close(ldr[i], auto_expose(hdr[i : i + 1])[0][0])


def test_black_image_and_bad_input() -> None:
    ldr, scale = auto_expose(torch.zeros(1, 3, 2, 2))
    assert torch.count_nonzero(ldr) == 0 and scale.item() == 0
    with pytest.raises(ValueError, match="NaN"):
        auto_exposure_scale(torch.full((1, 3, 2, 2), math.nan))
    with pytest.raises(ValueError, match=r"\(\*, 3, H, W\)"):
        luminance(torch.zeros(1, 4, 2, 2))
