"""Ground: bare soil with scattered gravel and fallen leaves, seen from above.

Depicts a patch of earth (garden bed, forest floor, path): a fractal soil base with clods and
small cracks, optional gravel (one jittered pebble per cell: raised domes, smoother and lighter
than the soil) and optional fallen leaves (almond-shaped, randomly oriented, green to brown, with
a midrib, lying on top of everything). Dielectric throughout; wet soil is darker and smoother.

Parameters:
    soil_value: brightness of the soil (sRGB).
    soil_hue: hue of the soil, in turns (reddish … yellowish brown).
    moisture: wetness (darker, smoother soil).
    gravel: fraction of pebble cells that hold a pebble (0 = no gravel).
    pebble_cells: pebbles per side (lattice cells, rounded).
    leaves: fraction of leaf cells that hold a leaf (0 = no leaves).
    leaf_cells: leaves per side (lattice cells, rounded).
    relief: soil relief, as a fraction of the image width (pebbles follow their own size).
    roughness: perceptual roughness of dry soil.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, lerp_color, texel_coordinates

LEAF_GREEN = (0.36, 0.42, 0.14)
LEAF_YELLOW = (0.62, 0.50, 0.18)
LEAF_BROWN = (0.42, 0.25, 0.10)


def _neighbour_offsets(size: int, cells: int) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Integer cell and fractional position of every texel in a periodic ``cells²`` lattice."""
    u, v = texel_coordinates(size)
    x, y = u * cells, v * cells
    i0, j0 = x.floor(), y.floor()
    return i0.long(), j0.long(), x - i0, y - j0


def _pebbles(size: int, cells: int, keep: float, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Domed pebbles, one per kept lattice cell: ``(dome, tone)``, dome in [0, 1] (0 off-pebble).

    Tracks the nearest feature point in a running minimum over the 9 neighbouring cells, which is
    much cheaper than sorting all 9 distances. Shape: each ``(size, size)``.
    """
    attrs = torch.rand((cells, cells, 6), generator=generator)
    points = 0.2 + 0.6 * attrs[..., :2]
    i0, j0, fu, fv = _neighbour_offsets(size, cells)
    dome = torch.zeros(size, size)
    tone = torch.zeros(size, size)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            i, j = (i0 + di) % cells, (j0 + dj) % cells
            a = attrs[j, i]
            du = di + points[j, i, 0] - fu
            dv = dj + points[j, i, 1] - fv
            # Elongated, rotated pebble: an ellipse in its own frame with radius 0.3–0.5 cells.
            angle = math.pi * a[..., 2]
            c, s = torch.cos(angle), torch.sin(angle)
            along, across = du * c + dv * s, -du * s + dv * c
            radius = 0.3 + 0.2 * a[..., 3]
            r2 = (along / radius) ** 2 + (across / (radius * (0.6 + 0.4 * a[..., 4]))) ** 2
            present = (a[..., 5] < keep).float()
            here = torch.sqrt((1.0 - r2).clamp(min=0.0)) * present * radius
            take = here > dome
            dome = torch.where(take, here, dome)
            tone = torch.where(take, a[..., 4], tone)
    return dome / 0.5, tone


def _leaves(size: int, cells: int, keep: float, generator: torch.Generator) -> tuple[Tensor, Tensor, Tensor]:
    """Leaves, one per kept lattice cell, overlapping by a random stacking order.

    Returns ``(cover, vein, colour_t)``: coverage in [0, 1], midrib mask, and a per-leaf colour
    parameter in [0, 1] (green → yellow → brown). Shape: each ``(size, size)``.
    """
    attrs = torch.rand((cells, cells, 6), generator=generator)
    i0, j0, fu, fv = _neighbour_offsets(size, cells)
    cover = torch.zeros(size, size)
    vein = torch.zeros(size, size)
    colour = torch.zeros(size, size)
    order = torch.full((size, size), -1.0)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            i, j = (i0 + di) % cells, (j0 + dj) % cells
            a = attrs[j, i]
            du = di + a[..., 0] - fu
            dv = dj + a[..., 1] - fv
            angle = 2.0 * math.pi * a[..., 2]
            c, s = torch.cos(angle), torch.sin(angle)
            along, across = du * c + dv * s, -du * s + dv * c
            # Almond outline: half-width follows a sine along the leaf length (0.7–1.1 cells).
            half_length = 0.35 + 0.2 * a[..., 3]
            t = (along / half_length).clamp(-1.0, 1.0)
            half_width = 0.42 * half_length * torch.cos(0.5 * math.pi * t) ** 0.8
            inside = (along.abs() < half_length) & (across.abs() < half_width)
            edge = smoothstep(0.0, 0.02, half_width - across.abs()) * inside.float()
            here = edge * (a[..., 5] < keep).float()
            # The leaf with the highest stacking order covering the texel wins (lies on top).
            take = (here > 0.0) & (a[..., 4] > order)
            cover = torch.where(take, here, cover)
            colour = torch.where(take, a[..., 4], colour)
            vein = torch.where(take, (1.0 - across.abs() / 0.012).clamp(0.0, 1.0) * (t.abs() < 0.95), vein)
            order = torch.where(take, a[..., 4], order)
    return cover, vein, colour


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    moisture = params["moisture"]

    # Soil: broad undulation plus crumbly clods; cracks where a ridged field peaks.
    broad = fbm(size, 4, generator, octaves=3)
    clods = fbm(size, 24, generator, octaves=4, persistence=0.6)
    height = params["relief"] * size * (0.6 * broad + 0.5 * clods)
    value = params["soil_value"] * (1.0 - 0.45 * moisture) * (1.0 + 0.15 * clods + 0.1 * broad)
    soil_rgb = torch.stack(
        [
            value * (1.0 + 0.25 * (1.0 - params["soil_hue"] / 0.12)),
            value * (0.78 + 0.1 * params["soil_hue"] / 0.12),
            value * 0.55,
        ]
    )
    basecolor = soil_rgb.clamp(0.02, 0.95)
    roughness = (params["roughness"] - 0.25 * moisture + 0.04 * clods).expand(1, size, size).clone()

    # Gravel: pebbles rise above the soil by a fraction of their own size; worn smooth by water
    # they are less rough than soil and grey-beige.
    cells = max(2, round(params["pebble_cells"]))
    if params["gravel"] > 0.0:
        dome, tone = _pebbles(size, cells, params["gravel"], generator)
        pebble = (dome > 0.0).float()
        pebble_height = 0.5 * (size / cells) * dome  # dome height ≈ half a pebble radius (texels)
        height = torch.where(dome > 0.0, torch.maximum(height, pebble_height + 0.3 * height), height)
        pebble_rgb = lerp_color((0.45, 0.43, 0.40), (0.68, 0.62, 0.52), tone) * (1.0 + 0.06 * clods)
        basecolor = torch.lerp(basecolor, pebble_rgb.clamp(0.02, 0.95), pebble[None])
        roughness = torch.lerp(roughness, (0.6 + 0.1 * tone - 0.15 * moisture)[None], pebble[None])

    # Leaves lie on top of everything: a thin sheet slightly above the local ground, curled up
    # towards the rim, waxy (smoother than soil).
    leaf_cells = max(1, round(params["leaf_cells"]))
    if params["leaves"] > 0.0:
        cover, vein, colour_t = _leaves(size, leaf_cells, params["leaves"], generator)
        leaf_rgb = torch.where(
            colour_t[None] < 0.5,
            lerp_color(LEAF_GREEN, LEAF_YELLOW, (2.0 * colour_t).clamp(0.0, 1.0)),
            lerp_color(LEAF_YELLOW, LEAF_BROWN, (2.0 * colour_t - 1.0).clamp(0.0, 1.0)),
        )
        leaf_rgb = leaf_rgb * (1.0 + 0.1 * clods - 0.2 * vein)
        lift = 0.004 * size * (1.0 + 0.3 * vein) + 0.5 * height.clamp(min=0.0)
        height = torch.lerp(height, lift + 0.3 * height, cover)
        basecolor = torch.lerp(basecolor, leaf_rgb.clamp(0.02, 0.95), cover[None])
        roughness = torch.lerp(roughness, (0.5 + 0.25 * colour_t)[None], cover[None])

    return MaterialLayers(
        basecolor=basecolor,
        height=height[None],
        roughness=roughness.clamp(0.0, 1.0),
        metallic=torch.zeros(1, size, size),
    )


FAMILY = MaterialFamily(
    name="ground",
    parameters={
        "soil_value": Parameter(0.32, 0.15, 0.5, "brightness of the soil (sRGB)"),
        "soil_hue": Parameter(0.07, 0.02, 0.12, "hue of the soil, in turns (reddish … yellowish brown)"),
        "moisture": Parameter(0.25, 0.0, 1.0, "wetness: darker, smoother soil"),
        "gravel": Parameter(0.4, 0.0, 1.0, "fraction of pebble cells holding a pebble (0 = none)"),
        "pebble_cells": Parameter(14.0, 6.0, 40.0, "pebbles per side (lattice cells, rounded)"),
        "leaves": Parameter(0.25, 0.0, 0.9, "fraction of leaf cells holding a leaf (0 = none)"),
        "leaf_cells": Parameter(5.0, 2.0, 10.0, "leaves per side (lattice cells, rounded)"),
        "relief": Parameter(0.006, 0.002, 0.015, "soil relief, fraction of the image width"),
        "roughness": Parameter(0.92, 0.8, 1.0, "perceptual roughness of dry soil"),
    },
    generate=_generate,
    description="Soil seen from above with optional gravel pebbles and scattered fallen leaves.",
    tags=("ground", "soil", "gravel", "leaves", "organic", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
