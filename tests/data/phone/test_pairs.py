"""The no-flash shot of a flash + no-flash pair (brdfgan.data.phone.pairs): its draw, the handheld
misregistration, the pair record and how the phone's sensor changes it."""

from __future__ import annotations

import math

import pytest
import torch

from brdfgan.data.phone.conditions import CaptureSampling
from brdfgan.data.phone.pairs import (
    PairSampling,
    exposure_ratio,
    misregister,
    pair_batch,
    pair_meta,
    sensed_pair_meta,
    twin_sensor,
)
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.data.storage.shards import ShardError
from brdfgan.data.storage.spec_checks import DatasetConfigError

EV_RANGE = CaptureSampling(exposure_ev_min=-1.5, exposure_ev_max=1.0)


def test_draws_stay_within_their_bounds_and_are_a_function_of_the_generator() -> None:
    sampling = PairSampling(enabled=True, white_balance_spread=0.03, shift_max_px=2.0, rotation_max_deg=0.5)
    draws = [sampling.sample(torch.Generator().manual_seed(seed), EV_RANGE) for seed in range(500)]
    assert all(math.hypot(*draw.shift_px) <= 2.0 for draw in draws)
    assert all(abs(draw.rotation_deg) <= 0.5 for draw in draws)
    assert all(-1.5 <= draw.exposure_ev <= 1.0 for draw in draws)
    # The bounds are reached, not just respected, and the two shots' gains are drawn apart.
    assert max(math.hypot(*draw.shift_px) for draw in draws) > 1.9
    assert max(abs(draw.rotation_deg) for draw in draws) > 0.49
    logs = torch.tensor([draw.white_balance for draw in draws]).log()
    assert 0.025 < float(logs.std()) < 0.035 and abs(float(logs.mean())) < 0.005
    assert not torch.equal(logs[:, 0], logs[:, 1])
    assert sampling.sample(torch.Generator().manual_seed(3), EV_RANGE) == draws[3]


def test_a_draw_takes_the_same_random_numbers_whatever_the_settings() -> None:
    still = PairSampling(enabled=True, white_balance_spread=0.0, shift_max_px=0.0, rotation_max_deg=0.0)
    generator = torch.Generator().manual_seed(0)
    draw = still.sample(generator, CaptureSampling())
    assert draw.white_balance == ((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)) and draw.misregistration() == (0, 0, 0)
    after = torch.rand(1, generator=generator)
    generator = torch.Generator().manual_seed(0)
    PairSampling(enabled=True).sample(generator, EV_RANGE)
    assert torch.equal(torch.rand(1, generator=generator), after)


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("enabled", "yes"),
        ("white_balance_spread", -0.1),
        ("shift_max_px", 100.0),
        ("rotation_max_deg", "abc"),
    ],
)
def test_a_bad_setting_names_its_key(key: str, value: object) -> None:
    with pytest.raises(DatasetConfigError, match=rf"^data\.pairs\.{key}="):
        PairSampling(**{key: value})  # type: ignore[arg-type]


def test_misregistration_shifts_and_turns_the_photo_about_its_centre() -> None:
    photos = torch.rand(2, 3, 16, 16, generator=torch.Generator().manual_seed(0))
    moved = misregister(photos, torch.tensor([[2.0, -1.0, 0.0], [0.0, 0.0, 90.0]]))
    # Content moves 2 columns right and 1 row up: output (y, x) shows input (y + 1, x - 2).
    assert torch.allclose(moved[0, :, 0:-1, 2:], photos[0, :, 1:, :-2], atol=1e-5)
    # +90°: +x turns towards +y (down), clockwise on screen; pixel centres land on pixel centres.
    assert torch.allclose(moved[1], torch.rot90(photos[1], k=-1, dims=(-2, -1)), atol=1e-5)
    # No motion: the photo itself, bit for bit.
    assert torch.equal(misregister(photos, torch.zeros(2, 3)), photos)


def test_a_sub_pixel_shift_interpolates_and_the_border_repeats() -> None:
    ramp = torch.arange(8.0).expand(1, 1, 8, 8)
    moved = misregister(ramp, torch.tensor([[0.25, 0.0, 0.0]]))
    assert torch.allclose(moved[0, 0, :, 1:], ramp[0, 0, :, 1:] - 0.25, atol=1e-5)
    assert torch.allclose(moved[0, 0, :, 0], torch.zeros(8))  # from outside: the border column


def test_the_pair_record_and_a_black_no_flash_shot() -> None:
    record = pair_meta(2.0, {"exposure_scale": 8.0, "exposure_ev": 0.5}, [[1.0, 1.1, 0.9], [1.0, 1.0, 1.0]])
    assert record == {
        "exposure_ratio": 0.25,
        "white_balance": [[1.0, 1.1, 0.9], [1.0, 1.0, 1.0]],
        "no_flash": {"exposure_scale": 8.0, "exposure_ev": 0.5},
    }
    assert exposure_ratio(2.0, 0.0) == 0.0  # nothing to subtract
    batch = pair_batch([{"pair": record}, {"pair": pair_meta(1.0, {"exposure_scale": 4.0})}], ["a", "b"])
    assert batch["exposure_ratio"].tolist() == [0.25, 0.25] and batch["white_balance"].shape == (2, 2, 3)
    with pytest.raises(ShardError, match="sample 'b' has a no-flash photo but no meta"):
        pair_batch([{"pair": record}, {}], ["a", "b"])


def test_the_twins_sensor_keeps_the_lens_and_file_type_of_the_flash_shot() -> None:
    sensor = SensorEffects(raw_probability=0.5)
    flash_photo = torch.full((3, 8, 8), 0.3)
    for seed in range(8):
        _, record = sensor.apply(flash_photo, torch.Generator().manual_seed(seed))
        twin = twin_sensor(sensor, record)
        _, twin_record = twin.apply(flash_photo, torch.Generator().manual_seed(seed + 100))
        assert twin_record["vignetting"] == pytest.approx(record["vignetting"], abs=0)
        assert twin_record["raw"] == record["raw"]
    without = twin_sensor(SensorEffects(vignetting_probability=0.0), {"vignetting": None, "raw": False})
    assert without.vignetting_probability == 0.0 and without.raw_probability == 0.0


def test_the_sensors_exposures_and_gains_go_into_the_pair_record() -> None:
    pair = pair_meta(2.0, {"exposure_scale": 4.0}, [[1.0, 1.0, 1.0], [1.1, 1.0, 0.9]])
    flash = {"exposure_scale": 3.0, "white_balance": [1.2, 1.0, 0.8], "auto_white_balance": [1.5, 1.0, 1.0]}
    twin = {"exposure_scale": 6.0, "white_balance": [0.9, 1.0, 1.1], "auto_white_balance": None}
    sensed = sensed_pair_meta(pair, flash, twin)
    assert sensed["exposure_ratio"] == pytest.approx(0.5 * 3.0 / 6.0)
    assert torch.allclose(
        torch.tensor(sensed["white_balance"]), torch.tensor([[1.8, 1.0, 0.8], [0.99, 1.0, 0.99]])
    )
    assert sensed["no_flash"] == pair["no_flash"]
    assert sensed_pair_meta(pair, {}, {}) == pair  # a sensor switched off changes nothing
