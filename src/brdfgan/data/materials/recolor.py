"""Recolouring: move a material's base colour in hue, saturation and value, within physical albedos.

The families paint the colours their real counterparts usually have, which leaves whole regions
of colour space (a teal card, a red plastic crate, a blue glazed tile) rare in the data. A
recolour rotates the hue of the dielectric parts of a material, scales their saturation and
value, and then clamps their linear albedo into
:data:`~brdfgan.data.materials.albedo.DIELECTRIC_ALBEDO_LINEAR` (0.02–0.9): nothing darker than
charcoal or brighter than snow. Metal parts keep their measured F0 colour exactly (a blue
"gold" is not a metal any phone photographs); partly metallic texels are recoloured in
proportion to their dielectric share. Colour conversions are kornia's (HSV with hue in radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import kornia.color
import torch
from torch import Tensor

from brdfgan.core.sampling import log_uniform
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialLayers
from brdfgan.data.storage.spec_checks import in_range, ordered


@dataclass(frozen=True)
class RecolorConfig:
    """Share of materials recoloured and the ranges of the change.

    ``probability``: share of the materials recoloured (0 = none, today's data).
    ``hue_shift_max``: largest hue rotation in turns (0.5 reaches every hue).
    ``saturation_min/max``, ``value_min/max``: log-uniform scale factors of HSV saturation and
    value (sRGB-encoded value, as a colour picker shows it).
    """

    probability: float = 0.0
    hue_shift_max: float = 0.5
    saturation_min: float = 0.6
    saturation_max: float = 2.5
    value_min: float = 0.7
    value_max: float = 1.3

    def __post_init__(self) -> None:
        key = "dataset_spec.recolor"
        in_range(f"{key}.probability", self.probability, 0.0, 1.0)
        in_range(f"{key}.hue_shift_max", self.hue_shift_max, 0.0, 0.5)
        for name in ("saturation_min", "saturation_max", "value_min", "value_max"):
            in_range(f"{key}.{name}", getattr(self, name), 0.0, 10.0, low_open=True)
        ordered(key, self, "saturation_min", "saturation_max")
        ordered(key, self, "value_min", "value_max")


@dataclass(frozen=True)
class RecolorDraw:
    """One recolour: hue rotation in turns, saturation and value factors (recorded in metadata)."""

    hue_shift: float
    saturation: float
    value: float

    def to_json(self) -> dict[str, float]:
        return {"hue_shift": self.hue_shift, "saturation": self.saturation, "value": self.value}


def draw_recolor(config: RecolorConfig, generator: torch.Generator) -> RecolorDraw:
    """Hue shift uniform in ±``hue_shift_max``; saturation and value factors log-uniform."""
    u = torch.rand(3, generator=generator, dtype=torch.float64).tolist()
    return RecolorDraw(
        hue_shift=config.hue_shift_max * (2.0 * u[0] - 1.0),
        saturation=log_uniform(u[1], config.saturation_min, config.saturation_max),
        value=log_uniform(u[2], config.value_min, config.value_max),
    )


def recolor_basecolor(basecolor: Tensor, metallic: Tensor, draw: RecolorDraw) -> Tensor:
    """The recoloured sRGB base colour: HSV-shifted and albedo-clamped where dielectric, the
    input where metallic, blended by the metallic value in between.

    Shape: basecolor ``(3, H, W)``, metallic ``(1, H, W)`` → ``(3, H, W)``.
    """
    hsv = kornia.color.rgb_to_hsv(basecolor.clamp(0.0, 1.0)[None])[0]
    hue = torch.remainder(hsv[0] + 2.0 * math.pi * draw.hue_shift, 2.0 * math.pi)
    saturation = (hsv[1] * draw.saturation).clamp(0.0, 1.0)
    value = (hsv[2] * draw.value).clamp(0.0, 1.0)
    shifted = kornia.color.hsv_to_rgb(torch.stack([hue, saturation, value])[None])[0]
    dielectric = clamp_dielectric_albedo(shifted.clamp(0.0, 1.0))
    return torch.lerp(dielectric, basecolor, metallic.clamp(0.0, 1.0))


def recolor_layers(layers: MaterialLayers, draw: RecolorDraw) -> MaterialLayers:
    """``layers`` with the base colour recoloured (:func:`recolor_basecolor`); the rest as is."""
    return MaterialLayers(
        basecolor=recolor_basecolor(layers.basecolor, layers.metallic, draw),
        height=layers.height,
        roughness=layers.roughness,
        metallic=layers.metallic,
    )


__all__ = ["RecolorConfig", "RecolorDraw", "draw_recolor", "recolor_basecolor", "recolor_layers"]
