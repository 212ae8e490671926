"""Diamond (tread) plate: a steel or aluminium floor plate with raised lozenges.

Depicts the checker/diamond plate of steps, truck beds, ramps and toolboxes: a bare metal sheet
(metallic 1, base colour the measured F0 of steel or aluminium) with raised, tapered lozenges on
a square grid, their long axes alternating between the two diagonals from one cell to the next
(the classic pattern). Traffic polishes the lozenge tops (smoother than the mill-finished plate,
unevenly from lozenge to lozenge); dirt collects in the valleys between the lozenges, mostly
against their flanks, and corrosion grows there: orange rust on steel, chalky white oxide on
aluminium. Dirt and corrosion are dielectric (metallic 0), rough and slightly raised; metallic is
below 1 only where they cover the plate, with soft edges only at their boundary.

Why it is in the dataset: the first ten families have no regular raised relief on a metal and
almost no metal at all; tread plate is one of the most photographed industrial surfaces, and it
teaches that a metal can be dirty in places (mixed metallic) while its worn tops stay bright.

Parameters:
    metal: base metal, rounded down: 0 steel, 1 aluminium (uniform: neither preferred).
    lozenge_count: lozenges per image width (rounded to an even number, so the alternating
        pattern tiles).
    relief: lozenge height as a fraction of the lozenge pitch.
    width: lozenge half-width across its long axis, as a fraction of the pitch.
    roughness: perceptual roughness of the mill-finished plate.
    wear: how much traffic has polished the lozenge tops (0 = as rough as the plate).
    dirt: fraction of the valleys covered by dirt.
    rust: fraction of the valleys corroded (rust on steel, white oxide on aluminium).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo, metal_basecolor
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    gradient_noise,
    lerp_color,
    random_per_cell,
    smooth_fbm,
    texel_coordinates,
    value_noise,
)

METALS: tuple[str, ...] = ("steel", "aluminium")
# Half-length of a lozenge along its diagonal, in pitch units (the lozenge spans 80 % of the
# half-diagonal each way and never reaches its cell's border).
_HALF_LENGTH = 0.4
# Dielectric colours (sRGB): grime, rust on steel, white oxide on aluminium.
_DIRT_DARK = (0.16, 0.14, 0.12)
_DIRT_LIGHT = (0.36, 0.32, 0.27)
_RUST_ORANGE = (0.55, 0.28, 0.11)
_RUST_BROWN = (0.3, 0.15, 0.07)
_OXIDE_WHITE = (0.78, 0.78, 0.75)
_OXIDE_GREY = (0.55, 0.56, 0.55)


def lozenge_profile(size: int, count: int, half_width: float) -> tuple[Tensor, Tensor, Tensor]:
    """Height profile in [0, 1] of the lozenge pattern, the distance across the nearest
    lozenge's axis in its (tapered) half-widths (< 1 on the lozenge, ∞ beyond its tips) and the
    grid cell of every texel.

    Cell ``(row, col)`` holds one lozenge centred in it, its long axis along the main diagonal
    when ``row + col`` is even and along the other diagonal when odd. Across its axis the
    lozenge is a half-ellipse (steep flanks, rounded top) whose half-width tapers to the tips.

    Shape: each ``(size, size)``; the cell ids are ``row·count + col``.
    """
    u, v = texel_coordinates(size)
    x, y = u * count, v * count
    col, row = x.floor().long().clamp(max=count - 1), y.floor().long().clamp(max=count - 1)
    lx, ly = x - x.floor() - 0.5, y - y.floor() - 0.5
    # Alternate the diagonal per cell: flipping x mirrors the lozenge onto the other diagonal.
    sign = 1.0 - 2.0 * ((row + col) % 2).to(torch.float32)
    lx = lx * sign
    along = (lx + ly) / math.sqrt(2.0)
    across = (ly - lx) / math.sqrt(2.0)
    taper = (1.0 - (along / _HALF_LENGTH) ** 2).clamp(min=0.0) ** 0.6
    # Beyond the tips (taper 0) no texel is on the lozenge, not even one on its axis.
    t = torch.where(taper > 0.0, across.abs() / (half_width * taper).clamp(min=1e-6), math.inf)
    return (1.0 - t * t).clamp(min=0.0).sqrt(), t, row * count + col


def _coverage(field: Tensor, fraction: float, edge: float, within: Tensor) -> Tensor:
    """Soft mask of the ``fraction`` of ``field`` over the ``within`` texels with the highest
    values (edge width ``edge``); exactly 0 everywhere for fraction 0. The level is a quantile of
    a subsample, for speed.

    Shape: field and within (bool) ``(H, W)`` → ``(H, W)``.
    """
    if fraction <= 0.0 or not within.any():
        return torch.zeros_like(field)
    sample = field[within][:: max(1, int(within.sum()) // 65536)]
    level = torch.quantile(sample, 1.0 - min(fraction, 1.0)).item()
    return smoothstep(level - edge, level + edge, field)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    name = METALS[min(max(int(params["metal"]), 0), len(METALS) - 1)]
    count = 2 * max(1, round(params["lozenge_count"] / 2.0))
    lozenge_height = params["relief"] * size / count  # texels
    profile, across, cell = lozenge_profile(size, count, params["width"])
    height = lozenge_height * profile

    # Traffic polishes the tops, more on some lozenges than others and more along a worn path.
    per_lozenge = random_per_cell(cell, count * count, generator)[0]
    path = value_noise(size, 3, generator)
    top = smoothstep(0.55, 0.9, profile)
    polish = params["wear"] * top * (0.5 + 0.5 * per_lozenge) * (0.6 + 0.8 * path).clamp(max=1.0)
    mill = gradient_noise(size, min(size, 8 * count), generator)  # mill finish blotches
    metal_rough = params["roughness"] * (1.0 + 0.1 * mill) * (1.0 - 0.65 * polish)

    # Valleys: the plate between lozenges. Traffic pushes dirt against the flanks, so its field
    # is raised within two lozenge half-widths of one.
    valley = 1.0 - smoothstep(0.0, 0.2, profile)
    in_valley = valley > 0.5
    grime = smooth_fbm(size, 6, generator, octaves=4, texels_per_cell=8)
    near_flank = smoothstep(3.0, 1.0, across)
    dirt = valley * _coverage(grime + 0.5 * near_flank, params["dirt"], 0.01, in_valley)
    # Corrosion starts where dirt holds moisture, then spreads in spots.
    spots = value_noise(size, min(size, 4 * count), generator)
    rust = valley * _coverage(0.6 * spots + 0.4 * grime, params["rust"], 0.01, in_valley)
    cover = 1.0 - (1.0 - dirt) * (1.0 - rust)

    grain = value_noise(size, min(size, 32 * count), generator)
    height = height + lozenge_height * (0.12 * dirt * (0.5 + grain) + 0.08 * rust * grain)

    if name == "steel":
        corrosion = lerp_color(_RUST_ORANGE, _RUST_BROWN, (0.3 + 0.7 * grain * spots).clamp(0.0, 1.0))
    else:
        corrosion = lerp_color(_OXIDE_WHITE, _OXIDE_GREY, grain)
    grime_color = lerp_color(_DIRT_DARK, _DIRT_LIGHT, (0.5 + grime).clamp(0.0, 1.0))
    share = torch.where(cover > 0.0, rust / cover.clamp(min=1e-6), torch.zeros_like(cover))
    dielectric = clamp_dielectric_albedo(grime_color + (corrosion - grime_color) * share[None])
    color = torch.tensor(metal_basecolor(name), dtype=torch.float32).view(3, 1, 1)
    basecolor = color + (dielectric - color) * cover[None]

    roughness = metal_rough + (0.88 + 0.08 * grain - metal_rough) * cover
    return MaterialLayers(
        basecolor=basecolor,
        height=height[None],
        roughness=roughness.clamp(0.0, 1.0)[None],
        metallic=(1.0 - cover)[None],
    )


FAMILY = MaterialFamily(
    name="tread_plate",
    parameters={
        "metal": Parameter(1.0, 0.0, 1.99, "base metal (floor): 0 steel, 1 aluminium", uniform=True),
        "lozenge_count": Parameter(8.0, 4.0, 20.0, "lozenges per image width (rounded to even)"),
        "relief": Parameter(0.06, 0.03, 0.1, "lozenge height, fraction of the lozenge pitch"),
        "width": Parameter(0.08, 0.05, 0.11, "lozenge half-width, fraction of the pitch"),
        "roughness": Parameter(0.38, 0.2, 0.6, "perceptual roughness of the mill-finished plate"),
        "wear": Parameter(0.4, 0.0, 1.0, "polish of the lozenge tops by traffic (smoother)"),
        "dirt": Parameter(0.3, 0.0, 1.0, "fraction of the valleys covered by dirt"),
        "rust": Parameter(0.15, 0.0, 1.0, "fraction of the valleys corroded (rust / white oxide)"),
    },
    generate=_generate,
    description="Steel or aluminium diamond plate with alternating raised lozenges, polished tops "
    "and dirt and corrosion in the valleys.",
    tags=("metal", "tread-plate", "industrial", "mixed-metallic", "tileable"),
)

__all__ = ["FAMILY", "METALS", "lozenge_profile"]
