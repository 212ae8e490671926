"""Datasets of flash + no-flash pairs (``dataset_spec.pairs``): the twin of every photo, its own
exposure in the pair record, and a spec without pairs exactly as before."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import torch

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import srgb_to_linear
from brdfgan.data.generation.generation import run_generation
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.phone.conditions import CaptureDraw, CaptureSampling
from brdfgan.data.phone.environments import LightingDraw
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.data.spec.dataset_spec import SPLITS, DatasetSpec
from brdfgan.data.storage.shards import iter_shard, list_shards
from brdfgan.data.storage.spec_checks import DatasetConfigError
from tests.data.generation.test_generation import shard_hashes, tiny_spec, torch_photographer

ROOM = 0.3  # the stand-in's room light: a uniform diffuse light of this irradiance


def room_render(maps: torch.Tensor) -> torch.Tensor:
    """The stand-in's room light alone: a uniform light on the diffuse base colour."""
    return ROOM * srgb_to_linear(maps[:3])


class PairPhotographer:
    """A fast stand-in for Mitsuba that takes twins: the flash-only torch render plus a uniform
    room light, or the room light alone with ``flash=False``; auto-exposed with the drawn error."""

    def __init__(self, spec: DatasetSpec) -> None:
        self.spec = spec

    def __call__(
        self,
        maps: torch.Tensor,
        lighting: LightingDraw,
        intensity: float,
        temperature: float,
        draw: CaptureDraw,
        seed: int,
        /,
        *,
        flash: bool = True,
    ) -> tuple[torch.Tensor, float]:
        hdr = room_render(maps)
        if flash:
            hdr = (
                hdr
                + render_flash(maps[None], FlashCapture(draw.fov_deg, intensity, blackbody_rgb(temperature)))[
                    0
                ]
            )
        ldr, scale = auto_expose(hdr, draw.exposure_ev)
        return ldr, float(scale)


def pair_spec(**change: object) -> DatasetSpec:
    exposure = CaptureSampling(exposure_ev_min=-1.0, exposure_ev_max=0.5)
    return tiny_spec(pairs=True, capture=exposure, **change)


def test_every_photo_has_its_twin_at_its_own_exposure(tmp_path: Path) -> None:
    spec = pair_spec()
    run_generation(spec, tmp_path, progress=False, photographer=PairPhotographer)
    assert json.loads((tmp_path / "dataset.json").read_text())["pairs"] is True
    samples = [
        sample for split in SPLITS for path in list_shards(tmp_path, split) for sample in iter_shard(path)
    ]
    assert samples and all(sample.no_flash is not None for sample in samples)
    stops = []
    for sample in samples:
        twin = sample.meta["pair"]["no_flash"]
        stops.append(twin["exposure_ev"])
        assert -1.0 <= twin["exposure_ev"] <= 0.5
        assert sample.meta["pair"]["exposure_ratio"] == pytest.approx(
            sample.meta["exposure_scale"] / twin["exposure_scale"]
        )
        assert sample.meta["pair"]["white_balance"] == [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]
        # The twin is the room light alone at its own exposure (the shard's 16-bit codes aside).
        crop = sample.maps  # texture space: the stand-in renders the nominal camera
        expected = (room_render(crop) * twin["exposure_scale"]).clamp(0.0, 1.0)
        assert torch.allclose(sample.no_flash, expected, atol=1e-4)
    # Drawn apart from the flash photo's exposure error.
    assert len(set(stops)) == len(stops)
    assert stops != [sample.meta["capture"]["exposure_ev"] for sample in samples]


def test_the_pairs_switch_is_recorded_only_when_on_and_changes_nothing_else(tmp_path: Path) -> None:
    assert "pairs" not in tiny_spec().to_json() and pair_spec().to_json()["pairs"] is True
    run_generation(tiny_spec(), tmp_path / "single", progress=False, photographer=torch_photographer)
    run_generation(
        dataclasses.replace(tiny_spec(), pairs=False),
        tmp_path / "off",
        progress=False,
        photographer=torch_photographer,
    )
    assert shard_hashes(tmp_path / "single") == shard_hashes(tmp_path / "off")
    # With pairs the flash photos, maps and the rest of the metadata are the ones without.
    spec = tiny_spec(capture=CaptureSampling(exposure_ev_min=-1.0, exposure_ev_max=0.5))
    run_generation(spec, tmp_path / "a", progress=False, photographer=PairPhotographer)
    run_generation(
        dataclasses.replace(spec, pairs=True), tmp_path / "b", progress=False, photographer=PairPhotographer
    )
    for split in SPLITS:
        for one, two in zip(
            list_shards(tmp_path / "a", split), list_shards(tmp_path / "b", split), strict=True
        ):
            for single, paired in zip(iter_shard(one), iter_shard(two), strict=True):
                assert torch.equal(single.photo, paired.photo) and torch.equal(single.maps, paired.maps)
                assert single.no_flash is None and {**single.meta, "pair": paired.meta["pair"]} == paired.meta


def test_pairs_must_be_a_boolean() -> None:
    with pytest.raises(DatasetConfigError, match=r"^dataset_spec\.pairs='yes': must be true or false"):
        tiny_spec(pairs="yes")


def test_a_pair_dataset_loads_with_its_twins_through_the_evaluation_sensor(tmp_path: Path) -> None:
    run_generation(pair_spec(), tmp_path, progress=False, photographer=PairPhotographer)
    sensor = SensorEffects(noise_probability=0.0, jpeg_probability=0.0, raw_probability=1.0)
    module = ShardDataModule(str(tmp_path), batch_size=2, sensor=sensor, sensor_splits=("test",))
    module.setup("test")
    batch = next(iter(module.test_dataloader()))
    assert batch["photo_noflash"].shape == batch["photo"].shape
    assert batch["white_balance"].shape == (2, 2, 3) and batch["exposure_ratio"].shape == (2,)
    for meta, ratio, gains in zip(
        batch["meta"], batch["exposure_ratio"], batch["white_balance"], strict=True
    ):
        flash, twin = meta["sensor"], meta["sensor_noflash"]
        assert twin["vignetting"] == flash["vignetting"] and twin["raw"] and flash["raw"]
        expected = meta["exposure_scale"] * flash["exposure_scale"]
        expected /= meta["pair"]["no_flash"]["exposure_scale"] * twin["exposure_scale"]
        assert float(ratio) == pytest.approx(expected, rel=1e-6)
        assert torch.allclose(gains, torch.tensor([flash["white_balance"], twin["white_balance"]]))
    # Without the sensor the batch carries the stored twins.
    plain = ShardDataModule(str(tmp_path), batch_size=2)
    plain.setup("test")
    stored = next(iter(plain.test_dataloader()))
    samples = list(iter_shard(list_shards(tmp_path, "test")[0]))
    assert torch.equal(stored["photo_noflash"], torch.stack([sample.no_flash for sample in samples[:2]]))
