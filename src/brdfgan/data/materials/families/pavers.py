"""Pavers and cobblestones: a paved street, path or yard seen from above.

Depicts one of three pavings, chosen by ``layout``:

- **cobblestones**: rounded granite setts (one per Worley cell), each domed and at its own
  height, with strong relief; traffic has polished their tops smoother than their sides;
- **running bond**: rectangular 2:1 concrete or clay pavers in offset rows (the rows run along
  the image rows or columns at random), with a rounded chamfer and a slight per-paver tilt;
- **herringbone**: the same pavers laid at right angles in the 90° herringbone pattern.

Each stone has its own tone within ``color_variation`` of the mean colour, aggregate/mineral
speckles and gritty relief, and is darker towards its edges (dirt). The joints sit lower and hold
sand (grainy, pale), dirt (dark) or moss (green, fuzzy, a little raised): all very rough.
Dielectric throughout.

Why it is in the dataset: pavements are the ground in most outdoor photos, and the other
families have neither the strong domed relief of cobbles nor the regular rectangular joint
patterns of pavers; the joints teach that deep, rough, differently coloured gaps go together.

Parameters:
    layout: paving, rounded down: 0 cobblestones, 1 running bond, 2 herringbone.
    count: stones per side: Worley cells for cobbles, paver widths (short sides) for pavers
        (rounded to the pattern's period: even for running bond, a multiple of 4 for herringbone).
    joint_width: joint width as a fraction of the stone pitch.
    hue: hue of the mean stone colour, in turns (red brick … buff and yellowish sandstone).
    saturation: saturation of the mean stone colour (0 = grey granite or concrete).
    value: brightness of the mean stone colour (sRGB).
    color_variation: per-stone spread of brightness, hue and saturation.
    moss: fraction of the joints overgrown with moss (the rest holds sand and dirt).
    relief: height of the stones above the joint bottoms, as a fraction of the image width
        (pavers are flatter: half of it).
    roughness: perceptual roughness of the stone surface.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    fbm,
    hsv_to_rgb,
    lerp_color,
    random_per_cell,
    texel_coordinates,
    value_noise,
    worley,
)

LAYOUTS = ("cobblestones", "running_bond", "herringbone")
# Joint fillings (sRGB): sand, dirt and moss.
_SAND = (0.55, 0.50, 0.42)
_DIRT = (0.24, 0.20, 0.16)
_MOSS = (0.25, 0.32, 0.13)
_MOSS_TIPS = (0.33, 0.40, 0.16)  # lighter, younger moss tips
_PAVER_BEVEL = 0.12  # rounded chamfer of a paver, in paver widths
_COBBLE_BEVEL = 0.3  # cobbles round over much further, in cell units of f2 − f1


@dataclass(frozen=True)
class Paving:
    """Where the stones are: ``stone_mask`` in [0, 1] (0 in the joints, 1 on stone, a one-texel
    soft edge), the height ``profile`` of the stones in [0, 1] (rounded over their edges, domed
    for cobbles), the integer ``stone`` id of every texel in ``[0, count)``, and per-texel
    position inside the stone ``(along, across)`` in [-0.5, 0.5] (for the tilt of pavers).
    Each field ``(size, size)``."""

    stone_mask: Tensor
    profile: Tensor
    stone: Tensor
    count: int
    along: Tensor
    across: Tensor


def cobblestones(size: int, cells: int, joint_width: float, generator: torch.Generator) -> Paving:
    """Rounded setts, one per Worley cell: the stone face ends ``joint_width`` from the cell border."""
    f1, f2, cell_id = worley(size, cells, generator, jitter=0.85)
    edge = f2 - f1  # 0 on the cell border, up to ~1 at the feature point
    mask = smoothstep(joint_width, joint_width + 2.0 * cells / size, edge)
    # Radial position from the feature point (0) to the border (1): a dome over the whole sett
    # whose sides round steeply down into the joint.
    radial = (2.0 * f1 / (f1 + f2).clamp(min=1e-6)).clamp(0.0, 1.0)
    dome = torch.sqrt((1.0 - radial * radial).clamp(min=0.0))
    profile = torch.sqrt(smoothstep(joint_width, joint_width + _COBBLE_BEVEL, edge)) * (0.55 + 0.45 * dome)
    zeros = torch.zeros(size, size)
    return Paving(mask, profile, cell_id, cells * cells, zeros, zeros)


def _paver_edges(edge: Tensor, joint_width: float, texel: float) -> tuple[Tensor, Tensor]:
    """Stone mask and rounded-chamfer profile of flat pavers from the distance to the paver
    border ``edge`` (in paver widths; ``texel`` is one texel in the same unit). Shape: any."""
    half_joint = joint_width / 2.0
    mask = smoothstep(half_joint, half_joint + texel, edge)
    profile = torch.sqrt(smoothstep(half_joint, half_joint + _PAVER_BEVEL, edge))
    return mask, profile


def running_bond(size: int, widths: int, joint_width: float) -> Paving:
    """2:1 pavers in rows offset by half a paver; ``widths`` (even) paver widths per side."""
    u, v = texel_coordinates(size)
    x, y = u * widths, v * widths
    row = y.floor().long().clamp(max=widths - 1)
    shifted = (x + (row % 2).float()) / 2.0  # in paver lengths; odd rows shift by half a paver
    per_row = widths // 2
    col = shifted.floor().long() % per_row
    along, across = shifted - shifted.floor(), y - y.floor()
    edge = torch.minimum(2.0 * torch.minimum(along, 1.0 - along), torch.minimum(across, 1.0 - across))
    mask, profile = _paver_edges(edge, joint_width, widths / size)
    stone = row * per_row + col
    return Paving(mask, profile, stone, widths * per_row, along - 0.5, across - 0.5)


def herringbone(size: int, widths: int, joint_width: float) -> Paving:
    """2:1 pavers in the 90° herringbone pattern; ``widths`` (a multiple of 4) paver widths per side.

    On the grid of unit squares (one paver width), square ``(i, j)`` with ``r = (i − j) mod 4``
    belongs to a horizontal paver starting at ``(i − r, j)`` for r ∈ {0, 1}, and to a vertical one
    starting at ``(i, j − 1)`` for r = 2 or at ``(i, j)`` for r = 3. Each paver covers two
    squares, every square is covered once, and the pattern repeats every 4 squares along both
    axes, so it tiles the unit square when ``widths`` is a multiple of 4.
    """
    u, v = texel_coordinates(size)
    x, y = u * widths, v * widths
    i, j = x.floor(), y.floor()
    r = (i.long() - j.long()) % 4
    horizontal = r < 2
    origin_i = torch.where(horizontal, i - r.float(), i)
    origin_j = torch.where(r == 2, j - 1.0, j)
    along = torch.where(horizontal, x - origin_i, y - origin_j) / 2.0  # in paver lengths
    across = torch.where(horizontal, y - j, x - i)
    edge = torch.minimum(2.0 * torch.minimum(along, 1.0 - along), torch.minimum(across, 1.0 - across))
    mask, profile = _paver_edges(edge, joint_width, widths / size)
    oi, oj = origin_i.long() % widths, origin_j.long() % widths
    stone = (oj * widths + oi) * 2 + (~horizontal).long()
    return Paving(mask, profile, stone, 2 * widths * widths, along - 0.5, across - 0.5)


def _paving(layout: str, count: float, joint_width: float, size: int, generator: torch.Generator) -> Paving:
    if layout == "cobblestones":
        return cobblestones(size, max(2, round(count)), joint_width, generator)
    if layout == "running_bond":
        paving = running_bond(size, max(2, 2 * round(count / 2)), joint_width)
        if torch.rand((), generator=generator).item() < 0.5:
            # Rows along the columns instead; transposing keeps every field periodic.
            paving = Paving(
                paving.stone_mask.T,
                paving.profile.T,
                paving.stone.T,
                paving.count,
                paving.along.T,
                paving.across.T,
            )
        return paving
    return herringbone(size, max(4, 4 * round(count / 4)), joint_width)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    layout = LAYOUTS[min(max(int(params["layout"]), 0), len(LAYOUTS) - 1)]
    paving = _paving(layout, params["count"], params["joint_width"], size, generator)
    mask, profile = paving.stone_mask, paving.profile
    attrs = random_per_cell(paving.stone, paving.count, generator, channels=6)

    # Stone relief: pavers are flatter than cobbles; each stone sits at its own height, and pavers
    # tilt a little (never set perfectly level).
    cobbles = layout == "cobblestones"
    amplitude = params["relief"] * size * (1.0 if cobbles else 0.5)
    grit = fbm(size, 48, generator, octaves=3, persistence=0.6)  # fixed in image units
    tilt = 0.15 * ((2 * attrs[0] - 1) * paving.along + (2 * attrs[1] - 1) * paving.across)
    stone_height = amplitude * (profile * (0.85 + 0.15 * attrs[2] + tilt) + 0.04 * grit)

    # Joints: sand and dirt at the bottom, moss filling them up a little higher.
    joint_grain = value_noise(size, min(size, 160), generator)
    moss_field = value_noise(size, 8, generator)
    moss = smoothstep(1.0 - params["moss"], 1.0 - params["moss"] + 0.1, moss_field)
    dirt = smoothstep(0.3, 0.7, value_noise(size, 16, generator))
    fill_height = amplitude * (0.12 + 0.06 * joint_grain + moss * (0.12 + 0.1 * joint_grain))
    height = torch.maximum(stone_height, fill_height)
    # Stone shows where it rises above the filling (sand and moss bank up against its foot).
    stone = mask * smoothstep(0.0, 0.05 * amplitude, stone_height - fill_height)

    # Stone colour: per-stone tone, mineral speckles, darker towards the edges.
    variation = params["color_variation"]
    speckle = smoothstep(0.6, 0.8, joint_grain) - smoothstep(0.6, 0.8, 1.0 - joint_grain)
    value = (
        params["value"]
        * (1.0 + variation * (2 * attrs[3] - 1))
        * (1.0 + 0.08 * grit + (0.15 if cobbles else 0.06) * speckle)
        * (0.8 + 0.2 * smoothstep(0.0, 0.6, profile))
    )
    stone_rgb = hsv_to_rgb(
        torch.full_like(value, params["hue"]) + 0.1 * variation * (2 * attrs[4] - 1),
        (params["saturation"] * (1.0 + variation * (2 * attrs[5] - 1))).clamp(0.0, 1.0).expand(size, size),
        value.clamp(0.0, 1.0),
    )
    fill_rgb = lerp_color(_SAND, _DIRT, dirt) * (1.0 + 0.15 * (joint_grain - 0.5))
    fill_rgb = torch.lerp(fill_rgb, lerp_color(_MOSS, _MOSS_TIPS, joint_grain), moss[None])
    basecolor = fill_rgb + (stone_rgb - fill_rgb) * stone[None]

    # Traffic polishes cobble tops; joints (sand, soil, moss) are very rough.
    stone_roughness = params["roughness"] + 0.05 * grit - (0.15 * profile if cobbles else 0.0)
    fill_roughness = 0.95 - 0.03 * dirt
    roughness = fill_roughness + (stone_roughness - fill_roughness) * stone
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


FAMILY = MaterialFamily(
    name="pavers",
    parameters={
        "layout": Parameter(
            1.5, 0.0, 2.99, "paving (floor): 0 cobblestones, 1 running bond, 2 herringbone", uniform=True
        ),
        "count": Parameter(10.0, 4.0, 24.0, "stones per side (cobble cells or paver widths, rounded)"),
        "joint_width": Parameter(0.07, 0.03, 0.15, "joint width, fraction of the stone pitch"),
        "hue": Parameter(
            0.07, 0.0, 0.15, "hue of the mean stone colour, in turns (red … buff)", uniform=True
        ),
        "saturation": Parameter(0.2, 0.0, 0.5, "saturation of the mean stone colour (0 = grey)"),
        "value": Parameter(0.45, 0.25, 0.7, "brightness of the mean stone colour (sRGB)"),
        "color_variation": Parameter(0.12, 0.0, 0.3, "per-stone spread of brightness, hue and saturation"),
        "moss": Parameter(0.3, 0.0, 1.0, "fraction of the joints overgrown with moss"),
        "relief": Parameter(0.012, 0.004, 0.03, "stone height above the joints, fraction of the width"),
        "roughness": Parameter(0.72, 0.5, 0.92, "perceptual roughness of the stone surface"),
    },
    generate=_generate,
    description="Domed cobblestones or running-bond / herringbone pavers with sand and moss joints.",
    tags=("pavers", "cobblestones", "stone", "ground", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
