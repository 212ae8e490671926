"""Bricks: a wall of fired clay bricks in running (stretcher) bond with recessed mortar.

Depicts courses of bricks where every other course is shifted by half a brick, each brick with its
own colour (clay and firing temperature vary), a mottled, pitted, rough face, chipped irregular
edges, and rough, greyish, sandy mortar joints set back from the faces.

Parameters:
    brick_rows: courses across the square (rounded to an even number so the bond tiles).
    bricks_per_row: bricks along one course (rounded).
    mortar_width: joint width as a fraction of the course pitch.
    hue, saturation, value: HSV of the mean brick colour (sRGB).
    color_variation: per-brick spread of brightness and hue.
    chipping: how much the brick edges are broken away (0 = crisp).
    brick_roughness: perceptual roughness of the brick faces.
    mortar_value: brightness of the mortar (sRGB).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, random_per_cell, texel_coordinates

# Relief as fractions of the image width, so normals look alike at every resolution.
_MORTAR_DEPTH = 0.005
_BEVEL_WIDTH = 0.003
_CHIP_REACH = 0.012  # how far into a brick a chip may reach at chipping = 1


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    rows_n = max(2, 2 * round(params["brick_rows"] / 2.0))  # even: the half-brick shift repeats
    per_row = max(1, round(params["bricks_per_row"]))
    u, v = texel_coordinates(size)
    y = v * rows_n
    row = y.floor().long().clamp(max=rows_n - 1)
    x = u * per_row + 0.5 * (row % 2).float()  # running bond: odd courses shifted half a brick
    col = x.floor().long() % per_row
    brick = row * per_row + col
    lu, lv = x - x.floor(), y - y.floor()

    # Distance to the nearest joint in image-width units; eroded by noise for chipped edges.
    edge = torch.minimum(torch.minimum(lv, 1.0 - lv) / rows_n, torch.minimum(lu, 1.0 - lu) / per_row)
    chip_noise = fbm(size, 24, generator, octaves=4)
    chip = params["chipping"] * _CHIP_REACH * (chip_noise * 2.0).clamp(min=0.0)
    half_joint = params["mortar_width"] / rows_n / 2.0
    face = smoothstep(half_joint, half_joint + _BEVEL_WIDTH, edge - chip)

    attrs = random_per_cell(brick, rows_n * per_row, generator, channels=3)
    mottle = fbm(size, 16, generator, octaves=5)
    grit = fbm(size, 96, generator, octaves=2)  # sand and pores, fixed in image units
    depth = _MORTAR_DEPTH * size

    # Height: brick faces proud of the mortar, a pitted face, and a per-brick offset (bricks are
    # never laid perfectly flush).
    face_height = depth * (1.0 + 0.15 * (attrs[0] - 0.5) + 0.06 * mottle + 0.05 * grit)
    mortar_height = depth * 0.1 * grit
    height = mortar_height + (face_height - mortar_height) * face

    variation = params["color_variation"]
    value = params["value"] * (1.0 + variation * (2 * attrs[1] - 1)) * (1.0 + 0.12 * mottle + 0.06 * grit)
    hue = params["hue"] + 0.1 * variation * (2 * attrs[2] - 1)
    saturation = torch.full_like(value, params["saturation"]) * (1.0 - 0.2 * mottle)
    clay = hsv_to_rgb(hue, saturation.clamp(0.0, 1.0), value.clamp(0.0, 1.0))
    mortar_v = (params["mortar_value"] * (1.0 + 0.1 * grit)).clamp(0.0, 1.0)
    mortar = hsv_to_rgb(torch.full_like(mortar_v, 0.11), torch.full_like(mortar_v, 0.08), mortar_v)
    basecolor = (mortar + (clay - mortar) * face[None]).clamp(0.02, 0.95)

    brick_rough = params["brick_roughness"] + 0.05 * grit - 0.03 * mottle
    mortar_rough = 0.95 + 0.03 * grit
    roughness = mortar_rough + (brick_rough - mortar_rough) * face
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="bricks",
    parameters={
        "brick_rows": Parameter(10.0, 4.0, 16.0, "courses across the square (rounded to even)"),
        "bricks_per_row": Parameter(3.0, 2.0, 6.0, "bricks along each course (rounded)"),
        "mortar_width": Parameter(0.15, 0.06, 0.3, "joint width, fraction of the course pitch"),
        "hue": Parameter(0.03, 0.0, 0.08, "hue of the mean brick colour, in turns (red-orange)"),
        "saturation": Parameter(0.55, 0.25, 0.75, "saturation of the mean brick colour"),
        "value": Parameter(0.5, 0.3, 0.75, "brightness of the mean brick colour (sRGB)"),
        "color_variation": Parameter(0.15, 0.0, 0.35, "per-brick spread of brightness and hue"),
        "chipping": Parameter(0.5, 0.0, 1.0, "how much the brick edges are broken away"),
        "brick_roughness": Parameter(0.8, 0.6, 0.9, "perceptual roughness of the brick faces"),
        "mortar_value": Parameter(0.62, 0.4, 0.85, "brightness of the mortar (sRGB)"),
    },
    generate=_generate,
    description="Running-bond brick wall with per-brick colour, chipped edges and recessed mortar.",
    tags=("bricks", "masonry", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
