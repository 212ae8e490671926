"""Rough stone: a weathered, unpolished rock surface broken into slabs by cracks.

Depicts a rough rock face (slate, sandstone, weathered granite): fractal relief, irregular
cellular slabs each with its own tone and height (Worley cells), dark, deep, very rough cracks
along the cell borders, mineral speckles, muted low-saturation colours and high roughness.

Parameters:
    cell_count: slabs per side (Worley lattice cells per side, rounded).
    crack_width: crack width in cell units (0 = no cracks).
    relief: height amplitude as a fraction of the image width.
    detail: fractal persistence of the relief (higher = grittier surface).
    hue, saturation, value: HSV of the mean stone colour (sRGB).
    color_variation: per-slab spread of brightness.
    roughness: perceptual roughness of the stone surface.
    speckle: amount of dark/light mineral grains.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, random_per_cell, worley


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    cells = max(1, round(params["cell_count"]))
    f1, f2, cell_id = worley(size, cells, generator, jitter=0.9)
    attrs = random_per_cell(cell_id, cells * cells, generator, channels=2)

    # Cracks follow the Worley borders (f2 − f1 small), wobbled by noise so they are not straight.
    wobble = fbm(size, 4 * cells, generator, octaves=3)
    border = f2 - f1 + 0.12 * wobble
    crack_width = params["crack_width"]
    crack = 1.0 - smoothstep(0.0, max(crack_width, 1e-4), border) if crack_width > 0 else torch.zeros_like(f1)

    # Relief: broad undulation + grit; each slab sits at its own height and bulges at its centre.
    broad = fbm(size, 4, generator, octaves=3)
    grit = fbm(size, 16, generator, octaves=6, persistence=params["detail"])
    amplitude = params["relief"] * size
    slab = 0.25 * (attrs[0] - 0.5) + 0.15 * (1.0 - smoothstep(0.0, 0.8, f1))
    height = amplitude * (0.35 * broad + 0.5 * grit + slab - 0.6 * crack)

    # Colour: muted, per-slab tone, speckles of darker and lighter grains; cracks hold dirt.
    fine = fbm(size, 128, generator, octaves=2)
    speckle = params["speckle"] * (smoothstep(0.35, 0.6, fine) - smoothstep(0.35, 0.6, -fine))
    tone = 1.0 + params["color_variation"] * (2 * attrs[1] - 1)
    value = params["value"] * tone * (1.0 + 0.12 * broad + 0.1 * grit + 0.25 * speckle) * (1.0 - 0.55 * crack)
    saturation = torch.full_like(value, params["saturation"]) * (1.0 + 0.3 * broad)
    basecolor = hsv_to_rgb(
        torch.full_like(value, params["hue"]) + 0.02 * broad,
        saturation.clamp(0.0, 1.0),
        value.clamp(0.0, 1.0),
    ).clamp(0.02, 0.95)

    roughness = params["roughness"] + 0.06 * grit + (0.98 - params["roughness"]) * crack
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="rough_stone",
    parameters={
        "cell_count": Parameter(5.0, 2.0, 12.0, "slabs per side (Worley cells, rounded)"),
        "crack_width": Parameter(0.04, 0.0, 0.1, "crack width in cell units (0 = no cracks)"),
        "relief": Parameter(0.012, 0.004, 0.025, "height amplitude, fraction of the image width"),
        "detail": Parameter(0.55, 0.4, 0.7, "fractal persistence of the relief (grittiness)"),
        "hue": Parameter(0.09, 0.0, 0.16, "hue of the mean stone colour, in turns"),
        "saturation": Parameter(0.12, 0.0, 0.3, "saturation of the mean stone colour"),
        "value": Parameter(0.5, 0.2, 0.75, "brightness of the mean stone colour (sRGB)"),
        "color_variation": Parameter(0.12, 0.0, 0.3, "per-slab spread of brightness"),
        "roughness": Parameter(0.85, 0.7, 0.95, "perceptual roughness of the stone surface"),
        "speckle": Parameter(0.3, 0.0, 0.8, "amount of dark and light mineral grains"),
    },
    generate=_generate,
    description="Weathered rough rock with fractal relief, cellular slabs and dark cracks.",
    tags=("stone", "rock", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
