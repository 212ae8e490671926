from __future__ import annotations

import pytest
import torch

from brdfgan.data.phone.flash import FlashSampling, blackbody_rgb, planckian_xy


def test_planckian_locus_golden_values() -> None:
    # CIE 1931 chromaticities of black bodies (tabulated Planckian locus).
    assert planckian_xy(6500.0) == pytest.approx((0.3135, 0.3237), abs=2e-3)
    assert planckian_xy(2856.0) == pytest.approx((0.4476, 0.4074), abs=2e-3)  # illuminant A


def test_blackbody_colours_are_ordered_and_normalised() -> None:
    warm, neutral, cold = blackbody_rgb(3000.0), blackbody_rgb(6500.0), blackbody_rgb(12000.0)
    assert warm[0] > warm[1] > warm[2]
    assert cold[2] > cold[1] and cold[2] > cold[0]
    assert max(neutral) / min(neutral) < 1.1  # 6500 K is close to the sRGB white point
    for rgb in (warm, neutral, cold):
        assert 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2] == pytest.approx(1.0)
    ratios = [blackbody_rgb(t)[2] / blackbody_rgb(t)[0] for t in (2000, 3000, 4500, 6500, 9000, 20000)]
    assert ratios == sorted(ratios)
    with pytest.raises(ValueError, match="colour temperature"):
        blackbody_rgb(1000.0)


def test_flash_sampling_ranges_and_seeding() -> None:
    sampling = FlashSampling()
    draws = [sampling.sample(torch.Generator().manual_seed(s)) for s in range(200)]
    assert all(0.5 <= i <= 4.0 and 4000 <= t <= 6500 for i, t in draws)
    assert sampling.sample(torch.Generator().manual_seed(3)) == draws[3]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"intensity_min": -3}, "dataset_spec.flash.intensity_min=-3: must be > 0"),
        ({"intensity_min": 5.0}, "dataset_spec.flash.intensity_min=5 > dataset_spec.flash.intensity_max=4"),
        (
            {"temperature_min_k": 9000, "temperature_max_k": 1000},
            "dataset_spec.flash.temperature_min_k=9000 > dataset_spec.flash.temperature_max_k=1000",
        ),
        (
            {"temperature_min_k": 1000},
            r"dataset_spec.flash.temperature_min_k=1000: must be in \[1667, 25000\]",
        ),
        (
            {"temperature_max_k": 30000},
            r"dataset_spec.flash.temperature_max_k=30000: must be in \[1667, 25000\]",
        ),
        ({"intensity_max": "abc"}, "dataset_spec.flash.intensity_max='abc': must be a number"),
        ({"intensity_max": float("inf")}, "dataset_spec.flash.intensity_max=inf: must be a finite number"),
    ],
)
def test_flash_sampling_rejects_bad_ranges_naming_the_key(change: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        FlashSampling(**change)  # type: ignore[arg-type]


def test_a_constant_flash_is_allowed() -> None:
    sampling = FlashSampling(
        intensity_min=2.0, intensity_max=2.0, temperature_min_k=5000, temperature_max_k=5000
    )
    assert sampling.sample(torch.Generator().manual_seed(0)) == pytest.approx((2.0, 5000.0))
