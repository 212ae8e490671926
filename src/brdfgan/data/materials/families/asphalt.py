"""Asphalt: a road or car-park surface, optionally with a painted road marking.

Depicts an asphalt pavement from above: aggregate stones (one per Worley cell, each its own size
and grey, beige or reddish tone) bound in dark bitumen that fills the gaps between them to part of
their height, so the surface is a fine, granular relief of coated stone domes. Traffic and weather
strip the bitumen off the stone tops (``aggregate``: bare, lighter stone) and grind the tops flat
and smooth (``wear``). An optional painted marking stripe (white or yellow) runs along the rows or
the columns: the paint fills the low gaps (less relief), is smoother than the asphalt and wears
away in patches. Cracks (polygonal, "alligator" cracking) are dark, deep and very rough.
Dielectric throughout.

Why it is in the dataset: roads and car parks are in countless outdoor photos, and nothing else
in the dataset is this dark yet rough, with a dense granular relief and bright, smooth paint
beside it.

Parameters:
    bitumen_value: brightness of the bitumen (sRGB): fresh black … aged grey.
    aggregate: how much of the stones' tops is bare of bitumen (0 = fully coated).
    aggregate_value: mean brightness of the bare stones (sRGB).
    grain: aggregate stones per image width.
    wear: how far traffic has ground the stone tops flat and smooth.
    marking: road marking, rounded down: 0 none, 1 white, 2 yellow.
    marking_width: width of the marking stripe as a fraction of the image width.
    cracks: amount of cracking (0 = none).
    roughness: perceptual roughness of the bitumen surface.
"""

from __future__ import annotations

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
)

MARKINGS = ("none", "white", "yellow")
# Marking paints (HSV, sRGB): road white and road yellow.
_PAINT_HSV = {"white": (0.1, 0.03, 0.88), "yellow": (0.13, 0.85, 0.85)}
_PAINT_ROUGHNESS = 0.5
_PAINT_LEVEL = 0.55  # paint fills the gaps up to this fraction of the stone height
_BITUMEN_FILL = 0.3  # bitumen fills the gaps up to this fraction of the stone height
_STONE_HEIGHT = 0.35  # stone dome height in cell widths (a stone is ~0.3–0.55 cells in radius)
_CRACK_CELLS = 4  # crack polygons per image width
_POLISHED_ROUGHNESS = 0.45  # aggregate tops ground flat by traffic


def aggregate_stones(size: int, cells: int, generator: torch.Generator) -> tuple[Tensor, Tensor, Tensor]:
    """Stone domes, one per Worley cell: ``(height, stone_id, inside)``.

    Height in [0, 1] (1 at the top of the largest stone), ``inside`` in {0, 1} on a stone.
    Radii are 0.3–0.55 cells, so neighbouring stones touch or leave gaps.

    Shape: each ``(size, size)``.
    """
    f1, _, cell_id = worley(size, cells, generator, jitter=0.9)
    attrs = random_per_cell(cell_id, cells * cells, generator, channels=1)[0]
    radius = 0.3 + 0.25 * attrs
    r = f1 / radius
    dome = torch.sqrt((1.0 - r * r).clamp(min=0.0))
    return dome * radius / 0.55, cell_id, (f1 < radius).float()


def crack_network(size: int, amount: float, generator: torch.Generator) -> Tensor:
    """Polygonal cracks in [0, 1] along Worley cell borders, kept where a blotchy field allows.

    Shape: ``(size, size)``.
    """
    if amount <= 0.0:
        return torch.zeros(size, size)
    f1, f2, _ = worley(size, _CRACK_CELLS, generator, jitter=1.0)
    wobble = value_noise(size, min(size, 8 * _CRACK_CELLS), generator) - 0.5
    line = 1.0 - smoothstep(0.0, 0.02, (f2 - f1 + 0.06 * wobble).abs())
    extent = smoothstep(1.0 - amount, 1.0 - amount + 0.2, value_noise(size, 3, generator))
    return line * extent


def marking_stripe(size: int, width: float, generator: torch.Generator) -> Tensor:
    """A straight stripe ``width`` of the image wide at a random offset, along the rows or the
    columns (so it wraps round seamlessly), with edges about a texel soft. Shape: ``(size, size)``."""
    draws = torch.rand(2, generator=generator)
    u, v = texel_coordinates(size)
    across = u if draws[0].item() < 0.5 else v
    offset = across - draws[1].item()
    distance = (offset - torch.round(offset)).abs()  # periodic distance to the stripe centre
    edge = 1.0 / size
    return 1.0 - smoothstep(width / 2.0 - edge, width / 2.0 + edge, distance)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    cells = max(4, round(params["grain"]))
    stones, stone_id, inside = aggregate_stones(size, cells, generator)
    wear = params["wear"]
    # Traffic grinds the tops flat: heights above the cap are mostly removed.
    cap = 1.0 - 0.5 * wear
    ground = (stones - cap).clamp(min=0.0)
    stones = stones - 0.85 * ground
    flat_top = smoothstep(0.0, 0.05, ground)

    sand = value_noise(size, min(size, 4 * cells), generator) - 0.5  # sand and filler in the bitumen
    surface = torch.maximum(stones, torch.full_like(stones, _BITUMEN_FILL) + 0.15 * sand)
    # Bitumen wears off the stone tops first: the bare part grows with ``aggregate`` and wear,
    # and tops ground flat are bare stone whatever the coating was.
    bare_from = 1.0 - 0.9 * min(params["aggregate"] + 0.3 * wear, 1.0)
    bare = inside * torch.maximum(smoothstep(bare_from, bare_from + 0.1, stones), flat_top)

    crack = crack_network(size, params["cracks"], generator)
    marking = MARKINGS[min(max(int(params["marking"]), 0), len(MARKINGS) - 1)]
    if marking != "none":
        stripe = marking_stripe(size, params["marking_width"], generator)
        # Paint flakes off in small patches, few at first and more and more as it wears.
        worn_paint = value_noise(size, min(size, 48), generator)
        flaked = 0.6 * wear**2
        paint = stripe * smoothstep(flaked, flaked + 0.08, worn_paint) * (1.0 - crack)
    else:
        paint = torch.zeros(size, size)
    surface = torch.lerp(surface, torch.maximum(surface, torch.full_like(surface, _PAINT_LEVEL)), paint)
    surface = surface - 0.8 * crack
    height = _STONE_HEIGHT * (size / cells) * surface

    # Colour: dark bitumen with lighter sand; bare stones in greys, beiges and reds.
    bitumen_v = params["bitumen_value"] * (1.0 + 0.25 * sand) * (1.0 - 0.4 * crack)
    bitumen = hsv_to_rgb(torch.full_like(sand, 0.08), torch.full_like(sand, 0.06), bitumen_v.clamp(0.0, 1.0))
    tone = random_per_cell(stone_id, cells * cells, generator, channels=3)
    stone_rgb = hsv_to_rgb(
        0.03 + 0.09 * tone[0],
        0.04 + 0.22 * tone[1] * tone[1],
        (params["aggregate_value"] * (0.7 + 0.6 * tone[2]) * (1.0 + 0.2 * sand)).clamp(0.0, 1.0),
    )
    basecolor = torch.lerp(bitumen, stone_rgb, bare[None])
    if marking != "none":
        h, s, v = _PAINT_HSV[marking]
        paint_v = torch.full_like(sand, v) * (1.0 + 0.08 * sand)
        paint_rgb = hsv_to_rgb(torch.full_like(sand, h), torch.full_like(sand, s), paint_v.clamp(0.0, 1.0))
        basecolor = torch.lerp(basecolor, paint_rgb, paint[None])

    rough = params["roughness"]
    roughness = rough + 0.05 * sand
    roughness = torch.lerp(roughness, torch.full_like(roughness, _POLISHED_ROUGHNESS), bare * flat_top)
    roughness = torch.lerp(roughness, torch.full_like(roughness, _PAINT_ROUGHNESS), paint)
    roughness = torch.lerp(roughness, torch.full_like(roughness, 0.98), crack)
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


FAMILY = MaterialFamily(
    name="asphalt",
    parameters={
        "bitumen_value": Parameter(0.25, 0.16, 0.45, "brightness of the bitumen (sRGB): fresh … aged"),
        "aggregate": Parameter(0.45, 0.0, 1.0, "how much of the stone tops is bare of bitumen"),
        "aggregate_value": Parameter(0.55, 0.35, 0.8, "mean brightness of the bare stones (sRGB)"),
        "grain": Parameter(70.0, 30.0, 150.0, "aggregate stones per image width"),
        "wear": Parameter(0.3, 0.0, 1.0, "how far traffic has ground the stone tops flat and smooth"),
        "marking": Parameter(1.0, 0.0, 2.99, "road marking (floor): 0 none, 1 white, 2 yellow"),
        "marking_width": Parameter(0.15, 0.05, 0.4, "marking stripe width, fraction of the image width"),
        "cracks": Parameter(0.3, 0.0, 1.0, "amount of cracking (0 = none)"),
        "roughness": Parameter(0.88, 0.7, 0.98, "perceptual roughness of the bitumen surface"),
    },
    generate=_generate,
    description="Aggregate in dark bitumen, worn and cracked, with an optional white or yellow road marking.",
    tags=("asphalt", "road", "ground", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
