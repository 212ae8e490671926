"""The Deschaintre 2018 baseline network and the converter for their dataset layout."""

from __future__ import annotations

import json
from pathlib import Path

import hydra
import numpy as np
import pytest
import torch
from hydra.errors import InstantiationException
from torch import Tensor, nn

from brdfgan.cli import main
from brdfgan.core.svbrdf import (
    diffuse_albedo,
    specular_albedo,
    split_maps,
    srgb_to_linear,
    validate_maps,
)
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.storage.shards import iter_shard, list_shards, read_manifest
from brdfgan.data.tools.deschaintre_dataset import (
    DeschaintreDatasetError,
    DeschaintreFormatError,
    albedos_to_basecolor_metallic,
    convert_deschaintre_folder,
    maps_from_deschaintre,
    maps_to_deschaintre,
    read_deschaintre_sample,
    write_deschaintre_sample,
)
from brdfgan.io.images import write_image
from brdfgan.models.deschaintre2018 import Deschaintre2018
from brdfgan.training.run import build
from tests.conftest import compose_train, random_maps

# 8-bit files: a quantisation step is 1/255; in linear units up to ~1.2/255 near 1 (sRGB slope).
STEP = 1.0 / 255.0


def rand(*shape: int, seed: int) -> Tensor:
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed))


def forward_albedos(basecolor_srgb: Tensor, metallic: Tensor) -> tuple[Tensor, Tensor]:
    linear = srgb_to_linear(basecolor_srgb)
    return diffuse_albedo(linear, metallic), specular_albedo(linear, metallic)


# --- diffuse/specular → base colour/metallic ---------------------------------------------------------


def test_albedo_inversion_recovers_maps_made_by_the_forward_formulas() -> None:
    # Base colours with mean linear value > 0.04 (sRGB >= 0.25): the inversion is unique there.
    basecolor, metallic = 0.25 + 0.75 * rand(2, 3, 48, 40, seed=0), rand(2, 1, 48, 40, seed=1)
    linear, m = albedos_to_basecolor_metallic(*forward_albedos(basecolor, metallic))
    assert linear.shape == (2, 3, 48, 40) and m.shape == (2, 1, 48, 40)
    assert (linear - srgb_to_linear(basecolor)).abs().max() < 1e-5
    assert (m - metallic).abs().max() < 1e-5


def test_albedo_inversion_with_binary_metallic_is_exact_for_any_colour() -> None:
    basecolor, metallic = rand(3, 64, 64, seed=2), (rand(1, 64, 64, seed=3) > 0.5).float()
    linear, m = albedos_to_basecolor_metallic(*forward_albedos(basecolor, metallic))
    assert (linear - srgb_to_linear(basecolor)).abs().max() < 1e-5
    assert (m - metallic).abs().max() < 1e-5


@pytest.mark.parametrize(
    ("gray", "metallic"), [(0.02, 0.0), (0.02, 1.0), (0.0, 0.0), (0.0, 1.0), (0.01, 0.0)]
)
def test_ambiguous_dark_grays_resolve_to_the_binary_dielectric_or_metal(gray: float, metallic: float) -> None:
    # b = 0.02, m = 0 and b = 0.04, m = 0.5 give the same d, s; black b = 0, m = 0 equals b = 0.04, m = 1.
    b, m = torch.full((3, 2, 2), gray), torch.full((1, 2, 2), metallic)
    linear, found = albedos_to_basecolor_metallic(diffuse_albedo(b, m), specular_albedo(b, m))
    assert (found - metallic).abs().max() < 1e-5 and (linear - gray).abs().max() < 1e-5


def test_albedo_inversion_of_inconsistent_maps_stays_in_range() -> None:
    # Colours the model cannot produce (specular above diffuse, specular below 0.04): a fit, no error.
    diffuse, specular = rand(3, 16, 16, seed=4), rand(3, 16, 16, seed=5)
    linear, m = albedos_to_basecolor_metallic(diffuse, specular)
    assert torch.isfinite(linear).all() and linear.min() >= 0 and linear.max() <= 1
    assert m.min() >= 0 and m.max() <= 1
    with pytest.raises(ValueError, match="diffuse and specular"):
        albedos_to_basecolor_metallic(diffuse, specular[:1])


def test_tile_conversion_round_trips_and_flip_green_negates_y() -> None:
    maps = random_maps(32, 24, seed=6)
    tiles = maps_to_deschaintre(maps)
    assert all(t.shape == (3, 32, 24) and t.min() >= 0 and t.max() <= 1 for t in tiles)
    direct = maps_from_deschaintre(*tiles)
    validate_maps(direct)
    assert (direct - maps).abs().max() < 1e-4
    flipped = maps_from_deschaintre(*maps_to_deschaintre(maps, flip_green=True))
    normal, normal_flipped = split_maps(maps).normal, split_maps(flipped).normal
    assert torch.allclose(normal_flipped[1], -normal[1], atol=1e-5)
    assert torch.allclose(normal_flipped[::2], normal[::2], atol=1e-5)
    back = maps_from_deschaintre(*maps_to_deschaintre(maps, flip_green=True), flip_green=True)
    assert (back - maps).abs().max() < 1e-4


# --- files and folders -------------------------------------------------------------------------------


def make_sample(seed: int, size: int = 32) -> tuple[Tensor, Tensor]:
    return rand(3, size, size, seed=100 + seed), random_maps(size, size, seed=seed)


def assert_close_after_8_bit(photo: Tensor, maps: Tensor, got_photo: Tensor, got_maps: Tensor) -> None:
    assert (got_photo - photo).abs().max() < 1.3 * STEP
    want, got = split_maps(maps), split_maps(got_maps)
    assert (got.basecolor - want.basecolor).abs().max() < 1.5 * STEP  # measured ≤ 1.0 step
    assert (got.normal - want.normal).abs().max() < 2 * STEP  # renormalised after rounding
    assert (got.roughness - want.roughness).abs().max() <= 0.5 * STEP + 1e-6
    # Rounding d and s can read a dark dielectric as slightly metallic (measured ≤ 0.032, mean 2e-4).
    assert (got.metallic - want.metallic).abs().max() < 0.05
    assert (got.metallic - want.metallic).abs().mean() < 2e-3


def test_sample_png_round_trip(tmp_path: Path) -> None:
    photo, maps = make_sample(0)
    path = write_deschaintre_sample(tmp_path / "0001;Wood planks;0Xdefault.png", photo, maps)
    sample = read_deschaintre_sample(path)
    assert sample.key == "0001_Wood_planks_0Xdefault"
    assert sample.meta["file"] == path.name and sample.meta["tile"] == 32
    assert_close_after_8_bit(photo, maps, sample.photo, sample.maps)


def test_crop_takes_the_centre_of_every_tile(tmp_path: Path) -> None:
    photo, maps = make_sample(1, size=40)
    path = write_deschaintre_sample(tmp_path / "a.png", photo, maps)
    full, cropped = read_deschaintre_sample(path), read_deschaintre_sample(path, crop=32)
    assert cropped.photo.shape == (3, 32, 32) and cropped.maps.shape == (8, 32, 32)
    assert torch.equal(cropped.photo, full.photo[:, 4:36, 4:36])
    assert torch.equal(cropped.maps, full.maps[:, 4:36, 4:36])
    with pytest.raises(DeschaintreFormatError, match=r"a\.png.*crop 48"):
        read_deschaintre_sample(path, crop=48)


def test_folder_conversion_writes_shards_and_manifest(tmp_path: Path) -> None:
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    originals = {}
    for i, name in enumerate(["b;x.png", "a;y.png", "c z.png"]):
        originals[name] = make_sample(i)
        write_deschaintre_sample(src / name, *originals[name])
    summary = convert_deschaintre_folder(src, out, samples_per_shard=2)
    assert summary.samples == 3 and len(summary.shards) == 2 and not summary.skipped
    assert [p.name for p in list_shards(out, "test")] == ["test-000000.tar", "test-000001.tar"]
    samples = [s for path in list_shards(out, "test") for s in iter_shard(path)]
    assert [s.key for s in samples] == ["000000_a_y", "000001_b_x", "000002_c_z"]  # sorted file names
    for sample in samples:
        assert_close_after_8_bit(*originals[sample.meta["file"]], sample.photo, sample.maps)
    manifest = read_manifest(out, "test")
    assert manifest["samples"] == 3 and manifest["source"]["files"] == 3
    assert [s["samples"] for s in manifest["shards"]] == [2, 1]
    assert manifest["conversion"]["flip_green"] is False and manifest["skipped"] == []


def test_converted_split_streams_through_the_datamodule(tmp_path: Path) -> None:
    src = tmp_path / "src"
    src.mkdir()
    for i in range(3):
        write_deschaintre_sample(src / f"{i}.png", *make_sample(i, size=16))
    convert_deschaintre_folder(src, tmp_path / "out")
    module = ShardDataModule(str(tmp_path / "out"), batch_size=2, train_split=None, val_split=None)
    module.setup("test")
    batches = list(module.test_dataloader())
    assert [b["photo"].shape[0] for b in batches] == [2, 1]
    assert batches[0]["maps"].shape == (2, 8, 16, 16)


def write_malformed(src: Path) -> Path:
    bad = src / "bad.png"
    write_image(bad, np.zeros((16, 64, 3), dtype=np.float32))  # four tiles, not five
    return bad


def test_malformed_file_is_a_one_line_error_naming_it(tmp_path: Path) -> None:
    bad = write_malformed(tmp_path)
    with pytest.raises(DeschaintreFormatError, match=r"bad\.png: expected 5 square tiles.*got 64×16") as info:
        read_deschaintre_sample(bad)
    assert "\n" not in str(info.value)
    (tmp_path / "corrupt.png").write_bytes(b"not a png")
    with pytest.raises(DeschaintreFormatError, match=r"corrupt\.png"):
        read_deschaintre_sample(tmp_path / "corrupt.png")


def test_folder_conversion_stops_or_skips_on_malformed_files(tmp_path: Path) -> None:
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    write_deschaintre_sample(src / "a.png", *make_sample(0, size=16))
    write_malformed(src)
    with pytest.raises(DeschaintreFormatError, match=r"bad\.png"):
        convert_deschaintre_folder(src, out)
    assert not (out / "test" / "manifest.json").exists()  # never mistaken for a complete split

    summary = convert_deschaintre_folder(src, out, skip_malformed=True, overwrite=True)
    assert summary.samples == 1 and [name for name, _ in summary.skipped] == ["bad.png"]
    manifest = read_manifest(out, "test")
    assert manifest["samples"] == 1 and manifest["skipped"][0]["file"] == "bad.png"


def test_existing_split_needs_overwrite_and_loses_stale_shards(tmp_path: Path) -> None:
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    for i in range(3):
        write_deschaintre_sample(src / f"{i}.png", *make_sample(i, size=16))
    convert_deschaintre_folder(src, out, samples_per_shard=1)
    with pytest.raises(DeschaintreDatasetError, match="already holds"):
        convert_deschaintre_folder(src, out)
    convert_deschaintre_folder(src, out, samples_per_shard=3, overwrite=True)
    assert len(list_shards(out, "test")) == 1
    with pytest.raises(DeschaintreDatasetError, match=r"no \.png files"):
        convert_deschaintre_folder(tmp_path / "out", tmp_path / "other")


def test_cli_converts_and_reports_errors_on_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "src"
    src.mkdir()
    write_deschaintre_sample(src / "a.png", *make_sample(0, size=16))
    assert (
        main(["convert-deschaintre", str(src), str(tmp_path / "out"), "--split", "val", "--flip-green"]) == 0
    )
    assert "1 sample(s) in 1 shard(s)" in capsys.readouterr().out
    assert json.loads((tmp_path / "out" / "val" / "manifest.json").read_text())["conversion"]["flip_green"]
    assert main(["convert-deschaintre", str(tmp_path / "missing"), str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "missing: source folder not found" in err and err.count("\n") == 1


# --- the baseline network ----------------------------------------------------------------------------


def count(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def test_paper_sized_network_parameter_count() -> None:
    with torch.device("meta"):
        net = Deschaintre2018(width=64, levels=8)
    # Tens of millions like the original: encoder 19.5 M, decoder 53.0 M, global track 7.4 M.
    assert count(net) == 79_994_560
    assert count(net.encoder) == 19_532_800 and count(net.decoder) == 53_036_032
    assert [conv.out_channels for conv in net.encoder] == [64, 128, 256, 512, 512, 512, 512, 512]


@pytest.mark.parametrize("size", [(64, 64), (64, 128)])
def test_output_is_a_valid_map_set(size: tuple[int, int]) -> None:
    net = Deschaintre2018(width=8, levels=6)
    with torch.no_grad():
        maps = net(rand(2, 3, *size, seed=7))
    assert maps.shape == (2, 8, *size)
    validate_maps(maps)
    assert Deschaintre2018(**net.config()).config() == {"in_channels": 3, "width": 8, "levels": 6}


def test_global_track_changes_the_output() -> None:
    net = Deschaintre2018(width=8, levels=6)
    photo = rand(1, 3, 64, 64, seed=8)
    with torch.no_grad():
        before = net(photo)
        for fc in net.global_to_features:
            fc.weight.mul_(50.0)
        after = net(photo)
        for fc in net.global_steps:
            fc.weight.zero_()
        without_means = net(photo)
    assert (after - before).abs().max() > 1e-3
    assert (without_means - after).abs().max() > 1e-3


def test_gradients_reach_every_parameter() -> None:
    net = Deschaintre2018(width=8, levels=6)
    maps = net(rand(2, 3, 64, 64, seed=9))
    (maps * torch.randn(maps.shape, generator=torch.Generator().manual_seed(0))).sum().backward()
    missing = [name for name, p in net.named_parameters() if p.grad is None or not p.grad.abs().sum() > 0]
    assert not missing


def test_normal_head_is_shared_with_the_generator_and_stored_only_when_not_the_default() -> None:
    from brdfgan.models.heads import GeneratorConfigError

    photo = rand(1, 3, 16, 16, seed=1)
    unit_z = Deschaintre2018(width=4, levels=4, normal_head="unit_z")
    assert unit_z.config() == {"in_channels": 3, "width": 4, "levels": 4, "normal_head": "unit_z"}
    rebuilt = Deschaintre2018(**unit_z.config())
    rebuilt.load_state_dict(unit_z.state_dict())
    torch.testing.assert_close(rebuilt(photo), unit_z(photo))
    # Same weights, the other head: a different normal map, the same other maps.
    softplus = Deschaintre2018(width=4, levels=4)
    softplus.load_state_dict(unit_z.state_dict())
    assert "normal_head" not in softplus.config()
    a, b = unit_z(photo), softplus(photo)
    torch.testing.assert_close(a[:, [0, 1, 2, 6, 7]], b[:, [0, 1, 2, 6, 7]])
    assert not torch.allclose(a[:, 3:6], b[:, 3:6])
    with pytest.raises(GeneratorConfigError, match=r"model\.generator\.normal_head='flat'"):
        Deschaintre2018(normal_head="flat")  # type: ignore[arg-type]


def test_wrong_input_is_a_value_error() -> None:
    net = Deschaintre2018(width=4, levels=6)
    with pytest.raises(ValueError, match=r"multiples of 64.*48×64"):
        net(rand(1, 3, 48, 64, seed=0))
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        net(rand(1, 4, 64, 64, seed=0))
    with pytest.raises(ValueError, match="levels"):
        Deschaintre2018(levels=0)


# --- config ------------------------------------------------------------------------------------------


@pytest.mark.integration
def test_config_composes_and_builds_without_discriminator(tmp_path: Path) -> None:
    cfg = compose_train(["model=deschaintre2018", "loss=no_adv", "loss.switches.feature=false"], tmp_path)
    keys = {"_target_", "in_channels", "width", "levels", "normal_head"}
    assert set(cfg.model.generator) == keys  # nothing of the default generator leaked
    _, module, _ = build(cfg)
    assert isinstance(module.generator, Deschaintre2018) and module.discriminator is None
    assert module.generator.config() == {"in_channels": 3, "width": 16, "levels": 8}
    with pytest.raises(InstantiationException, match="discriminator"):
        hydra.utils.instantiate(
            compose_train(["model=deschaintre2018", "loss=no_adv"], tmp_path).model,
            loss=hydra.utils.instantiate(compose_train(["loss=no_adv"], tmp_path).loss),
        )
