"""Tests of the wood, tiles, bricks, stone and marble material families."""

from __future__ import annotations

import importlib

import pytest
import torch

from brdfgan.core.svbrdf import split_maps, validate_maps
from brdfgan.data.materials.base import MaterialFamily

SIZE = 128
MODULES = ("wood", "tiles", "bricks", "stone", "marble")


def _family(module: str) -> MaterialFamily:
    return importlib.import_module(f"brdfgan.data.materials.families.{module}").FAMILY


def _height_from_generate(family: MaterialFamily, params: dict[str, float], seed: int) -> torch.Tensor:
    layers = family.generate({**family.defaults(), **params}, SIZE, torch.Generator().manual_seed(seed))
    return layers.height


@pytest.fixture(params=MODULES)
def family(request: pytest.FixtureRequest) -> MaterialFamily:
    return _family(request.param)


def test_defaults_and_samples_give_valid_maps(family: MaterialFamily) -> None:
    generator = torch.Generator().manual_seed(0)
    draws = [family.defaults()] + [family.sample_parameters(generator) for _ in range(3)]
    for params in draws:
        maps = family.make_maps(params, SIZE, generator)
        assert maps.shape == (8, SIZE, SIZE)
        validate_maps(maps)
        parts = split_maps(maps)
        assert torch.equal(parts.metallic, torch.zeros_like(parts.metallic))  # all dielectrics
        assert parts.basecolor.min() >= 0.02 - 1e-6 and parts.basecolor.max() <= 0.95 + 1e-6
        assert (parts.normal[2] < 0.9999).float().mean() > 0.05  # some relief
        assert parts.basecolor.std() > 1e-3 and parts.roughness.std() > 1e-4


@pytest.mark.parametrize("module", ["wood", "tiles", "bricks"])
def test_joints_are_lower_and_rougher(module: str) -> None:
    family = _family(module)
    generator = torch.Generator().manual_seed(1)
    draws = [family.defaults()] + [family.sample_parameters(generator) for _ in range(3)]
    for seed, params in enumerate(draws):
        height = _height_from_generate(family, params, seed).flatten()
        maps = family.make_maps(params, SIZE, torch.Generator().manual_seed(seed))
        roughness = split_maps(maps).roughness.flatten()
        low = height <= height.quantile(0.10)
        high = height >= height.quantile(0.50)
        assert roughness[low].mean() > roughness[high].mean() + 0.02, (module, params)


@pytest.mark.parametrize("module", ["tiles", "bricks", "stone"])
def test_height_relief_scales_with_size(module: str) -> None:
    # Relief is a fraction of the image width, so normals look alike at every resolution once
    # bevels span a few texels: the mean normal tilt barely changes from 256² to 512².
    family = _family(module)
    tilts = []
    for size in (256, 512):
        maps = family.make_maps({}, size, torch.Generator().manual_seed(0))
        tilts.append((1.0 - split_maps(maps).normal[2]).mean().item())
    assert tilts[0] == pytest.approx(tilts[1], rel=0.3)


def test_marble_is_smoother_than_stone() -> None:
    marble, stone = _family("marble"), _family("stone")
    for seed in range(3):
        gen = torch.Generator().manual_seed(seed)
        m = marble.make_maps(marble.sample_parameters(gen), SIZE, gen)
        s = stone.make_maps(stone.sample_parameters(gen), SIZE, gen)
        assert split_maps(m).roughness.mean() < split_maps(s).roughness.mean() - 0.3
