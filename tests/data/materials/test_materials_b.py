"""Tests of the brushed-metal, rusted-metal, leather, concrete and ground material families."""

from __future__ import annotations

import pytest
import torch

from brdfgan.core.svbrdf import validate_maps
from brdfgan.data.materials.albedo import metal_basecolor
from brdfgan.data.materials.base import MaterialFamily
from brdfgan.data.materials.families import brushed_metal, concrete, ground, leather, rusted_metal
from tests.conftest import family_maps

FAMILIES: list[MaterialFamily] = [
    brushed_metal.FAMILY,
    rusted_metal.FAMILY,
    leather.FAMILY,
    concrete.FAMILY,
    ground.FAMILY,
]
SIZE = 128


@pytest.mark.parametrize("family", FAMILIES, ids=lambda f: f.name)
def test_defaults_and_samples_are_valid(family: MaterialFamily) -> None:
    generator = torch.Generator().manual_seed(123)
    for draw in range(4):
        params = {} if draw == 0 else family.sample_parameters(generator)
        for key, value in params.items():
            p = family.parameters[key]
            assert p.low <= value <= p.high
        maps = family_maps(family, params, seed=draw)
        assert maps.shape == (8, SIZE, SIZE)
        validate_maps(maps)
        assert (maps[5] < 0.9999).any(), "normals are all flat"
        assert maps[0:3].std() > 1e-3 and maps[6].std() > 1e-3


@pytest.mark.parametrize("family", [leather.FAMILY, concrete.FAMILY, ground.FAMILY], ids=lambda f: f.name)
def test_dielectric_families_not_metallic(family: MaterialFamily) -> None:
    generator = torch.Generator().manual_seed(9)
    for params in ({}, family.sample_parameters(generator)):
        assert torch.all(family_maps(family, params)[7] == 0.0)


def test_brushed_metal_metallic_and_scratches() -> None:
    family = brushed_metal.FAMILY
    generator = torch.Generator().manual_seed(3)
    for params in ({}, family.sample_parameters(generator), {"metal": 3.5, "vertical": 1.0}):
        assert torch.all(family_maps(family, params)[7] > 0.99)
    clean = family_maps(family, {"scratch_density": 0.0}, seed=1, size=256)
    scratched = family_maps(family, {"scratch_density": 1.0}, seed=1, size=256)
    assert scratched[6].mean() > clean[6].mean() + 0.01
    # Scratches tilt the normals: the tangential spread of the normals grows.
    assert scratched[3:5].std() > clean[3:5].std() * 1.1


def test_brushed_metal_base_colour_is_metal_f0() -> None:
    for metal, name in zip((0.0, 1.0, 2.0, 3.0), ("steel", "aluminium", "brass", "copper"), strict=True):
        f0 = torch.tensor(metal_basecolor(name)).view(3, 1, 1)
        maps = family_maps(brushed_metal.FAMILY, {"metal": metal + 0.5, "scratch_density": 0.0})
        # The measured F0, only shaded by smudges (darker, ≤ 6 %) and the brushing (± 1.5 %).
        ratio = maps[0:3] / f0
        assert ratio.max() <= 1.016 and ratio.min() >= 0.92, name
        assert torch.allclose(maps[0:3].mean(dim=(1, 2)), f0.flatten(), atol=0.03), name


def test_brushing_is_streaky_along_its_direction() -> None:
    maps = family_maps(brushed_metal.FAMILY, {"scratch_density": 0.0, "smudge": 0.0}, size=256)
    rough = maps[6]
    # Horizontal brushing: neighbours along a row are far more alike than neighbours down a column.
    along = (rough[:, 1:] - rough[:, :-1]).abs().mean()
    across = (rough[1:] - rough[:-1]).abs().mean()
    assert across > 2.0 * along


def test_rusted_metal_rust_is_rough_and_not_metallic() -> None:
    maps = family_maps(rusted_metal.FAMILY, size=256)
    rough, metal = maps[6].flatten(), maps[7].flatten()
    assert (metal < 0.01).any() and (metal > 0.99).any()
    assert torch.corrcoef(torch.stack([rough, metal]))[0, 1] < -0.2
    # Rust texels (orange: red well above blue) are non-metallic and rougher than bare metal.
    rust = (maps[0] - maps[2]).flatten() > 0.25
    assert rust.any()
    assert metal[rust].mean() < 0.05
    assert rough[rust].mean() > rough[metal > 0.99].mean() + 0.3


def test_rusted_metal_without_rust_or_paint_is_bare_steel() -> None:
    maps = family_maps(rusted_metal.FAMILY, {"rust_coverage": 0.0, "paint_coverage": 0.0})
    assert torch.all(maps[7] > 0.99)


def test_leather_weave_switch_gives_regular_threads() -> None:
    fabric = family_maps(leather.FAMILY, {"weave": 1.0, "threads": 64.0}, size=256)
    validate_maps(fabric)
    # 64 threads over 256 texels: the relief repeats every 2 threads = 8 texels (plain weave).
    nx = fabric[3]
    assert (nx - nx.roll(8, dims=1)).abs().mean() < 0.5 * (nx - nx.roll(4, dims=1)).abs().mean()
    assert fabric[6].mean() > family_maps(leather.FAMILY, {"weave": 0.0}, size=256)[6].mean()


def test_concrete_is_rough_with_dark_rough_pores() -> None:
    maps = family_maps(concrete.FAMILY, size=256)
    assert maps[6].mean() > 0.6
    no_pores = family_maps(concrete.FAMILY, {"pore_density": 0.0}, size=256)
    many = family_maps(concrete.FAMILY, {"pore_density": 0.25}, size=256)
    assert many[0:3].mean() < no_pores[0:3].mean()
    assert many[6].mean() > no_pores[6].mean()


def test_ground_pebbles_higher_than_soil() -> None:
    family = ground.FAMILY
    size = 256
    params = {"gravel": 0.8, "leaves": 0.0}
    generator = torch.Generator().manual_seed(4)
    layers = family.generate({**family.defaults(), **params}, size, generator)
    generator = torch.Generator().manual_seed(4)
    soil = family.generate({**family.defaults(), **params, "gravel": 0.0}, size, generator)
    pebble = layers.height != soil.height
    assert 0.05 < pebble.float().mean() < 0.95
    assert layers.height[pebble].mean() > soil.height[pebble].mean() + 0.5
    assert layers.height[pebble].mean() > layers.height[~pebble].mean()
    # Pebbles are smoother than the soil around them.
    assert layers.roughness[pebble].mean() < layers.roughness[~pebble].mean()
