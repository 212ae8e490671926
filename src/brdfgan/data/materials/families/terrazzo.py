"""Terrazzo: chips of coloured stone and glass set in cement, ground flat and polished.

Depicts a terrazzo floor or counter: angular chips in several colours and sizes (a palette
built around ``chip_hue``: its own shades, an analogous hue, a complementary accent, white and
black marble and grey stone) embedded in a cement matrix of any pale colour with a fine sandy
speckle. The slab is ground flat and polished, so the relief is almost nil: the harder chips stand
a hair proud of the matrix, and tiny air pits (dark, dirt-filled, rough) dot the matrix. Chips are
polished smoother than the softer, micro-porous cement. Dielectric throughout.

Chips are Voronoi (Worley) cells shrunk towards their centres, which gives the convex, angular
outlines of crushed stone; a second, three times finer lattice adds small chips between the big
ones. Chip coverage is calibrated by a quantile so ``chip_density`` is the covered fraction.

Why it is in the dataset: terrazzo is common in public buildings, kitchens and shops, and it is
the only flat, polished, low-roughness dielectric with many small saturated colour patches:
the network must learn that colour edges without relief are not bumps.

Parameters:
    matrix_hue: hue of the cement matrix, in turns.
    matrix_saturation: saturation of the matrix (0 = white or grey cement).
    matrix_value: brightness of the matrix (sRGB).
    chip_hue: hue the chip palette is built around, in turns.
    chip_saturation: saturation of the coloured chips.
    chip_density: fraction of the surface covered by chips.
    chip_count: large chips per image width (small chips are three times denser).
    roughness: perceptual roughness of the polished chips (the matrix is a little rougher).
    pits: density of tiny air pits in the matrix (0 = none).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    hsv_to_rgb,
    random_per_cell,
    texel_coordinates,
    value_noise,
    worley,
)

# Chip palette: (hue offset from chip_hue, saturation factor, value low, value high, weight).
# Offsets and factors shape the colour scheme; the whites, blacks and greys are marble and stone.
_PALETTE: tuple[tuple[float, float, float, float, float], ...] = (
    (0.0, 1.0, 0.35, 0.85, 0.30),  # the main colour, light to dark
    (0.08, 0.9, 0.4, 0.8, 0.20),  # an analogous hue
    (0.5, 1.0, 0.4, 0.8, 0.10),  # a complementary accent
    (0.0, 0.03, 0.85, 0.93, 0.15),  # white marble
    (0.0, 0.05, 0.12, 0.25, 0.15),  # black marble
    (0.08, 0.08, 0.4, 0.65, 0.10),  # grey stone
)
# Height of the chips above the matrix and depth of the pits, fractions of the image width.
_CHIP_PROUD = 0.0002
_PIT_DEPTH = 0.002
_PIT_CELLS = 64  # pit lattice cells per image width
_MATRIX_EXTRA_ROUGHNESS = 0.07


def chip_layer(size: int, cells: int, density: float, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Angular chips covering about ``density`` of the surface: ``(coverage, cell_id)``.

    Each Voronoi cell holds one chip: the part of the cell farther than a threshold from its
    border (``f2 − f1`` is twice that distance), scaled per cell so chips differ in size. The
    threshold is the quantile that leaves ``density`` of the texels inside a chip. Coverage is
    1 inside, 0 outside, with a one-texel soft edge; ``cell_id`` indexes the chip of each texel.

    Shape: each ``(size, size)``.
    """
    f1, f2, cell_id = worley(size, cells, generator, jitter=1.0)
    scale = 0.5 + random_per_cell(cell_id, cells * cells, generator)[0]
    inset = (f2 - f1) * scale
    if density <= 0.0:
        return torch.zeros(size, size), cell_id
    sample = inset.flatten()[:: max(1, inset.numel() // 65536)]
    level = torch.quantile(sample, 1.0 - min(density, 0.99)).item()
    edge = 1.5 * cells / size  # about one texel of f2 − f1
    return smoothstep(level - 0.5 * edge, level + 0.5 * edge, inset), cell_id


def chip_colors(
    cell_id: Tensor, count: int, params: Mapping[str, float], generator: torch.Generator
) -> Tensor:
    """A palette colour per chip (sRGB), looked up per texel.

    Shape: cell_id ``(H, W)`` integers in ``[0, count)`` → ``(3, H, W)``.
    """
    draws = torch.rand((2, count), generator=generator)
    weights = torch.tensor([entry[4] for entry in _PALETTE])
    bounds = torch.cumsum(weights, 0) / weights.sum()
    index = torch.bucketize(draws[0], bounds).clamp(max=len(_PALETTE) - 1)
    table = torch.tensor([entry[:4] for entry in _PALETTE])[index]  # (count, 4)
    hue = (params["chip_hue"] + table[:, 0]) % 1.0
    saturation = (params["chip_saturation"] * table[:, 1]).clamp(0.0, 1.0)
    value = table[:, 2] + (table[:, 3] - table[:, 2]) * draws[1]
    colors = hsv_to_rgb(hue[None], saturation[None], value[None])[:, 0]  # (3, count): one per chip
    return colors[:, cell_id]


def pit_field(size: int, density: float, generator: torch.Generator) -> Tensor:
    """Tiny round pits in [0, 1] (1 at a pit's centre), at most one per lattice cell.

    A pit lies wholly inside its cell (centre at least one radius from the border), so one cell
    lookup per texel suffices, without a neighbour search. Shape: ``(size, size)``.
    """
    if density <= 0.0:
        return torch.zeros(size, size)
    cells = min(size, _PIT_CELLS)
    u, v = texel_coordinates(size)
    x, y = u * cells, v * cells
    col, row = x.floor().long().clamp(max=cells - 1), y.floor().long().clamp(max=cells - 1)
    attrs = torch.rand((4, cells * cells), generator=generator)
    cell = row * cells + col
    radius = 0.12 + 0.2 * attrs[0][cell]
    cx = radius + (1.0 - 2.0 * radius) * attrs[1][cell]
    cy = radius + (1.0 - 2.0 * radius) * attrs[2][cell]
    dx, dy = x - x.floor() - cx, y - y.floor() - cy
    present = attrs[3][cell] < 0.3 * density
    return (1.0 - (dx * dx + dy * dy) / (radius * radius)).clamp(min=0.0) * present


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    cells = max(2, round(params["chip_count"]))
    density = params["chip_density"]
    # Big chips take 70 % of the covered area; small ones fill that share of the remaining matrix.
    big_density = 0.7 * density
    small_density = (density - big_density) / (1.0 - big_density)
    big, big_id = chip_layer(size, cells, big_density, generator)
    small, small_id = chip_layer(size, 3 * cells, small_density, generator)
    small = small * (1.0 - big)
    chips = big + small

    grain = value_noise(size, min(size, 128), generator) - 0.5  # sand in the cement, veins in stone
    matrix_value = params["matrix_value"] * (1.0 + 0.08 * grain)
    matrix = hsv_to_rgb(
        torch.full_like(grain, params["matrix_hue"]),
        torch.full_like(grain, params["matrix_saturation"]),
        matrix_value.clamp(0.0, 1.0),
    )
    big_rgb = chip_colors(big_id, cells * cells, params, generator)
    small_rgb = chip_colors(small_id, 9 * cells * cells, params, generator)
    chip_rgb = (big_rgb * big[None] + small_rgb * small[None]) * (1.0 + 0.1 * grain)
    basecolor = matrix * (1.0 - chips)[None] + chip_rgb

    pits = pit_field(size, params["pits"], generator) * (1.0 - chips)
    pit = (pits > 0.0).float()
    basecolor = torch.lerp(basecolor, basecolor * 0.35, pit[None])
    height = size * (_CHIP_PROUD * chips - _PIT_DEPTH * pits)

    chip_roughness = params["roughness"]
    matrix_roughness = chip_roughness + _MATRIX_EXTRA_ROUGHNESS
    roughness = chip_roughness * chips + matrix_roughness * (1.0 - chips) + 0.02 * grain
    roughness = torch.lerp(roughness, torch.full_like(roughness, 0.85), pit)
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


FAMILY = MaterialFamily(
    name="terrazzo",
    parameters={
        "matrix_hue": Parameter(0.5, 0.0, 1.0, "hue of the cement matrix, in turns", uniform=True),
        "matrix_saturation": Parameter(0.06, 0.0, 0.45, "saturation of the matrix (0 = white or grey)"),
        "matrix_value": Parameter(0.8, 0.5, 0.93, "brightness of the matrix (sRGB)"),
        "chip_hue": Parameter(0.5, 0.0, 1.0, "hue the chip palette is built around, in turns", uniform=True),
        "chip_saturation": Parameter(0.4, 0.0, 0.9, "saturation of the coloured chips"),
        "chip_density": Parameter(0.4, 0.15, 0.7, "fraction of the surface covered by chips"),
        "chip_count": Parameter(14.0, 6.0, 40.0, "large chips per image width (small: 3× denser)"),
        "roughness": Parameter(0.12, 0.04, 0.35, "perceptual roughness of the polished chips"),
        "pits": Parameter(0.3, 0.0, 1.0, "density of tiny air pits in the matrix (0 = none)"),
    },
    generate=_generate,
    description="Polished terrazzo: multicoloured angular chips of several sizes in a pale cement matrix.",
    tags=("terrazzo", "stone", "polished", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
