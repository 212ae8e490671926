"""1-D patterns (``core/stripes.py``): stripes at any angle are found with their period, textures
with no period are not, and a tile made on their cell vectors keeps every stripe whole across its
wraps, where today's cut shifts them."""

from __future__ import annotations

import math

import pytest
import torch
from torch import Tensor

from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.lattice import CellTile, autocorrelation, detection_features, tile_whole_cells
from brdfgan.core.seamless import make_seamless
from brdfgan.core.stripes import (
    Stripes,
    choose_stripe_cells,
    find_stripe_perspective,
    find_stripes,
    ridge_direction,
    ridge_means,
)
from brdfgan.core.svbrdf import BASECOLOR, join_maps, normalize_normal
from tests.core.test_lattice import SIZE, noise_maps


def stripe_phase(points: Tensor, period: float, degrees: float) -> Tensor:
    """The stripes' phase (radians) at points ``(..., 2)`` ``(x, y)``: constant along ``degrees``."""
    radians = math.radians(degrees)
    across = -math.sin(radians) * points[..., 0] + math.cos(radians) * points[..., 1]
    return 2 * math.pi * across / period


def planks(
    period: float,
    degrees: float,
    *,
    seed: int = 0,
    size: int = SIZE,
    keystone: tuple[float, float] = (0.0, 0.0),
) -> Tensor:
    """Stripes of ``period`` px at ``degrees`` in the base colour (a cosine: its value is known at
    every point), grooves in the normals, and grain along the stripes in the roughness (so that
    copies one period apart agree in the stripes, not in everything). ``keystone``: the plane seen
    in mild perspective, its scale changing by that much from the centre to the right and bottom
    edges (``q = c + d / (1 + g·d)``, ``g = keystone / half side``, as ``tests/core/test_lattice``'s
    lattices)."""
    axis = torch.arange(size, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    dx, dy = xx - size / 2, yy - size / 2
    depth = 1.0 + (keystone[0] * dx + keystone[1] * dy) / (size / 2)
    xx, yy = size / 2 + dx / depth, size / 2 + dy / depth
    phase = stripe_phase(torch.stack([xx, yy], dim=-1), period, degrees)
    luminance = 0.5 + 0.3 * torch.cos(phase)
    basecolor = luminance * torch.tensor([1.0, 0.8, 0.6], dtype=torch.float64).view(3, 1, 1)
    radians = math.radians(degrees)
    slope = 0.3 * torch.sin(phase)
    normal = normalize_normal(
        torch.stack([-slope * -math.sin(radians), slope * math.cos(radians), torch.ones_like(slope)])
    )
    grain = torch.rand(1, 1, size, size, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    roughness = (0.5 + 2.0 * (gaussian_blur(grain, 4.0, "reflect")[0] - 0.5)).clamp(0, 1)
    return join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))


@pytest.mark.parametrize(("period", "degrees"), [(11.3, 30.0), (17.0, 0.0), (9.5, 120.0), (23.7, 75.0)])
def test_stripes_are_found_with_their_period_and_direction(period: float, degrees: float) -> None:
    found = find_stripes(planks(period, degrees))
    assert found is not None
    assert found.period == pytest.approx(period, rel=0.01)
    assert abs((found.direction_deg - degrees + 90.0) % 180.0 - 90.0) <= 0.5
    # A period across: the stripes' phase changes by a whole turn along it and not at all along d.
    origin = torch.tensor([50.0, 60.0], dtype=torch.float64)
    turn = stripe_phase(origin + torch.tensor(found.across), period, degrees) - stripe_phase(
        origin, period, degrees
    )
    assert abs(abs(float(turn)) - 2 * math.pi) < 0.02 * 2 * math.pi
    along = torch.tensor(found.cell_vectors()[1], dtype=torch.float64)
    assert float(
        stripe_phase(origin + along, period, degrees) - stripe_phase(origin, period, degrees)
    ) == pytest.approx(0.0, abs=1e-9)


def test_textures_with_no_period_have_no_stripes() -> None:
    assert find_stripes(noise_maps(3)) is None
    assert find_stripes(noise_maps(4, sigma=8.0)) is None


def test_stripes_too_wide_to_repeat_three_times_are_none() -> None:
    assert find_stripes(planks(70.0, 10.0)) is None  # under three periods across the maps


def whole_period_tile(maps: Tensor) -> tuple[Stripes, CellTile]:
    """The maps' stripes and the tile of whole periods across them (``make_tileable``'s stripes
    path without the flash repair)."""
    found = find_stripes(maps)
    assert found is not None
    cells = choose_stripe_cells(found, maps.shape[-2], maps.shape[-1])
    assert cells is not None
    return found, tile_whole_cells(maps, cells)


def test_a_tile_on_the_stripes_cell_vectors_keeps_every_stripe_whole() -> None:
    period, degrees = 11.3, 30.0
    maps = planks(period, degrees)
    found, tile = whole_period_tile(maps)
    # Where each tile pixel came from (before the roll), and so the base colour it must show.
    tiling = tile.tiling
    axis = torch.arange(SIZE, dtype=torch.float64) + 0.5
    rows, columns = torch.meshgrid(
        (axis + tiling.roll[0]) / SIZE, (axis + tiling.roll[1]) / SIZE, indexing="ij"
    )
    source = (
        torch.tensor(tiling.origin, dtype=torch.float64)
        + columns[..., None] * torch.tensor(tiling.u, dtype=torch.float64)
        + rows[..., None] * torch.tensor(tiling.v, dtype=torch.float64)
    )
    expected = 0.5 + 0.3 * torch.cos(stripe_phase(source, period, degrees))
    error = (tile.maps[BASECOLOR][0] - expected).abs()
    assert float(error.max()) < 0.03, float(error.max())
    # Today's cut joins copies that are not whole periods apart: somewhere along a stripe its
    # value steps, where the whole-period tile's stays as the stripe's.
    along = torch.tensor(found.along, dtype=torch.float64)
    affine = tiling.affine()
    tile_along = affine @ along / (affine @ along).norm()
    cut = make_seamless(maps).maps[BASECOLOR][0]
    assert along_step(tile.maps[BASECOLOR][0], tile_along) < 0.03
    assert along_step(cut, along) > 0.15


def along_step(image: Tensor, direction: Tensor, distance: float = 4.0) -> float:
    """The largest change of a wrapping image ``(H, W)`` over ``distance`` pixels along
    ``direction`` ``(dx, dy)``, bilinear, across its wraps."""
    height, width = image.shape
    sheet = image.repeat(3, 3)[None, None]
    axis_y = torch.arange(height, dtype=torch.float64) + height + 0.5
    axis_x = torch.arange(width, dtype=torch.float64) + width + 0.5
    yy, xx = torch.meshgrid(axis_y, axis_x, indexing="ij")
    moved_x, moved_y = xx + distance * float(direction[0]), yy + distance * float(direction[1])
    grid = torch.stack([2 * moved_x / (3 * width) - 1, 2 * moved_y / (3 * height) - 1], dim=-1)
    shifted = torch.nn.functional.grid_sample(sheet, grid[None], align_corners=False)[0, 0]
    return float((shifted - image).abs().max())


def test_stripes_round_trip_through_json() -> None:
    found = find_stripes(planks(11.3, 30.0))
    assert found is not None and Stripes.from_json(found.to_json()) == found


@pytest.mark.parametrize("degrees", [0.0, 15.0, 30.0, 45.0, 60.0])
def test_stripes_in_mild_perspective_give_its_keystone(degrees: float) -> None:
    # Level stripes too: there the scale change across them shows in their period, and the one
    # along them only in their slight convergence, which the offsets across the ridge read.
    keystone = (0.02, -0.015)
    maps = planks(11.3, degrees, keystone=keystone, size=256)
    found = find_stripes(maps)
    assert found is not None
    perspective = find_stripe_perspective(maps, found)
    assert perspective is not None and perspective.keystone == pytest.approx(keystone, abs=0.004)
    assert perspective.spread_after < 0.5 * perspective.spread_before
    # Square-on stripes have none to take out.
    assert find_stripe_perspective(planks(11.3, degrees, size=256), found) is None


@pytest.mark.parametrize("degrees", [0.3, -0.4, 30.25])
def test_the_ridge_direction_reads_a_tilt_of_tenths_of_a_degree(degrees: float) -> None:
    rho = autocorrelation(detection_features(planks(11.3, degrees, size=256))[0])
    start = round(degrees)
    assert ridge_direction(rho, float(start), 0.35 * 256) == pytest.approx(degrees, abs=0.05)
    # The test can fail: the mean along lines favours the pixel grid near an axis.
    if start == 0:
        angles, means = ridge_means(rho, 0.35 * 256, torch.arange(-1.0, 1.05, 0.1, dtype=rho.dtype))
        assert float(angles[int(torch.argmax(means))]) == pytest.approx(0.0, abs=1e-9)
