"""Plastics and rubber: injection-moulded plastic of any saturated hue, and rubber mats.

Depicts a moulded surface selected by ``mode``: smooth plastic with a faint orange-peel
waviness, plastic with a moulded texture (leather grain: domed pebbles between a network of
narrow grooves; stipple: scattered fine round bumps; ribbed: parallel rounded ribs), or a rubber
mat (dark, rough, studded with round flat-topped studs or ribbed with broad flat bars, both
with strong relief and a fine matte micro-texture). Plastic is one saturated colour with a glossy
to satin finish; rubber is dark and less saturated with a rough finish. Wear adds scuffs: on
plastic they are rougher and paler (stress whitening), on rubber the raised parts are polished
smoother and greyed by dust.

Why it is in the dataset: the original families contain no plastics and hardly any saturated
colours, yet phones photograph plastic casings, toys, appliances, dashboards and rubber mats all
the time. Plastic decouples colour from everything else (any hue, any gloss), and the moulded
textures and mats give regular, strong relief on an otherwise uniform material.

Parameters:
    mode: surface type, rounded down: 0 smooth, 1 leather grain, 2 stipple, 3 ribbed,
        4 rubber studs, 5 rubber ribs (uniform: no preferred type).
    texture_scale: position of the feature count in the mode's range, 0 = coarsest, 1 = finest
        (features per image width: leather grain 20–80, stipple 30–120, ribs 12–60, studs 6–24,
        rubber ribs 6–30; log-spaced).
    relief: height of the texture as a fraction of its feature pitch (smooth plastic ignores it:
        its orange peel is 1.5 % of its pitch).
    hue: hue of the material, in turns (uniform: any hue).
    saturation: saturation of the plastic (rubber takes half of it).
    value: brightness of the plastic (sRGB; rubber is dark: 0.03 + 0.25 × value).
    roughness: perceptual roughness of the plastic, glossy to satin (rubber maps it to 0.67–0.95).
    wear: amount of scuffing (0 = pristine).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    gradient_noise,
    hsv_to_rgb,
    smooth_fbm,
    texel_coordinates,
    value_noise,
)

MODES = ("smooth", "leather_grain", "stipple", "ribbed", "rubber_studs", "rubber_ribs")
# Features per image width at texture_scale 0 and 1, per mode (smooth: orange-peel cells).
_FEATURE_RANGE: dict[str, tuple[float, float]] = {
    "smooth": (16.0, 32.0),
    "leather_grain": (20.0, 80.0),
    "stipple": (30.0, 120.0),
    "ribbed": (12.0, 60.0),
    "rubber_studs": (6.0, 24.0),
    "rubber_ribs": (6.0, 30.0),
}
_RUBBER = ("rubber_studs", "rubber_ribs")
# Orange-peel waviness of smooth mouldings, as a fraction of its cell pitch.
_ORANGE_PEEL = 0.015


def _texture(mode: str, count: int, size: int, generator: torch.Generator) -> Tensor:
    """Relief of the moulded texture in [0, 1] (1 = raised), ``count`` features per width.

    Shape: ``(size, size)``.
    """
    u, v = texel_coordinates(size)
    if mode == "smooth":
        return 0.5 + 0.5 * gradient_noise(size, count, generator)
    if mode == "leather_grain":
        # |noise| vanishes along a network of curves (its zero crossings): narrow grooves
        # between domed pebbles, like a grained dashboard.
        return torch.sqrt(gradient_noise(size, count, generator).abs().clamp(max=0.6) / 0.6)
    if mode == "stipple":
        # The positive lobes of gradient noise: scattered round bumps on a flat ground.
        return smoothstep(0.15, 0.55, gradient_noise(size, count, generator))
    if mode == "ribbed":
        d = (u * count - (u * count).floor() - 0.5).abs()  # 0 on the rib crest, 0.5 in the valley
        return torch.sqrt((1.0 - (d / 0.35) ** 2).clamp(min=0.0))  # rounded ribs, flat valleys
    if mode == "rubber_studs":
        x, y = u * count, v * count
        r = torch.sqrt((x - x.floor() - 0.5) ** 2 + (y - y.floor() - 0.5) ** 2)
        return smoothstep(0.0, 0.05, 0.3 - r) * (0.9 + 0.1 * (1.0 - r / 0.3).clamp(min=0.0))
    d = (v * count - (v * count).floor() - 0.5).abs()  # rubber ribs: broad flat bars along the rows
    return smoothstep(0.0, 0.07, 0.25 - d)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    mode = MODES[min(max(int(params["mode"]), 0), len(MODES) - 1)]
    rubber = mode in _RUBBER
    low, high = _FEATURE_RANGE[mode]
    count = max(1, round(low * (high / low) ** params["texture_scale"]))
    relief = _texture(mode, count, size, generator)
    pitch = size / count
    amplitude = _ORANGE_PEEL if mode == "smooth" else params["relief"]
    height = amplitude * pitch * relief

    # Scuffs: patches with ragged outlines (three octaves from 6 cells per width, a smooth
    # field evaluated coarse and upsampled); fbm stays within [-1, 1], so wear = 0 puts the
    # threshold at its maximum and leaves no scuff, wear = 1 scuffs more than half the surface.
    scuff_field = smooth_fbm(size, 6, generator, octaves=3, texels_per_cell=8)
    threshold = (1.0 - params["wear"]) ** 2 - 0.1 * params["wear"]
    scuff = smoothstep(threshold, threshold + 0.08, scuff_field)
    wear = params["wear"]

    hue, saturation, value = params["hue"], params["saturation"], params["value"]
    if rubber:
        saturation, value = 0.5 * saturation, 0.03 + 0.25 * value
        # Fine matte micro-texture of moulded rubber: a fixed fraction of the image width.
        micro = 2.0 * value_noise(size, min(size, 128), generator) - 1.0
        height = height + 0.05 * (size / 128) * micro
    colour = hsv_to_rgb(torch.tensor([[hue]]), torch.tensor([[saturation]]), torch.tensor([[value]]))
    flow = 1.0 + 0.01 * scuff_field  # faint flow marks of the moulding
    if rubber:
        # Dust settles on the worn raised parts and greys them.
        dust = (0.15 * wear * relief * scuff)[None]
        basecolor = colour * flow[None] * (1.0 - dust) + 0.35 * dust
        base_rough = 0.67 + 0.28 * (params["roughness"] - 0.05) / 0.55
        # Walking polishes the tops of studs and bars.
        roughness = base_rough - 0.25 * wear * relief - 0.1 * scuff * relief + 0.03 * micro
    else:
        # Stress whitening: scuffed plastic turns paler and greyer.
        basecolor = colour * flow[None] + (0.75 - colour) * (0.15 * scuff)[None]
        # Valleys of a texture hold a little dirt and grit: slightly rougher than the peaks.
        roughness = params["roughness"] + 0.35 * scuff + 0.04 * (1.0 - relief)
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


FAMILY = MaterialFamily(
    name="plastic",
    parameters={
        "mode": Parameter(
            2.5,
            0.0,
            5.99,
            "type (floor): 0 smooth, 1 leather grain, 2 stipple, 3 ribbed, 4 rubber studs, 5 rubber ribs",
            uniform=True,
        ),
        "texture_scale": Parameter(0.5, 0.0, 1.0, "feature count within the mode's range, 0 coarse, 1 fine"),
        "relief": Parameter(0.1, 0.03, 0.25, "texture height, fraction of its feature pitch"),
        "hue": Parameter(0.5, 0.0, 1.0, "hue of the material, in turns", uniform=True),
        "saturation": Parameter(0.75, 0.0, 1.0, "saturation of the plastic (rubber: half)"),
        "value": Parameter(0.6, 0.1, 0.95, "brightness of the plastic (sRGB; rubber 0.03 + 0.25 × value)"),
        "roughness": Parameter(0.25, 0.05, 0.6, "perceptual roughness of the plastic (rubber: 0.67–0.95)"),
        "wear": Parameter(0.2, 0.0, 1.0, "amount of scuffing (0 = pristine)"),
    },
    generate=_generate,
    description="Moulded plastic of any hue (smooth, grained, stippled, ribbed) or studded or ribbed rubber.",
    tags=("plastic", "rubber", "glossy", "saturated", "dielectric", "tileable"),
)

__all__ = ["FAMILY", "MODES"]
