"""Polished marble: a honed/polished slab with turbulent veins.

Depicts a polished marble surface (Carrara, Calacatta, Nero Marquina): a cloudy light (or dark)
ground crossed by warped main veins (a sine of position displaced by fractal noise, the classic
turbulence construction) and a web of thin secondary veins, low roughness with slightly duller
veins, and only a whisper of relief (veins etch a little deeper in polishing).

Parameters:
    vein_count: main veins across the square (rounded, so the pattern tiles).
    vein_warp: turbulence displacing the veins (0 = straight bands).
    vein_sharpness: how thin the main veins are.
    secondary_veins: strength of the web of thin secondary veins.
    hue, saturation, value: HSV of the ground colour (sRGB).
    vein_value: brightness of the veins (sRGB); below value for dark veins on light ground.
    roughness: perceptual roughness of the polish.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, texel_coordinates

# Relief as a fraction of the image width: polished stone is nearly flat.
_RELIEF = 0.0006


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    a = max(1, round(params["vein_count"]))
    # A random integer direction (a, b) keeps sin(2π(a·u + b·v)) periodic on the unit square
    # while letting the veins run diagonally.
    b = int(torch.randint(-a, a + 1, (), generator=generator).item())
    u, v = texel_coordinates(size)
    turbulence = fbm(size, 3, generator, octaves=6, persistence=0.55)
    phase = a * u + b * v + params["vein_warp"] * turbulence
    main = (1.0 - torch.sin(2.0 * math.pi * phase).abs()) ** params["vein_sharpness"]

    # Secondary veins: thin zero-crossings of an independent fractal field.
    web_field = fbm(size, 6, generator, octaves=5)
    web = (1.0 - smoothstep(0.0, 0.03, web_field.abs())) * params["secondary_veins"]
    veins = torch.maximum(main, 0.6 * web)

    cloud = fbm(size, 4, generator, octaves=5)
    ground_v = (params["value"] * (1.0 + 0.06 * cloud)).clamp(0.0, 1.0)
    ground = hsv_to_rgb(
        torch.full_like(ground_v, params["hue"]), torch.full_like(ground_v, params["saturation"]), ground_v
    )
    vein_v = torch.full_like(ground_v, params["vein_value"]) * (1.0 + 0.1 * cloud)
    vein_colour = hsv_to_rgb(
        torch.full_like(ground_v, params["hue"]),
        torch.full_like(ground_v, min(1.0, params["saturation"] * 1.5)),
        vein_v.clamp(0.0, 1.0),
    )
    basecolor = (ground + (vein_colour - ground) * veins[None]).clamp(0.02, 0.95)

    relief = _RELIEF * size
    height = relief * (0.3 * cloud - veins)
    roughness = params["roughness"] * (1.0 + 0.5 * veins + 0.1 * cloud)
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="marble",
    parameters={
        "vein_count": Parameter(2.0, 1.0, 5.0, "main veins across the square (rounded)"),
        "vein_warp": Parameter(1.0, 0.2, 2.0, "turbulence displacing the veins"),
        "vein_sharpness": Parameter(10.0, 3.0, 30.0, "exponent thinning the main veins"),
        "secondary_veins": Parameter(0.5, 0.0, 1.0, "strength of the thin secondary vein web"),
        "hue": Parameter(0.1, 0.0, 0.2, "hue of the ground colour, in turns (warm white)"),
        "saturation": Parameter(0.05, 0.0, 0.25, "saturation of the ground colour"),
        "value": Parameter(0.85, 0.1, 0.92, "brightness of the ground (sRGB); low for black marble"),
        "vein_value": Parameter(0.4, 0.1, 0.9, "brightness of the veins (sRGB)"),
        "roughness": Parameter(0.1, 0.03, 0.25, "perceptual roughness of the polish"),
    },
    generate=_generate,
    description="Polished marble with turbulent main veins, thin secondary veins and low roughness.",
    tags=("marble", "stone", "polished", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
