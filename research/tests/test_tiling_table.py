"""The lattice measures of research/tiling_table.py on a synthetic periodic material: a whole-cell
tile keeps every cell whole and repeats with the true period; a tile with a seam that shifts the
pattern, and today's cut on a turned lattice, do not. Fast (CPU seconds), no data files."""

from __future__ import annotations

import doctest
import math

import pytest
import torch
from tests.core.test_stripes import whole_period_tile
from torch import Tensor

import research.tiling_table as table
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.lattice import choose_cells, find_lattice, tile_whole_cells
from brdfgan.core.seamless import make_seamless
from brdfgan.core.stripes import find_stripes
from brdfgan.core.svbrdf import join_maps, normalize_normal
from research.tiling_table import (
    Frame,
    check_cells,
    period_error,
    photo_frame,
    snap_to_period,
    tile_frame_reference,
    transform_vectors,
)

SIDE = 128  # the material's side: 4 × 4 cells of 32 px
CELL = 32.0
CROP = 160
MATERIAL_LATTICE = ((CELL, 0.0), (0.0, CELL))


def periodic_material(seed: int = 0) -> Tensor:
    """Tiles on a square grid of :data:`CELL` px, periodic on the material's side: recessed grout
    3 px wide, each tile its own shade and fine noise (so that no two cells are identical and a copy
    matches one place only). Shape: ``(8, SIDE, SIDE)`` float64."""
    generator = torch.Generator().manual_seed(seed)
    axis = torch.arange(SIDE, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    to_edge = torch.minimum(
        (xx - CELL * torch.round(xx / CELL)).abs(), (yy - CELL * torch.round(yy / CELL)).abs()
    )
    grout = torch.exp(-((to_edge / 1.5) ** 2))
    cells = int(SIDE / CELL)
    shade = 0.15 * torch.rand(cells, cells, generator=generator, dtype=torch.float64)
    index_y = torch.floor(yy / CELL).long() % cells
    index_x = torch.floor(xx / CELL).long() % cells
    noise = torch.rand(1, 1, SIDE, SIDE, generator=generator, dtype=torch.float64)
    # Blurred with wrap-around, so that the material stays periodic on its side.
    padded = torch.nn.functional.pad(noise, (8, 8, 8, 8), mode="circular")
    speckle = gaussian_blur(padded, 1.0)[0, 0, 8:-8, 8:-8] - 0.5
    luminance = (0.6 + shade[index_y, index_x] - 0.4 * grout + 0.1 * speckle).clamp(0, 1)
    basecolor = luminance * torch.tensor([1.0, 0.9, 0.8], dtype=torch.float64).view(3, 1, 1)
    gy, gx = torch.gradient(-grout)
    normal = normalize_normal(torch.stack([-0.5 * gx, 0.5 * gy, torch.ones_like(gx)]))
    roughness = (0.4 + 0.4 * grout)[None]
    return join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))


@pytest.fixture(scope="module")
def material() -> Tensor:
    return periodic_material()


def whole_cell_tile(crop: Tensor) -> tuple[Tensor, Tensor, Tensor, table.PointMap, Tensor]:
    """The lattice path on a crop: the tile, the untiled maps on its grid with where they are valid,
    their map to crop positions, and the tiling's affine map."""
    lattice = find_lattice(crop)
    assert lattice.periodic and lattice.vectors is not None, lattice
    tiling = choose_cells(lattice.vectors, *crop.shape[-2:])
    assert tiling is not None
    tile = tile_whole_cells(crop, tiling).maps
    reference, valid, to_crop = tile_frame_reference(crop, tiling.affine(), tiling.origin)
    return tile, reference, valid, to_crop, tiling.affine()


def test_the_frames_truth_is_what_the_crop_shows(material: Tensor) -> None:
    # The true vectors, turned back by the frame, are the lattice find_lattice sees in the crop.
    frame = Frame(CROP, 30.0)
    found = find_lattice(photo_frame(material, frame))
    assert found.vectors is not None
    assert period_error(found.vectors, frame.crop_vectors(MATERIAL_LATTICE))[0] < 0.01
    # And the flat material's lattice snaps exactly onto its period.
    flat = find_lattice(material)
    assert flat.vectors is not None
    snapped = snap_to_period(flat.vectors, SIDE)
    assert snapped is not None and period_error(snapped, MATERIAL_LATTICE) == (0.0, 0.0)


def test_a_whole_cell_tile_keeps_every_cell_and_the_period(material: Tensor) -> None:
    frame = Frame(CROP, 30.0)
    crop = photo_frame(material, frame)
    tile, reference, valid, to_crop, affine = whole_cell_tile(crop)
    tile_lattice = transform_vectors(affine, frame.crop_vectors(MATERIAL_LATTICE))
    check = check_cells(
        tile,
        reference,
        valid,
        tile_lattice,
        lambda p: frame.to_material(to_crop(p), (SIDE, SIDE)),
        MATERIAL_LATTICE,
    )
    assert check.jumps.numel() >= 10
    assert check.share() == 1.0, check
    assert float(check.jumps.max()) < 0.5 and float(check.unexplained.max()) < 0.1
    # Repeated 2 × 2 it shows the true lattice, as the resampling maps it.
    sheet = find_lattice(tile.repeat(1, 2, 2))
    length, angle = period_error(sheet.vectors, tile_lattice)
    assert length < 0.01 and angle < 0.5


def test_an_exact_tiling_has_no_period_error(material: Tensor) -> None:
    # An unturned crop of a whole number of periods is itself a tile: every cell whole, the
    # period exact.
    frame = Frame(SIDE, 0.0)
    crop = photo_frame(material, frame)
    identity = torch.ones(SIDE, SIDE, dtype=torch.bool)
    check = check_cells(
        crop, crop, identity, MATERIAL_LATTICE, lambda p: frame.to_material(p, (SIDE, SIDE)), MATERIAL_LATTICE
    )
    assert check.share() == 1.0 and float(check.jumps.max()) < 1e-6
    sheet = find_lattice(crop.repeat(1, 2, 2))
    length, angle = period_error(sheet.vectors, MATERIAL_LATTICE)
    assert length < 1e-3 and angle < 0.1


def test_a_seam_that_shifts_the_pattern_breaks_the_cells_it_crosses(material: Tensor) -> None:
    # The whole-cell tile with its lower half moved along by a third of a cell (in the tile's
    # pixels): the seams at its middle and at its wrap shift the lattice by ~10 px, so every
    # cell that either crosses is broken, and only those.
    frame = Frame(CROP, 30.0)
    crop = photo_frame(material, frame)
    tile, reference, valid, to_crop, affine = whole_cell_tile(crop)
    broken = tile.clone()
    half = tile.shape[-2] // 2
    broken[:, half:] = torch.roll(tile[:, half:], 10, dims=-1)
    tile_lattice = transform_vectors(affine, frame.crop_vectors(MATERIAL_LATTICE))

    def to_material(points: Tensor) -> Tensor:
        return frame.to_material(to_crop(points), (SIDE, SIDE))

    check = check_cells(broken, reference, valid, tile_lattice, to_material, MATERIAL_LATTICE)
    assert 0.2 < check.share() < 0.8, check
    assert float(check.jumps.max()) > 5.0
    # The share counts cells, not pixels: the same break at a tolerance above it passes.
    assert check.share(tolerance=20.0) == 1.0


def test_todays_cut_on_a_turned_lattice_breaks_cells(material: Tensor) -> None:
    # Today's cut joins copies shifted by a whole number of pixels, not of cells, where the
    # lattice is turned (tests/core/test_lattice.py shows it by the cells' centres).
    frame = Frame(CROP, 30.0)
    crop = photo_frame(material, frame)
    identity = torch.ones(CROP, CROP, dtype=torch.bool)
    tile = make_seamless(crop).maps
    check = check_cells(
        tile,
        crop,
        identity,
        frame.crop_vectors(MATERIAL_LATTICE),
        lambda p: frame.to_material(p, (SIDE, SIDE)),
        MATERIAL_LATTICE,
    )
    assert check.share() < 0.8, check
    assert float(check.jumps.max()) > 2.0


def test_a_blend_is_not_a_copy(material: Tensor) -> None:
    # A tile whose pixels are no copy of the maps (here: the maps blended with themselves half a
    # cell on) has no whole cell: where the blend passes for either copy, the two are half a cell
    # apart; elsewhere it is no copy at all.
    frame = Frame(SIDE, 0.0)
    crop = photo_frame(material, frame)
    blended = 0.5 * (crop + torch.roll(crop, 16, dims=-1))
    identity = torch.ones(SIDE, SIDE, dtype=torch.bool)
    check = check_cells(
        blended,
        crop,
        identity,
        MATERIAL_LATTICE,
        lambda p: frame.to_material(p, (SIDE, SIDE)),
        MATERIAL_LATTICE,
    )
    assert check.share() == 0.0
    assert bool(((check.jumps >= 15.0) | (check.unexplained > table.MAX_UNEXPLAINED)).all())


def test_perspective_is_part_of_the_truth(material: Tensor) -> None:
    # In perspective the frame's map to the material is what the crop was sampled through: the
    # crop's pixel is the material at that point (bilinear), and the Jacobian at the centre is
    # the turn alone.
    frame = Frame(CROP, 15.0, (0.02, 0.015))
    crop = photo_frame(material, frame)
    centre = torch.tensor([[CROP / 2, CROP / 2]], dtype=torch.float64)
    jacobian = table._jacobians(lambda p: frame.to_material(p, (SIDE, SIDE)), centre)[0]
    assert torch.allclose(jacobian, table.rotation(15.0), atol=1e-6)
    assert crop.shape == (8, CROP, CROP)
    assert math.isfinite(float(crop.sum()))


def test_doctests() -> None:
    result = doctest.testmod(table, optionflags=doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted >= 2


def stripe_material(seed: int = 0) -> Tensor:
    """Planks along x, one every 16 px (8 a side), periodic on the material's side: a dark gap
    between them, each plank its own shade and grain that runs along it. Shape: ``(8, SIDE, SIDE)``."""
    generator = torch.Generator().manual_seed(seed)
    axis = torch.arange(SIDE, dtype=torch.float64) + 0.5
    yy = axis.view(-1, 1).expand(SIDE, SIDE)
    width = 16.0
    gap = torch.exp(-(((yy - width * torch.round(yy / width)) / 1.2) ** 2))
    shade = 0.2 * torch.rand(int(SIDE / width), generator=generator, dtype=torch.float64)
    noise = torch.rand(1, 1, SIDE, SIDE, generator=generator, dtype=torch.float64)
    padded = torch.nn.functional.pad(noise, (8, 8, 8, 8), mode="circular")
    grain = gaussian_blur(padded, 1.5)[0, 0, 8:-8, 8:-8] - 0.5
    luminance = 0.55 + shade[torch.floor(yy / width).long() % len(shade)] - 0.4 * gap + 0.2 * grain
    basecolor = luminance.clamp(0, 1) * torch.tensor([1.0, 0.8, 0.6], dtype=torch.float64).view(3, 1, 1)
    gy, gx = torch.gradient(-gap)
    normal = normalize_normal(torch.stack([-0.5 * gx, 0.5 * gy, torch.ones_like(gx)]))
    roughness = (0.5 + 0.3 * gap)[None]
    return join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))


def test_stripes_tiled_by_whole_periods_stay_whole_where_the_cut_shifts_them() -> None:
    material = stripe_material()
    cells, material_lattice, how = table.true_stripes(material)
    assert how == "snapped" and math.hypot(*cells[0]) == pytest.approx(16.0)
    frame = Frame(CROP, 30.0)
    crop = photo_frame(material, frame)
    _, tiled = whole_period_tile(crop)
    tile, tiling = tiled.maps, tiled.tiling  # closed on the maps: its edges as the tile was cut
    reference, valid, to_crop = tile_frame_reference(crop, tiling.affine(), tiling.origin)
    tile_cells = transform_vectors(tiling.affine(), frame.crop_vectors(cells))

    def to_material(points: Tensor) -> Tensor:
        return frame.to_material(to_crop(points), (SIDE, SIDE))

    whole = check_cells(tile, reference, valid, tile_cells, to_material, material_lattice)
    assert whole.jumps.numel() >= 10 and whole.share() == 1.0, whole
    length, angle = table.stripes_period_error(find_stripes(tile.repeat(1, 2, 2)), tile_cells)
    assert length < 0.01 and angle < 0.5
    # Today's cut joins copies that are not whole periods apart across the planks.
    cut = make_seamless(crop).maps
    identity = torch.ones(CROP, CROP, dtype=torch.bool)
    crop_cells = frame.crop_vectors(cells)
    shifted = check_cells(
        cut,
        crop.double(),
        identity,
        crop_cells,
        lambda p: frame.to_material(p, (SIDE, SIDE)),
        material_lattice,
    )
    assert shifted.share() < 1.0 and float(shifted.jumps.max()) > 3.0, shifted
