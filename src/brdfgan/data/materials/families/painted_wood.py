"""Lacquered and painted wood: boards under paint of any colour or under a clear lacquer.

Depicts horizontal boards (panelling, shiplap, fences, doors, furniture) separated by V-grooves,
coated with paint or lacquer. The wood underneath has warped growth rings and fibres; the coat
follows the wood's surface, so the grain shows through as relief even under opaque paint, and
through its colour where the coat is transparent (a clear lacquer shows the bare wood, a thin
paint or stain lets it tint the colour). The coat sets the roughness: glossy lacquer is smooth,
matte paint rough, with faint brush streaks along the boards. Chipped paint exposes raw,
weathered wood (paler, greyer, rough and a paint layer lower), mostly along board edges where
boards get knocked, with ragged outlines stretched along the grain. The wood's hue and
saturation (browns) are drawn from the generator.

Why it is in the dataset: the original families have bare or varnished wood in browns only;
painted surfaces (doors, furniture, walls of boards, toys) come in every colour, are either
glossy or matte independently of the colour, and show wood relief under a uniform colour. Chips
teach the model that a colour boundary can carry both a roughness and a height step.

Parameters:
    boards: boards across the square (rounded; one per row, so the layout tiles).
    hue: hue of the paint, in turns (uniform: any hue).
    saturation: saturation of the paint.
    value: brightness of the paint (sRGB).
    paint: opacity of the coat, 0 = clear lacquer over the bare wood, 1 = opaque paint.
    gloss: 0 = matte coat (rough), 1 = high-gloss lacquer (smooth).
    chipping: amount of paint chipped off (0 = intact coat), concentrated at board edges.
    grain_relief: height of the grain relief, as a fraction of the image width.
    grain_scale: growth rings across one board.
    wood_value: brightness of the bare wood (sRGB).
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
    smooth_fbm,
    texel_coordinates,
    value_noise,
)

# Relief as fractions of the image width, so normals look alike at every resolution.
_GROOVE_DEPTH = 0.004
_GROOVE_WIDTH = 0.003
_BEVEL_WIDTH = 0.006
_PAINT_THICKNESS = 0.0012
# Roughness of a matte and of a high-gloss coat, and of raw weathered wood.
_MATTE, _GLOSSY, _RAW_WOOD = 0.7, 0.06, 0.8


def _hsv(hue: float, saturation: float, value: float) -> Tensor:
    """One sRGB colour from HSV (hue in turns). Shape: ``(3, 1, 1)``."""
    return hsv_to_rgb(torch.tensor([[hue]]), torch.tensor([[saturation]]), torch.tensor([[value]]))


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    n = max(1, round(params["boards"]))
    # Boards are bands of rows, so everything that depends on the board alone is computed per
    # row, shape (size, 1), and broadcast: no full-resolution integer maths.
    v = texel_coordinates(size)[1][:, :1]
    y = v * n
    board = y.floor().long().clamp(max=n - 1)
    lv = y - y.floor()

    # Distance to the nearest groove, in image-width units; V-grooves between the boards.
    edge = torch.minimum(lv, 1.0 - lv) / n
    face = smoothstep(_GROOVE_WIDTH / 2.0, _GROOVE_WIDTH / 2.0 + _BEVEL_WIDTH, edge)

    # Each board is cut from a different part of the log: its own rows of the grain fields,
    # read with the row axis compressed (an integer factor keeps them periodic) so the
    # features run long along the board, like fibres.
    attrs = random_per_cell(board, n, generator, channels=3)
    rows = torch.arange(size).view(size, 1) + (attrs[0] * size).long()
    warp_field = smooth_fbm(size, 4, generator, octaves=2, texels_per_cell=16)  # smooth: coarse, upsampled
    fibre_field = value_noise(size, min(size, 32), generator)
    warp = warp_field[(rows[:, 0] * n) % size]
    fibre = fibre_field[(rows[:, 0] * 8) % size]

    # Growth rings: iso-lines of the warped across-board position, sawtooth profile (gradual
    # earlywood, abrupt latewood).
    ring_coord = params["grain_scale"] * (lv + 0.25 * warp) + 4.0 * attrs[1]
    ring = ring_coord - ring_coord.floor()
    latewood = smoothstep(0.5, 0.9, ring) * (1.0 - smoothstep(0.9, 1.0, ring))
    grain = latewood + 0.5 * fibre

    wood_draws = torch.rand(2, generator=generator)
    wood_hue, wood_saturation = 0.05 + 0.05 * float(wood_draws[0]), 0.4 + 0.25 * float(wood_draws[1])
    tone = 1.0 + 0.1 * (2.0 * attrs[2] - 1.0)
    wood_value = (params["wood_value"] * tone * (1.0 - 0.3 * latewood - 0.08 * fibre)).clamp(0.0, 1.0)
    # HSV is linear in the value: the wood is its constant tint times the value field.
    wood = _hsv(wood_hue, wood_saturation, 1.0) * wood_value[None]

    # Chips: blotches of paint knocked off, likelier near the board edges, ragged along the
    # grain. chipping = 0 puts the threshold above the field's maximum, so no chip at all.
    near_edge = 1.0 - smoothstep(0.0, 0.3 / n, edge)
    ragged = 0.7 * fibre_field + 0.3 * fibre  # fibre_field unstretched: round blotches
    chip_threshold = 1.4 - 0.8 * params["chipping"]
    chipped = smoothstep(chip_threshold, chip_threshold + 0.04, ragged + 0.4 * near_edge)
    coat = 1.0 - chipped

    paint = _hsv(params["hue"], params["saturation"], params["value"])
    # Brush streaks along the boards give the paint a faint tone variation.
    painted = wood + (paint * (1.0 + 0.04 * (fibre - 0.5)) - wood) * params["paint"]
    # Bare wood weathers: paler and greyer than the wood kept under the coat.
    weathered = 0.75 * wood + 0.25 * wood.mean(dim=0, keepdim=True) + 0.05
    surface = weathered + (painted - weathered) * coat[None]
    groove_shade = 0.4 + 0.6 * face  # the groove is in shadow and holds dirt
    basecolor = clamp_dielectric_albedo(surface * groove_shade[None])

    # The coat follows the wood; bare wood shows more grain (the soft earlywood erodes) and
    # lies a paint layer lower.
    grain_height = params["grain_relief"] * size * grain * (1.0 + 0.5 * chipped)
    height = grain_height + _PAINT_THICKNESS * size * coat - _GROOVE_DEPTH * size * (1.0 - face)

    coat_rough = _MATTE + (_GLOSSY - _MATTE) * params["gloss"] + 0.04 * (fibre - 0.5)
    raw_rough = _RAW_WOOD + 0.1 * (fibre - 0.5)
    surface_rough = raw_rough + (coat_rough - raw_rough) * coat
    roughness = surface_rough + (1.0 - face) * (0.1 + 0.2 * (1.0 - params["gloss"]))
    return MaterialLayers.dielectric(basecolor, height, roughness)


FAMILY = MaterialFamily(
    name="painted_wood",
    parameters={
        "boards": Parameter(5.0, 2.0, 10.0, "boards across the square (rounded)"),
        "hue": Parameter(0.5, 0.0, 1.0, "hue of the paint, in turns", uniform=True),
        "saturation": Parameter(0.6, 0.0, 0.95, "saturation of the paint"),
        "value": Parameter(0.6, 0.1, 0.92, "brightness of the paint (sRGB)"),
        "paint": Parameter(0.85, 0.0, 1.0, "coat opacity: 0 clear lacquer over bare wood, 1 opaque paint"),
        "gloss": Parameter(0.4, 0.0, 1.0, "0 matte coat (rough), 1 high-gloss lacquer (smooth)"),
        "chipping": Parameter(0.3, 0.0, 1.0, "amount of chipped paint exposing the wood (0 = intact)"),
        "grain_relief": Parameter(0.0008, 0.0002, 0.002, "grain relief height, fraction of the image width"),
        "grain_scale": Parameter(5.0, 2.0, 10.0, "growth rings across one board"),
        "wood_value": Parameter(0.55, 0.25, 0.8, "brightness of the bare wood (sRGB)"),
    },
    generate=_generate,
    description="Painted or clear-lacquered boards: grain relief under the coat, chipped paint at edges.",
    tags=("wood", "painted", "lacquer", "planks", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
