"""Flash + no-flash pairs rendered on the fly (``data.pairs``): the twin is the room light alone at
its own exposure, the pair record undoes the exposures and white balance, the twin moves within
its drawn bounds, and with pairs off every batch is what it was."""

from __future__ import annotations

import random
from dataclasses import replace
from pathlib import Path

import hydra
import pytest
import torch

from brdfgan.capture import NO_FLASH_PHOTO
from brdfgan.data.loading.datamodule import collate_samples, random_crop, sensed_sample
from brdfgan.data.loading.rendered import (
    MaterialBank,
    RenderedDataModule,
    RenderedStream,
    _mix,
    collate_scenes,
    draw_scene,
    pair_tensors,
    photograph_pairs,
    photograph_scenes,
    render_scenes,
    scene_tensors,
)
from brdfgan.data.phone.conditions import CaptureSampling
from brdfgan.data.phone.pairs import PAIR_BATCH_KEYS, PairSampling, misregister
from brdfgan.data.phone.sensor import SensorEffects, vignetting_falloff
from brdfgan.data.spec.dataset_spec import DatasetSpec
from brdfgan.data.storage.shards import Sample
from tests.conftest import compose_train

# Exposed a stop or two under: few clipped pixels, so the subtraction holds almost everywhere.
SPEC = DatasetSpec(
    materials=6,
    material_resolution=64,
    resolution=32,
    test_fraction=0.2,
    val_fraction=0.2,
    capture=CaptureSampling(fov_min_deg=40.0, fov_max_deg=60.0, exposure_ev_min=-2.0, exposure_ev_max=-1.0),
)
PAIRS = PairSampling(enabled=True)
STILL = replace(PAIRS, shift_max_px=0.0, rotation_max_deg=0.0)
LIGHTS = 4


@pytest.fixture(scope="module")
def bank(tmp_path_factory: pytest.TempPathFactory) -> MaterialBank:
    bank = MaterialBank(SPEC, tmp_path_factory.mktemp("banks"), environment_resolution=16)
    bank.build(progress=False)
    return bank


def scenes(bank: MaterialBank, pairs: PairSampling, seed: int = 5) -> dict:
    stream = RenderedStream(
        bank, batch_size=3, batches_per_epoch=1, seed=seed, environment_lights=LIGHTS, pairs=pairs
    )
    return next(iter(stream))


def module(
    bank: MaterialBank, tmp_path: Path, pairs: PairSampling | None, **options: object
) -> RenderedDataModule:
    return RenderedDataModule(
        str(tmp_path / "shards"), bank, epoch_samples=3, environment_lights=LIGHTS, pairs=pairs, **options
    )


def test_a_pair_draws_the_flash_photos_scene_as_without_pairs(bank: MaterialBank) -> None:
    single, paired = scenes(bank, PairSampling()), scenes(bank, PAIRS)
    assert set(paired) == set(single) | {"no_flash_ev", "white_balance", "misregistration"}
    for name, value in single.items():
        if isinstance(value, torch.Tensor):
            assert torch.equal(value, paired[name]), name
    assert paired["meta"] == single["meta"]


def test_the_twin_is_the_room_light_alone_at_its_own_exposure(bank: MaterialBank) -> None:
    batch = scenes(bank, replace(STILL, white_balance_spread=0.0))
    photos, twins, maps, scales = photograph_pairs(*scene_tensors(batch), *pair_tensors(batch))
    # The flash's light_rgb row zeroed, photographed at the twin's drawn exposure error.
    maps_, camera, positions, colours, grids, _ = scene_tensors(batch)
    room = colours.clone()
    room[:, 0] = 0.0
    expected, expected_maps, expected_scales = photograph_scenes(
        maps_, camera, positions, room, grids, batch["no_flash_ev"]
    )
    assert torch.allclose(twins, expected, atol=1e-5)
    assert torch.allclose(scales[:, 1], expected_scales, rtol=1e-5) and torch.equal(maps, expected_maps)
    # The flash photo: the scene as photographed without pairs.
    flash, _, flash_scales = photograph_scenes(*scene_tensors(batch))
    assert torch.allclose(photos, flash, atol=1e-5) and torch.allclose(scales[:, 0], flash_scales, rtol=1e-5)
    assert float(twins.mean()) > 0.01


def test_the_pair_record_recovers_the_flash_alone(bank: MaterialBank) -> None:
    batch = scenes(bank, STILL)
    photos, twins, _, scales = photograph_pairs(*scene_tensors(batch), *pair_tensors(batch))
    maps, camera, positions, colours, grids, _ = scene_tensors(batch)
    flash_alone = (
        render_scenes(maps, camera, positions[:, :1], colours[:, :1], grids) * scales[:, :1, None, None]
    )
    ratio = (scales[:, 0] / scales[:, 1])[:, None, None, None]
    gains = batch["white_balance"][..., None, None]
    assert not torch.allclose(gains, torch.ones_like(gains))
    recovered = photos / gains[:, 0] - ratio * twins / gains[:, 1]
    unclipped = (photos < 0.99).all(1, keepdim=True) & (twins < 0.99).all(1, keepdim=True)
    assert unclipped.float().mean() > 0.9
    assert torch.allclose(recovered * unclipped, flash_alone * unclipped, atol=2e-5)


def test_the_twin_moves_within_its_drawn_bounds(bank: MaterialBank) -> None:
    wide = replace(PAIRS, shift_max_px=3.0, rotation_max_deg=1.0)
    batch = scenes(bank, wide)
    motion = batch["misregistration"]
    assert (motion[:, :2].norm(dim=1) <= 3.0).all() and (motion[:, 2].abs() <= 1.0).all()
    assert (motion != 0).all()
    _, twins, _, _ = photograph_pairs(*scene_tensors(batch), *pair_tensors(batch))
    still = {**batch, "misregistration": torch.zeros_like(motion)}
    _, unmoved, _, _ = photograph_pairs(*scene_tensors(still), *pair_tensors(still))
    assert torch.allclose(twins, misregister(unmoved, motion))
    assert not torch.allclose(twins, unmoved, atol=1e-3)


def test_the_datamodule_batch_of_pairs(bank: MaterialBank, tmp_path: Path) -> None:
    batch = module(bank, tmp_path, STILL, train_crop=16).photograph(scenes(bank, STILL))
    assert batch[NO_FLASH_PHOTO.batch_key].shape == batch["photo"].shape == (3, 3, 16, 16)
    assert set(PAIR_BATCH_KEYS) <= set(batch)
    for meta, ratio, gains in zip(
        batch["meta"], batch["exposure_ratio"], batch["white_balance"], strict=True
    ):
        record = meta["pair"]
        assert float(ratio) == pytest.approx(
            meta["exposure_scale"] / record["no_flash"]["exposure_scale"], rel=1e-6
        )
        assert torch.allclose(gains, torch.tensor(record["white_balance"]))
        assert record["no_flash"]["shift_px"] == [0.0, 0.0] and record["no_flash"]["rotation_deg"] == 0.0
    # The train crop cuts both photos at one window.
    whole = module(bank, tmp_path, STILL).photograph(scenes(bank, STILL))
    for index, meta in enumerate(batch["meta"]):
        x, y, size = meta["train_crop"]
        window = (..., slice(y, y + size), slice(x, x + size))
        assert torch.equal(batch["photo_noflash"][index], whole["photo_noflash"][index][window])


def test_through_the_sensor_the_record_still_recovers_the_flash_alone(
    bank: MaterialBank, tmp_path: Path
) -> None:
    # RAW files without noise: the sensor's vignetting, white balance and auto exposure, which the
    # pair record takes in, and 16-bit quantisation.
    sensor = SensorEffects(noise_probability=0.0, raw_probability=1.0, auto_white_balance=True)
    raw = scenes(bank, STILL)
    batch = module(bank, tmp_path, STILL, sensor=sensor).photograph(raw)
    maps, camera, positions, colours, grids, _ = scene_tensors(raw)
    flash_alone = render_scenes(maps, camera, positions[:, :1], colours[:, :1], grids)
    gains = batch["white_balance"][..., None, None]
    ratio = batch["exposure_ratio"][:, None, None, None]
    recovered = batch["photo"] / gains[:, 0] - ratio * batch["photo_noflash"] / gains[:, 1]
    for index, meta in enumerate(batch["meta"]):
        flash, twin = meta["sensor"], meta["sensor_noflash"]
        assert twin["vignetting"] == flash["vignetting"] and twin["auto_white_balance"] is None
        scale = meta["exposure_scale"] * flash["exposure_scale"]
        expected = flash_alone[index] * scale * vignetting_falloff(32, 32, flash["vignetting"])
        unclipped = (batch["photo"][index] < 0.98).all(0) & (batch["photo_noflash"][index] < 0.98).all(0)
        assert unclipped.float().mean() > 0.9
        error = (recovered[index] - expected)[:, unclipped].abs().max()
        assert error < 5e-4, (index, float(error))


def test_with_pairs_off_the_batches_are_the_ones_the_existing_functions_make(
    bank: MaterialBank, tmp_path: Path
) -> None:
    # What RenderedDataModule.photograph computed before pairs existed, from the same functions.
    sensor = SensorEffects()
    raw = scenes(bank, PairSampling())
    assert set(raw) == {
        "scene_maps",
        "camera_position",
        "light_position",
        "light_rgb",
        "grid",
        "exposure_ev",
        "key",
        "meta",
    }
    photos, maps, scales = photograph_scenes(*scene_tensors(raw))
    samples = []
    for key, photo, aligned, scale, meta in zip(
        raw["key"], photos, maps, scales.tolist(), raw["meta"], strict=True
    ):
        sample = Sample(key, photo, aligned, {**meta, "exposure_scale": scale}, check=False)
        seed = int(meta["render"]["seed"])
        sample = sensed_sample(sample, sensor, _mix(seed, "sensor"))
        samples.append(random_crop(sample, 16, random.Random(_mix(seed, "crop"))))
    expected = collate_samples(samples)
    for pairs in (None, PairSampling(), replace(PAIRS, enabled=False)):
        batch = module(bank, tmp_path, pairs, sensor=sensor, train_crop=16).photograph(raw)
        assert set(batch) == set(expected) == {"photo", "maps", "flash", "key", "meta"}
        for name in ("photo", "maps", "flash"):
            assert torch.equal(batch[name], expected[name]), name
        assert batch["key"] == expected["key"] and batch["meta"] == expected["meta"]
    # And the scenes of a stream without pairs are those draw_scene draws as it did.
    for position, key in enumerate(raw["key"]):
        seed = _mix(5, "rendered", 0, 0, 0, position)
        alone = collate_scenes([draw_scene(bank, key, seed, LIGHTS)])
        assert torch.equal(alone["light_rgb"][0], raw["light_rgb"][position])


def test_collate_adds_the_pair_only_when_every_sample_has_a_twin(bank: MaterialBank, tmp_path: Path) -> None:
    samples = [
        Sample(s.key, s.photo, s.maps, s.meta, check=False, no_flash=s.no_flash)
        for s in _pair_samples(bank, tmp_path)
    ]
    assert set(PAIR_BATCH_KEYS) | {"photo_noflash"} <= set(collate_samples(samples))
    single = Sample(samples[0].key, samples[0].photo, samples[0].maps, {}, check=False)
    mixed = collate_samples([single, *samples[1:]])
    assert not ({"photo_noflash", *PAIR_BATCH_KEYS} & set(mixed))
    assert torch.equal(mixed["photo"][1:], collate_samples(samples)["photo"][1:])


def _pair_samples(bank: MaterialBank, tmp_path: Path) -> list[Sample]:
    batch = scenes(bank, PAIRS)
    photos, twins, maps, scales = photograph_pairs(*scene_tensors(batch), *pair_tensors(batch))
    from brdfgan.data.phone.pairs import pair_meta

    return [
        Sample(
            key,
            photo,
            aligned,
            {"pair": pair_meta(float(s[0]), {"exposure_scale": float(s[1])})},
            no_flash=twin,
        )
        for key, photo, twin, aligned, s in zip(batch["key"], photos, twins, maps, scales, strict=True)
    ]


@pytest.mark.integration
def test_the_rendered_config_switches_pairs_on(tmp_path: Path) -> None:
    overrides = [
        "data=rendered",
        "dataset_spec@data.prepare.spec=tiny",
        "data.data_dir=${paths.data_dir}/tiny",
    ]
    default = hydra.utils.instantiate(compose_train(overrides, tmp_path).data, _convert_="all")
    assert default.pairs == PairSampling() and not default.pairs.enabled
    cfg = compose_train([*overrides, "data.pairs.enabled=true", "data.pairs.shift_max_px=1.0"], tmp_path)
    paired = hydra.utils.instantiate(cfg.data, _convert_="all")
    assert paired.pairs == PairSampling(enabled=True, shift_max_px=1.0)
    assert paired.hparams["pairs"]["enabled"] is True
