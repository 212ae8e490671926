"""Glass and ceramic mosaics: small glossy tesserae of saturated colours set in deep, rough grout.

Depicts a mosaic of small tesserae, either on a square grid (machine-made glass or ceramic
mosaic sheets) or as irregular cells (hand-cut or "random" mosaics, Worley cells), each tessera
taking one colour from a small palette (a mosaic sheet mixes a few glass batches) with a slight
shade of its own, each set slightly tilted (they never sit perfectly flat in the bed), with a
rounded edge, a faint waviness of the glass surface, and a deep, rough, sandy grey grout between
them. The tesserae are glossy (glass very smooth, glazed ceramic a bit rougher), so the material
has a strong roughness contrast at a fine scale and a strong relief.

Why it is in the dataset: the original ten families are mostly brown and grey with large
features; bathroom, pool, kitchen and mural mosaics are common phone subjects with many small,
saturated, glossy features of any hue, which the training set did not show. They teach the model
that a fine grid of saturated colours goes with deep grout normals and glossy-versus-rough
roughness at the tessera scale.

Parameters:
    tesserae: tesserae along each side of the square (rounded; Worley cells per side when
        irregular), so the layout tiles.
    irregular: layout, < 0.5 a square grid, otherwise irregular (Worley) cells.
    grout_width: width of the grout lines as a fraction of the tessera pitch.
    tilt: largest per-tessera height change across a tessera, as a fraction of the grout depth.
    hue: central hue of the palette, in turns (uniform: any hue).
    hue_spread: largest hue offset of a palette colour from ``hue``, in turns (0.5 = any hue).
    saturation: saturation of the palette colours (each colour draws 70–100 % of it).
    value: brightness of the palette colours (sRGB; each colour draws 65–100 % of it).
    tessera_roughness: perceptual roughness of the tesserae (glass ≈ 0.03, glazed ceramic ≈ 0.2).
    grout_value: brightness of the grout (sRGB).
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
    worley,
    wrapped_upsample,
)

# Grout depth as a fraction of the image width, so normals look alike at every resolution.
_GROUT_DEPTH = 0.004
# Width of the rounded tessera edge, as a fraction of the pitch.
_BEVEL = 0.12
# Colours per mosaic: a sheet mixes a few glass or glaze batches.
# Grout colour at value 1: a warm grey (hue 0.1, saturation 0.08).
_GROUT_TINT = hsv_to_rgb(torch.tensor([0.1]), torch.tensor([0.08]), torch.tensor([1.0]))[:, 0]
PALETTE_SIZE = 5


def _offsets_from_centre(x: Tensor, cell: Tensor, count: int, period: int) -> Tensor:
    """Periodic offset of every texel from the centre of its cell along one axis.

    The centre is the circular mean of the coordinate over the cell's texels, so a cell that
    wraps around the border of the square gets the right centre. ``x`` is in pitch units
    (periodic over ``period``); the result is in pitch units too.

    Shape: ``x`` and ``cell`` ``(H, W)`` → ``(H, W)``.
    """
    angle = x * (2.0 * math.pi / period)
    flat = cell.flatten()
    sin_sum = torch.zeros(count).index_add_(0, flat, torch.sin(angle).flatten())
    cos_sum = torch.zeros(count).index_add_(0, flat, torch.cos(angle).flatten())
    centre = torch.atan2(sin_sum, cos_sum) * (period / (2.0 * math.pi))
    return torch.remainder(x - centre[cell] + 0.5 * period, period) - 0.5 * period


def _cells(size: int, n: int, generator: torch.Generator) -> tuple[Tensor, Tensor, Tensor]:
    """Worley ``(f1, f2, cell_id)`` of ``n`` cells per side, from 512² up computed at half
    resolution: Worley noise is most of the family's cost, a tessera is at least 21 texels wide at
    1024², and the ids, read nearest-neighbour, can only be off by a texel at a cell border, which
    lies in the grout.

    Shape: each ``(size, size)``.
    """
    if size < 512 or size % 2:
        return worley(size, n, generator, jitter=0.85)
    f1, f2, cell = worley(size // 2, n, generator, jitter=0.85)
    return (
        wrapped_upsample(f1, 2),
        wrapped_upsample(f2, 2),
        cell.repeat_interleave(2, 0).repeat_interleave(2, 1),
    )


def _palette(params: Mapping[str, float], generator: torch.Generator) -> Tensor:
    """The sRGB colours of the mosaic's glass batches. Shape: ``(PALETTE_SIZE, 3)``."""
    draws = torch.rand((3, 1, PALETTE_SIZE), generator=generator)
    hue = torch.remainder(params["hue"] + params["hue_spread"] * (2.0 * draws[0] - 1.0), 1.0)
    saturation = params["saturation"] * (0.7 + 0.3 * draws[1])
    value = params["value"] * (0.65 + 0.35 * draws[2])
    return hsv_to_rgb(hue, saturation, value)[:, 0, :].T


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    n = max(2, round(params["tesserae"]))
    u, v = texel_coordinates(size)
    x, y = u * n, v * n
    count = n * n
    if params["irregular"] >= 0.5:
        f1, f2, cell = _cells(size, n, generator)
        # Half the gap between the two nearest feature points: the distance to the cell border
        # (the bisector) along the line joining them, in pitch units.
        edge = 0.5 * (f2 - f1)
        du = _offsets_from_centre(x, cell, count, n)
        dv = _offsets_from_centre(y, cell, count, n)
    else:
        # Per axis, a row (1, size) and a column (size, 1), broadcast where they combine.
        x, y = x[:1], y[:, :1]
        col, row = x.floor().long().clamp(max=n - 1), y.floor().long().clamp(max=n - 1)
        du, dv = x - x.floor() - 0.5, y - y.floor() - 0.5
        edge = 0.5 - torch.maximum(du.abs(), dv.abs())
        cell = row * n + col

    half_grout = params["grout_width"] / 2.0
    face = smoothstep(half_grout, half_grout + _BEVEL, edge)
    profile = torch.sqrt(face)  # convex: the glass or glaze rounds over the edge

    # Per tessera: palette pick, shade, tilt slopes and roughness spread.
    attrs = random_per_cell(cell, count, generator, channels=5)
    depth = _GROUT_DEPTH * size
    slope_u, slope_v = 2.0 * attrs[2] - 1.0, 2.0 * attrs[3] - 1.0
    tilt = params["tilt"] * depth * (slope_u * du + slope_v * dv)

    # One noise field at a few cells per tessera: sand grains in the grout, a faint waviness
    # and internal streaks in the glass.
    grain = 2.0 * value_noise(size, min(size, 4 * n), generator) - 1.0  # in [-1, 1]
    height = profile * (depth + tilt + 0.03 * depth * grain) + (1.0 - face) * 0.1 * depth * grain

    palette = _palette(params, generator)
    pick = (attrs[0] * PALETTE_SIZE).long().clamp(max=PALETTE_SIZE - 1)
    shade = (0.9 + 0.2 * attrs[1]) * (1.0 + 0.04 * grain)
    tessera = palette[pick].permute(2, 0, 1) * shade[None]
    # Warm grey; HSV is linear in the value, so a constant tint times the value field.
    grout = _GROUT_TINT.view(3, 1, 1) * (params["grout_value"] * (1.0 + 0.12 * grain))[None]
    basecolor = clamp_dielectric_albedo(grout + (tessera - grout) * face[None])

    # Glossy tesserae (each a little different), rough porous grout.
    tessera_rough = params["tessera_roughness"] * (0.8 + 0.4 * attrs[4]) * (1.0 + 0.1 * grain)
    grout_rough = 0.9 + 0.05 * grain
    roughness = grout_rough + (tessera_rough - grout_rough) * face
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="mosaic",
    parameters={
        "tesserae": Parameter(20.0, 8.0, 48.0, "tesserae along each side (rounded)"),
        "irregular": Parameter(
            0.3, 0.0, 1.0, "layout: < 0.5 square grid, otherwise irregular (Worley) cells"
        ),
        "grout_width": Parameter(0.1, 0.04, 0.2, "grout line width, fraction of the tessera pitch"),
        "tilt": Parameter(0.3, 0.0, 0.7, "per-tessera tilt, height change as a fraction of the grout depth"),
        "hue": Parameter(0.55, 0.0, 1.0, "central hue of the palette, in turns", uniform=True),
        "hue_spread": Parameter(0.12, 0.0, 0.5, "largest hue offset of a palette colour, in turns"),
        "saturation": Parameter(0.7, 0.15, 1.0, "saturation of the palette colours"),
        "value": Parameter(0.7, 0.3, 0.95, "brightness of the palette colours (sRGB)"),
        "tessera_roughness": Parameter(
            0.1, 0.02, 0.4, "perceptual roughness of the tesserae (glass 0.03, ceramic 0.2)"
        ),
        "grout_value": Parameter(0.6, 0.2, 0.9, "brightness of the grout (sRGB)"),
    },
    generate=_generate,
    description="Glossy glass or ceramic tesserae of a saturated palette, tilted, in deep rough grout.",
    tags=("mosaic", "tiles", "glass", "ceramic", "glossy", "dielectric", "tileable"),
)

__all__ = ["FAMILY", "PALETTE_SIZE"]
