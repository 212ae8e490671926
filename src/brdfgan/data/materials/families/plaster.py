"""Painted plaster and stucco: a wall of any paint colour over a textured plaster finish.

Depicts an interior or exterior wall: emulsion paint of any colour, from off-white to strongly
saturated, matte to eggshell, over one of three common plaster textures chosen by ``stucco``:

- **orange peel**: a sprayed finish of small rounded bumps;
- **trowel swirls**: overlapping curved trowel strokes, each a smooth sweep that ends in a small
  ridge of pushed-up plaster, with faint comb lines along the stroke;
- **knock-down**: splats of plaster flattened by the trowel into smooth plateaus (a little
  glossier: the trowel burnished them) over a finer sprayed base.

Meandering hairline cracks (thin grooves, darker and rougher: they hold dust and break the paint
film) and grime that settles in the low parts and in broad blotches (darker, browner, rougher)
complete it. Dielectric throughout.

Why it is in the dataset: painted walls are the most common background of phone photos, and the
other families have neither a uniformly coloured, saturated paint nor the low, soft relief of
sprayed and trowelled plaster; ``concrete`` covers only bare, grey, mineral surfaces.

Parameters:
    hue: hue of the paint, in turns.
    saturation: saturation of the paint (0 = white or grey).
    value: brightness of the paint (sRGB).
    roughness: perceptual roughness of the paint film (0.3 eggshell … 0.95 flat matte).
    stucco: plaster texture, rounded down: 0 orange peel, 1 trowel swirls, 2 knock-down.
    relief: height of the plaster texture, as a fraction of the image width.
    scale: texture features (bumps, strokes, splats) per image width.
    cracks: amount of hairline cracks (0 = none).
    dirt: amount of grime (0 = freshly painted).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, value_noise

STUCCO_STYLES = ("orange_peel", "trowel", "knock_down")
# Hairline crack groove depth as a fraction of the image width (independent of the stucco relief).
_CRACK_DEPTH = 0.002
# Grime: a grey-brown, dusty colour (sRGB) that dirt blends the paint towards.
_DIRT_RGB = (0.33, 0.30, 0.26)


def stucco_relief(style: str, size: int, scale: int, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Relief of a plaster texture and where the trowel smoothed it.

    Returns ``(height, burnish)``: height roughly in [-1, 1] (× the relief amplitude) and the
    burnished fraction in [0, 1] (trowelled plateaus and sweeps, smoother than sprayed plaster).

    Shape: each ``(size, size)``.
    """
    fine = fbm(size, min(size, 3 * scale), generator, octaves=2)  # sprayed droplets
    if style == "orange_peel":
        return fine, torch.zeros(size, size)
    if style == "trowel":
        # Contour bands of a smooth field are curved strokes; inside a band the plaster is swept
        # smooth and rises towards the far edge, where a ridge drops off to the next stroke.
        field = fbm(size, max(2, scale // 4), generator, octaves=3)
        bands = field * (scale / 6.0)
        sweep = bands - bands.floor()
        ridge = smoothstep(0.75, 0.97, sweep) * (1.0 - smoothstep(0.97, 1.0, sweep))
        comb = torch.cos(bands * 12.0 * torch.pi)  # faint comb lines along the stroke
        height = 0.9 * sweep + 0.6 * ridge + 0.08 * comb + 0.25 * fine - 0.6
        return height, smoothstep(0.05, 0.5, sweep) * (1.0 - ridge)
    # Knock-down: splats where a blotchy field is high, flattened to plateaus by the trowel.
    blotch = fbm(size, scale, generator, octaves=3, persistence=0.55)
    splat = smoothstep(0.05, 0.15, blotch)
    height = 1.2 * splat + 0.1 * blotch * splat + 0.35 * fine * (1.0 - splat) - 0.5
    return height, splat


def hairline_cracks(size: int, amount: float, generator: torch.Generator) -> Tensor:
    """Meandering hairline cracks in [0, 1] (1 on a crack): zero-crossings of a fractal field,
    kept only where a second field allows, so cracks start and stop instead of closing into loops.

    Shape: ``(size, size)``.
    """
    if amount <= 0.0:
        return torch.zeros(size, size)
    field = fbm(size, 2, generator, octaves=4, persistence=0.45)
    width = 0.01  # in field units; the field changes by ~0.3 per tenth of the image
    line = 1.0 - smoothstep(0.0, width, field.abs())
    extent = smoothstep(1.0 - amount, 1.0 - amount + 0.15, value_noise(size, 4, generator))
    return line * extent


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    style = STUCCO_STYLES[min(max(int(params["stucco"]), 0), len(STUCCO_STYLES) - 1)]
    relief, burnish = stucco_relief(style, size, max(2, round(params["scale"])), generator)
    crack = hairline_cracks(size, params["cracks"], generator)
    height = params["relief"] * size * relief - _CRACK_DEPTH * size * crack

    # Grime settles in broad blotches and in the hollows of the texture.
    blotch = value_noise(size, 3, generator)
    hollow = smoothstep(0.2, -0.8, relief)
    grime = (params["dirt"] * smoothstep(0.3, 0.9, blotch + 0.5 * hollow)).clamp(0.0, 1.0)

    # Paint: uniform colour, slightly lighter on the crests (thinner film over sprayed plaster
    # reads lighter), darker in cracks (shadowed, dusty).
    value = params["value"] * (1.0 + 0.03 * relief) * (1.0 - 0.35 * crack)
    paint = hsv_to_rgb(
        torch.full_like(value, params["hue"]),
        torch.full_like(value, params["saturation"]),
        value.clamp(0.0, 1.0),
    )
    dirt_rgb = torch.tensor(_DIRT_RGB).view(3, 1, 1)
    basecolor = torch.lerp(paint, dirt_rgb.expand_as(paint), 0.55 * grime[None])

    # The trowel burnishes plaster (smoother); grime and broken paint in cracks scatter more.
    paint_roughness = params["roughness"]
    roughness = (
        paint_roughness * (1.0 - 0.2 * burnish)
        + 0.03 * relief
        + 0.15 * grime
        + (1.0 - paint_roughness) * 0.8 * crack
    )
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


FAMILY = MaterialFamily(
    name="plaster",
    parameters={
        "hue": Parameter(0.58, 0.0, 1.0, "hue of the paint, in turns", uniform=True),
        "saturation": Parameter(0.15, 0.0, 0.85, "saturation of the paint (0 = white or grey)"),
        "value": Parameter(0.8, 0.3, 0.93, "brightness of the paint (sRGB)"),
        "roughness": Parameter(0.7, 0.3, 0.95, "perceptual roughness of the paint (eggshell … matte)"),
        "stucco": Parameter(
            1.5,
            0.0,
            2.99,
            "plaster texture (floor): 0 orange peel, 1 trowel swirls, 2 knock-down",
            uniform=True,
        ),
        "relief": Parameter(
            0.004, 0.001, 0.012, "height of the plaster texture, fraction of the image width"
        ),
        "scale": Parameter(14.0, 6.0, 40.0, "bumps, strokes or splats per image width"),
        "cracks": Parameter(0.2, 0.0, 1.0, "amount of hairline cracks (0 = none)"),
        "dirt": Parameter(0.15, 0.0, 1.0, "amount of grime in blotches and hollows (0 = fresh paint)"),
    },
    generate=_generate,
    description="Painted plaster of any colour over orange-peel, trowel-swirl or knock-down stucco.",
    tags=("plaster", "stucco", "paint", "wall", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
