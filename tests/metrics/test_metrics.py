"""Evaluation metrics: golden values, sum-based accumulation, downscaling, DDP-style merging."""

from __future__ import annotations

import math
from collections.abc import Iterator

import kornia.color
import pytest
import torch
from torch import Tensor

from brdfgan.core.svbrdf import InvalidMapsError, flat_maps, join_maps, split_maps
from brdfgan.metrics import (
    CHECKERBOARD_MAPS,
    RMSE_MAPS,
    CheckerboardRatio,
    HueError,
    MapRMSE,
    NormalAngularError,
    RerenderError,
    SaturationRatio,
    SVBRDFMetrics,
    basecolor_hsv,
    checkerboard_ratio,
    compared_maps,
    fixed_render_configs,
    hue_difference_deg,
    hue_error_deg,
    period2_amplitudes,
    period2_floor,
    period2_power,
    saturation_ratio,
)
from tests.conftest import random_maps

SRGB_HALF_LINEAR = ((0.5 + 0.055) / 1.055) ** 2.4  # sRGB 0.5 decoded: 0.21404…
# The collection's keys besides the per-map RMSE (without hotspot).
CHECKERBOARD_KEYS = tuple(
    f"checkerboard/{name}{kind}" for name in CHECKERBOARD_MAPS for kind in ("", "/pooled")
)


def photos(batch: int, size: int = 8, seed: int = 0, dtype: torch.dtype = torch.float32) -> Tensor:
    """Linear photos for the maps' batch (the observable normal angle reads their 8-bit rounding)."""
    return torch.rand(batch, 3, size, size, generator=torch.Generator().manual_seed(seed), dtype=dtype)


SCALAR_KEYS = (
    "normal_angle_deg",
    "rerender_rmse",
    "basecolor_saturation_ratio",
    "basecolor_hue_error_deg",
    *CHECKERBOARD_KEYS,
    "false_metal",
    "normal_angle_deg/observable",
    "normal_angle_deg/observable_flat",
    "relief_leak",
    "relief_leak/slope",
    "normal_slope_cosine",
    "normal_slope_ratio",
)


def normal_maps(normal: tuple[float, float, float], size: int = 4, batch: int = 1) -> Tensor:
    """Flat gray maps with one constant normal."""
    maps = flat_maps(size, size, batch=(batch,), dtype=torch.float64)
    maps[:, 3:6] = torch.tensor(normal, dtype=torch.float64).view(1, 3, 1, 1)
    return maps


# ---------------------------------------------------------------- golden values


def test_constant_offsets_give_known_rmse() -> None:
    true = flat_maps(6, 6, basecolor=(0.5, 0.5, 0.5), roughness=0.5, metallic=0.0, batch=(2,))
    pred = flat_maps(6, 6, basecolor=(0.6, 0.5, 0.3), roughness=0.75, metallic=0.1, batch=(2,))
    metric = MapRMSE()
    metric.update(pred, true)
    out = metric.compute()
    assert set(out) == set(RMSE_MAPS)
    assert out["roughness"].item() == pytest.approx(0.25, abs=1e-7)
    assert out["metallic"].item() == pytest.approx(0.1, abs=1e-7)
    # base colour in its stored sRGB encoding: per-channel offsets 0.1, 0, -0.2
    assert out["basecolor"].item() == pytest.approx(math.sqrt((0.01 + 0.0 + 0.04) / 3), abs=1e-7)
    assert out["normal"].item() == 0.0


def test_derived_albedo_rmse_by_hand() -> None:
    # Base colour sRGB 0.5 everywhere (linear b = 0.21404). Prediction dielectric (m = 0),
    # ground truth half metallic (m = 0.5):
    #   diffuse  pred b,    true b/2            -> error b/2
    #   specular pred 0.04, true 0.02 + b/2     -> error 0.02 - b/2
    true = flat_maps(4, 4, basecolor=(0.5, 0.5, 0.5), metallic=0.5, batch=(1,), dtype=torch.float64)
    pred = flat_maps(4, 4, basecolor=(0.5, 0.5, 0.5), metallic=0.0, batch=(1,), dtype=torch.float64)
    b = SRGB_HALF_LINEAR
    metric = MapRMSE()
    metric.update(pred, true)
    out = metric.compute()
    assert out["diffuse"].item() == pytest.approx(b / 2, rel=1e-6)
    assert out["specular"].item() == pytest.approx(abs(0.02 - b / 2), rel=1e-6)
    assert out["basecolor"].item() == 0.0
    assert out["metallic"].item() == pytest.approx(0.5)


def test_derived_albedo_rmse_metal_vs_dielectric_and_srgb_switch() -> None:
    # White metal vs white dielectric: diffuse 0 vs 1, specular 1 vs 0.04 (linear).
    metal = flat_maps(2, 2, basecolor=(1.0, 1.0, 1.0), metallic=1.0, batch=(1,), dtype=torch.float64)
    plastic = flat_maps(2, 2, basecolor=(1.0, 1.0, 1.0), metallic=0.0, batch=(1,), dtype=torch.float64)
    linear = MapRMSE()
    linear.update(metal, plastic)
    assert linear.compute()["diffuse"].item() == pytest.approx(1.0)
    assert linear.compute()["specular"].item() == pytest.approx(0.96)
    srgb = MapRMSE(albedo_space="srgb")
    srgb.update(metal, plastic)
    f0_srgb = 1.055 * 0.04 ** (1 / 2.4) - 0.055  # 0.04 sRGB-encoded: 0.2213…
    assert srgb.compute()["specular"].item() == pytest.approx(1.0 - f0_srgb, rel=1e-6)
    with pytest.raises(ValueError, match="albedo_space"):
        MapRMSE(albedo_space="xyz")  # type: ignore[arg-type]


def test_normals_90_degrees_apart() -> None:
    pred, true = normal_maps((1.0, 0.0, 0.0)), normal_maps((0.0, 0.0, 1.0))
    angle = NormalAngularError()
    angle.update(pred, true)
    assert angle.compute().item() == pytest.approx(90.0, abs=1e-9)
    rmse = MapRMSE()
    rmse.update(pred, true)
    # |a - b|² = 2 per pixel, spread over 3 components
    assert rmse.compute()["normal"].item() == pytest.approx(math.sqrt(2.0 / 3.0))


def test_normal_metrics_renormalise_and_are_exact_for_identical_normals() -> None:
    true = normal_maps((0.0, 0.6, 0.8))
    pred = normal_maps((0.0, 3.0, 4.0))  # same direction, length 5
    angle, rmse = NormalAngularError(), MapRMSE()
    angle.update(pred, true)
    rmse.update(pred, true)
    assert angle.compute().item() == pytest.approx(0.0, abs=1e-6)
    assert rmse.compute()["normal"].item() == pytest.approx(0.0, abs=1e-7)
    small = normal_maps((math.sin(1e-4), 0.0, math.cos(1e-4)))
    angle.reset()
    angle.update(small, normal_maps((0.0, 0.0, 1.0)))
    assert angle.compute().item() == pytest.approx(math.degrees(1e-4), rel=1e-6)  # atan2, not acos


# ---------------------------------------------------------------- base-colour hue and saturation


def coloured_maps(size: int = 8, batch: int = 3, seed: int = 0) -> tuple[Tensor, Tensor]:
    """Random maps whose base colour has HSV saturation and value in [0.3, 1], and that HSV."""
    g = torch.Generator().manual_seed(seed)
    hue = 2.0 * math.pi * torch.rand(batch, 1, size, size, generator=g, dtype=torch.float64)
    sat_value = 0.3 + 0.7 * torch.rand(batch, 2, size, size, generator=g, dtype=torch.float64)
    hsv = torch.cat([hue, sat_value], dim=1)
    maps = random_maps(size, size, seed=seed, batch=(batch,), dtype=torch.float64)
    maps[:, 0:3] = kornia.color.hsv_to_rgb(hsv)
    return maps, hsv


def with_hsv(maps: Tensor, hsv: Tensor) -> Tensor:
    """``maps`` with the base colour of HSV ``hsv`` (every other map kept)."""
    out = maps.clone()
    out[:, 0:3] = kornia.color.hsv_to_rgb(hsv)
    return out


def test_basecolor_hsv_round_trips_and_matches_kornia() -> None:
    maps, hsv = coloured_maps()
    torch.testing.assert_close(basecolor_hsv(maps), hsv)
    clipped = maps.clone()
    clipped[:, 0] += 0.5  # out of range: clamped first, like brdfgan.data.tools.statistics
    expected = kornia.color.rgb_to_hsv(clipped[:, 0:3].clamp(0.0, 1.0))
    torch.testing.assert_close(basecolor_hsv(clipped), expected)
    with pytest.raises(InvalidMapsError):
        basecolor_hsv(torch.zeros(1, 3, 4, 4))


def test_hue_difference_is_circular() -> None:
    deg = math.pi / 180.0
    a = torch.tensor([10.0, 350.0, 0.0, 90.0, 359.0], dtype=torch.float64) * deg
    b = torch.tensor([350.0, 10.0, 180.0, 90.0, 0.0], dtype=torch.float64) * deg
    torch.testing.assert_close(hue_difference_deg(a, b), torch.tensor([20.0, 20.0, 180.0, 0.0, 1.0]).double())


def test_identical_base_colours_give_ratio_one_and_hue_error_zero() -> None:
    maps, _ = coloured_maps()
    assert saturation_ratio(maps, maps).item() == 1.0
    assert hue_error_deg(maps, maps).item() == 0.0


def test_grey_prediction_of_a_saturated_truth() -> None:
    true, hsv = coloured_maps()
    grey = with_hsv(true, torch.stack([hsv[:, 0], torch.zeros_like(hsv[:, 1]), hsv[:, 2]], dim=1))
    assert saturation_ratio(grey, true).item() == pytest.approx(0.0, abs=1e-12)
    # No hue to compare: every weight min(S_pred, S_true) is 0.
    assert math.isnan(hue_error_deg(grey, true).item())


@pytest.mark.parametrize("degrees", [60.0, -60.0, 150.0])
def test_hue_rotation_gives_its_angle(degrees: float) -> None:
    true, hsv = coloured_maps()
    rotated = hsv.clone()
    rotated[:, 0] = torch.remainder(hsv[:, 0] + math.radians(degrees), 2.0 * math.pi)
    pred = with_hsv(true, rotated)
    assert hue_error_deg(pred, true).item() == pytest.approx(abs(degrees), abs=1e-6)
    assert saturation_ratio(pred, true).item() == pytest.approx(1.0, abs=1e-9)


def test_half_saturation_gives_ratio_one_half() -> None:
    true, hsv = coloured_maps()
    pred = with_hsv(true, hsv * torch.tensor([1.0, 0.5, 1.0], dtype=torch.float64).view(1, 3, 1, 1))
    assert saturation_ratio(pred, true).item() == pytest.approx(0.5, abs=1e-9)
    assert hue_error_deg(pred, true).item() == pytest.approx(0.0, abs=1e-6)  # same hues
    assert saturation_ratio(true, pred).item() == pytest.approx(2.0, abs=1e-9)  # oversaturated


def test_teal_turned_grey_brown_by_hand() -> None:
    # Teal sRGB (0.1, 0.6, 0.6): hue 180°, S = 0.5 / 0.6. Grey-brown (0.5, 0.45, 0.4): hue 30°, S = 0.2.
    true = flat_maps(4, 4, basecolor=(0.1, 0.6, 0.6), batch=(2,), dtype=torch.float64)
    pred = flat_maps(4, 4, basecolor=(0.5, 0.45, 0.4), batch=(2,), dtype=torch.float64)
    assert saturation_ratio(pred, true).item() == pytest.approx(0.2 / (0.5 / 0.6), rel=1e-7)  # kornia eps
    assert hue_error_deg(pred, true).item() == pytest.approx(150.0, abs=1e-9)


def test_grey_truths_are_finite_and_weigh_nothing() -> None:
    true, hsv = coloured_maps(batch=2)
    pred = with_hsv(true, hsv * torch.tensor([1.0, 0.5, 1.0], dtype=torch.float64).view(1, 3, 1, 1))
    for level in (0.0, 0.5):  # black and mid grey: S = 0, kornia's hue 0
        grey = flat_maps(8, 8, basecolor=(level, level, level), batch=(1,), dtype=torch.float64)
        both_true, both_pred = torch.cat([true, grey]), torch.cat([pred, grey])
        # A grey truth predicted grey adds nothing: the values of the coloured samples alone.
        assert saturation_ratio(both_pred, both_true).item() == pytest.approx(0.5, abs=1e-9)
        assert hue_error_deg(both_pred, both_true).item() == pytest.approx(0.0, abs=1e-6)
        # A grey truth predicted coloured raises the ratio (finite) and has no hue weight.
        coloured_pred = torch.cat([pred, true[:1]])
        ratio = saturation_ratio(coloured_pred, both_true).item()
        assert math.isfinite(ratio) and ratio > 0.5
        assert hue_error_deg(coloured_pred, both_true).item() == pytest.approx(0.0, abs=1e-6)
    # Only an all-grey truth leaves the ratio undefined: NaN, never inf.
    grey = flat_maps(8, 8, basecolor=(0.5, 0.5, 0.5), batch=(2,), dtype=torch.float64)
    assert math.isnan(saturation_ratio(pred[:2], grey).item())
    assert math.isnan(saturation_ratio(grey, grey).item()) and math.isnan(hue_error_deg(grey, grey).item())


def test_colour_metrics_accumulate_exactly() -> None:
    true, hsv = coloured_maps(batch=5, seed=3)
    scale = torch.tensor([1.0, 0.7, 1.0], dtype=torch.float64).view(1, 3, 1, 1)
    shifted = hsv * scale
    shifted[:, 0] = torch.remainder(hsv[:, 0] + 0.4 * torch.rand(5, 8, 8, dtype=torch.float64), 2 * math.pi)
    pred = with_hsv(true, shifted)
    true[3:] = flat_maps(8, 8, basecolor=(0.4, 0.4, 0.4), batch=(2,), dtype=torch.float64)  # grey truths
    for metric, function in ((SaturationRatio(), saturation_ratio), (HueError(), hue_error_deg)):
        for part in (slice(0, 1), slice(1, 4), slice(4, 5)):  # uneven batches
            metric.update(pred[part], true[part])
        torch.testing.assert_close(metric.compute(), function(pred, true), rtol=1e-12, atol=0.0)
        assert metric.compute().dtype == torch.float64
        metric.reset()
        with pytest.warns(UserWarning, match="called before the ``update``"):
            assert math.isnan(metric.compute().item())  # nothing accumulated
    unbatched = SaturationRatio()
    unbatched.update(pred[0], true[0])
    torch.testing.assert_close(unbatched.compute(), saturation_ratio(pred[:1], true[:1]))


def test_colour_metric_input_checks() -> None:
    maps, _ = coloured_maps()
    with pytest.raises(ValueError, match="same shape"):
        saturation_ratio(maps, maps[:, :, :4])
    with pytest.raises(InvalidMapsError):
        hue_error_deg(maps[:, :7], maps[:, :7])
    with pytest.raises(ValueError, match="same shape"):
        HueError().update(maps, maps[:2])


# ---------------------------------------------------------------- period-2 (checkerboard) power


def alternating(size: int, rows: bool = True, cols: bool = True) -> Tensor:
    """``(−1)^i``, ``(−1)^j`` or ``(−1)^(i+j)`` on a ``size²`` grid (i the row), float64."""
    i, j = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    return (1 - 2 * ((i * rows + j * cols) % 2)).to(torch.float64)


def smooth_maps(size: int = 16, batch: int = 1) -> Tensor:
    """Maps of low-frequency periodic cosines (1–2 cycles per image): no period-2 power at all
    under the periodic Hann window, whose spectrum spreads a frequency only to its neighbours — but
    for the renormalised normals, whose high harmonics are ~1e-17, far below the 8-bit floor."""
    index = torch.arange(size, dtype=torch.float64)
    i, j = torch.meshgrid(index, index, indexing="ij")
    wave = torch.cos(2 * math.pi * (i + 2 * j) / size)
    maps = flat_maps(size, size, basecolor=(0.5, 0.4, 0.3), batch=(batch,), dtype=torch.float64)
    maps[:, 0:3] += 0.1 * wave
    maps[:, 3] += 0.2 * wave  # tilted normals, renormalised by the metric
    maps[:, 6] += 0.1 * wave
    return maps


def quantisation_floor(size: int, channels: int, step: float = 1 / 255) -> float:
    """By hand: 3 bins × channels × step²/12 × Σw_i² Σw_j² / (Σw_i Σw_j)², where the periodic
    Hann window of even n >= 4 has Σw = n/2 and Σw² = 3n/8: 3 C step² / 12 · 9 / (4 n²)."""
    return 3 * channels * step**2 / 12 * 9 / (4 * size**2)


def test_period2_power_of_a_checkerboard_by_hand() -> None:
    smooth = smooth_maps()
    smooth_power = period2_power(smooth)
    assert smooth_power.pop("normal").item() < 1e-15
    assert all(power.item() < 1e-28 for power in smooth_power.values())
    a, b = 0.1, 0.02
    pred, true = smooth.clone(), smooth.clone()
    pred[:, 6] += a * alternating(16)  # ±a checkerboard on roughness
    true[:, 6] += b * alternating(16)
    amplitudes = period2_amplitudes(pred[:, 6:7])[0, 0]  # (H/2, 0), (0, W/2), (H/2, W/2)
    torch.testing.assert_close(
        amplitudes, torch.tensor([0.0, 0.0, a], dtype=torch.float64), atol=1e-15, rtol=0
    )
    power = period2_power(pred)
    assert power["roughness"].item() == pytest.approx(a**2, rel=1e-12)
    assert power["basecolor"].item() < 1e-28 and power["metallic"].item() == 0.0
    floor = period2_floor(16, 16)
    assert floor["roughness"] == pytest.approx(quantisation_floor(16, 1), rel=1e-12)
    assert floor["normal"] == pytest.approx(quantisation_floor(16, 3, step=2 / 255), rel=1e-12)
    ratio = checkerboard_ratio(pred, true)
    f = quantisation_floor(16, 1)
    assert ratio["roughness"].item() == pytest.approx((a**2 + f) / (b**2 + f), rel=1e-12)  # ≈ 25
    assert ratio["roughness/pooled"].item() == pytest.approx((a**2 + f) / (b**2 + f), rel=1e-12)
    for name in ("basecolor", "normal", "metallic"):
        assert ratio[name].item() == pytest.approx(1.0, abs=1e-12), name
        assert ratio[f"{name}/pooled"].item() == pytest.approx(1.0, abs=1e-12), name
    # Two samples: the geometric mean of the per-sample ratios vs the ratio of the summed powers.
    c = 0.002  # a nearly smooth second truth: its ratio is large, its weight in the pooled one small
    pair_true = torch.cat([true, smooth + 0.0])
    pair_true[1, 6] += c * alternating(16)
    pair = checkerboard_ratio(torch.cat([pred, pred]), pair_true)
    first, second = (a**2 + f) / (b**2 + f), (a**2 + f) / (c**2 + f)
    assert pair["roughness"].item() == pytest.approx(math.sqrt(first * second), rel=1e-12)  # ≈ 250
    assert pair["roughness/pooled"].item() == pytest.approx(2 * (a**2 + f) / (b**2 + c**2 + 2 * f), rel=1e-12)
    # Stripes on every base-colour channel: (−1)^i and (−1)^j, amplitude a each, 3 channels.
    striped = smooth.clone()
    striped[:, 0:3] += a * alternating(16, cols=False) + a * alternating(16, rows=False)
    assert period2_power(striped)["basecolor"].item() == pytest.approx(3 * 2 * a**2, rel=1e-12)


def test_period2_power_ignores_the_mean_and_ramps() -> None:
    # The periodic Hann window: no leakage of a constant or a linear ramp into the period-2 bins,
    # where an unwindowed sum would read a ramp of slope s per texel as a checkerboard of s / 2.
    index = torch.arange(32, dtype=torch.float64)
    i, j = torch.meshgrid(index, index, indexing="ij")
    maps = flat_maps(32, 32, basecolor=(0.9, 0.1, 0.5), roughness=0.7, metallic=1.0, dtype=torch.float64)
    maps[6] = 0.2 + 0.01 * i + 0.005 * j
    maps[0] = 0.8 - 0.02 * j
    assert all(power.item() < 1e-28 for power in period2_power(maps).values())
    unwindowed = (maps[6] * alternating(32, cols=False)).mean().square().item()
    assert unwindowed == pytest.approx((0.01 / 2) ** 2)


def test_blurred_prediction_scores_below_one_and_identity_one() -> None:
    true = random_maps(32, 32, seed=1, batch=(4,))
    identity = checkerboard_ratio(true, true)
    assert {f"checkerboard/{key}": value.item() for key, value in identity.items()} == dict.fromkeys(
        CHECKERBOARD_KEYS, 1.0
    )
    blurred = torch.nn.functional.avg_pool2d(true, 3, stride=1, padding=1, count_include_pad=False)
    for key, value in checkerboard_ratio(blurred, true).items():
        assert 0.0 < value.item() < 0.2, key  # measured 0.06–0.10


def test_flat_maps_are_finite() -> None:
    flat_true = flat_maps(16, 16, basecolor=(0.2, 0.3, 0.4), roughness=0.3, batch=(2,))
    flat_pred = flat_maps(16, 16, basecolor=(0.6, 0.5, 0.4), roughness=0.8, metallic=1.0, batch=(2,))
    for value in checkerboard_ratio(flat_pred.double(), flat_true.double()).values():
        assert value.item() == pytest.approx(1.0, abs=1e-12)  # both at the 8-bit floor
    for value in checkerboard_ratio(flat_pred, flat_true).values():
        assert value.item() == pytest.approx(1.0, abs=1e-6)  # float32 rounding: measured 2e-9
    a = 0.01
    checkered = flat_true.double()
    checkered[:, 6] += a * alternating(16)
    ratio = checkerboard_ratio(checkered, flat_true.double())
    f = quantisation_floor(16, 1)
    for key in ("roughness", "roughness/pooled"):
        value = ratio[key].item()
        assert math.isfinite(value) and value == pytest.approx((a**2 + f) / f, rel=1e-9)  # ≈ 3·10⁴


def test_checkerboard_ratio_accumulates_exactly_and_handles_sizes() -> None:
    true = random_maps(9, 11, seed=3, batch=(5,), dtype=torch.float64)  # odd: last row/column ignored
    pred = true.clone()
    pred[:, 6] += 0.05 * torch.rand(5, 9, 11, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    metric = CheckerboardRatio(prefix="chk/")
    for part in (slice(0, 1), slice(1, 4), slice(4, 5)):  # uneven batches
        metric.update(pred[part], true[part])
    whole = checkerboard_ratio(pred, true)
    assert whole["roughness"] > 1.0
    computed = metric.compute()
    assert computed.keys() == {f"chk/{key}" for key in whole} and len(whole) == 2 * len(CHECKERBOARD_MAPS)
    for key, value in whole.items():
        torch.testing.assert_close(computed[f"chk/{key}"], value, rtol=1e-12, atol=0.0)
    cropped = checkerboard_ratio(pred[..., :8, :10], true[..., :8, :10])
    for key, value in whole.items():
        torch.testing.assert_close(value, cropped[key], rtol=1e-12, atol=0.0)
    unbatched = CheckerboardRatio()
    unbatched.update(pred[0], true[0])
    torch.testing.assert_close(unbatched.compute(), checkerboard_ratio(pred[:1], true[:1]))
    metric.reset()
    with pytest.warns(UserWarning, match="called before the ``update``"):
        assert all(math.isnan(value.item()) for value in metric.compute().values())  # nothing accumulated
    tiny = random_maps(3, 8, seed=5, batch=(1,))
    metric.update(tiny, tiny)  # fewer than 4 rows: skipped
    assert all(math.isnan(value.item()) for value in metric.compute().values())
    with pytest.raises(ValueError, match="even size >= 4"):
        checkerboard_ratio(tiny, tiny)
    with pytest.raises(ValueError, match="same shape"):
        checkerboard_ratio(tiny, tiny[..., :2])


# ---------------------------------------------------------------- accumulation


def test_two_updates_equal_one_concatenated_batch() -> None:
    pred, true = random_maps(8, 8, seed=1, batch=(5,)), random_maps(8, 8, seed=2, batch=(5,))
    # Uneven split: a mean of per-batch means would weight the single sample like the four others.
    split, whole = SVBRDFMetrics(downscale_to=4, rerender_configs=2), SVBRDFMetrics(4, rerender_configs=2)
    photo = torch.rand(5, 3, 8, 8, generator=torch.Generator().manual_seed(3))
    split.update(pred[:1], true[:1], photo=photo[:1])
    split.update(pred[1:], true[1:], photo=photo[1:])
    whole.update(pred, true, photo=photo)
    a, b = split.compute(), whole.compute()
    assert a.keys() == b.keys()
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=1e-6, atol=0.0)
    mean_of_means = MapRMSE()
    mean_of_means.update(pred[:1], true[:1])
    first = mean_of_means.compute()["roughness"]
    assert not torch.isclose(first, b["rmse/roughness"])


def test_reset() -> None:
    metric = SVBRDFMetrics(downscale_to=4, rerender_configs=2)
    metric.update(random_maps(8, 8, seed=1, batch=(2,)), random_maps(8, 8, seed=2, batch=(2,)))
    before = metric.compute()
    metric.reset()
    same = random_maps(8, 8, seed=3, batch=(2,))
    metric.update(same, same, photo=torch.full((2, 3, 8, 8), 0.5))
    after = metric.compute()
    assert before["rmse/roughness"] > 0
    assert after.pop("basecolor_saturation_ratio").item() == pytest.approx(1.0, abs=1e-6)
    assert after.pop("normal_angle_deg/observable_flat").item() > 0  # a flat map misses the random relief
    for key in ("normal_slope_cosine", "normal_slope_ratio"):
        assert after.pop(key).item() == pytest.approx(1.0), key  # the same relief, as steep
    for key in CHECKERBOARD_KEYS:
        assert after.pop(key).item() == 1.0, key  # identical maps: the same period-2 power
    for key, value in after.items():
        assert value.item() == pytest.approx(0.0, abs=1e-5), key


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dtypes(dtype: torch.dtype) -> None:
    pred = random_maps(8, 8, seed=1, batch=(2,), dtype=dtype)
    true = random_maps(8, 8, seed=2, batch=(2,), dtype=dtype)
    photo = photos(2, dtype=dtype)
    metric = SVBRDFMetrics(downscale_to=4, rerender_configs=2)
    metric.update(pred, true, photo=photo)
    out = metric.compute()
    reference = SVBRDFMetrics(downscale_to=4, rerender_configs=2)
    reference.update(pred.double(), true.double(), photo=photo.double())
    for key, value in reference.compute().items():
        assert torch.isfinite(out[key]) and out[key] > 0, key
        torch.testing.assert_close(out[key], value, rtol=1e-4, atol=1e-6)


def test_bad_input() -> None:
    metric = MapRMSE()
    with pytest.raises(ValueError, match="same shape"):
        metric.update(torch.zeros(1, 8, 4, 4), torch.zeros(1, 8, 4, 5))
    with pytest.raises(InvalidMapsError):
        metric.update(torch.zeros(1, 7, 4, 4), torch.zeros(1, 7, 4, 4))
    with pytest.raises(ValueError, match="positive"):
        MapRMSE(downscale_to=0)
    with pytest.raises(ValueError, match="configuration"):
        RerenderError(configs=0)


def test_unbatched_input() -> None:
    pred, true = random_maps(4, 4, seed=1), random_maps(4, 4, seed=2)
    single, batched = MapRMSE(), MapRMSE()
    single.update(pred, true)
    batched.update(pred[None], true[None])
    assert single.compute() == batched.compute()


# ---------------------------------------------------------------- downscaling


def checkerboard(size: int) -> Tensor:
    """1 on even (i + j), 0 on odd: every 2×2 block averages to 0.5."""
    index = torch.arange(size)
    return ((index[:, None] + index[None, :]) % 2 == 0).double()


def test_downscale_is_area_average() -> None:
    size, tilt = 8, 0.4
    board = checkerboard(size)
    pred = flat_maps(size, size, batch=(1,), dtype=torch.float64)
    pred[:, 0:3] = board  # base colour black/white
    pred[:, 6] = board  # roughness 0/1
    # normals tilted ±x: their block mean points straight up once renormalised
    sign = 2.0 * board - 1.0
    pred[:, 3] = sign * math.sin(tilt)
    pred[:, 5] = math.cos(tilt)
    true = flat_maps(size, size, basecolor=(0.5, 0.5, 0.5), roughness=0.5, batch=(1,), dtype=torch.float64)

    full, half = MapRMSE(), MapRMSE(downscale_to=size // 2)
    full.update(pred, true)
    half.update(pred, true)
    full_out, half_out = full.compute(), half.compute()
    assert full_out["roughness"].item() == pytest.approx(0.5)
    assert full_out["basecolor"].item() == pytest.approx(0.5)
    assert full_out["normal"].item() > 0.1
    for name in ("roughness", "basecolor", "normal", "metallic"):
        assert half_out[name].item() == pytest.approx(0.0, abs=1e-12), name
    # Derived albedos are downscaled in their compared (linear) space: the mean of linear 0 and 1
    # is 0.5, not the linear value of sRGB 0.5, so the diffuse error is 0.5 - 0.214.
    assert half_out["diffuse"].item() == pytest.approx(0.5 - SRGB_HALF_LINEAR, rel=1e-9)


def test_downscale_skips_small_inputs() -> None:
    pred, true = random_maps(8, 8, seed=1, batch=(1,)), random_maps(8, 8, seed=2, batch=(1,))
    metric = MapRMSE(downscale_to=8)
    metric.update(pred, true)
    assert metric.compute() == {}
    collection = SVBRDFMetrics(downscale_to=8, rerender_configs=2)
    collection.update(pred, true)
    keys = set(collection.compute())
    assert keys == {f"rmse/{name}" for name in RMSE_MAPS} | set(SCALAR_KEYS)
    collection = SVBRDFMetrics(downscale_to=4, rerender_configs=2, prefix="val/")
    collection.update(pred, true)
    keys = set(collection.compute())
    assert {f"val/rmse4/{name}" for name in RMSE_MAPS} <= keys
    assert "val/rerender_rmse" in keys and len(keys) == 2 * len(RMSE_MAPS) + len(SCALAR_KEYS)


def test_downscale_non_square_keeps_aspect() -> None:
    pred, true = random_maps(8, 16, seed=1, batch=(1,)), random_maps(8, 16, seed=2, batch=(1,))
    metric = MapRMSE(downscale_to=4)
    metric.update(pred, true)
    assert int(metric.pixels) == 4 * 8


# ---------------------------------------------------------------- re-rendering error


def test_rerender_error_zero_for_identical_positive_otherwise() -> None:
    a, b = random_maps(8, 8, seed=1, batch=(2,)), random_maps(8, 8, seed=2, batch=(2,))
    metric = RerenderError(configs=4)
    metric.update(a, a)
    assert metric.compute().item() == 0.0
    metric.reset()
    metric.update(a, b)
    assert metric.compute().item() > 0.01
    assert int(metric.values) == 2 * 4 * 3 * 8 * 8


def test_rerender_error_reproducible_and_batch_independent() -> None:
    pred, true = random_maps(8, 8, seed=3, batch=(4,)), random_maps(8, 8, seed=4, batch=(4,))
    split, whole = RerenderError(configs=4, seed=7), RerenderError(configs=4, seed=7)
    split.update(pred[:1], true[:1])
    split.update(pred[1:], true[1:])
    whole.update(pred, true)
    torch.testing.assert_close(split.compute(), whole.compute(), rtol=1e-6, atol=0.0)
    other_seed = RerenderError(configs=4, seed=8)
    other_seed.update(pred, true)
    assert not torch.isclose(other_seed.compute(), whole.compute())


def test_fixed_configs_depend_on_seed_and_count_only() -> None:
    torch.manual_seed(123)  # the global generator must not matter
    a = fixed_render_configs(6, seed=5)
    torch.manual_seed(456)
    b = fixed_render_configs(6, seed=5)
    assert torch.equal(a.camera_position, b.camera_position)
    assert torch.equal(a.lights.color, b.lights.color)
    assert a.camera_position.shape == (1, 6, 3)
    # half random, half highlight configurations, all above the sample
    assert (a.camera_position[..., 2] > 0).all() and (a.lights.position[..., 2] > 0).all()


# ---------------------------------------------------------------- distributed reduction


def _states(metric: MapRMSE) -> Iterator[Tensor]:
    return iter([getattr(metric, name) for name in metric._reductions])


def test_merge_state_equals_single_process() -> None:
    pred, true = random_maps(8, 8, seed=5, batch=(3,)), random_maps(8, 8, seed=6, batch=(3,))
    photo = photos(3)
    single = SVBRDFMetrics(downscale_to=4, rerender_configs=2)
    single.update(pred, true, photo=photo)
    expected = single.compute()

    ranks = [SVBRDFMetrics(downscale_to=4, rerender_configs=2) for _ in range(2)]
    ranks[0].update(pred[:2], true[:2], photo=photo[:2])
    ranks[1].update(pred[2:], true[2:], photo=photo[2:])
    for name, metric in ranks[0].items(keep_base=True):
        metric.merge_state(ranks[1][name])
    merged = ranks[0].compute()
    for key, value in expected.items():
        torch.testing.assert_close(merged[key], value, rtol=1e-6, atol=0.0)


def test_simulated_all_gather_sync_equals_single_process() -> None:
    # The path DDP takes: every state is all-gathered, then reduced with its dist_reduce_fx.
    pred, true = random_maps(8, 8, seed=7, batch=(4,)), random_maps(8, 8, seed=8, batch=(4,))
    single = MapRMSE()
    single.update(pred, true)
    rank0, rank1 = MapRMSE(), MapRMSE()
    rank0.update(pred[:1], true[:1])
    rank1.update(pred[1:], true[1:])
    peer_states = _states(rank1)

    def fake_all_gather(tensor: Tensor, group: object = None) -> list[Tensor]:
        return [tensor, next(peer_states)]

    rank0.sync(dist_sync_fn=fake_all_gather, distributed_available=lambda: True)
    synced = MapRMSE.compute(rank0)  # the unwrapped compute: the wrapper would try to sync again
    for key, value in single.compute().items():
        torch.testing.assert_close(synced[key], value, rtol=1e-6, atol=0.0)
    rank0.unsync()
    assert int(rank0.pixels) == 8 * 8


def test_collection_forwards_sync_options() -> None:
    # Rank 0 evaluating alone after DDP training must not all-gather: sync_on_compute=False.
    metrics = SVBRDFMetrics(downscale_to=4, rerender_configs=2, sync_on_compute=False)
    assert all(not metric.sync_on_compute for metric in metrics.values())
    assert all(metric.sync_on_compute for metric in SVBRDFMetrics(rerender_configs=2).values())


def test_compared_maps_layout() -> None:
    maps = random_maps(4, 4, seed=9, batch=(2,), dtype=torch.float64)
    images = compared_maps(maps)
    assert {name: image.shape[1] for name, image in images.items()} == RMSE_MAPS
    parts = split_maps(maps)
    assert torch.equal(images["basecolor"], parts.basecolor)
    rebuilt = join_maps(parts.basecolor, images["normal"], images["roughness"], images["metallic"])
    torch.testing.assert_close(rebuilt, maps)


def _ddp_worker(rank: int, world: int, port: int, out_dir: str) -> None:
    import torch.distributed as dist

    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    try:
        pred, true = random_maps(8, 8, seed=11, batch=(3,)), random_maps(8, 8, seed=12, batch=(3,))
        shard = slice(0, 1) if rank == 0 else slice(1, 3)  # uneven shards, as a last batch can be
        photo = photos(3)
        metrics = SVBRDFMetrics(downscale_to=4, rerender_configs=2)
        metrics.update(pred[shard], true[shard], photo=photo[shard])
        synced = metrics.compute()
        # rank 0 alone, as after training: without sync_on_compute=False this would wait forever
        if rank == 0:
            alone = SVBRDFMetrics(downscale_to=4, rerender_configs=2, sync_on_compute=False)
            alone.update(pred, true, photo=photo)
            torch.save({"synced": synced, "alone": alone.compute()}, f"{out_dir}/rank0.pt")
        dist.barrier()
    finally:
        dist.destroy_process_group()


@pytest.mark.integration
def test_real_gloo_all_gather_equals_single_process(tmp_path) -> None:
    import socket

    import torch.multiprocessing as mp

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    # spawn, not fork: a forked child can deadlock in the thread pools torch already started here
    mp.spawn(_ddp_worker, args=(2, port, str(tmp_path)), nprocs=2, join=True)
    result = torch.load(tmp_path / "rank0.pt")
    pred, true = random_maps(8, 8, seed=11, batch=(3,)), random_maps(8, 8, seed=12, batch=(3,))
    single = SVBRDFMetrics(downscale_to=4, rerender_configs=2)
    single.update(pred, true, photo=photos(3))
    for key, value in single.compute().items():
        torch.testing.assert_close(result["synced"][key], value, rtol=1e-6, atol=0.0)
        torch.testing.assert_close(result["alone"][key], value, rtol=1e-6, atol=0.0)
