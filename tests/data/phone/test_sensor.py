"""The simulated phone capture (brdfgan.data.phone.sensor) and its use in the DataModule."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image

from brdfgan.core.exposure import auto_expose
from brdfgan.core.sampling import log_uniform
from brdfgan.core.svbrdf import linear_to_srgb, srgb_to_linear
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.phone.sensor import (
    SensorEffects,
    auto_white_balance_gains,
    decode_srgb8,
    encode_srgb8,
    flash_illuminant,
    jpeg_roundtrip,
    local_contrast,
    quantise_linear16,
    quantise_srgb8,
    saturation_boost,
    sensor_noise,
    sharpening,
    tone_curve,
    vignetting,
    vignetting_falloff,
    white_balance,
)
from brdfgan.data.storage.shards import Sample, shard_path, write_shard
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.errors import UserError
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.intake.preprocess import Crop, preprocess
from tests.conftest import random_maps

# Every random effect off: only the file steps (sRGB, 8 bits, decoding) and the exposure remain.
NOTHING_RANDOM = SensorEffects(
    vignetting_probability=0.0, white_balance_probability=0.0, noise_probability=0.0, jpeg_probability=0.0
)
# The phone's look, every effect always applied.
PHONE_LOOK: dict[str, Any] = {
    "local_contrast_probability": 1.0,
    "tone_curve_probability": 1.0,
    "saturation_probability": 1.0,
    "sharpening_probability": 1.0,
}
# The record's keys before the phone processing existed, and the ones it added.
TODAYS_KEYS = ("vignetting", "white_balance", "shot_noise", "read_noise", "jpeg_quality", "exposure_scale")
PHONE_KEYS = {
    "raw",
    "illuminant",
    "auto_white_balance",
    "local_contrast",
    "tone_curve",
    "saturation",
    "sharpening",
}


def flash_photo(size: int = 64, seed: int = 0) -> torch.Tensor:
    """A linear LDR photo like the training renders: smooth coloured texture with some fine
    grain, flash falloff, a hotspot that clips, auto-exposed."""
    g = torch.Generator().manual_seed(seed)
    axis = torch.linspace(-1.0, 1.0, size)
    ys, xs = torch.meshgrid(axis, axis, indexing="ij")
    coarse = torch.rand(1, 3, max(2, size // 8), max(2, size // 8), generator=g)
    texture = 0.4 + 0.5 * F.interpolate(coarse, size=(size, size), mode="bilinear", align_corners=False)[0]
    texture = texture + 0.1 * torch.rand(3, size, size, generator=g)
    falloff = (1.0 + xs**2 + ys**2) ** -2
    hdr = texture * falloff * torch.tensor([0.6, 0.5, 0.35]).view(3, 1, 1)
    hdr = hdr + 2.0 * torch.exp(-(xs**2 + ys**2) / 0.01)
    return auto_expose(hdr)[0]


def gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


# ------------------------------------------------------------------------------------ SensorEffects


def test_same_seed_same_result_other_seed_other_result() -> None:
    photo, sensor = flash_photo(), SensorEffects()
    out, record = sensor.apply(photo, gen(3))
    again, record_again = sensor.apply(photo, gen(3))
    other, record_other = sensor.apply(photo, gen(4))
    assert torch.equal(out, again) and record == record_again
    assert not torch.equal(out, other) and record != record_other
    assert out.dtype == torch.float32 and out.shape == photo.shape
    assert float(out.min()) >= 0.0 and float(out.max()) <= 1.0
    assert set(record) == {*TODAYS_KEYS, *PHONE_KEYS}
    assert all(record[key] is not None for key in TODAYS_KEYS)  # every probability is 1
    # The phone processing is off by default; no illuminant was given.
    assert record["raw"] is False and all(record[key] is None for key in PHONE_KEYS - {"raw"})


def test_switched_off_leaves_the_photo_untouched() -> None:
    photo = flash_photo()
    out, record = SensorEffects(enabled=False).apply(photo, gen(0))
    assert torch.equal(out, photo) and record == {}
    # An effect at probability 0 is not drawn, and switching it off leaves the others' draws alone.
    _, everything = SensorEffects().apply(photo, gen(5))
    _, without_jpeg = SensorEffects(jpeg_probability=0.0).apply(photo, gen(5))
    assert without_jpeg["jpeg_quality"] is None
    assert without_jpeg["white_balance"] == everything["white_balance"]
    assert without_jpeg["shot_noise"] == everything["shot_noise"]


def test_8bit_values_survive_the_round_trip() -> None:
    every_code = torch.arange(256, dtype=torch.uint8).view(1, 16, 16).expand(3, 16, 16)
    assert torch.equal(encode_srgb8(decode_srgb8(every_code)), every_code)
    codes = torch.randint(0, 256, (3, 40, 48), generator=gen(1), dtype=torch.uint8)
    photo = decode_srgb8(codes)
    out, record = dataclasses.replace(NOTHING_RANDOM, auto_exposure=False).apply(photo, gen(0))
    assert torch.equal(out, photo)
    assert record["raw"] is False and all(value is None for key, value in record.items() if key != "raw")


def test_vignetting_darkens_the_corners_not_the_centre() -> None:
    strength = 0.25
    falloff = vignetting_falloff(64, 64, strength)[0]
    # Cross-check against the cos⁴ law itself: corners at r = 1 see tan θ = k.
    k = math.sqrt((1.0 - strength) ** -0.5 - 1.0)
    corner_r = 31.5 / 32.0  # pixel centre of a corner over the half-diagonal
    assert float(falloff[0, 0]) == pytest.approx(math.cos(math.atan(k * corner_r)) ** 4, rel=1e-6)
    assert float(falloff[31, 31]) > 0.9995  # the four centre pixels
    assert float(falloff[0, 0]) == pytest.approx(1.0 - strength, abs=0.01)
    diagonal = torch.diagonal(falloff)[:32]
    assert bool((diagonal[1:] > diagonal[:-1]).all())  # brighter towards the centre
    assert torch.equal(falloff, falloff.flip(0)) and torch.equal(falloff, falloff.flip(1))
    assert torch.equal(vignetting_falloff(8, 8, 0.0), torch.ones(1, 8, 8))
    flat = torch.full((3, 64, 64), 0.5)
    assert torch.allclose(vignetting(flat, strength), 0.5 * falloff.expand(3, -1, -1))


def test_white_balance_changes_the_channel_ratios_by_the_drawn_gains() -> None:
    photo = flash_photo(seed=1)
    gains = (1.08, 1.0, 0.93)
    balanced = white_balance(photo, gains)
    for channel, gain in enumerate(gains):
        assert torch.allclose(balanced[channel], photo[channel] * gain, rtol=1e-6)
    sensor = dataclasses.replace(NOTHING_RANDOM, white_balance_probability=1.0, auto_exposure=False)
    unclipped = photo.clamp(max=0.8)  # gains above 1 must not clip for the ratio to show
    drawn = set()
    for seed in range(6):
        out, record = sensor.apply(unclipped, gen(seed))
        red, green, blue = record["white_balance"]
        assert green == 1.0 and 1 / 1.1 <= red <= 1.1 and 1 / 1.1 <= blue <= 1.1
        ratio = out.sum(dim=(1, 2)) / unclipped.sum(dim=(1, 2))
        # 8-bit sRGB quantisation changes a mean by far less than 0.1 %.
        assert ratio.tolist() == pytest.approx([red, green, blue], rel=1e-3)
        drawn.add((red, blue))
    assert len(drawn) == 6


@pytest.mark.parametrize("level", [0.02, 0.3, 0.8])
def test_noise_variance_is_shot_times_signal_plus_read(level: float) -> None:
    shot, read = 4e-3, 1e-4
    flat = torch.full((3, 256, 256), level, dtype=torch.float64)
    noisy = sensor_noise(flat, shot, read, gen(7))
    expected = shot * level + read
    # 196 608 values: the variance estimate's relative standard error is sqrt(2 / n) = 0.32 %.
    assert float(noisy.var()) == pytest.approx(expected, rel=0.016)
    assert float(noisy.mean()) == pytest.approx(level, abs=5 * math.sqrt(expected / flat.numel()))


def test_jpeg_at_low_quality_differs_more_than_at_high_quality() -> None:
    codes = encode_srgb8(flash_photo(seed=2))
    errors = [
        float((jpeg_roundtrip(codes, q).float() - codes.float()).abs().mean()) for q in (20, 50, 80, 95)
    ]
    assert errors == sorted(errors, reverse=True) and errors[-1] > 0
    assert errors[0] > 2 * errors[-1]
    sensor = dataclasses.replace(
        NOTHING_RANDOM, jpeg_probability=1.0, jpeg_quality_min=75, jpeg_quality_max=76
    )
    qualities = {sensor.apply(flash_photo(), gen(seed))[1]["jpeg_quality"] for seed in range(12)}
    assert qualities == {75, 76}  # both ends of the range are drawn, nothing outside it


def test_output_is_what_predict_makes_of_the_same_jpeg(tmp_path: Path) -> None:
    """The simulated file, written as a real JPEG and run through read_photo and preprocess
    (predict's intake), gives the training photo bit for bit."""
    photo = flash_photo(size=64, seed=3)
    sensor = SensorEffects(noise_probability=0.0)  # so the test can rebuild the 8-bit file
    out, record = sensor.apply(photo, gen(11))
    codes = encode_srgb8(white_balance(vignetting(photo, record["vignetting"]), record["white_balance"]))
    path = tmp_path / "phone.jpg"
    Image.fromarray(codes.permute(1, 2, 0).numpy()).save(path, quality=record["jpeg_quality"])
    read = read_photo(path)
    assert read.source == "jpeg" and read.colorspace == "srgb"
    prepared = preprocess(read, 64, Crop(0, 0, 64))
    assert torch.equal(prepared.photo, out)
    assert prepared.exposure_scale == record["exposure_scale"]
    # And the decoding is the sRGB curve, not a stand-in for it.
    without_exposure = dataclasses.replace(sensor, auto_exposure=False).apply(photo, gen(11))[0]
    with Image.open(path) as image:
        stored = torch.from_numpy(np.array(image)).permute(2, 0, 1)
    assert torch.allclose(without_exposure, srgb_to_linear(stored.double() / 255).float(), atol=1e-7)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("vignetting_max", 1.0, "data.sensor.vignetting_max=1: must be in [0, 1)"),
        ("jpeg_quality_min", 0, "data.sensor.jpeg_quality_min=0: must be an integer >= 1"),
        ("jpeg_quality_max", 101, "data.sensor.jpeg_quality_max=101: must be in [1, 100]"),
        ("jpeg_quality_max", 80.5, "data.sensor.jpeg_quality_max=80.5: must be an integer"),
        ("shot_noise_min", 0.0, "data.sensor.shot_noise_min=0: must be in (0, 1]"),
        ("read_noise_min", 1e-3, "data.sensor.read_noise_min=0.001 > data.sensor.read_noise_max"),
        ("noise_probability", 1.5, "data.sensor.noise_probability=1.5: must be in [0, 1]"),
        ("white_balance_max_error", -0.1, "data.sensor.white_balance_max_error=-0.1: must be in [0, 1]"),
        ("enabled", "yes", "data.sensor.enabled='yes': must be true or false"),
        ("auto_white_balance", 1, "data.sensor.auto_white_balance=1: must be true or false"),
        ("raw_probability", -0.5, "data.sensor.raw_probability=-0.5: must be in [0, 1]"),
        ("tone_curve_probability", 2, "data.sensor.tone_curve_probability=2: must be in [0, 1]"),
        ("tone_curve_max", 1.5, "data.sensor.tone_curve_max=1.5: must be in [0, 1]"),
        ("tone_curve_min", 0.7, "data.sensor.tone_curve_min=0.7 > data.sensor.tone_curve_max"),
        ("saturation_min", -1.0, "data.sensor.saturation_min=-1: must be in [0, 3]"),
        ("saturation_max", 0.9, "data.sensor.saturation_min=1 > data.sensor.saturation_max"),
        ("sharpening_max", 10.0, "data.sensor.sharpening_max=10: must be in [0, 5]"),
        ("sharpening_radius", 0.0, "data.sensor.sharpening_radius=0: must be in (0, 10]"),
        ("local_contrast_max", "a lot", "data.sensor.local_contrast_max='a lot': must be a number"),
        (
            "local_contrast_radius_max",
            0.75,
            "data.sensor.local_contrast_radius_max=0.75: must be in (0, 0.5]",
        ),
        ("local_contrast_radius_min", 0.2, "data.sensor.local_contrast_radius_min=0.2 > data.sensor"),
    ],
)
def test_bad_values_are_one_line_errors_naming_the_key(key: str, value: Any, message: str) -> None:
    with pytest.raises(DatasetConfigError) as error:
        SensorEffects(**{key: value})
    assert isinstance(error.value, UserError)
    assert str(error.value).startswith(message) and "\n" not in str(error.value)


# ---------------------------------------------------------------------- phone processing (issue 31)


def todays_apply(sensor: SensorEffects, photo: torch.Tensor, generator: torch.Generator) -> tuple:
    """``SensorEffects.apply`` as it was before the phone processing and the auto white balance,
    copied with its own sRGB encoding and noise formula: the golden reference that the new
    effects, switched off, change nothing."""
    u = torch.rand(10, generator=generator, dtype=torch.float64).tolist()
    record: dict[str, Any] = dict.fromkeys(TODAYS_KEYS)
    linear = photo.to(torch.float32)
    if u[0] < sensor.vignetting_probability:
        strength = sensor.vignetting_min + u[1] * (sensor.vignetting_max - sensor.vignetting_min)
        linear = linear * vignetting_falloff(linear.shape[-2], linear.shape[-1], strength)
        record["vignetting"] = strength
    if u[2] < sensor.white_balance_probability:
        limit = 1.0 + sensor.white_balance_max_error
        gains = (log_uniform(u[3], 1.0 / limit, limit), 1.0, log_uniform(u[4], 1.0 / limit, limit))
        linear = linear * torch.tensor(gains, dtype=linear.dtype).view(3, 1, 1)
        record["white_balance"] = list(gains)
    if u[5] < sensor.noise_probability:
        shot = log_uniform(u[6], sensor.shot_noise_min, sensor.shot_noise_max)
        read = log_uniform(u[7], sensor.read_noise_min, sensor.read_noise_max)
        variance = linear.clamp(min=0.0) * shot + read
        linear = linear + variance.sqrt() * torch.randn(linear.shape, generator=generator, dtype=linear.dtype)
        record["shot_noise"], record["read_noise"] = shot, read
    codes = (linear_to_srgb(linear.clamp(0.0, 1.0).to(torch.float32)) * 255).round().to(torch.uint8)
    if u[8] < sensor.jpeg_probability:
        span = sensor.jpeg_quality_max - sensor.jpeg_quality_min + 1
        quality = sensor.jpeg_quality_min + min(int(u[9] * span), span - 1)
        codes = jpeg_roundtrip(codes, quality)
        record["jpeg_quality"] = quality
    linear = decode_srgb8(codes)
    if sensor.auto_exposure:
        linear, scale = auto_expose(linear.clamp(min=0.0))
        record["exposure_scale"] = float(scale)
    return linear, record


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"vignetting_probability": 0.5, "noise_probability": 0.5, "jpeg_probability": 0.5},
        {"auto_exposure": False, "jpeg_quality_min": 40},
        # The new effects' ranges alone change nothing while their probabilities are 0.
        {"tone_curve_max": 1.0, "saturation_min": 1.2, "sharpening_radius": 2.0, "local_contrast_max": 1.0},
    ],
)
def test_new_effects_off_give_todays_output_bit_for_bit(options: dict[str, Any]) -> None:
    sensor = SensorEffects(**options)
    for seed in range(8):
        photo = flash_photo(size=32 + 16 * (seed % 2), seed=seed)
        expected, todays = todays_apply(sensor, photo, gen(seed))
        # A flash colour given changes nothing either while the auto white balance is off.
        for illuminant in (None, blackbody_rgb(4000.0)):
            out, record = sensor.apply(photo, gen(seed), illuminant_rgb=illuminant)
            assert torch.equal(out, expected)
            assert {key: record[key] for key in TODAYS_KEYS} == todays
            assert record["raw"] is False and record["auto_white_balance"] is None
            assert record["illuminant"] == (None if illuminant is None else list(illuminant))


def test_tone_curve_is_a_monotonic_s_curve_with_fixed_ends() -> None:
    x = torch.linspace(0.0, 1.0, 1001).view(1, 1, -1).expand(3, 1, -1)
    assert torch.equal(tone_curve(x, 0.0), x)
    for strength in (0.3, 0.6, 1.0):
        y = tone_curve(x, strength)
        assert bool((y[..., 1:] >= y[..., :-1]).all())  # monotonic
        assert float(y[..., 0].max()) == 0.0 and float(y[..., -1].min()) == pytest.approx(1.0, abs=1e-7)
        assert float(y[..., 500].max()) == pytest.approx(0.5, abs=1e-7)
        # S-shaped: darker below the middle, brighter above it, steeper in it.
        assert bool((y[..., 1:500] < x[..., 1:500]).all()) and bool((y[..., 501:-1] > x[..., 501:-1]).all())
        slope = float((y[0, 0, 501] - y[0, 0, 499]) / (x[0, 0, 501] - x[0, 0, 499]))
        assert slope == pytest.approx(1.0 + strength / 2.0, rel=1e-3)
    assert torch.equal(tone_curve(torch.tensor([-0.5, 1.5]), 0.5), torch.tensor([0.0, 1.0]))  # clipped first
    with pytest.raises(ValueError, match="strength"):
        tone_curve(x, 1.5)


def test_saturation_boost_keeps_greys_and_luma_and_scales_chroma() -> None:
    grey = torch.rand(1, 16, 16, generator=gen(0)).expand(3, -1, -1)
    assert torch.allclose(saturation_boost(grey, 1.3), grey, atol=1e-6)
    colour = linear_to_srgb(flash_photo(size=32, seed=4))
    weights = torch.tensor([0.2126, 0.7152, 0.0722]).view(3, 1, 1)
    luma = (colour * weights).sum(0, keepdim=True)
    boosted = saturation_boost(colour, 1.25)
    assert torch.allclose((boosted * weights).sum(0, keepdim=True), luma, atol=1e-6)
    assert torch.allclose(boosted - luma, 1.25 * (colour - luma), atol=1e-6)
    assert torch.allclose(saturation_boost(colour, 1.0), colour, atol=1e-6)


@pytest.mark.parametrize(("effect", "sigma"), [(sharpening, 1.0), (local_contrast, 6.0)])
def test_unsharp_masks_leave_flat_images_and_raise_edge_contrast(effect: Any, sigma: float) -> None:
    flat = torch.full((3, 48, 48), 0.4)
    assert torch.allclose(effect(flat, 0.8, sigma), flat, atol=1e-6)
    edge = torch.full((3, 48, 48), 0.3)
    edge[:, :, 24:] = 0.6
    out = effect(edge, 0.8, sigma)
    # Overshoot on both sides of the edge, the same in every channel (the luma is sharpened).
    assert float(out[:, :, 23].max()) < 0.3 - 0.01 and float(out[:, :, 24].min()) > 0.6 + 0.01
    assert torch.allclose(out[0], out[1]) and torch.allclose(out[1], out[2])
    assert float(out[0, 10, 24] - out[0, 10, 23]) > 0.3  # a steeper step
    assert float(out.mean()) == pytest.approx(float(edge.mean()), abs=1e-3)  # the mean stays
    photo = linear_to_srgb(flash_photo(size=48, seed=5))
    assert float(effect(photo, 0.8, sigma).mean()) == pytest.approx(float(photo.mean()), abs=5e-3)
    assert torch.equal(effect(photo, 0.0, sigma), photo)


def test_raw_capture_skips_the_phone_look_and_the_jpeg() -> None:
    photo = flash_photo(size=32, seed=6)
    look = dataclasses.replace(NOTHING_RANDOM, jpeg_probability=1.0, auto_exposure=False, **PHONE_LOOK)
    out, record = dataclasses.replace(look, raw_probability=1.0).apply(photo, gen(0))
    assert record["raw"] is True and record["jpeg_quality"] is None
    assert all(record[key] is None for key in ("local_contrast", "tone_curve", "saturation", "sharpening"))
    assert torch.equal(out, quantise_linear16(photo))  # linear, 16 bits: as read_photo gets a DNG
    assert float((out - photo).abs().max()) <= 0.5 / 65535 + 1e-7
    processed, processed_record = look.apply(photo, gen(0))
    assert processed_record["raw"] is False and processed_record["jpeg_quality"] is not None
    assert all(processed_record[key] is not None for key in ("tone_curve", "saturation", "sharpening"))
    assert float((processed - photo).abs().mean()) > 0.01
    # Noise and white balance still apply to a RAW capture, and are recorded.
    _, noisy = SensorEffects(raw_probability=1.0).apply(photo, gen(0))
    assert noisy["raw"] is True and noisy["shot_noise"] is not None and noisy["white_balance"] is not None
    raws = [SensorEffects(raw_probability=0.5).apply(photo, gen(seed))[1]["raw"] for seed in range(40)]
    assert 5 < sum(raws) < 35


def test_phone_file_is_what_predict_makes_of_the_same_jpeg(tmp_path: Path) -> None:
    """With the look on, the simulated file, written as a real JPEG and read by predict's intake,
    still gives the training photo bit for bit: training sees what predict sees."""
    photo = flash_photo(size=64, seed=3)
    sensor = SensorEffects(noise_probability=0.0, auto_white_balance=True, **PHONE_LOOK)
    illuminant = blackbody_rgb(4500.0)
    out, record = sensor.apply(photo, gen(11), illuminant_rgb=illuminant)
    linear = white_balance(vignetting(photo, record["vignetting"]), record["auto_white_balance"])
    display = local_contrast(
        linear_to_srgb(white_balance(linear, record["white_balance"]).clamp(0, 1)), *record["local_contrast"]
    )
    display = saturation_boost(tone_curve(display, record["tone_curve"]), record["saturation"])
    codes = quantise_srgb8(sharpening(display, record["sharpening"], sensor.sharpening_radius))
    path = tmp_path / "phone.jpg"
    Image.fromarray(codes.permute(1, 2, 0).numpy()).save(path, quality=record["jpeg_quality"])
    prepared = preprocess(read_photo(path), 64, Crop(0, 0, 64))
    assert torch.equal(prepared.photo, out)


def test_auto_white_balance_neutralises_the_flash_colour() -> None:
    illuminant = blackbody_rgb(4000.0)
    white = torch.full((3, 32, 32), 0.5) * torch.tensor(illuminant).view(3, 1, 1) / max(illuminant)
    only_balance = dataclasses.replace(NOTHING_RANDOM, auto_exposure=False, white_balance_probability=1.0)
    cast = only_balance.apply(white, gen(0))[0].mean(dim=(1, 2))
    assert float(cast[0] / cast[2]) > 2.5  # without AWB: orange
    awb = dataclasses.replace(only_balance, auto_white_balance=True)
    for seed in range(10):
        out, record = awb.apply(white, gen(seed), illuminant_rgb=illuminant)
        assert record["auto_white_balance"] == pytest.approx(
            [1.0, illuminant[0] / illuminant[1], illuminant[0] / illuminant[2]]
        )
        red, green, blue = out.mean(dim=(1, 2)).tolist()
        # Neutral up to the residual error (±10 % on red and blue) and 8-bit rounding.
        for ratio in (red / green, blue / green):
            assert 1 / 1.1 - 0.005 < ratio < 1.1 + 0.005
    # Without the residual error: neutral up to the 8-bit rounding.
    out = dataclasses.replace(awb, white_balance_probability=0.0).apply(
        white, gen(0), illuminant_rgb=illuminant
    )[0]
    assert float(out.max() - out.min()) < 0.004
    # A highlight clipped in every channel stays white (gains scaled so the smallest is 1).
    clipped = dataclasses.replace(awb, white_balance_probability=0.0).apply(
        torch.ones(3, 8, 8), gen(0), illuminant_rgb=illuminant
    )[0]
    assert torch.equal(clipped, torch.ones(3, 8, 8))


def test_a_share_of_photos_keeps_the_flash_cast() -> None:
    # auto_white_balance_probability: each photo is white-balanced or keeps the flash's cast whole,
    # in about that share, and the draw leaves every other effect's values as they were.
    illuminant = blackbody_rgb(4000.0)
    white = torch.full((3, 16, 16), 0.5) * torch.tensor(illuminant).view(3, 1, 1) / max(illuminant)
    always = dataclasses.replace(NOTHING_RANDOM, auto_exposure=False, auto_white_balance=True)
    share = dataclasses.replace(always, auto_white_balance_probability=0.7)
    kept = 0
    for seed in range(200):
        out, record = share.apply(white, gen(seed), illuminant_rgb=illuminant)
        reference, reference_record = always.apply(white, gen(seed), illuminant_rgb=illuminant)
        if record["auto_white_balance"] is None:
            kept += 1
            red, _, blue = out.mean(dim=(1, 2)).tolist()
            assert red / blue > 2.5  # orange, as without AWB
        else:
            assert torch.equal(out, reference) and record == reference_record
    assert 40 <= kept <= 80  # 30 % of 200, binomial σ ≈ 6.5
    with pytest.raises(DatasetConfigError, match="auto_white_balance_probability"):
        dataclasses.replace(always, auto_white_balance_probability=1.5)
    assert auto_white_balance_gains((2.0, 1.0, 0.5)) == (1.0, 2.0, 4.0)
    with pytest.raises(ValueError, match="illuminant"):
        auto_white_balance_gains((1.0, 0.0, 1.0))


def test_auto_white_balance_without_a_flash_colour_does_nothing() -> None:
    photo = flash_photo(size=32, seed=7)
    awb = SensorEffects(auto_white_balance=True)
    out, record = awb.apply(photo, gen(3))
    plain, plain_record = SensorEffects().apply(photo, gen(3))
    assert torch.equal(out, plain) and record == plain_record
    assert record["illuminant"] is None and record["auto_white_balance"] is None


def test_noise_through_white_balance_gains_is_the_raw_noise_amplified() -> None:
    shot, read, level = 4e-3, 1e-4, 0.3
    gains = (1.0, 1.5, 2.5)
    flat = torch.full((3, 256, 256), level, dtype=torch.float64)
    noisy = sensor_noise(flat, shot, read, gen(7), gains=gains)
    for channel, g in enumerate(gains):
        assert float(noisy[channel].var()) == pytest.approx(g * shot * level + g**2 * read, rel=0.03)
    assert torch.equal(
        sensor_noise(flat, shot, read, gen(7), gains=(1.0, 1.0, 1.0)), sensor_noise(flat, shot, read, gen(7))
    )


def test_phone_draws_are_deterministic_and_independent_of_the_other_effects() -> None:
    photo = flash_photo(size=32, seed=8)
    sensor = SensorEffects(auto_white_balance=True, raw_probability=0.3, **PHONE_LOOK)
    illuminant = blackbody_rgb(5200.0)
    out, record = sensor.apply(photo, gen(3), illuminant_rgb=illuminant)
    again, record_again = sensor.apply(photo, gen(3), illuminant_rgb=illuminant)
    assert torch.equal(out, again) and record == record_again
    others = [sensor.apply(photo, gen(seed), illuminant_rgb=illuminant)[1] for seed in range(4, 12)]
    assert len({r["tone_curve"] for r in others if not r["raw"]}) > 1
    # Switching the noise off (whose draws follow the uniforms) leaves the look's draws alone.
    quiet = dataclasses.replace(sensor, noise_probability=0.0).apply(
        photo, gen(3), illuminant_rgb=illuminant
    )[1]
    look = ("raw", "local_contrast", "tone_curve", "saturation", "sharpening")
    assert {key: quiet[key] for key in look} == {key: record[key] for key in look}
    # And the look's draws leave today's alone.
    plain = SensorEffects().apply(photo, gen(3))[1]
    assert {key: record[key] for key in ("vignetting", "white_balance", "shot_noise", "read_noise")} == {
        key: plain[key] for key in ("vignetting", "white_balance", "shot_noise", "read_noise")
    }


def test_flash_illuminant_reads_the_recorded_temperature() -> None:
    assert flash_illuminant({"flash": {"intensity_w_sr": 1.0, "temperature_k": 4321.0}}) == blackbody_rgb(
        4321.0
    )
    assert flash_illuminant({}) is None and flash_illuminant({"flash": {"intensity_w_sr": 1.0}}) is None
    assert SensorEffects.flash_illuminant({"flash": {"temperature_k": 5000}}) == blackbody_rgb(5000.0)


# ----------------------------------------------------------------------------------- DataModule

SIZE = 16


def write_dataset(root: Path) -> None:
    """Two train shards (4 samples each) and one val shard (3 samples) of 16² samples."""
    for split, shards in (("train", 2), ("val", 1)):
        for index in range(shards):
            samples = []
            for i in range(4 if split == "train" else 3):
                seed = 100 * index + i + (0 if split == "train" else 50)
                photo = flash_photo(SIZE, seed)
                maps = random_maps(SIZE, SIZE, seed=seed)
                samples.append(Sample(f"{split}-{index}-{i}", photo, maps, {"seed": seed}))
            write_shard(shard_path(root, split, index), samples)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("sensor_dataset")
    write_dataset(root)
    return root


def batches(dm: ShardDataModule, kind: str = "train") -> list[dict[str, Any]]:
    loader = dm.train_dataloader() if kind == "train" else dm.val_dataloader()
    out = list(loader)
    dm.teardown()
    return out


def module(root: Path, **options: Any) -> ShardDataModule:
    options = {"batch_size": 2, "shuffle_buffer": 0, "seed": 1, **options}
    dm = ShardDataModule(str(root), **options)
    dm.setup("fit")
    return dm


def photos_by_key(batch_list: list[dict[str, Any]]) -> dict[str, torch.Tensor]:
    return {key: photo for b in batch_list for key, photo in zip(b["key"], b["photo"], strict=True)}


def test_sensor_off_gives_the_stored_photos_bitwise(dataset: Path) -> None:
    plain = batches(module(dataset))
    disabled = batches(module(dataset, sensor=SensorEffects(enabled=False)))
    for a, b in zip(plain, disabled, strict=True):
        assert torch.equal(a["photo"], b["photo"]) and torch.equal(a["maps"], b["maps"])
        assert a["key"] == b["key"] and a["meta"] == b["meta"]
        assert all("sensor" not in meta for meta in b["meta"])


def test_sensor_changes_train_photos_and_records_the_draws(dataset: Path) -> None:
    plain, plain_val = module(dataset), module(dataset)
    sensed = module(dataset, sensor=SensorEffects())
    plain_batches = batches(plain)
    stored = photos_by_key(plain_batches)
    stored_maps = {key: maps for b in plain_batches for key, maps in zip(b["key"], b["maps"], strict=True)}
    for batch in batches(sensed):
        for key, photo, maps, meta in zip(
            batch["key"], batch["photo"], batch["maps"], batch["meta"], strict=True
        ):
            assert not torch.equal(photo, stored[key])
            assert torch.equal(maps, stored_maps[key])  # the maps are the ground truth: untouched
            assert meta["sensor"]["jpeg_quality"] in range(70, 96)
            assert 1 / 1.1 <= meta["sensor"]["white_balance"][0] <= 1.1
    # Validation is not touched by default (sensor_splits=["train"]).
    for a, b in zip(batches(plain_val, "val"), batches(sensed, "val"), strict=True):
        assert torch.equal(a["photo"], b["photo"]) and all("sensor" not in m for m in b["meta"])
    # When asked for, validation gets the same draws every epoch.
    val_sensed = module(dataset, sensor=SensorEffects(), sensor_splits=["train", "val"])
    loader = val_sensed.val_dataloader()
    first, second = list(loader), list(loader)  # two epochs of one loader
    stored_val = photos_by_key(batches(plain_val, "val"))
    assert all(not torch.equal(photo, stored_val[key]) for key, photo in photos_by_key(first).items())
    assert all(torch.equal(a["photo"], b["photo"]) for a, b in zip(first, second, strict=True))
    with pytest.raises(DatasetConfigError, match=r"data\.sensor_splits"):
        ShardDataModule(str(dataset), sensor_splits=["training"])


@pytest.mark.parametrize("num_workers", [0, 2])
def test_sensor_draws_follow_the_seed_the_epoch_and_the_key(dataset: Path, num_workers: int) -> None:
    def epochs(seed: int) -> list[list[dict[str, Any]]]:
        dm = module(dataset, sensor=SensorEffects(), seed=seed, num_workers=num_workers, shuffle_buffer=4)
        loader = dm.train_dataloader()
        out = [list(loader), list(loader)]
        dm.teardown()
        return out

    first, again, other = epochs(1), epochs(1), epochs(2)
    for a, b in zip(first[0] + first[1], again[0] + again[1], strict=True):
        assert torch.equal(a["photo"], b["photo"]) and a["meta"] == b["meta"]
    # The next epoch draws anew for the same sample; another seed draws other values.
    epoch0, epoch1 = photos_by_key(first[0]), photos_by_key(first[1])
    assert all(not torch.equal(epoch0[key], epoch1[key]) for key in epoch0.keys() & epoch1.keys())
    other0 = photos_by_key(other[0])
    assert all(not torch.equal(epoch0[key], other0[key]) for key in epoch0.keys() & other0.keys())


def test_resumed_stream_sees_the_same_sensor_draws(dataset: Path) -> None:
    whole = batches(module(dataset, sensor=SensorEffects(), shuffle_buffer=4))
    resumed = module(dataset, sensor=SensorEffects(), shuffle_buffer=4)
    loader = resumed.train_dataloader()
    loader.dataset.skip_batches = 2  # type: ignore[attr-defined]  # what _train_position sets on resume
    tail = list(loader)
    resumed.teardown()
    assert len(tail) == len(whole) - 2
    for a, b in zip(whole[2:], tail, strict=True):
        assert torch.equal(a["photo"], b["photo"]) and a["meta"] == b["meta"]


def test_sensor_sees_the_whole_sample_and_the_crop_cuts_it(dataset: Path) -> None:
    full = photos_by_key(batches(module(dataset, sensor=SensorEffects())))
    plain_crops = batches(module(dataset, train_crop=8))
    sensed_crops = batches(module(dataset, train_crop=8, sensor=SensorEffects()))
    for plain, sensed in zip(plain_crops, sensed_crops, strict=True):
        assert [m["train_crop"] for m in plain["meta"]] == [m["train_crop"] for m in sensed["meta"]]
        for key, photo, meta in zip(sensed["key"], sensed["photo"], sensed["meta"], strict=True):
            x, y, size = meta["train_crop"]
            assert torch.equal(photo, full[key][:, y : y + size, x : x + size])


def test_checkpointed_hyperparameters_are_plain_values(dataset: Path, tmp_path: Path) -> None:
    dm = ShardDataModule(str(dataset), sensor=SensorEffects(jpeg_quality_min=80))
    path = tmp_path / "hparams.pt"
    torch.save(dict(dm.hparams), path)
    loaded = torch.load(path, weights_only=True)  # how checkpoints are read
    assert loaded["sensor"]["jpeg_quality_min"] == 80 and list(loaded["sensor_splits"]) == ["train"]


def test_datamodule_passes_each_samples_flash_colour(tmp_path: Path) -> None:
    """The auto white balance gets the flash colour that a sample's meta records; a sample that
    records none is sensed without it."""
    temperatures = {"train-0-0": 4000.0, "train-0-1": 6500.0, "train-0-2": None}
    samples = []
    for i, (key, temperature) in enumerate(temperatures.items()):
        meta: dict[str, Any] = {"seed": i}
        if temperature is not None:
            meta["flash"] = {"intensity_w_sr": 1.0, "temperature_k": temperature}
        samples.append(Sample(key, flash_photo(SIZE, i), random_maps(SIZE, SIZE, seed=i), meta))
    write_shard(shard_path(tmp_path, "train", 0), samples)
    write_shard(shard_path(tmp_path, "val", 0), [Sample("val-0-0", samples[0].photo, samples[0].maps, {})])
    sensor = SensorEffects(auto_white_balance=True)
    sensed = batches(module(tmp_path, sensor=sensor, batch_size=1))
    records = {b["key"][0]: b["meta"][0]["sensor"] for b in sensed}
    assert records.keys() == temperatures.keys()
    for key, temperature in temperatures.items():
        if temperature is None:
            assert records[key]["illuminant"] is None and records[key]["auto_white_balance"] is None
        else:
            rgb = blackbody_rgb(temperature)
            assert records[key]["illuminant"] == list(rgb)
            assert records[key]["auto_white_balance"] == list(auto_white_balance_gains(rgb))
    # Off (the default), the flash colour is recorded and nothing else changes.
    plain = batches(module(tmp_path, sensor=SensorEffects(), batch_size=1))
    assert [b["meta"][0]["sensor"]["auto_white_balance"] for b in plain] == [None, None, None]
