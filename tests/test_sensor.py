"""The simulated phone capture (brdfgan.data.sensor) and its use in the DataModule."""

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
from brdfgan.core.svbrdf import srgb_to_linear
from brdfgan.data.datamodule import ShardDataModule
from brdfgan.data.sensor import (
    SensorEffects,
    decode_srgb8,
    encode_srgb8,
    jpeg_roundtrip,
    sensor_noise,
    vignetting,
    vignetting_falloff,
    white_balance,
)
from brdfgan.data.shards import Sample, shard_path, write_shard
from brdfgan.data.spec_checks import DatasetConfigError
from brdfgan.errors import UserError
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.intake.preprocess import Crop, preprocess
from tests.conftest import random_maps

# Every random effect off: only the file steps (sRGB, 8 bits, decoding) and the exposure remain.
NOTHING_RANDOM = SensorEffects(
    vignetting_probability=0.0, white_balance_probability=0.0, noise_probability=0.0, jpeg_probability=0.0
)


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
    assert set(record) == {
        "vignetting",
        "white_balance",
        "shot_noise",
        "read_noise",
        "jpeg_quality",
        "exposure_scale",
    }
    assert all(value is not None for value in record.values())  # every probability is 1


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
    assert all(value is None for value in record.values())


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
    ],
)
def test_bad_values_are_one_line_errors_naming_the_key(key: str, value: Any, message: str) -> None:
    with pytest.raises(DatasetConfigError) as error:
        SensorEffects(**{key: value})
    assert isinstance(error.value, UserError)
    assert str(error.value).startswith(message) and "\n" not in str(error.value)


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
