"""Tests of the metal families: polished_metal, metallic_paint, anodized_metal and tread_plate."""

from __future__ import annotations

import torch

from brdfgan.core.svbrdf import srgb_to_linear, validate_maps
from brdfgan.data.materials.albedo import METAL_F0_LINEAR, metal_basecolor
from brdfgan.data.materials.base import MaterialFamily
from brdfgan.data.materials.families import polished_metal

SIZE = 128


def _maps(family: MaterialFamily, params: dict[str, float], size: int = SIZE, seed: int = 0) -> torch.Tensor:
    maps = family.make_maps(params, size, torch.Generator().manual_seed(seed))
    validate_maps(maps)
    return maps


def _tilt_degrees(maps: torch.Tensor) -> torch.Tensor:
    """Angle of every normal from +Z. Shape: ``(8, H, W)`` → ``(H, W)``."""
    return torch.rad2deg(torch.acos(maps[5].clamp(-1.0, 1.0)))


def _f0(name: str) -> torch.Tensor:
    return torch.tensor(metal_basecolor(name)).view(3, 1, 1)


def test_polished_metal_is_exactly_the_named_metal_everywhere() -> None:
    assert set(polished_metal.METALS) <= set(METAL_F0_LINEAR)
    assert len(polished_metal.METALS) == 9
    for index, name in enumerate(polished_metal.METALS):
        # Fingerprints, haze and swirls at their strongest still leave the colour alone.
        maps = _maps(polished_metal.FAMILY, {"metal": index + 0.5, "smudge": 1.0, "swirl": 1.0}, size=64)
        assert torch.allclose(maps[0:3], _f0(name).expand(3, 64, 64), atol=1e-6), name
        assert torch.equal(maps[7], torch.ones(64, 64)), name
    # Gold is yellow, chrome neutral: the index really picks different measured colours.
    gold = srgb_to_linear(_f0("gold").flatten())
    assert gold[0] > 1.5 * gold[2]


def test_hammered_dents_tilt_the_normals_strongly() -> None:
    flat = {"hammered": 0.0, "waviness": 0.0, "swirl": 0.0}
    assert _tilt_degrees(_maps(polished_metal.FAMILY, flat)).max() < 1e-3
    half = _tilt_degrees(_maps(polished_metal.FAMILY, {**flat, "hammered": 0.5}))
    full = _tilt_degrees(_maps(polished_metal.FAMILY, {**flat, "hammered": 1.0}))
    assert 10.0 < full.mean() < 25.0 and full.flatten().quantile(0.95) > 20.0
    assert full.mean() > 1.7 * half.mean()
    # Relief is in image-width units: the tilt is alike at twice the resolution.
    full_256 = _tilt_degrees(_maps(polished_metal.FAMILY, {**flat, "hammered": 1.0}, size=256))
    assert abs(full_256.mean() - full.mean()) < 0.2 * full.mean()


def test_polished_metal_smudges_and_swirls_only_roughen() -> None:
    clean = {"roughness": 0.1, "smudge": 0.0, "swirl": 0.0}
    assert torch.allclose(_maps(polished_metal.FAMILY, clean, size=256)[6], torch.full((256, 256), 0.1))
    smudged = _maps(polished_metal.FAMILY, {**clean, "smudge": 1.0}, size=256)[6]
    swirled = _maps(polished_metal.FAMILY, {**clean, "swirl": 1.0}, size=256)[6]
    for roughness in (smudged, swirled):
        assert roughness.min() >= 0.1 - 1e-6
        assert (roughness > 0.15).float().mean() > 0.005
    assert smudged.mean() > 0.11
    # Swirls are thin lines: they touch little of the surface.
    assert (swirled > 0.11).float().mean() < 0.15
