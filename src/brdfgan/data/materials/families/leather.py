"""Leather or woven fabric: soft dielectric surfaces with a fine, regular micro-structure.

Leather: a pebbled grain of small pillow-shaped bumps between narrow grooves (Worley cells), a
finer second grain, and longer creases (ridged noise) that are lower, darker and rougher; medium
roughness, slightly glossier on the tops of the bumps (worn by handling). Fabric (``weave`` ≥ 0.5):
a plain weave of over/under threads (a periodic pattern), fibre streaks along each thread, dark
gaps between threads and a high roughness. Both are dielectric (metallic 0).

Parameters:
    weave: < 0.5 leather, otherwise woven fabric.
    grain_cells: leather grain bumps per side (Worley cells, rounded).
    threads: fabric threads per side (rounded).
    relief: grain / thread height, as a fraction of the image width.
    crease: amount of creases (leather) or fold wrinkles (fabric).
    hue, saturation, value: HSV of the mean colour (sRGB).
    roughness: perceptual roughness of the bump tops / threads.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    fbm,
    gradient_noise,
    hsv_to_rgb,
    texel_coordinates,
    value_noise,
    worley,
)


def _leather(params: Mapping[str, float], size: int, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Leather relief in [about -1, 1] and a 0–1 'crease / groove' mask. Shape: each ``(size, size)``."""
    cells = max(4, round(params["grain_cells"]))
    f1, f2, _ = worley(size, cells, generator, jitter=0.9)
    # Pillow bumps: high in the cell interior, dropping into narrow grooves at the cell borders.
    border = f2 - f1
    bumps = torch.sqrt((border / 0.35).clamp(0.0, 1.0))
    fine = value_noise(size, min(size, 4 * cells), generator)  # finer pores in the bump tops
    # Creases: a few long lines where ridged noise (1 − |gradient noise|) peaks.
    ridged = 1.0 - gradient_noise(size, 5, generator).abs() - 0.35 * fbm(size, 10, generator, octaves=3).abs()
    crease = params["crease"] * ((ridged - 0.8) / 0.2).clamp(0.0, 1.0) ** 2
    relief = bumps - 0.25 * fine - 1.2 * crease
    groove = ((1.0 - bumps) * 0.7 + crease).clamp(0.0, 1.0)
    return relief, groove


def _fabric(params: Mapping[str, float], size: int, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Plain-weave relief in [about 0, 1] and a 0–1 gap mask. Shape: each ``(size, size)``."""
    threads = max(4, round(params["threads"]))
    u, v = texel_coordinates(size)
    x, y = u * threads, v * threads
    i, j = x.floor().long(), y.floor().long()
    fu, fv = x - x.floor(), y - y.floor()
    # Each thread has an elliptical cross-section; along its length it dips where it passes under
    # the crossing thread, so warp (vertical) threads are high in alternate cells and weft in the rest.
    across_warp = torch.sin(math.pi * fu).clamp(min=0.0).sqrt()
    across_weft = torch.sin(math.pi * fv).clamp(min=0.0).sqrt()
    along_warp = 0.55 + 0.45 * torch.sin(math.pi * fv)
    along_weft = 0.55 + 0.45 * torch.sin(math.pi * fu)
    warp_over = ((i + j) % 2) == 0
    relief = torch.where(warp_over, across_warp * along_warp, across_weft * along_weft)
    # Fibres: fine streaks along each thread (noise stretched by sampling a coarse axis finely).
    streak_v = value_noise(size, min(size, 8 * threads), generator)
    fibre = torch.where(warp_over, streak_v.roll(shifts=size // 3, dims=0), streak_v.T)
    relief = relief * (0.85 + 0.15 * fibre)
    wrinkle = params["crease"] * fbm(size, 3, generator, octaves=3)
    gap = (1.0 - relief).clamp(0.0, 1.0) ** 2
    return relief + 0.8 * wrinkle, gap


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    is_fabric = params["weave"] >= 0.5
    relief, groove = (_fabric if is_fabric else _leather)(params, size, generator)
    height = params["relief"] * size * relief

    # Dye / tan variation: broad blotches of tone; grooves and gaps hold more dye and dirt (darker).
    blotch = fbm(size, 4, generator, octaves=4)
    value = params["value"] * (1.0 + 0.12 * blotch) * (1.0 - 0.35 * groove)
    basecolor = hsv_to_rgb(
        torch.full_like(value, params["hue"]) + 0.01 * blotch,
        torch.full_like(value, params["saturation"]).clamp(0.0, 1.0),
        value.clamp(0.0, 1.0),
    ).clamp(0.02, 0.95)

    # Fabric scatters light in its fibres (always rough); leather tops are polished by wear, the
    # grooves and creases stay rough.
    base = min(params["roughness"] + 0.2, 0.95) if is_fabric else params["roughness"]
    roughness = base + 0.2 * groove + 0.04 * blotch
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="leather",
    parameters={
        "weave": Parameter(0.0, 0.0, 1.0, "surface type: < 0.5 leather grain, otherwise woven fabric"),
        "grain_cells": Parameter(70.0, 30.0, 160.0, "leather grain bumps per side (Worley cells)"),
        "threads": Parameter(90.0, 40.0, 220.0, "fabric threads per side (rounded)"),
        "relief": Parameter(0.002, 0.0007, 0.005, "grain / thread height, fraction of the image width"),
        "crease": Parameter(0.4, 0.0, 1.0, "amount of creases (leather) or wrinkles (fabric)"),
        "hue": Parameter(0.07, 0.0, 1.0, "hue of the mean colour, in turns (0.07 = tan brown)"),
        "saturation": Parameter(0.55, 0.0, 0.85, "saturation of the mean colour"),
        "value": Parameter(0.4, 0.08, 0.85, "brightness of the mean colour (sRGB)"),
        "roughness": Parameter(0.55, 0.35, 0.8, "perceptual roughness of the bump tops / threads"),
    },
    generate=_generate,
    description="Pebbled leather grain with creases, or a plain-weave fabric with threads and fibres.",
    tags=("leather", "fabric", "organic", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
