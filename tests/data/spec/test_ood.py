"""Mixed materials in generated datasets, and scanned sets as the test-only OOD benchmark."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from brdfgan.core.svbrdf import encode_normal, split_maps
from brdfgan.data.generation.generation import run_generation
from brdfgan.data.materials.mixing import MixingConfig
from brdfgan.data.materials.recolor import RecolorConfig
from brdfgan.data.materials.scanned import read_scanned_material
from brdfgan.data.spec.dataset_spec import DatasetSpec, split_materials
from brdfgan.data.storage.shards import iter_shard, list_shards
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.io.images import write_image
from tests.conftest import ROOT, random_maps
from tests.data.generation.test_generation import tiny_spec, torch_photographer


def _samples(root: Path, split: str) -> list:
    return [sample for shard in list_shards(root, split) for sample in iter_shard(shard)]


def test_mixed_materials_take_their_partner_from_their_own_split(tmp_path: Path) -> None:
    spec = tiny_spec(materials=9, mixing=MixingConfig(fraction=1.0), recolor=RecolorConfig(probability=0.5))
    run_generation(spec, tmp_path, progress=False, photographer=torch_photographer)
    splits = split_materials(spec)
    mixed = recoloured = 0
    for split, indices in splits.items():
        for sample in _samples(tmp_path, split):
            mix = sample.meta.get("mix")
            if mix is None:  # a split of one material has no partner to mix with
                assert len(indices) == 1
                continue
            mixed += 1
            assert mix["partner_index"] in indices and mix["partner_index"] != sample.meta["material_index"]
            recoloured += "recolor" in sample.meta
    assert mixed > 0 and 0 < recoloured < mixed


def _write_scanned_set(folder: Path, maps: torch.Tensor, metallic: bool) -> None:
    folder.mkdir(parents=True)
    parts = split_maps(maps)
    write_image(folder / "albedo.png", parts.basecolor.permute(1, 2, 0).numpy())
    write_image(folder / "normal.png", encode_normal(parts.normal).permute(1, 2, 0).numpy())
    write_image(folder / "roughness.png", parts.roughness[0].numpy())
    if metallic:
        write_image(folder / "metallic.png", parts.metallic[0].numpy())
    write_image(folder / "displacement.png", np.full((maps.shape[-2], maps.shape[-1]), 0.5, np.float32))


@pytest.fixture
def scanned_root(tmp_path: Path) -> Path:
    root = tmp_path / "scans"
    _write_scanned_set(root / "b_metal", random_maps(64, 64, seed=1), metallic=True)
    _write_scanned_set(root / "a_stone", random_maps(64, 64, seed=2), metallic=False)
    return root


def test_scanned_sets_read_like_our_maps(scanned_root: Path) -> None:
    maps = read_scanned_material(scanned_root / "a_stone", 32)
    assert maps.shape == (8, 32, 32) and torch.all(maps[7] == 0)  # no metallic file: dielectric
    metal = read_scanned_material(scanned_root / "b_metal", 64)
    assert metal[7].max() > 0.5


def test_scanned_dataset_is_test_only_and_checked(scanned_root: Path, tmp_path: Path) -> None:
    spec = tiny_spec(materials=2, scanned=str(scanned_root))
    assert split_materials(spec) == {"train": (), "val": (), "test": (0, 1)}
    out = tmp_path / "ood"
    run_generation(spec, out, progress=False, photographer=torch_photographer)
    assert not list_shards(out, "train") and not list_shards(out, "val")
    samples = _samples(out, "test")
    assert len(samples) == 2 * spec.crops_per_material * spec.eval_renders
    assert {s.meta["family"] for s in samples} == {"scanned/a_stone", "scanned/b_metal"}  # sorted by name
    assert all((out / split / "manifest.json").exists() for split in ("train", "val", "test"))
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.materials=3: .* holds 2 sets"):
        tiny_spec(materials=3, scanned=str(scanned_root))
    with pytest.raises(DatasetConfigError, match=r"scanned materials are a benchmark"):
        tiny_spec(materials=2, scanned=str(scanned_root), mixing=MixingConfig(fraction=0.5))
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.scanned='.*nowhere': folder of scanned"):
        tiny_spec(materials=2, scanned=str(tmp_path / "nowhere"))


def test_resolved_families_are_recorded() -> None:
    recorded = DatasetSpec(materials=10).to_json()["families"]
    from brdfgan.data.materials.families import FAMILIES

    assert recorded == list(FAMILIES)


@pytest.mark.integration
def test_ood_config_composes_with_its_folder_from_the_environment(scanned_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "plan"
    env = {"BRDFGAN_OOD_DIR": str(scanned_root), "PATH": "/usr/bin"}
    result = subprocess.run(
        [sys.executable, "generate.py", "dataset_spec=ood", "materials=2", "plan=true", f"out_dir={out}"],
        cwd=ROOT, capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert result.returncode == 2 and "materials" in result.stderr  # a top-level key, not the spec's
    result = subprocess.run(
        [sys.executable, "generate.py", "dataset_spec=ood", "dataset_spec.materials=2", "plan=true",
         f"out_dir={out}"],
        cwd=ROOT, capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "test" in result.stdout and "train" not in result.stdout.replace("train_", "")


@pytest.mark.integration
def test_eval_sensor_gives_val_and_test_predicts_intake(tiny_data: Path) -> None:
    from brdfgan.core.exposure import auto_expose
    from brdfgan.data.loading.datamodule import ShardDataModule
    from brdfgan.data.phone.sensor import SensorEffects, decode_srgb8, encode_srgb8

    intake = SensorEffects(
        enabled=True, vignetting_probability=0.0, white_balance_probability=0.0, noise_probability=0.0,
        jpeg_probability=0.0, auto_exposure=True,
    )  # fmt: skip
    data = str(tiny_data / "data" / "tiny")
    plain = ShardDataModule(data, batch_size=2, shuffle_buffer=0)
    module = ShardDataModule(data, batch_size=2, shuffle_buffer=0, eval_sensor=intake)
    for m in (plain, module):
        m.setup("test")
    stored, seen = next(iter(plain.test_dataloader())), next(iter(module.test_dataloader()))
    assert stored["key"] == seen["key"]
    for photo, got in zip(stored["photo"], seen["photo"], strict=True):
        expected, _ = auto_expose(decode_srgb8(encode_srgb8(photo)))
        assert torch.equal(got, expected.float()) and not torch.equal(got, photo)
