"""The torch renderer against Mitsuba 3 ``principled`` + ``normalmap`` under a flash.

Mitsuba integrates each pixel's footprint (box filter) while our renderer shades texel centres,
so the torch side shades 4×4 points per pixel (``render_flash(..., supersample=4)``, maps
repeated nearest-neighbour like Mitsuba's texture filter) and averages them. Low-roughness
highlights are a few pixels wide, so those cases get more samples per pixel to keep Mitsuba's
Monte Carlo noise well under the tolerance.
"""

from __future__ import annotations

import pytest
import torch

from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import CHANNELS, flat_maps, normalize_normal
from tests.conftest import random_maps

pytestmark = [pytest.mark.mitsuba, pytest.mark.integration]

RESOLUTION = 48
SUPERSAMPLE = 4
TOLERANCE = 0.02
CAPTURE = FlashCapture(fov_deg=45.0, intensity=8.0)


@pytest.fixture(scope="module")
def variant() -> str:
    from brdfgan.mitsuba_render.variant import select_variant

    return select_variant()


def _torch_reference(maps: torch.Tensor) -> torch.Tensor:
    return render_flash(maps[None], CAPTURE, supersample=SUPERSAMPLE)[0]


def _mitsuba(maps: torch.Tensor, spp: int) -> torch.Tensor:
    from brdfgan.mitsuba_render.scene import render_flash_mitsuba

    return render_flash_mitsuba(maps, CAPTURE, spp=spp, seed=3)


def _relative_l1(ours: torch.Tensor, reference: torch.Tensor) -> float:
    return ((ours - reference).abs().sum() / reference.abs().sum()).item()


def _tilted(maps: torch.Tensor, x: float, y: float) -> torch.Tensor:
    maps = maps.clone()
    maps[CHANNELS["normal"]] = normalize_normal(torch.tensor([x, y, 1.0]).view(3, 1, 1)).expand(
        3, *maps.shape[1:]
    )
    return maps


def _cases() -> dict[str, tuple[torch.Tensor, int]]:
    n = RESOLUTION
    cases: dict[str, tuple[torch.Tensor, int]] = {}
    for metallic in (0.0, 1.0):
        for roughness in (0.1, 0.3, 0.6, 1.0):
            spp = 2048 if roughness < 0.2 else 128
            maps = flat_maps(n, n, basecolor=(0.8, 0.45, 0.2), roughness=roughness, metallic=metallic)
            cases[f"uniform-m{metallic:g}-r{roughness:g}"] = (maps, spp)
    cases["tilted-normal-dielectric-r0.3"] = (_tilted(flat_maps(n, n, roughness=0.3), 0.15, 0.3), 256)
    cases["tilted-normal-metal-r0.4"] = (
        _tilted(flat_maps(n, n, roughness=0.4, metallic=1.0), -0.2, 0.25),
        256,
    )
    cases["spatially-varying-bumpy"] = (random_maps(n, n, seed=11), 256)
    return cases


CASES = _cases()


@pytest.mark.parametrize("name", list(CASES))
def test_torch_renderer_agrees_with_mitsuba(variant: str, name: str) -> None:
    maps, spp = CASES[name]
    reference = _mitsuba(maps, spp)
    ours = _torch_reference(maps)
    assert reference.shape == ours.shape == (3, RESOLUTION, RESOLUTION)
    error = _relative_l1(ours, reference)
    assert error <= TOLERANCE, f"{name}: relative L1 {error:.4f} vs Mitsuba ({variant}, {spp} spp)"


def test_a_wrong_convention_is_caught(variant: str) -> None:
    # The check is sharp: flipping the Y of the normals (DirectX vs OpenGL) or the rows of the
    # maps exceeds the tolerance many times over.
    maps, spp = CASES["spatially-varying-bumpy"]
    reference = _mitsuba(maps, spp)
    flipped_y = maps.clone()
    flipped_y[4] = -flipped_y[4]
    assert _relative_l1(_torch_reference(flipped_y), reference) > 5 * TOLERANCE
    assert _relative_l1(_torch_reference(maps.flip(-2)), reference) > 5 * TOLERANCE
