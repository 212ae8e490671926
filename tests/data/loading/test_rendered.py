"""Training photos rendered on the fly (brdfgan.data.loading.rendered): the environment as distant lights,
the torch photo against Mitsuba's, the material bank, the stream's determinism, the DataModule."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import hydra
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.lighting import Environment, SunLight, environment_lights, upper_hemisphere_irradiance_rgb
from brdfgan.core.svbrdf import NORMAL, flat_maps, normalize_normal, validate_maps
from brdfgan.data.generation.generation import MitsubaPhotographer
from brdfgan.data.loading.rendered import (
    MaterialBank,
    ReliefSampling,
    RenderedDataModule,
    RenderedStream,
    add_relief,
    capture_scene,
    collate_scenes,
    photograph_scenes,
    sample_relief,
    scene_tensors,
)
from brdfgan.data.materials.augment import random_crops
from brdfgan.data.phone.conditions import CaptureDraw, CaptureSampling
from brdfgan.data.phone.environments import (
    LightingConfig,
    LightingDraw,
    balance_environment,
    flash_centre_irradiance,
    load_environment,
    room_spec,
    sunsky_spec,
)
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.spec.dataset_spec import DatasetSpec, paint_material
from brdfgan.data.spec.determinism import material_seed
from brdfgan.data.storage.shards import decode_maps
from brdfgan.data.storage.spec_checks import DatasetConfigError
from tests.conftest import compose_train, random_maps, run_python

RES = 64
TINY_SPEC = DatasetSpec(
    materials=6, material_resolution=64, resolution=32, test_fraction=0.2, val_fraction=0.2
)


def _smooth_maps(seed: int) -> torch.Tensor:
    # Per-texel noise is the worst case for resampling a tilted view; real maps are smoother.
    maps = random_maps(RES, RES, seed=seed)
    smooth = F.avg_pool2d(F.pad(maps[None], (2, 2, 2, 2), mode="replicate"), 5, 1)[0]
    smooth[NORMAL] = normalize_normal(smooth[NORMAL], dim=0)
    return smooth


def _photo(maps: torch.Tensor, capture: CaptureDraw, flash, lights) -> torch.Tensor:  # type: ignore[no-untyped-def]
    batch = collate_scenes([capture_scene("k", maps, capture, flash, lights, {})])
    return photograph_scenes(*scene_tensors(batch))[0][0]


def test_environment_lights_estimate_the_environment_without_bias() -> None:
    environment = load_environment(room_spec(3, 0), 32)
    truth = upper_hemisphere_irradiance_rgb(environment.radiance)
    estimates = []
    for seed in range(200):
        directions, irradiance = environment_lights(environment, 16, torch.Generator().manual_seed(seed))
        assert np.allclose(np.linalg.norm(directions, axis=1), 1.0) and (directions[:, 2] >= 0).all()
        estimates.append((irradiance * directions[:, 2:3]).sum(axis=0))
    mean = np.mean(estimates, axis=0)
    assert np.allclose(mean, truth, rtol=0.03), (mean, truth)


def test_environment_lights_put_the_sun_last_and_nothing_for_a_black_sky() -> None:
    sun = SunLight((0.0, 0.6, 0.8), (3.0, 2.0, 1.0))
    black = Environment(np.zeros((8, 16, 3), np.float32), sun)
    directions, irradiance = environment_lights(black, 4, torch.Generator().manual_seed(0))
    assert directions.shape == irradiance.shape == (5, 3)
    assert np.allclose(irradiance[:4], 0.0)
    assert np.allclose(directions[4], sun.direction) and np.allclose(irradiance[4], sun.irradiance)
    set_sun = Environment(np.zeros((8, 16, 3), np.float32), SunLight((0.0, 0.6, -0.8), (3.0, 2.0, 1.0)))
    assert np.allclose(environment_lights(set_sun, 4, torch.Generator())[1], 0.0)
    with pytest.raises(ValueError, match="count"):
        environment_lights(black, 0, torch.Generator())


@pytest.mark.integration
@pytest.mark.parametrize(
    ("environment", "ratio", "tolerance"),
    [(room_spec(0, 1), 0.05, 0.015), (room_spec(1, 1), 1.0, 0.03), (sunsky_spec(0, 2), 1.0, 0.03)],
    ids=["room-faint", "room-even", "sunsky-even"],
)
def test_torch_photo_agrees_with_mitsuba(environment, ratio: float, tolerance: float) -> None:  # type: ignore[no-untyped-def]
    # A tilted, closer camera with the flash off the lens and an environment: the same draws
    # through Mitsuba (256 spp) and through photograph_scenes (the mean of 8 light draws).
    spec = DatasetSpec(
        materials=5, material_resolution=RES, resolution=RES, spp=256, lighting=LightingConfig(resolution=32)
    )
    maps = _smooth_maps(3)
    capture = CaptureDraw(fov_deg=50.0, tilt_deg=3.0, tilt_axis_deg=30.0, distance_drawn=0.95,
                          distance_factor=0.95, flash_offset=0.05, flash_offset_angle_deg=70.0)  # fmt: skip
    draw = LightingDraw(environment, 1.0, ratio)
    mitsuba, _ = MitsubaPhotographer(spec)(maps, draw, 2.0, 5000.0, capture, 7)
    flash = tuple(2.0 * c for c in blackbody_rgb(5000.0))
    balanced = balance_environment(
        load_environment(environment, 32), draw, flash_centre_irradiance(flash, capture.flash_position)
    )
    photos = torch.stack(
        [
            _photo(maps, capture, flash, environment_lights(balanced, 64, torch.Generator().manual_seed(s)))
            for s in range(8)
        ]
    )
    difference = float((photos.mean(0) - mitsuba).abs().mean() / mitsuba.mean())
    assert difference < tolerance


@pytest.mark.integration
def test_torch_photo_shows_the_tilted_views_hotspot_where_mitsuba_does() -> None:
    # Rendered in texture space, then warped into the photo: a glossy uniform sample's highlight
    # sits where the mirror geometry puts it, in both renderers.
    spec = DatasetSpec(
        materials=5, material_resolution=RES, resolution=RES, spp=64, lighting=LightingConfig(resolution=16)
    )
    maps = flat_maps(RES, RES, roughness=0.3)
    capture = CaptureDraw(fov_deg=40.0, tilt_deg=10.0, tilt_axis_deg=60.0, distance_drawn=0.9,
                          distance_factor=0.9, flash_offset=0.2, flash_offset_angle_deg=20.0)  # fmt: skip
    draw = LightingDraw(room_spec(0, 1), 0.0, 1e-4)
    mitsuba, _ = MitsubaPhotographer(spec)(maps, draw, 2.0, 6500.0, capture, 1)
    ours = _photo(maps, capture, (2.0, 2.0, 2.0), (np.zeros((1, 3)), np.zeros((1, 3))))
    hotspot = torch.tensor(capture.hotspot_px(RES))
    for photo in (mitsuba, ours):
        peak = int(photo.mean(0).flatten().argmax())
        assert torch.dist(torch.tensor([peak % RES + 0.5, peak // RES + 0.5]), hotspot) < 1.5


@pytest.fixture(scope="module")
def bank(tmp_path_factory: pytest.TempPathFactory) -> MaterialBank:
    bank = MaterialBank(TINY_SPEC, tmp_path_factory.mktemp("banks"), environment_resolution=16)
    bank.build(progress=False)
    return bank


def test_bank_holds_the_training_materials_as_generation_paints_them(bank: MaterialBank) -> None:
    index = bank.procedural[0]
    painted = paint_material(
        TINY_SPEC, "train", index, torch.Generator().manual_seed(material_seed(0, index))
    )
    banked = decode_maps(bank.material_path(index).read_bytes(), "test")
    assert torch.allclose(banked[:3], painted.maps[:3], atol=1 / 65535) and torch.allclose(
        banked[6:], painted.maps[6:], atol=1 / 65535
    )
    assert torch.allclose(banked[NORMAL], painted.maps[NORMAL], atol=1e-4)
    recorded = json.loads((bank.root / "bank.json").read_text())
    assert recorded["materials"][str(index)]["family"] == painted.family
    assert sorted(int(k) for k in recorded["materials"]) == sorted(bank.procedural)


def test_bank_build_resumes_and_leaves_a_complete_bank_alone(bank: MaterialBank) -> None:
    stamps = {path.name: path.stat().st_mtime_ns for path in bank.root.iterdir()}
    bank.build(progress=False)
    assert {path.name: path.stat().st_mtime_ns for path in bank.root.iterdir()} == stamps
    # A killed build: one material and the index missing. The rebuild restores the same bytes.
    victim = bank.material_path(bank.procedural[-1])
    before = victim.read_bytes()
    victim.unlink()
    (bank.root / "bank.json").unlink()
    assert not bank.ready()
    MaterialBank(TINY_SPEC, bank.root.parent, environment_resolution=16).build(progress=False)
    assert victim.read_bytes() == before and bank.ready()


def test_bank_painted_by_several_processes_is_byte_for_byte_the_same(
    bank: MaterialBank, tmp_path: Path
) -> None:
    parallel = MaterialBank(TINY_SPEC, tmp_path, environment_resolution=16, paint_workers=2)
    assert parallel.root.name == bank.root.name
    parallel.build(progress=False)
    assert parallel.ready()
    names = sorted(path.name for path in bank.root.iterdir())
    assert names == sorted(path.name for path in parallel.root.iterdir())
    for name in names:
        assert (parallel.root / name).read_bytes() == (bank.root / name).read_bytes(), name


def test_bank_keeps_a_complete_environment_table_and_retabulates_another_resolution(
    bank: MaterialBank, tmp_path: Path
) -> None:
    # A table carried to a machine without Mitsuba (sun and sky need it) is used as it is.
    carried = MaterialBank(TINY_SPEC, tmp_path, environment_resolution=16)
    carried.root.mkdir(parents=True)
    table = carried.root / "environments.npz"
    table.write_bytes((bank.root / "environments.npz").read_bytes())
    stamp = table.stat().st_mtime_ns
    carried.build(progress=False)
    assert table.stat().st_mtime_ns == stamp and carried.ready()
    # At another resolution the table no longer fits: it is tabulated again.
    (carried.root / "bank.json").unlink()
    MaterialBank(TINY_SPEC, tmp_path, environment_resolution=8).build(progress=False)
    with np.load(table) as data:
        assert {data[name].shape[0] for name in data.files if name.endswith("/radiance")} == {8}
    # Nor does a table of other lighting settings (the bank's folder does not follow them).
    (carried.root / "bank.json").unlink()
    rooms = replace(TINY_SPEC, lighting=replace(TINY_SPEC.lighting, sunsky_fraction=0.0))
    relit = MaterialBank(rooms, tmp_path, environment_resolution=8)
    assert relit.root == carried.root
    relit.build(progress=False)
    with np.load(table) as data:
        tabulated = {name.split("/")[0] for name in data.files if name.endswith("/radiance")}
    assert tabulated == {spec.env_id for spec in relit.environments}
    assert all(spec.kind == "room" for spec in relit.environments)


def test_bank_rejects_no_paint_workers(tmp_path: Path) -> None:
    with pytest.raises(DatasetConfigError, match=r"data\.bank\.paint_workers=0"):
        MaterialBank(TINY_SPEC, tmp_path, paint_workers=0)


def test_bank_folder_follows_the_materials_not_the_capture(tmp_path: Path) -> None:
    same = MaterialBank(replace(TINY_SPEC, capture=CaptureSampling(fov_min_deg=30.0)), tmp_path)
    other = MaterialBank(replace(TINY_SPEC, seed=1), tmp_path)
    assert same.root == MaterialBank(TINY_SPEC, tmp_path).root != other.root


def test_stream_is_a_pure_function_of_seed_epoch_and_batch(bank: MaterialBank) -> None:
    def batches(seed: int, epoch: int = 0, skip: int = 0) -> list[dict]:
        stream = RenderedStream(bank, batch_size=2, batches_per_epoch=4, seed=seed, environment_lights=4)
        stream.epoch, stream.skip_batches = epoch, skip
        return list(stream)

    first, again = batches(0), batches(0)
    assert len(first) == 4
    for a, b in zip(first, again, strict=True):
        assert torch.equal(a["scene_maps"], b["scene_maps"]) and torch.equal(a["light_rgb"], b["light_rgb"])
    resumed = batches(0, skip=2)
    assert [b["key"] for b in resumed] == [b["key"] for b in first[2:]]
    assert torch.equal(resumed[0]["light_position"], first[2]["light_position"])
    assert not torch.equal(batches(0, epoch=1)[0]["light_rgb"], first[0]["light_rgb"])
    assert not torch.equal(batches(1)[0]["light_rgb"], first[0]["light_rgb"])


@pytest.mark.integration
def test_datamodule_renders_training_photos_and_generates_only_the_eval_shards(tmp_path: Path) -> None:
    cfg = compose_train(
        ["debug=default", "data=rendered", "dataset_spec@data.prepare.spec=tiny",
         "data.data_dir=${paths.data_dir}/tiny", "data.epoch_samples=8", "data.batch_size=2",
         "data.environment_lights=4", "data.bank.environment_resolution=16", "data.train_crop=32"],
        tmp_path,
    )  # fmt: skip
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    assert isinstance(module, RenderedDataModule)
    module.prepare_data()
    data = tmp_path / "data" / "tiny"
    assert (data / "val" / "manifest.json").exists() and (data / "test" / "manifest.json").exists()
    assert not list((data / "train").glob("*.tar"))  # its folder is made, never filled
    module.setup("fit")
    assert module.train_batches_per_epoch == 4 and len(module.val_dataloader()) >= 1
    scenes = next(iter(module.train_dataloader()))
    batch = module.on_after_batch_transfer(scenes, 0)
    photo, maps = batch["photo"], batch["maps"]
    assert photo.shape == (2, 3, 32, 32) == (maps.shape[0], 3, *maps.shape[2:])
    assert float(photo.min()) >= 0.0 and float(photo.max()) <= 1.0 and float(photo.mean()) > 0.01
    for sample in maps:
        validate_maps(sample)
    assert batch["flash"].shape == (2, 3)
    assert all(meta["render"]["renderer"] == "torch" and "sensor" in meta for meta in batch["meta"])
    # A shard batch (validation) passes through unchanged.
    val_batch = next(iter(module.val_dataloader()))
    assert module.on_after_batch_transfer(val_batch, 0) is val_batch
    module.teardown("fit")


def first_crop(bank: MaterialBank) -> Tensor:
    """A 32² crop of the bank's first drawn material (seeded: the same in every test)."""
    return random_crops(
        bank.draw(torch.Generator().manual_seed(0)).maps, 1, 32, torch.Generator().manual_seed(1)
    )[0][0]


def test_relief_sampling_swaps_and_bumps_the_normals_only(bank: MaterialBank) -> None:
    crop = first_crop(bank)
    swapped, record = sample_relief(
        bank, crop, ReliefSampling(swap_probability=1.0), torch.Generator().manual_seed(2)
    )
    assert set(record) == {"swap"} and not torch.equal(swapped[NORMAL], crop[NORMAL])
    assert torch.equal(swapped[:3], crop[:3]) and torch.equal(swapped[6:], crop[6:])
    flat = crop.clone()
    flat[NORMAL] = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1)
    sampling = ReliefSampling(bump_probability=1.0, bump_slope_min=0.1, bump_slope_max=0.1)
    bumped, record = sample_relief(bank, flat, sampling, torch.Generator().manual_seed(3))
    slopes = -bumped[NORMAL][:2] / bumped[NORMAL][2:]
    assert record["bumps"]["rms_slope"] == pytest.approx(0.1)
    assert float(slopes.square().sum(0).mean().sqrt()) == pytest.approx(0.1, rel=1e-4)
    validate_maps(bumped)
    same, record = sample_relief(bank, crop, ReliefSampling(), torch.Generator().manual_seed(2))
    assert same is crop and record == {}


def test_plain_albedo_fades_the_base_colour_toward_its_mean_and_nothing_else(bank: MaterialBank) -> None:
    crop = first_crop(bank)
    faded, record = sample_relief(
        bank, crop, ReliefSampling(plain_albedo_probability=1.0), torch.Generator().manual_seed(4)
    )
    contrast = record["plain_albedo"]["contrast"]
    assert 0.0 <= contrast < 1.0 and set(record) == {"plain_albedo"}
    mean = crop[:3].mean(dim=(1, 2), keepdim=True)
    torch.testing.assert_close(faded[:3].mean(dim=(1, 2), keepdim=True), mean)
    torch.testing.assert_close(faded[:3] - mean, contrast * (crop[:3] - mean))
    assert torch.equal(faded[3:], crop[3:]) and not torch.equal(faded[:3], crop[:3])
    validate_maps(faded)
    # Switched on over swaps and bumps, it leaves them as they were drawn.
    both = ReliefSampling(swap_probability=1.0, bump_probability=1.0)
    relief_only, _ = sample_relief(bank, crop, both, torch.Generator().manual_seed(5))
    with_fade, record = sample_relief(
        bank, crop, replace(both, plain_albedo_probability=1.0), torch.Generator().manual_seed(5)
    )
    assert set(record) == {"swap", "bumps", "plain_albedo"}
    assert torch.equal(relief_only[NORMAL], with_fade[NORMAL])


def test_flat_relief_removes_the_crops_own_relief_and_keeps_every_other_draw(bank: MaterialBank) -> None:
    crop = first_crop(bank).clone()  # with a ripple: relief of its own to remove
    crop[NORMAL] = add_relief(crop[NORMAL], torch.sin(torch.arange(32.0) / 3).expand(1, 32, 32), 0.2)
    flattened, record = sample_relief(
        bank, crop, ReliefSampling(flat_probability=1.0), torch.Generator().manual_seed(4)
    )
    assert record == {"flat": True}
    assert torch.equal(flattened[NORMAL], torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand(3, 32, 32))
    assert torch.equal(flattened[:3], crop[:3]) and torch.equal(flattened[6:], crop[6:])
    validate_maps(flattened)
    # Bumps drawn with it lie on the flat surface: the same bumps as over a flat crop without it.
    bumps = ReliefSampling(bump_probability=1.0)
    flat_crop = flattened.clone()
    over_flat, _ = sample_relief(bank, flat_crop, bumps, torch.Generator().manual_seed(6))
    both, record = sample_relief(
        bank, crop, replace(bumps, flat_probability=1.0), torch.Generator().manual_seed(6)
    )
    assert set(record) == {"flat", "bumps"}
    torch.testing.assert_close(both[NORMAL], over_flat[NORMAL])
    # A swapped crop keeps its partner's relief; and switched on, it leaves the earlier draws as
    # they were (the same swap, bumps and fade).
    every = ReliefSampling(swap_probability=1.0, bump_probability=1.0, plain_albedo_probability=1.0)
    without, record_without = sample_relief(bank, crop, every, torch.Generator().manual_seed(7))
    with_flat, record_with = sample_relief(
        bank, crop, replace(every, flat_probability=1.0), torch.Generator().manual_seed(7)
    )
    assert record_with == record_without and torch.equal(with_flat, without)


def test_inverted_relief_negates_the_slopes_so_grooves_become_ridges(bank: MaterialBank) -> None:
    crop = first_crop(bank).clone()
    ripple = torch.sin(torch.arange(32.0) / 3).expand(1, 32, 32)
    flat = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand(3, 32, 32)
    crop[NORMAL] = add_relief(flat, ripple, 0.2)
    sampling = ReliefSampling(invert_probability=1.0)
    inverted, record = sample_relief(bank, crop, sampling, torch.Generator().manual_seed(4))
    assert record == {"inverted": True}
    # The relief of the negated height: the same slopes' magnitudes, the opposite signs.
    torch.testing.assert_close(inverted[NORMAL], add_relief(flat, -ripple, 0.2))
    assert torch.equal(inverted[:3], crop[:3]) and torch.equal(inverted[6:], crop[6:])
    validate_maps(inverted)
    # Switched on, it leaves the earlier draws as they were (the same swap, bumps and fade).
    every = ReliefSampling(swap_probability=1.0, bump_probability=1.0, plain_albedo_probability=1.0)
    without, record_without = sample_relief(bank, crop, every, torch.Generator().manual_seed(7))
    with_invert, record_with = sample_relief(
        bank, crop, replace(every, invert_probability=1.0), torch.Generator().manual_seed(7)
    )
    assert record_with == {**record_without, "inverted": True} and torch.equal(with_invert[:3], without[:3])


def test_relief_sampling_leaves_every_other_draw_of_the_photo_as_it_was(bank: MaterialBank) -> None:
    from brdfgan.data.loading.rendered import draw_scene

    plain = draw_scene(bank, "k", 5, 4)
    bumped = draw_scene(bank, "k", 5, 4, ReliefSampling(swap_probability=1.0, bump_probability=1.0))
    assert torch.equal(plain.light_rgb, bumped.light_rgb) and torch.equal(plain.grid, bumped.grid)
    assert torch.equal(plain.maps[:3], bumped.maps[:3]) and not torch.equal(
        plain.maps[NORMAL], bumped.maps[NORMAL]
    )
    assert set(bumped.meta["relief"]) == {"swap", "bumps"} and "relief" not in plain.meta


def test_relief_sampling_names_a_bad_key() -> None:
    with pytest.raises(DatasetConfigError, match=r"data\.relief\.swap_probability"):
        ReliefSampling(swap_probability=1.5)
    with pytest.raises(DatasetConfigError, match=r"data\.relief"):
        ReliefSampling(bump_slope_min=0.3, bump_slope_max=0.1)


@pytest.mark.integration
@pytest.mark.mitsuba
def test_a_fresh_clone_trains_the_rendered_recipe_without_a_training_set(tmp_path: Path) -> None:
    # experiment=anchored_rendered at toy sizes: the bank is painted, only the validation shards are
    # generated, and the run trains on rendered photos and validates on Mitsuba ones.
    result = run_python(
        "train.py", "experiment=anchored_rendered", "task_name=rendered_smoke",
        "dataset_spec@data.prepare.spec=tiny",
        "data.data_dir=${paths.data_dir}/tiny", "data.train_crop=32", "data.batch_size=2",
        "data.epoch_samples=4", "data.environment_lights=4", "data.bank.environment_resolution=16",
        "data.compile_renderer=false", "loss.compile=false", "model.generator.width=8",
        "trainer.max_epochs=1", "trainer.check_val_every_n_epoch=1", "test=false",
        cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    data = tmp_path / "data" / "tiny"
    assert (data / "val" / "manifest.json").exists()
    assert not list((data / "train").glob("*.tar")) and not (data / "test" / "manifest.json").exists()
    assert list((tmp_path / "data" / "banks").glob("*/bank.json"))
    run = sorted((tmp_path / "logs" / "rendered_smoke" / "runs").iterdir())[-1]
    assert (run / "checkpoints" / "last.ckpt").exists()
    metrics = next((run / "csv").glob("version_*/metrics.csv")).read_text()
    assert "val/loss" in metrics and "train/g_total" in metrics
