"""Ceramic tiles: a square grid of glazed tiles set in grout.

Depicts glazed ceramic tiles on a regular grid, each with its own slight colour shift (firing
batches differ) and a slight tilt (tiles are never set perfectly flat), rounded edges, a smooth
glossy glaze with faint mottling, and recessed, rough, greyish, sandy grout lines.

Parameters:
    tile_count: tiles along each side of the square (rounded, so the grid tiles).
    grout_width: width of the grout lines as a fraction of the tile pitch.
    bevel: width of the rounded tile edge as a fraction of the tile pitch.
    hue, saturation, value: HSV of the mean glaze colour (sRGB).
    color_variation: per-tile spread of brightness and hue.
    glaze_roughness: perceptual roughness of the glaze.
    grout_value: brightness of the grout (sRGB).
    tilt: largest per-tile height change across a tile, as a fraction of the grout depth.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, random_per_cell, texel_coordinates

# Grout depth as a fraction of the image width, so normals look alike at every resolution.
_GROUT_DEPTH = 0.003


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    n = max(1, round(params["tile_count"]))
    u, v = texel_coordinates(size)
    x, y = u * n, v * n
    col, row = x.floor().long().clamp(max=n - 1), y.floor().long().clamp(max=n - 1)
    lu, lv = x - x.floor(), y - y.floor()
    tile = row * n + col

    # Distance to the tile border in tile-pitch units; the glaze rounds over the edge.
    edge = torch.minimum(torch.minimum(lu, 1.0 - lu), torch.minimum(lv, 1.0 - lv))
    half_grout = params["grout_width"] / 2.0
    face = smoothstep(half_grout, half_grout + params["bevel"], edge)
    # A rounded (convex) profile rather than the S of smoothstep: glaze flows over the edge.
    profile = torch.sqrt(face.clamp(min=0.0))

    attrs = random_per_cell(tile, n * n, generator, channels=4)
    depth = _GROUT_DEPTH * size
    # Per-tile plane tilt, bounded by a fraction of the grout depth so a face never sinks below it.
    tilt = params["tilt"] * depth * ((2 * attrs[0] - 1) * (lu - 0.5) + (2 * attrs[1] - 1) * (lv - 0.5))

    grout_noise = fbm(size, 64, generator, octaves=2)  # sand grains, fixed in image units
    glaze_noise = fbm(size, 4 * n, generator, octaves=4)
    height = depth * profile + profile * tilt + (1.0 - face) * 0.08 * depth * grout_noise
    height = height + face * 0.01 * depth * glaze_noise

    # Glaze colour: per-tile brightness and hue shift plus faint mottling.
    variation = params["color_variation"]
    value = params["value"] * (1.0 + variation * (2 * attrs[2] - 1)) * (1.0 + 0.04 * glaze_noise)
    hue = params["hue"] + 0.15 * variation * (2 * attrs[3] - 1)
    saturation = torch.full_like(value, params["saturation"])
    glaze = hsv_to_rgb(hue, saturation, value.clamp(0.0, 1.0))
    grout_v = (params["grout_value"] * (1.0 + 0.12 * grout_noise)).clamp(0.0, 1.0)
    grout = hsv_to_rgb(torch.full_like(grout_v, 0.1), torch.full_like(grout_v, 0.06), grout_v)
    basecolor = (grout + (glaze - grout) * face[None]).clamp(0.02, 0.95)

    glaze_rough = params["glaze_roughness"] * (1.0 + 0.15 * glaze_noise)
    grout_rough = 0.9 + 0.05 * grout_noise
    roughness = grout_rough + (glaze_rough - grout_rough) * face
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="ceramic_tiles",
    parameters={
        "tile_count": Parameter(6.0, 2.0, 16.0, "tiles along each side (rounded)"),
        "grout_width": Parameter(0.05, 0.02, 0.12, "grout line width, fraction of the tile pitch"),
        "bevel": Parameter(0.06, 0.02, 0.15, "rounded tile edge width, fraction of the tile pitch"),
        "hue": Parameter(0.55, 0.0, 1.0, "hue of the glaze, in turns"),
        "saturation": Parameter(0.25, 0.0, 0.7, "saturation of the glaze"),
        "value": Parameter(0.75, 0.2, 0.92, "brightness of the glaze (sRGB)"),
        "color_variation": Parameter(0.05, 0.0, 0.15, "per-tile spread of brightness and hue"),
        "glaze_roughness": Parameter(0.15, 0.04, 0.4, "perceptual roughness of the glaze"),
        "grout_value": Parameter(0.6, 0.3, 0.85, "brightness of the grout (sRGB)"),
        "tilt": Parameter(0.3, 0.0, 0.6, "per-tile tilt, height change as a fraction of grout depth"),
    },
    generate=_generate,
    description="Glazed ceramic tiles on a grid with recessed rough grout and slight per-tile tilt.",
    tags=("tiles", "ceramic", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
