"""Coloured anodised aluminium: bead-blasted or brushed, optionally perforated with bright
diamond-cut chamfers.

Depicts dyed anodised aluminium (laptop and phone bodies, bike parts, carabiners, torches, knobs,
speaker grilles): a coloured metallic surface of any hue, from pale champagne to deep blue, red
or black, with a fine bead-blasted grain (isotropic) or brushing streaks (along one axis), a
faint mottling of the dye uptake, and optionally a grid of drilled holes whose chamfers were
machined after anodising and so show bright bare aluminium.

**Colour: a metallic-workflow approximation.** Anodising grows a porous, transparent oxide layer
on the aluminium and dyes it; light passes the dyed oxide, reflects off the metal and passes the
dye again, so the reflection is coloured (interference in the thin oxide adds its own tints,
bronze and gold, on undyed parts). The metallic workflow has no layered model, so the surface is
metallic 1 with a coloured F0 at normal incidence: linear base colour = 0.04 + 0.96 × aluminium
F0 × dye transmittance², the oxide's own uncoloured reflection (4 %, like any dielectric) plus
the dyed metal reflection, with the dye transmittance² the linear value of the sRGB colour of
``hue``, ``saturation`` and ``value`` (HSV, so saturation and brightness mean what they mean for
the paints of the other families). What it leaves out is the angular behaviour: the real oxide
reflection rises towards grazing angles in white, while a metal's reflection stays coloured.
Black anodising is thus a dark metal reflecting about 4 %.

Why it is in the dataset: the first ten families have no coloured metal at all, yet saturated
coloured metals are everywhere in phone photos of products; without them the model takes any
saturated colour for a dielectric diffuse albedo.

Parameters:
    hue: hue of the dye, in turns (uniform: every hue is anodised).
    saturation: saturation of the dye (0 = clear anodising, the bare aluminium colour).
    value: brightness of the dye (low = dark, down to black anodising).
    finish: surface finish, < 0.5 bead-blasted (isotropic grain), otherwise brushed.
    roughness: mean perceptual roughness of the anodised surface.
    texture: strength of the blasting grain or brushing streaks, in height and roughness.
    holes: drilled holes per image width (rounded; 0 = no holes).
    hole_size: hole radius as a fraction of the hole pitch.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.core.svbrdf import linear_to_srgb, srgb_to_linear
from brdfgan.data.materials.albedo import DIELECTRIC_ALBEDO_LINEAR, METAL_F0_LINEAR, metal_basecolor
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    gradient_noise,
    hsv_to_rgb,
    stretched_value_noise,
    texel_coordinates,
    value_noise,
)

# Grain cells per image width of the bead blasting (capped at a texel pitch of 2).
_BLAST_CELLS = 200
# Brushing lines per image width.
_BRUSH_LINES = 320
# Height amplitude of the texture at strength 1, as a fraction of the image width: blast grain
# slopes of about 0.1, brushing grooves like brushed_metal's.
_BLAST_DEPTH = 0.00025
_BRUSH_DEPTH = 0.001
# Chamfer width as a fraction of the hole radius; 45° chamfer, so its depth is the same.
_CHAMFER = 0.3
_CHAMFER_ROUGHNESS = 0.1  # diamond-cut: a near-mirror cut
_VOID_ROUGHNESS = 1.0  # the dark hole interior scatters (and absorbs) everything
_OXIDE_F0 = 0.04  # the uncoloured reflection of the oxide surface


def _anodise(dye: Tensor) -> Tensor:
    """sRGB base colour of anodised aluminium under a dye of sRGB colour ``dye`` (its linear
    value is the transmittance²): 4 % oxide reflection plus the dyed aluminium F0.

    Shape: ``(3, H, W)`` → ``(3, H, W)``.
    """
    aluminium = torch.tensor(METAL_F0_LINEAR["aluminium"]).view(3, 1, 1)
    transmittance2 = srgb_to_linear(dye.clamp(0.0, 1.0))
    return linear_to_srgb(_OXIDE_F0 + (1.0 - _OXIDE_F0) * aluminium * transmittance2)


def _hole_pattern(size: int, count: int, radius: float) -> tuple[Tensor, Tensor, Tensor]:
    """Masks of a square grid of ``count × count`` holes: (void, chamfer, depth in pitch units).

    Each hole of ``radius`` (pitch units) is ringed by a 45° chamfer of width ``_CHAMFER·radius``;
    the masks have a one-texel soft edge so the pattern does not alias.
    Shape: each ``(size, size)``.
    """
    u, v = texel_coordinates(size)
    lx = u * count - (u * count).floor() - 0.5
    ly = v * count - (v * count).floor() - 0.5
    distance = torch.sqrt(lx * lx + ly * ly)
    texel = count / size  # one texel in pitch units
    outer = radius * (1.0 + _CHAMFER)
    void = smoothstep(radius + 0.5 * texel, radius - 0.5 * texel, distance)
    cut = smoothstep(outer + 0.5 * texel, outer - 0.5 * texel, distance)
    # The chamfer slopes down at 45° from its outer edge to the hole; the void is deeper again.
    depth = (outer - distance).clamp(0.0, outer - radius) + void * radius
    return void, cut * (1.0 - void), depth


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    strength = params["texture"]
    brushed = params["finish"] >= 0.5
    if brushed:
        # Three octaves of streaks along the rows (as brushed_metal), or the columns.
        texture = torch.zeros(size, size)
        for octave, weight in enumerate((1.0, 0.6, 0.35)):
            lines = min(_BRUSH_LINES * 2**octave, size)
            texture += weight * stretched_value_noise(size, 2 * 2**octave, lines, generator)
        texture = texture / 1.95 - 0.5
        if torch.rand((), generator=generator).item() < 0.5:
            texture = texture.T.contiguous()
        height = _BRUSH_DEPTH * size * (0.3 + 0.7 * strength) * texture
    else:
        texture = 0.5 * gradient_noise(size, min(_BLAST_CELLS, size // 2), generator)
        height = _BLAST_DEPTH * size * strength * texture
    # Uneven dye uptake: a faint low-frequency mottling of the colour.
    mottle = value_noise(size, 6, generator) - 0.5

    dye = hsv_to_rgb(
        torch.full((size, size), params["hue"]),
        torch.full((size, size), params["saturation"]),
        (params["value"] * (1.0 + 0.05 * mottle)).clamp(0.0, 1.0),
    )
    anodised = _anodise(dye)
    # Blasting scatters more where the grain is deep; brushing streaks modulate roughness.
    roughness = params["roughness"] + 0.2 * strength * texture + 0.03 * mottle

    basecolor = anodised
    metallic = torch.ones(size, size)
    count = round(params["holes"])
    if count > 0:
        void, chamfer, depth = _hole_pattern(size, count, params["hole_size"])
        height = height - (size / count) * depth
        bare = torch.tensor(metal_basecolor("aluminium")).view(3, 1, 1).expand(3, size, size)
        # The hole shows the dark void behind the sheet: a black, rough dielectric.
        dark = torch.full((3, size, size), float(linear_to_srgb(torch.tensor(DIELECTRIC_ALBEDO_LINEAR[0]))))
        basecolor = basecolor + (bare - basecolor) * chamfer[None] + (dark - basecolor) * void[None]
        roughness = roughness + (_CHAMFER_ROUGHNESS - roughness) * chamfer
        roughness = roughness + (_VOID_ROUGHNESS - roughness) * void
        metallic = 1.0 - void
    return MaterialLayers(
        basecolor=basecolor.clamp(0.0, 1.0),
        height=height[None],
        roughness=roughness.clamp(0.0, 1.0)[None],
        metallic=metallic[None],
    )


def anodised_color(hue: float, saturation: float, value: float) -> tuple[float, float, float]:
    """The sRGB base colour of anodised aluminium of this dye, without the mottling."""
    dye = hsv_to_rgb(torch.tensor([[hue]]), torch.tensor([[saturation]]), torch.tensor([[value]]))
    r, g, b = (float(c) for c in _anodise(dye).flatten())
    return (r, g, b)


FAMILY = MaterialFamily(
    name="anodized_metal",
    parameters={
        "hue": Parameter(0.5, 0.0, 1.0, "hue of the dye, in turns", uniform=True),
        "saturation": Parameter(0.65, 0.0, 0.95, "saturation of the dye (0 = clear anodising)"),
        "value": Parameter(0.7, 0.15, 1.0, "brightness of the dye (low = black anodising)"),
        "finish": Parameter(0.3, 0.0, 1.0, "finish: < 0.5 bead-blasted grain, otherwise brushed"),
        "roughness": Parameter(0.35, 0.15, 0.6, "mean perceptual roughness of the anodised surface"),
        "texture": Parameter(0.5, 0.0, 1.0, "strength of the blasting grain or brushing streaks"),
        "holes": Parameter(0.0, 0.0, 8.0, "drilled holes per image width (rounded; 0 = none)"),
        "hole_size": Parameter(0.25, 0.15, 0.35, "hole radius, fraction of the hole pitch"),
    },
    generate=_generate,
    description="Dyed anodised aluminium of any hue, bead-blasted or brushed, optionally "
    "perforated with bright diamond-cut chamfers.",
    tags=("metal", "anodized", "colored-metal", "metallic", "tileable"),
)

__all__ = ["FAMILY", "anodised_color"]
