"""Metallic paints and metal foils: flake paint of any colour, or crinkled gold, silver or copper
foil.

Two surfaces that share what makes them hard for the model, a metal that is not a flat sheet;
``mode`` picks one.

- **Metallic flake paint** (car bodies, bikes, guitars, boat hulls, spray-painted metal flake):
  a glossy coloured paint (dielectric, metallic 0, base colour in the plausible albedo range)
  holding aluminium flakes (metallic 1). Each flake is a small disc lying at its own tilt in the
  paint, so its normal differs from its neighbours' and it sparkles on its own under the flash.
  Flakes are seen through the coloured clear coat, so their colour is the aluminium F0 times the
  coat's transmittance² (``tint`` of the paint's hue; 0 = silver flakes): the same
  metallic-workflow approximation of a metal under a coloured layer as anodised aluminium. The
  paint has a faint orange-peel relief. Metallic is 1 on flakes and 0 in the paint, soft only at
  flake edges.
- **Crinkled foil** (kitchen foil, gold and copper foil, chocolate and gift wrap, leaf metal):
  a metal foil (metallic 1, base colour exactly the measured F0) crumpled into a network of sharp
  ridges and valleys (ridged noise), slightly rougher along its creases.

Why it is in the dataset: the first ten families hold no mixed metal/dielectric texture finer
than patches of paint or rust, and no strongly relieved metal; metallic paints and foils are
common in phone photos (cars, packaging, crafts) and need both: per-texel switches between
metal and paint, and a metal whose highlights are scattered by its relief, not its roughness.

Parameters:
    mode: < 0.5 metallic flake paint, otherwise crinkled foil.
    hue: hue of the paint (uniform: cars come in every hue). Paint only.
    saturation: saturation of the paint. Paint only.
    value: brightness of the paint (sRGB). Paint only.
    flake_density: fraction of the paint surface covered by flakes. Paint only.
    flake_count: flakes per image width along the coarser of the two flake grids (the other is
        √2 finer; each at most a third of the texels per width, so a flake always spans about
        two texels). Paint only.
    tint: how strongly the coat colours the flakes (0 = silver flakes, 1 = flakes of the paint's
        hue). Paint only.
    roughness: perceptual roughness of the clear coat (paint) or of the foil.
    foil_metal: foil metal, rounded down: 0 aluminium, 1 silver, 2 gold, 3 copper (uniform).
        Foil only.
    crinkle: how crumpled the foil is: deeper and finer creases (0 = nearly flat). Foil only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.core.svbrdf import linear_to_srgb, srgb_to_linear
from brdfgan.data.materials.albedo import METAL_F0_LINEAR, clamp_dielectric_albedo, metal_basecolor
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import gradient_noise, hsv_to_rgb, texel_coordinates

FOIL_METALS: tuple[str, ...] = ("aluminium", "silver", "gold", "copper")
# Flake disc radius in flake pitches; its centre is jittered only so far that the disc stays in
# its own grid cell (so a texel needs to look at one cell, not the 3×3 of Worley noise).
FLAKE_RADIUS = 0.3
_FLAKE_JITTER = 0.5 - FLAKE_RADIUS - 0.02
# Flakes lie on two grids whose pitches differ by √2, so no lattice shows even where most cells
# of both hold a flake.
_SECOND_GRID = math.sqrt(2.0)
# Largest flake tilt: tan(15°).
_FLAKE_SLOPE = math.tan(math.radians(15.0))
# Orange peel: bumps per image width and height as a fraction of the width (slopes of ~1–2°).
_PEEL_CELLS = 32
_PEEL_DEPTH = 0.0003
# Foil crease cells per image width at crinkle 0 and 1 (first octave; two finer octaves follow).
_CREASE_CELLS = (3, 9)
# Foil relief per octave as a fraction of that octave's cell pitch at crinkle 0 and 1.
_CREASE_DEPTH = (0.04, 0.3)


def flake_discs(size: int, cells: int, coverage: float, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Flakes on a jittered ``cells × cells`` grid: at most one disc of radius
    :data:`FLAKE_RADIUS` per cell, present in enough cells to cover ``coverage`` of the surface,
    each lying at its own random tilt (slope up to :data:`_FLAKE_SLOPE` along each axis).

    Returns:
        ``(mask, tilt)``: flake coverage in [0, 1] with a one-texel soft edge, and the height in
        texels of every texel's flake plane through the flake's centre (meaningful on flakes).

    Shape: each ``(size, size)``.
    """
    u, v = texel_coordinates(size)
    x, y = u * cells, v * cells
    col, row = x.floor().long().clamp(max=cells - 1), y.floor().long().clamp(max=cells - 1)
    cell = row * cells + col
    draws = torch.rand((5, cells * cells), generator=generator)
    centre_u = 0.5 + _FLAKE_JITTER * (2.0 * draws[0] - 1.0)
    centre_v = 0.5 + _FLAKE_JITTER * (2.0 * draws[1] - 1.0)
    present = (draws[2] < coverage / (math.pi * FLAKE_RADIUS**2)).to(torch.float32)
    slope_u, slope_v = _FLAKE_SLOPE * (2.0 * draws[3] - 1.0), _FLAKE_SLOPE * (2.0 * draws[4] - 1.0)
    du = x - col - centre_u[cell]
    dv = y - row - centre_v[cell]
    distance = torch.sqrt(du * du + dv * dv)
    half_texel = 0.5 * cells / size  # in pitches
    mask = present[cell] * smoothstep(FLAKE_RADIUS + half_texel, FLAKE_RADIUS - half_texel, distance)
    pitch = size / cells
    return mask, pitch * (slope_u[cell] * du + slope_v[cell] * dv)


def _paint(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    hue, saturation = params["hue"], params["saturation"]
    ones = torch.ones(size, size)
    paint = clamp_dielectric_albedo(hsv_to_rgb(hue * ones, saturation * ones, params["value"] * ones))

    # Each grid covers half of the flake density (overlaps between them are rare and harmless).
    flakes, tilt = torch.zeros(size, size), torch.zeros(size, size)
    for scale in (1.0, _SECOND_GRID):
        cells = max(1, min(round(scale * params["flake_count"]), size // 3))
        mask, plane = flake_discs(size, cells, params["flake_density"] / 2.0, generator)
        tilt = torch.where(mask > flakes, plane, tilt)
        flakes = torch.maximum(flakes, mask)
    peel = gradient_noise(size, min(_PEEL_CELLS, size), generator)
    height = _PEEL_DEPTH * size * peel + flakes * tilt

    # Flakes through the coat: aluminium F0 × the coat's transmittance² of the paint's hue.
    coat = srgb_to_linear(
        hsv_to_rgb(torch.full((1, 1), hue), torch.full((1, 1), saturation), torch.ones(1, 1))
    )
    aluminium = torch.tensor(METAL_F0_LINEAR["aluminium"]).view(3, 1, 1)
    flake_color = linear_to_srgb(aluminium * (1.0 + params["tint"] * (coat - 1.0)))
    basecolor = paint + (flake_color - paint) * flakes[None]
    # The coat is glossy; a flake's own micro-facets spread its highlight a little more.
    roughness = params["roughness"] + 0.08 * flakes
    return MaterialLayers(basecolor, height[None], roughness.clamp(0.0, 1.0)[None], flakes[None])


def _foil(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    name = FOIL_METALS[min(max(int(params["foil_metal"]), 0), len(FOIL_METALS) - 1)]
    crinkle = params["crinkle"]
    first = round(_CREASE_CELLS[0] + crinkle * (_CREASE_CELLS[1] - _CREASE_CELLS[0]))
    depth = _CREASE_DEPTH[0] + crinkle * (_CREASE_DEPTH[1] - _CREASE_DEPTH[0])
    height = torch.zeros(size, size)
    creases = torch.zeros(size, size)
    for octave in range(3):
        cells = min(first * 2**octave, max(1, size // 4))
        noise = gradient_noise(size, cells, generator)
        # |noise| folds the field along its zero lines into sharp creases; alternating the sign
        # makes ridges of one octave and valleys of the next, as crumpling leaves both.
        sign = 1.0 if octave % 2 == 0 else -1.0
        height += sign * depth * (size / cells) * (0.5 - noise.abs())
        creases = torch.maximum(creases, smoothstep(0.08, 0.0, noise.abs()))
    color = torch.tensor(metal_basecolor(name), dtype=torch.float32).view(3, 1, 1)
    # Creases are crushed finer than a texel: a little rougher than the flat facets.
    roughness = params["roughness"] + 0.1 * crinkle * creases
    return MaterialLayers(
        basecolor=color.expand(3, size, size).clone(),
        height=height[None],
        roughness=roughness.clamp(0.0, 1.0)[None],
        metallic=torch.ones(1, size, size),
    )


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    return _foil(params, size, generator) if params["mode"] >= 0.5 else _paint(params, size, generator)


FAMILY = MaterialFamily(
    name="metallic_paint",
    parameters={
        "mode": Parameter(0.3, 0.0, 1.0, "surface: < 0.5 metallic flake paint, otherwise crinkled foil"),
        "hue": Parameter(0.5, 0.0, 1.0, "hue of the paint, in turns (paint)", uniform=True),
        "saturation": Parameter(0.6, 0.0, 1.0, "saturation of the paint (paint)"),
        "value": Parameter(0.5, 0.05, 0.95, "brightness of the paint, sRGB (paint)"),
        "flake_density": Parameter(0.12, 0.02, 0.28, "fraction of the paint covered by flakes (paint)"),
        "flake_count": Parameter(120.0, 40.0, 300.0, "flakes per image width (paint)"),
        "tint": Parameter(0.5, 0.0, 1.0, "coat colour on the flakes: 0 silver, 1 paint hue (paint)"),
        "roughness": Parameter(0.1, 0.03, 0.35, "perceptual roughness of the clear coat or the foil"),
        "foil_metal": Parameter(
            2.0, 0.0, 3.99, "foil metal (floor): 0 aluminium, 1 silver, 2 gold, 3 copper (foil)", uniform=True
        ),
        "crinkle": Parameter(0.5, 0.0, 1.0, "how crumpled the foil is: deeper, finer creases (foil)"),
    },
    generate=_generate,
    description="Metallic flake paint of any colour (tilted aluminium flakes in a glossy coat) or "
    "crinkled aluminium, silver, gold or copper foil.",
    tags=("metal", "paint", "foil", "mixed-metallic", "metallic", "tileable"),
)

__all__ = ["FAMILY", "FLAKE_RADIUS", "FOIL_METALS", "flake_discs"]
