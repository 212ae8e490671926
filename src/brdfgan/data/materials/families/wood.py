"""Wood planks: a floor or panel of flat-sawn boards laid in staggered rows.

Depicts horizontal planks (rows along the image's v axis) whose end joints are staggered from
row to row, growth rings and fibres stretched along each board by warped noise, a per-plank
tone/hue shift (boards come from different trees), dark, rough, recessed gaps between boards,
and an optional varnish that lowers roughness and hides the open-pore relief.

Parameters:
    plank_rows: boards across the square (rounded; one per row).
    planks_per_row: boards along one row (rounded), i.e. end joints per row.
    gap_width: width of the gap between boards as a fraction of the image width.
    grain_scale: growth rings across one board width.
    grain_warp: how strongly the rings meander (0 = straight stripes).
    hue, saturation, value: HSV of the mean wood colour (sRGB).
    tone_variation: relative brightness spread between boards.
    varnish: 0 = raw sawn wood (rough, porous), 1 = glossy varnish.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, random_per_cell, texel_coordinates

# Relief as fractions of the image width, so normals look alike at every resolution.
_GAP_DEPTH = 0.004
_BEVEL_WIDTH = 0.003
_GRAIN_RELIEF = 0.0004


def _stretched(field: Tensor, rows: Tensor, cols: Tensor, stretch: int) -> Tensor:
    """Sample a periodic field with its v axis compressed ``stretch`` times (an integer, so the
    result stays periodic): features become elongated along u, like fibres along a board."""
    size = field.shape[-1]
    return field[(rows * stretch) % size, cols % size]


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    rows_n = max(1, round(params["plank_rows"]))
    per_row = max(1, round(params["planks_per_row"]))
    u, v = texel_coordinates(size)
    rows_idx = torch.arange(size).view(size, 1).expand(size, size)
    cols_idx = torch.arange(size).view(1, size).expand(size, size)

    # Plank layout: each row is shifted by a random fraction of a plank, so joints stagger; the
    # shift keeps every row periodic because a whole number of planks fits the square.
    y = v * rows_n
    row = y.floor().long().clamp(max=rows_n - 1)
    row_shift = torch.rand(rows_n, generator=generator)[row]
    x = u * per_row + row_shift
    col = x.floor().long() % per_row
    plank = row * per_row + col
    count = rows_n * per_row
    lu, lv = x - x.floor(), y - y.floor()

    # Distance to the nearest gap in image-width units (joints across u, seams across v).
    edge = torch.minimum(torch.minimum(lv, 1.0 - lv) / rows_n, torch.minimum(lu, 1.0 - lu) / per_row)
    half_gap = params["gap_width"] / 2.0
    face = smoothstep(half_gap, half_gap + _BEVEL_WIDTH, edge)

    # Per-plank random attributes: tone, hue shift, ring phase, and where in the log the board
    # was cut (a different offset into the shared noise fields gives each board its own grain).
    attrs = random_per_cell(plank, count, generator, channels=5)
    tone = 1.0 + params["tone_variation"] * (2.0 * attrs[0] - 1.0)
    hue_shift = 0.015 * (2.0 * attrs[1] - 1.0)
    offset_r = (attrs[2] * size).long()
    offset_c = (attrs[3] * size).long()

    warp_field = fbm(size, 4, generator, octaves=4)
    fibre_field = fbm(size, 32, generator, octaves=3)
    warp = _stretched(warp_field, rows_idx + offset_r, cols_idx + offset_c, 2 * rows_n)
    fibre = _stretched(fibre_field, rows_idx + offset_r, cols_idx + offset_c, 8)

    # Growth rings: iso-lines of (across-board position + meander); a sawtooth profile gives
    # the gradual earlywood → abrupt latewood transition of real rings.
    ring_coord = params["grain_scale"] * (lv + params["grain_warp"] * 0.6 * warp) + 3.0 * attrs[4]
    ring = ring_coord - ring_coord.floor()
    latewood = smoothstep(0.55, 0.95, ring) * (1.0 - smoothstep(0.95, 1.0, ring))

    darkening = 1.0 - 0.32 * latewood - 0.08 * fibre
    value = (params["value"] * tone * darkening).clamp(0.0, 1.0)
    saturation = torch.full_like(value, params["saturation"]) * (1.0 + 0.15 * latewood)
    hue = params["hue"] + hue_shift
    wood = hsv_to_rgb(hue, saturation.clamp(0.0, 1.0), value)
    gap_colour = wood * 0.25  # the gap is in shadow and full of dirt
    basecolor = (gap_colour + (wood - gap_colour) * face[None]).clamp(0.02, 0.95)

    # Height: gaps recessed; on raw wood the soft earlywood wears away so latewood stands proud,
    # varnish fills those pores.
    varnish = params["varnish"]
    grain_relief = _GRAIN_RELIEF * size * (1.0 - 0.8 * varnish) * (latewood + 0.5 * fibre)
    height = (-_GAP_DEPTH * size * (1.0 - face) + face * grain_relief)[None]

    face_roughness = 0.7 - 0.45 * varnish + 0.05 * fibre + 0.05 * (1.0 - varnish) * latewood
    roughness = face_roughness * face + 0.9 * (1.0 - face)
    return MaterialLayers(
        basecolor=basecolor,
        height=height,
        roughness=roughness.clamp(0.0, 1.0)[None],
        metallic=torch.zeros(1, size, size),
    )


FAMILY = MaterialFamily(
    name="wood_planks",
    parameters={
        "plank_rows": Parameter(6.0, 3.0, 12.0, "boards across the square (rounded)"),
        "planks_per_row": Parameter(1.0, 1.0, 3.0, "boards along each row (rounded): end joints per row"),
        "gap_width": Parameter(0.004, 0.001, 0.01, "gap between boards, fraction of the image width"),
        "grain_scale": Parameter(5.0, 2.0, 12.0, "growth rings across one board width"),
        "grain_warp": Parameter(0.5, 0.0, 1.0, "meander of the rings (0 = straight stripes)"),
        "hue": Parameter(0.075, 0.03, 0.11, "hue of the mean wood colour, in turns (orange-brown)"),
        "saturation": Parameter(0.55, 0.3, 0.75, "saturation of the mean wood colour"),
        "value": Parameter(0.6, 0.25, 0.85, "brightness of the mean wood colour (sRGB)"),
        "tone_variation": Parameter(0.12, 0.0, 0.3, "relative brightness spread between boards"),
        "varnish": Parameter(0.5, 0.0, 1.0, "0 raw sawn wood (rough), 1 glossy varnish"),
    },
    generate=_generate,
    description="Staggered wood planks with warped growth rings, per-board tone and recessed gaps.",
    tags=("wood", "planks", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
