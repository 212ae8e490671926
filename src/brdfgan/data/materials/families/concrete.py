"""Concrete and plaster: a rough, grey, mineral wall or floor surface.

Depicts cast concrete or plaster: low-frequency tone variation (cement mixing, moisture, stains),
a fine sandy grit, small air-void pores (thresholded high-frequency noise: darker, lower and
rougher, since they hold dust and are cavities) and optional trowel marks (smoother, slightly
glossier overlapping swirls with small ridges at their edges). High roughness, dielectric.

Parameters:
    value: mean brightness (sRGB).
    hue, saturation: warmth of the grey (hue in turns; low saturation).
    tone_variation: strength of the low-frequency blotches.
    pore_density: fraction of the surface covered by pores.
    pore_size: pore size, as a fraction of the image width.
    roughness: perceptual roughness of the surface.
    relief: grit height, as a fraction of the image width.
    trowel: strength of trowel marks (0 = cast / sprayed surface).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, value_noise


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    amplitude = params["relief"] * size
    blotch = fbm(size, 3, generator, octaves=5, persistence=0.55)
    grit = fbm(size, 64, generator, octaves=3, persistence=0.6)

    # Pores: value-noise blobs about one pore wide, kept where the noise is high enough for the
    # requested coverage (value noise is roughly bell-shaped: the top ~density fraction survives).
    pore_cells = min(size, max(8, round(0.5 / max(params["pore_size"], 1e-4))))
    blobs = value_noise(size, pore_cells, generator)
    sample = blobs.flatten()[:: max(1, blobs.numel() // 65536)]
    density = params["pore_density"]
    if density > 0.0:
        level = torch.quantile(sample, 1.0 - min(density, 0.99)).item()
        pore = smoothstep(level, level + 0.08, blobs)
    else:
        pore = torch.zeros(size, size)

    # Trowel marks: contour bands of a smooth field → overlapping arcs; the blade leaves a smooth,
    # compacted (less rough) patch and a small ridge where each stroke ends.
    trowel = params["trowel"]
    if trowel > 0.0:
        swirl = fbm(size, 2, generator, octaves=3) * 6.0
        band = swirl - swirl.floor()
        ridge = smoothstep(0.85, 1.0, band)
        smooth_patch = smoothstep(0.1, 0.6, band) * (1.0 - ridge)
    else:
        ridge = smooth_patch = torch.zeros(size, size)

    height = amplitude * (
        0.4 * blotch
        + (0.6 - 0.4 * trowel * smooth_patch) * grit
        + 0.5 * trowel * ridge
        - 2.0 * pore  # cavities: deeper than the grit
    )

    value = (
        params["value"]
        * (1.0 + params["tone_variation"] * blotch)
        * (1.0 + 0.06 * grit)
        * (1.0 - 0.45 * pore)
    )
    basecolor = hsv_to_rgb(
        torch.full_like(value, params["hue"]),
        (params["saturation"] * (1.0 + 0.5 * blotch)).clamp(0.0, 1.0),
        value.clamp(0.0, 1.0),
    ).clamp(0.02, 0.95)

    roughness = (
        params["roughness"]
        + 0.05 * grit
        - 0.03 * blotch  # damp / stained patches are a little smoother
        - 0.25 * trowel * smooth_patch
        + (1.0 - params["roughness"]) * 0.8 * pore
    )
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="concrete",
    parameters={
        "value": Parameter(0.55, 0.3, 0.85, "mean brightness (sRGB)"),
        "hue": Parameter(0.1, 0.0, 0.2, "hue of the grey, in turns (warm beige … cool grey)"),
        "saturation": Parameter(0.05, 0.0, 0.15, "saturation of the grey"),
        "tone_variation": Parameter(0.15, 0.0, 0.35, "strength of the low-frequency blotches"),
        "pore_density": Parameter(0.08, 0.0, 0.25, "fraction of the surface covered by pores"),
        "pore_size": Parameter(0.004, 0.0015, 0.012, "pore size, fraction of the image width"),
        "roughness": Parameter(0.85, 0.7, 0.97, "perceptual roughness of the surface"),
        "relief": Parameter(0.002, 0.001, 0.005, "grit height, fraction of the image width"),
        "trowel": Parameter(0.2, 0.0, 1.0, "strength of trowel marks (0 = cast or sprayed)"),
    },
    generate=_generate,
    description="Grey concrete or plaster with tone blotches, grit, dark pores and trowel marks.",
    tags=("concrete", "plaster", "mineral", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
