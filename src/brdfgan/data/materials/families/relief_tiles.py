"""Glazed relief tiles: embossed ceramic tiles under a glossy glaze that pools in the recesses.

Depicts decorative relief tiles (majolica, Victorian and Moroccan wall tiles, embossed
splashbacks) on a square grid: each tile carries a raised motif repeated a whole number of times
across it (a rosette of petals with a boss and a ring, concentric rings, wavy ridges or a
diamond lattice) under a glossy transparent-coloured glaze. Glaze flows off the crests and pools
in the recesses, so the recesses are darker and more saturated and the crests lighter (the glaze
"breaks" over them and the pale body shows); the pooled glaze is also a little smoother. The
tiles have rounded edges, a slight per-tile shade and faint mottling, and are set in recessed,
rough, sandy grout. The motif's petal, ring and wave counts are drawn from the generator.

Why it is in the dataset: the original families have flat-faced tiles only and mostly muted
colours; relief tiles are common (kitchens, bathrooms, façades) and combine strong smooth relief
with a glossy surface, a colour that correlates with the relief (pooling), and any hue. They teach
the model that colour shading in a glaze is not the same as shading by the light.

Parameters:
    tile_count: tiles along each side of the square (rounded, so the grid tiles).
    grout_width: width of the grout lines as a fraction of the tile pitch.
    pattern: motif, rounded down: 0 rosette, 1 concentric rings, 2 waves, 3 diamond lattice
        (uniform: no preferred motif).
    motif_repeat: motifs along each side of one tile (rounded).
    relief: height of the motif, as a fraction of the motif width (so the flanks of the motif
        are equally steep whatever the tile and repeat counts).
    hue: hue of the glaze, in turns (uniform: any hue).
    saturation: saturation of the glaze where it is of medium thickness.
    value: brightness of the glaze where it is of medium thickness (sRGB).
    pooling: how much the glaze darkens and saturates in recesses and lightens on crests.
    glaze_roughness: perceptual roughness of the glaze.
"""

from __future__ import annotations

import math
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
)

# Grout depth as a fraction of the image width, so normals look alike at every resolution.
_GROUT_DEPTH = 0.003
# Width of the rounded tile edge, as a fraction of the tile pitch.
_BEVEL = 0.04
# Grout colour at value 1: a warm grey (hue 0.1, saturation 0.06).
_GROUT_TINT = hsv_to_rgb(torch.tensor([0.1]), torch.tensor([0.06]), torch.tensor([1.0]))[:, 0]
PATTERNS = ("rosette", "rings", "waves", "diamonds")


def _motif(pattern: str, mu: Tensor, mv: Tensor, generator: torch.Generator) -> Tensor:
    """Height of one motif in [0, 1] over a motif cell (``mu``, ``mv`` in [0, 1)).

    Every motif falls to the same value along all four borders of the cell or repeats with it,
    so whole numbers of motifs join seamlessly.

    Shape: ``mu`` and ``mv`` broadcastable (e.g. ``(1, W)`` and ``(H, 1)``) → ``(H, W)``.
    """
    cx, cy = mu - 0.5, mv - 0.5
    r = torch.sqrt(cx * cx + cy * cy)
    if pattern == "rosette":
        petals = (4, 5, 6, 8)[int(torch.randint(4, (), generator=generator))]
        theta = torch.atan2(cy, cx)
        # |cos(kθ/2)| has k lobes with pointed gaps between them: petals.
        lobe = torch.cos(0.5 * petals * theta).abs()
        petal = smoothstep(0.0, 0.06, 0.14 + 0.2 * lobe - r) * (0.7 + 0.3 * lobe)
        boss = smoothstep(0.0, 0.04, 0.07 - r)
        ring = torch.exp(-(((r - 0.43) / 0.025) ** 2))
        # Quarter discs at the corners: where four motifs meet they form a small round stud.
        corner = torch.sqrt((0.5 - cx.abs()) ** 2 + (0.5 - cy.abs()) ** 2)
        stud = smoothstep(0.0, 0.04, 0.1 - corner)
        return torch.maximum(torch.maximum(petal, boss), torch.maximum(0.8 * ring, 0.8 * stud))
    if pattern == "rings":
        rings = int(torch.randint(2, 5, (), generator=generator))
        wave = 0.5 + 0.5 * torch.cos(2.0 * math.pi * rings * r)
        return wave * (1.0 - smoothstep(0.36, 0.47, r))
    if pattern == "waves":
        ridges = int(torch.randint(2, 5, (), generator=generator))
        # Whole numbers of ridges and of meander periods per cell: periodic in both directions.
        phase = ridges * mv + 0.3 * torch.sin(2.0 * math.pi * mu)
        return (0.5 + 0.5 * torch.sin(2.0 * math.pi * phase)) ** 1.5
    # Diamonds: a raised diamond frame with a recessed centre and a central dot; the frames of
    # neighbouring cells meet at the cell corners, giving a diagonal lattice.
    d = cx.abs() + cy.abs()
    frame = smoothstep(0.0, 0.1, 0.46 - d) - 0.6 * smoothstep(0.0, 0.06, 0.3 - d)
    dot = smoothstep(0.0, 0.04, 0.08 - d)
    return torch.maximum(frame, dot)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    n = max(1, round(params["tile_count"]))
    repeat = max(1, round(params["motif_repeat"]))
    pattern = PATTERNS[min(max(int(params["pattern"]), 0), len(PATTERNS) - 1)]
    # Tile coordinates along each axis, a row (1, size) and a column (size, 1), broadcast to the
    # texel grid only where both axes combine.
    u, v = texel_coordinates(size)
    x, y = u[:1] * n, v[:, :1] * n
    col, row = x.floor().long().clamp(max=n - 1), y.floor().long().clamp(max=n - 1)
    lu, lv = x - x.floor(), y - y.floor()

    edge = torch.minimum(torch.minimum(lu, 1.0 - lu), torch.minimum(lv, 1.0 - lv))
    half_grout = params["grout_width"] / 2.0
    face = smoothstep(half_grout, half_grout + _BEVEL, edge)
    profile = torch.sqrt(face)  # convex: the glaze rounds over the tile edge

    mu, mv = lu * repeat, lv * repeat
    motif = _motif(pattern, mu - mu.floor(), mv - mv.floor(), generator) * face

    grain = 2.0 * value_noise(size, min(size, 48), generator) - 1.0  # grout sand, glaze mottling
    depth = _GROUT_DEPTH * size
    motif_width = size / (n * repeat)
    height = depth * profile + params["relief"] * motif_width * motif
    height = height + (1.0 - face) * 0.08 * depth * grain + face * 0.01 * depth * grain

    # Glaze thickness follows the relief: thick (dark, saturated) in recesses, thin (pale) on crests.
    pooling = params["pooling"]
    recess, crest = face * (1.0 - motif), motif
    shade = 1.0 + 0.08 * (2.0 * random_per_cell(row * n + col, n * n, generator)[0] - 1.0)
    value = params["value"] * shade * (1.0 - 0.45 * pooling * recess + 0.2 * pooling * crest)
    value = value * (1.0 + 0.03 * grain)
    saturation = params["saturation"]
    saturation_map = (
        saturation + (1.0 - saturation) * 0.5 * pooling * recess - saturation * 0.35 * pooling * crest
    )
    glaze = hsv_to_rgb(
        torch.full_like(value, params["hue"]), saturation_map.clamp(0.0, 1.0), value.clamp(0.0, 1.0)
    )
    # Warm light grey; HSV is linear in the value, so a constant tint times the value field.
    grout = _GROUT_TINT.view(3, 1, 1) * (0.65 + 0.1 * grain)[None]
    basecolor = clamp_dielectric_albedo(grout + (glaze - grout) * face[None])

    # Pooled glaze levels out into a smoother surface; grout is rough and porous.
    glaze_rough = params["glaze_roughness"] * (1.0 - 0.25 * pooling * recess) * (1.0 + 0.1 * grain)
    grout_rough = 0.9 + 0.05 * grain
    roughness = grout_rough + (glaze_rough - grout_rough) * face
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="relief_tiles",
    parameters={
        "tile_count": Parameter(3.0, 1.0, 6.0, "tiles along each side (rounded)"),
        "grout_width": Parameter(0.025, 0.01, 0.06, "grout line width, fraction of the tile pitch"),
        "pattern": Parameter(
            2.0, 0.0, 3.99, "motif (floor): 0 rosette, 1 rings, 2 waves, 3 diamonds", uniform=True
        ),
        "motif_repeat": Parameter(1.0, 1.0, 3.0, "motifs along each side of one tile (rounded)"),
        "relief": Parameter(0.05, 0.02, 0.12, "motif height, fraction of the motif width"),
        "hue": Parameter(0.55, 0.0, 1.0, "hue of the glaze, in turns", uniform=True),
        "saturation": Parameter(0.55, 0.1, 0.95, "saturation of the glaze at medium thickness"),
        "value": Parameter(0.6, 0.2, 0.9, "brightness of the glaze at medium thickness (sRGB)"),
        "pooling": Parameter(0.6, 0.0, 1.0, "darkening/saturation in recesses and paling on crests"),
        "glaze_roughness": Parameter(0.08, 0.03, 0.3, "perceptual roughness of the glaze"),
    },
    generate=_generate,
    description="Embossed ceramic tiles (rosettes, rings, waves, diamonds), glaze pooling in the recesses.",
    tags=("tiles", "ceramic", "relief", "glossy", "dielectric", "tileable"),
)

__all__ = ["FAMILY", "PATTERNS"]
