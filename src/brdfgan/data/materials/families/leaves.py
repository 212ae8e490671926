"""Leaves: fallen leaves piled over soil, moss or tree bark, seen from above.

Depicts leaf litter: three layers of overlapping leaves (ovate outlines, random orientation, size and
aspect) lying over an organic ground of bare soil, a moss carpet or tree bark. Each leaf has a
raised midrib and grooved lateral veins, is cupped and arched (dry leaves curl more), and its colour
follows the season, from fresh green through yellow and red to dry brown, with per-leaf spread,
blotches and lighter veins. Fresh leaves are waxy (low roughness), dry ones matte. Overlaps stack:
every leaf lies at its own level, so the outlines of upper leaves are steps in the relief.
Dielectric throughout.

Leaves sit on a jittered lattice with their centres kept in the middle of their cell and their
reach below 0.85 cells, so only the 2 × 2 nearest cells can cover a texel: four candidates per
layer instead of a full 3 × 3 search.

Why it is in the dataset: foliage and leaf litter are in most outdoor photos, and the dataset had
no saturated greens, yellows and reds on a strongly stacked organic relief, nor the waxy gloss of
living leaves (the ``ground`` family's sparse leaves are flat and matte decoration of soil).

Parameters:
    cover: fraction of leaf places that hold a leaf, in each of the three layers (0 = bare ground).
    leaf_count: leaf places per side in each layer (rounded).
    season: mean leaf colour: 0 fresh green, 1/3 yellow, 2/3 red, 1 dry brown.
    color_variation: per-leaf spread of the season.
    leaf_roughness: perceptual roughness of fresh leaves (dry leaves are rougher).
    ground: what lies beneath, rounded down: 0 soil, 1 moss, 2 tree bark.
    ground_value: brightness of the ground (sRGB).
    relief: leaf stacking step and curl height, as a fraction of the image width.
    veins: strength of the vein relief and colour.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, texel_coordinates, value_noise
from brdfgan.data.materials.noise import lookup as _lookup

GROUNDS = ("soil", "moss", "bark")
LAYERS = 3
# Season palette (sRGB): fresh green, yellow, red-orange, dry brown, at seasons 0, 1/3, 2/3, 1.
_SEASON_COLORS = torch.tensor(
    [
        [0.22, 0.40, 0.09],
        [0.80, 0.64, 0.13],
        [0.70, 0.21, 0.07],
        [0.42, 0.26, 0.11],
    ]
)
_DRY_ROUGHNESS = 0.8
# Ground colours (hue in turns, saturation); ``ground_value`` sets the brightness.
_GROUND_HS = {"soil": (0.07, 0.45), "moss": (0.22, 0.6), "bark": (0.07, 0.22)}
_GROUND_ROUGHNESS = {"soil": 0.92, "moss": 0.95, "bark": 0.88}
_CENTRE_MARGIN = 0.35  # leaf centres lie in [0.35, 0.65] of their cell
# Below 0.5 + margin = 0.85 cells: then only the 2 × 2 nearest cells can reach a texel.
_MAX_HALF_LENGTH = 0.8
_MIDRIB_WIDTH = 0.012  # cells


@dataclass(frozen=True)
class LeafLayer:
    """One layer of leaves, each field ``(size, size)``: ``cover`` in [0, 1] (soft at the leaf
    margin), the covering leaf's stacking ``order`` in [0, 1) (−1 where bare), its ``season``
    colour parameter, and its ``shape`` height (curl and veins, in units of the relief), plus
    ``vein`` in [0, 1] for the colour."""

    cover: Tensor
    order: Tensor
    season: Tensor
    shape: Tensor
    vein: Tensor


def season_color(season: Tensor) -> Tensor:
    """Leaf colour (sRGB) along the season palette, piecewise linear. Shape: ``(H, W)`` → ``(3, H, W)``."""
    position = season.clamp(0.0, 1.0) * (len(_SEASON_COLORS) - 1)
    low = position.floor().long().clamp(max=len(_SEASON_COLORS) - 2)
    t = (position - low.float())[None]
    return torch.lerp(_SEASON_COLORS[low].permute(2, 0, 1), _SEASON_COLORS[low + 1].permute(2, 0, 1), t)


def leaf_layer(size: int, cells: int, params: Mapping[str, float], generator: torch.Generator) -> LeafLayer:
    """A layer of leaves, at most one per lattice cell, the higher stacking order on top.

    The four candidate leaves of a texel are only tested for covering it; the covering leaf's
    curl and veins are then shaded once. Shape: see :class:`LeafLayer`.
    """
    count = cells * cells
    draws = torch.rand((9, count), generator=generator)
    span = 1.0 - 2.0 * _CENTRE_MARGIN
    centre_u, centre_v = _CENTRE_MARGIN + span * draws[0], _CENTRE_MARGIN + span * draws[1]
    angle = 2.0 * math.pi * draws[2]
    cos_a, sin_a = torch.cos(angle), torch.sin(angle)
    half_length = 0.5 + (_MAX_HALF_LENGTH - 0.5) * draws[3]
    width = 0.3 + 0.25 * draws[4]  # widest half width as a fraction of the half length
    # Empty places get an order below every leaf's, so they never cover anything.
    order = torch.where(draws[7] < params["cover"], draws[5], torch.full_like(draws[5], -2.0))
    season = params["season"] + params["color_variation"] * (2.0 * draws[6] - 1.0)
    curl = 0.15 + 0.5 * smoothstep(0.55, 1.0, season) * draws[8]  # dry leaves curl more

    # Texel positions in cell units are separable: columns give x and the candidate columns,
    # rows give y and the candidate rows, so only the leaf lookups are done per texel.
    coordinate = (torch.arange(size, dtype=torch.float32) + 0.5) * (cells / size)
    base = coordinate.floor().long()
    neighbour = torch.where(coordinate - base < 0.5, base - 1, base + 1)
    best_order = torch.full((size, size), -1.0)
    best_leaf = torch.zeros((size, size), dtype=torch.long)
    best_along = torch.zeros(size, size)
    best_across = torch.zeros(size, size)
    for ci in (base, neighbour):
        for cj in (base, neighbour):
            leaf = (cj % cells).view(size, 1) * cells + (ci % cells).view(1, size)
            du = (coordinate - ci).view(1, size) - _lookup(centre_u, leaf)
            dv = (coordinate - cj).view(size, 1) - _lookup(centre_v, leaf)
            c, s = _lookup(cos_a, leaf), _lookup(sin_a, leaf)
            along, across = du * c + dv * s, dv * c - du * s
            length = _lookup(half_length, leaf)
            t = along / length
            inside = (t.abs() < 1.0) & (across.abs() < _half_width(t, length, _lookup(width, leaf)))
            leaf_order = _lookup(order, leaf)
            take = inside & (leaf_order > best_order)
            best_order = torch.where(take, leaf_order, best_order)
            best_leaf = torch.where(take, leaf, best_leaf)
            best_along = torch.where(take, along, best_along)
            best_across = torch.where(take, across, best_across)

    covered = (best_order >= 0.0).float()
    length = _lookup(half_length, best_leaf)
    t = (best_along / length).clamp(-1.0, 1.0)
    half_width = _half_width(t, length, _lookup(width, best_leaf))
    distance = best_across.abs()
    cover = smoothstep(0.0, 0.015, half_width - distance) * covered  # soft leaf margin
    side = (distance / half_width.clamp(min=1e-4)).clamp(0.0, 1.0)
    midrib = 1.0 - smoothstep(0.0, _MIDRIB_WIDTH, distance)
    # Lateral veins: chevrons running from the midrib towards the tip.
    phase = 7.0 * (t - 0.9 * distance / length)
    lateral = smoothstep(0.8, 1.0, torch.cos(2.0 * math.pi * phase)) * (1.0 - side)
    # Cupped across the blade and arched along it; the midrib stands, laterals are grooves.
    shape = _lookup(curl, best_leaf) * side * side + 0.25 * (1.0 - t * t)
    shape = shape + params["veins"] * (0.12 * midrib - 0.05 * lateral)
    return LeafLayer(
        cover=cover,
        order=torch.where(covered > 0.0, best_order, torch.full_like(best_order, -1.0)),
        season=_lookup(season, best_leaf),
        shape=shape * covered,
        vein=torch.maximum(midrib, 0.6 * lateral) * covered,
    )


def _half_width(t: Tensor, half_length: Tensor, width: Tensor) -> Tensor:
    """Half width of an ovate leaf at ``t`` ∈ [-1, 1] along it (−1 base, +1 tip): widest a
    little towards the base, tapering to the tip. Shape: any (broadcast)."""
    root = torch.sqrt((1.0 - t * t).clamp(min=0.0))
    return half_length * width * root * torch.sqrt(root) * (1.0 - 0.3 * t)  # (1 − t²)^¾: pointed ends


def ground_surface(ground: str, size: int, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Height roughly in [-1, 1] and a brightness factor around 1 of the ground under the leaves.

    Soil: crumbly clods. Moss: fuzzy clumps. Bark: vertical plates split by deep, wavy fissures
    (a warped sine across the columns; the column count is an integer, so it wraps).

    Shape: each ``(size, size)``.
    """
    if ground == "soil":
        clods = fbm(size, 16, generator, octaves=4, persistence=0.6)
        return clods, 1.0 + 0.2 * clods
    if ground == "moss":
        clumps = value_noise(size, 12, generator)
        fuzz = value_noise(size, min(size, 256), generator)  # fronds of a millimetre or two
        height = 1.2 * clumps + 0.6 * fuzz - 0.9
        return height, 0.8 + 0.25 * clumps + 0.2 * fuzz
    u, _ = texel_coordinates(size)
    warp = fbm(size, 3, generator, octaves=3)
    grain = value_noise(size, min(size, 64), generator) - 0.5
    plates = torch.sin(math.pi * (10.0 * u + 1.5 * warp)).abs() ** 0.4  # 0 in a fissure
    return 2.0 * plates - 1.2 + 0.3 * grain, 0.55 + 0.5 * plates + 0.2 * grain


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    ground = GROUNDS[min(max(int(params["ground"]), 0), len(GROUNDS) - 1)]
    step = params["relief"] * size  # texels
    ground_height, ground_shade = ground_surface(ground, size, generator)
    hue, saturation = _GROUND_HS[ground]
    ground_rgb = hsv_to_rgb(
        torch.full_like(ground_shade, hue),
        torch.full_like(ground_shade, saturation),
        (params["ground_value"] * ground_shade).clamp(0.0, 1.0),
    )
    height = 0.5 * step * ground_height
    basecolor = ground_rgb
    roughness = torch.full((size, size), _GROUND_ROUGHNESS[ground]) + 0.03 * ground_height

    cells = max(2, round(params["leaf_count"]))
    blotch = value_noise(size, min(size, 8 * cells), generator)
    for layer_index in range(LAYERS):
        layer = leaf_layer(size, cells, params, generator)
        # Each leaf lies at its own level: upper layers and higher orders above the rest.
        level = step * (1.0 + layer_index + layer.order + layer.shape)
        height = torch.lerp(height, level, layer.cover)
        dryness = smoothstep(0.55, 1.0, layer.season)
        leaf_rgb = season_color(layer.season) * (0.85 + 0.3 * blotch)[None]
        # Veins are paler; dry leaves darken towards their blotches.
        leaf_rgb = torch.lerp(leaf_rgb, leaf_rgb * 1.35 + 0.05, (params["veins"] * 0.5 * layer.vein)[None])
        leaf_rgb = leaf_rgb * (1.0 - 0.25 * dryness * blotch)[None]
        basecolor = torch.lerp(basecolor, leaf_rgb, layer.cover[None])
        leaf_roughness = params["leaf_roughness"] + (_DRY_ROUGHNESS - params["leaf_roughness"]) * dryness
        roughness = torch.lerp(roughness, leaf_roughness + 0.08 * layer.vein, layer.cover)
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


FAMILY = MaterialFamily(
    name="leaves",
    parameters={
        "cover": Parameter(0.75, 0.0, 1.0, "fraction of leaf places holding a leaf, per layer"),
        "leaf_count": Parameter(6.0, 3.0, 12.0, "leaf places per side in each layer (rounded)"),
        "season": Parameter(0.5, 0.0, 1.0, "mean leaf colour: 0 green, 1/3 yellow, 2/3 red, 1 brown"),
        "color_variation": Parameter(0.2, 0.0, 0.4, "per-leaf spread of the season"),
        "leaf_roughness": Parameter(0.4, 0.25, 0.7, "perceptual roughness of fresh leaves (dry: rougher)"),
        "ground": Parameter(1.5, 0.0, 2.99, "ground (floor): 0 soil, 1 moss, 2 tree bark", uniform=True),
        "ground_value": Parameter(0.3, 0.15, 0.5, "brightness of the ground (sRGB)"),
        "relief": Parameter(0.008, 0.003, 0.02, "leaf stacking step and curl, fraction of the image width"),
        "veins": Parameter(0.6, 0.0, 1.0, "strength of the vein relief and colour"),
    },
    generate=_generate,
    description="Overlapping green to autumn leaves with veins and curl over soil, moss or tree bark.",
    tags=("leaves", "foliage", "organic", "ground", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
