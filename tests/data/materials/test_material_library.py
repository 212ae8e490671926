"""Properties every registered material family must have, and the registry itself."""

from __future__ import annotations

import importlib
import pkgutil

import pytest
import torch

import brdfgan.data.materials.families as families_package
from brdfgan.core.svbrdf import split_maps, validate_maps
from brdfgan.data.materials.base import MaterialFamily
from brdfgan.data.materials.families import FAMILIES, UnknownFamilyError, get_family, resolve_families

SIZE = 64
# Every module of the package that defines a FAMILY, registered or not: a family under
# construction is held to the same standards before it joins the registry.
MODULE_FAMILIES = {
    info.name: importlib.import_module(f"{families_package.__name__}.{info.name}").FAMILY
    for info in pkgutil.iter_modules(families_package.__path__)
}
ALL = list(FAMILIES.values()) + [f for f in MODULE_FAMILIES.values() if f.name not in FAMILIES]


@pytest.fixture(params=ALL, ids=lambda f: f.name)
def family(request: pytest.FixtureRequest) -> MaterialFamily:
    return request.param


def test_registry_has_ten_distinct_families() -> None:
    assert len(FAMILIES) >= 10
    assert all(name == f.name for name, f in FAMILIES.items())
    assert resolve_families(None) == tuple(ALL)
    assert resolve_families(["marble", "bricks"]) == (FAMILIES["marble"], FAMILIES["bricks"])


def test_every_family_module_is_registered() -> None:
    unregistered = sorted(f.name for f in MODULE_FAMILIES.values() if FAMILIES.get(f.name) is not f)
    assert not unregistered, f"families defined but not in the registry: {unregistered}"


def test_unknown_or_repeated_family_is_a_one_line_error() -> None:
    with pytest.raises(UnknownFamilyError, match=r"family 'woood'; known: anodized_metal, asphalt"):
        get_family("woood")
    with pytest.raises(UnknownFamilyError, match="listed twice: marble"):
        resolve_families(["marble", "marble"])


def test_parameters_documented_with_sane_ranges(family: MaterialFamily) -> None:
    assert family.description and family.tags
    assert 4 <= len(family.parameters) <= 10
    for name, parameter in family.parameters.items():
        assert parameter.doc, name
        assert parameter.low < parameter.high, name


def test_maps_valid_for_defaults_and_samples(family: MaterialFamily) -> None:
    generator = torch.Generator().manual_seed(11)
    for params in (family.defaults(), family.sample_parameters(generator)):
        maps = family.make_maps(params, SIZE, generator)
        assert maps.shape == (8, SIZE, SIZE) and maps.dtype == torch.float32
        validate_maps(maps)  # ranges, finite, unit normals
        norm = split_maps(maps).normal.norm(dim=0)
        assert torch.allclose(norm, torch.ones_like(norm), atol=1e-5)


def test_sampling_in_range_centred_and_seeded(family: MaterialFamily) -> None:
    draws = [family.sample_parameters(torch.Generator().manual_seed(s)) for s in range(50)]
    assert draws[0] == family.sample_parameters(torch.Generator().manual_seed(0))
    for name, parameter in family.parameters.items():
        values = torch.tensor([d[name] for d in draws])
        assert values.min() >= parameter.low and values.max() <= parameter.high, name
        assert values.std() > 0, name
        # The median of a clipped normal stays at its centre, the default.
        assert abs(values.median().item() - parameter.default) < 0.35 * (parameter.high - parameter.low), name


def test_maps_seeded(family: MaterialFamily) -> None:
    def maps(seed: int) -> torch.Tensor:
        return family.make_maps({}, SIZE, torch.Generator().manual_seed(seed))

    assert torch.equal(maps(5), maps(5))
    assert not torch.equal(maps(5), maps(6))


def test_unknown_parameter_rejected(family: MaterialFamily) -> None:
    with pytest.raises(KeyError, match="no_such_parameter"):
        family.make_maps({"no_such_parameter": 1.0}, 16, torch.Generator().manual_seed(0))


def test_maps_tile_seamlessly(family: MaterialFamily) -> None:
    # Crops wrap around the material, so opposite borders must continue each other: the mean jump
    # across the seam is no larger than the largest jump between neighbouring interior lines
    # (grout or plank edges may lie on the border, so typical jumps are not the yardstick).
    maps = family.make_maps({}, 128, torch.Generator().manual_seed(0))
    for channels in (slice(0, 3), slice(3, 6), slice(6, 7)):
        x = maps[channels]
        for dim in (-2, -1):
            steps = (x - torch.roll(x, 1, dims=dim)).abs().mean(dim=(0, 1 if dim == -1 else 2))
            seam, interior = steps[0], steps[1:].max()
            assert seam <= 1.5 * interior + 1e-3, (family.name, channels, dim)


def test_every_parameter_at_its_bounds_gives_valid_maps(family: MaterialFamily) -> None:
    # σ = range/2 clips about a third of the draws to a bound, so the bounds are common inputs.
    corners = [
        {k: p.low for k, p in family.parameters.items()},
        {k: p.high for k, p in family.parameters.items()},
    ]
    corners += [{k: getattr(p, end)} for k, p in family.parameters.items() for end in ("low", "high")]
    for params in corners:
        validate_maps(family.make_maps(params, 32, torch.Generator().manual_seed(0)))
