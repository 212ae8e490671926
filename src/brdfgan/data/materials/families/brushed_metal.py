"""Brushed and scratched metal: a bare metal sheet (steel, aluminium, brass or copper).

Depicts a brushed metal panel as a phone would photograph it: fine parallel brushing grooves (the
anisotropic brushing is approximated by streaky noise stretched along the brushing direction, in
both the height and the roughness), low-frequency smudges of handling, and random straight
scratches: thin dents across the brushing that are rougher than the surrounding metal. Everything
is metallic (metallic 1) and the base colour is the F0 of the chosen metal.

Parameters:
    metal: metal type index, rounded down: 0 steel, 1 aluminium, 2 brass, 3 copper.
    roughness: mean perceptual roughness of the brushed surface.
    brush_lines: brushing grooves per image width (fine lines are denser).
    brush_strength: contrast of the brushing streaks in roughness and height (low = nearly polished).
    relief: height amplitude of the brushing grooves, as a fraction of the image width.
    vertical: brushing direction, < 0.5 along the rows (horizontal), otherwise vertical.
    scratch_density: scratch count, as a fraction of the maximum (0 = no scratches).
    scratch_depth: scratch depth, as a fraction of the image width.
    smudge: amount of low-frequency roughness and tint variation (fingerprints, oxidation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.data.materials.albedo import metal_basecolor
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, stretched_value_noise

# The metals of the ``metal`` parameter, in index order; base colour = measured F0 (albedo.py).
METALS: tuple[str, ...] = ("steel", "aluminium", "brass", "copper")
METAL_COLORS: tuple[tuple[float, float, float], ...] = tuple(metal_basecolor(name) for name in METALS)
MAX_SCRATCHES = 120


def _scratches(size: int, count: int, depth: float, generator: torch.Generator) -> Tensor:
    """Coverage in [0, 1] of ``count`` random straight scratches, each scaled by its own depth.

    Each scratch is a Gaussian-profile line segment rasterised in its own (wrapped) bounding
    window only, so the cost is proportional to the scratched area, not ``count × size²``.
    Returns the scratch depth profile (1 = deepest scratch). Shape: ``(size, size)``.
    """
    mask = torch.zeros(size, size)
    if count == 0 or depth <= 0.0:
        return mask
    draws = torch.rand((count, 6), generator=generator)
    centres = draws[:, :2] * size
    # Mostly across the brushing (random angle), lengths 5–45 % of the width.
    angles = draws[:, 2] * math.pi
    lengths = (0.05 + 0.4 * draws[:, 3] ** 2) * size
    # Width relative to the image, but never thinner than a texel (sub-texel lines would alias away).
    widths = torch.clamp((0.0004 + 0.0008 * draws[:, 4]) * size, min=0.6)
    strengths = 0.4 + 0.6 * draws[:, 5]
    for k in range(count):
        cx, cy = centres[k].tolist()
        dx, dy = math.cos(angles[k].item()), math.sin(angles[k].item())
        half, w = lengths[k].item() / 2.0, widths[k].item()
        ex, ey = abs(dx) * half + 3 * w, abs(dy) * half + 3 * w
        xs = torch.arange(math.floor(cx - ex), math.ceil(cx + ex) + 1)
        ys = torch.arange(math.floor(cy - ey), math.ceil(cy + ey) + 1)
        px = (xs.to(torch.float32) + 0.5 - cx).view(1, -1)
        py = (ys.to(torch.float32) + 0.5 - cy).view(-1, 1)
        along = px * dx + py * dy
        across = -px * dy + py * dx
        # Gaussian cross-section, tapering to nothing at both ends like a real scratch.
        taper = (1.0 - (along / half) ** 2).clamp(0.0, 1.0).sqrt()
        profile = strengths[k] * taper * torch.exp(-0.5 * (across / w) ** 2)
        rows, cols = (ys % size).view(-1, 1), (xs % size).view(1, -1)
        mask[rows, cols] = torch.maximum(mask[rows, cols], profile)
    return mask


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    metal = METAL_COLORS[min(max(int(params["metal"]), 0), len(METAL_COLORS) - 1)]
    lines = max(8, round(params["brush_lines"]))

    # Brushing: three octaves of streaks, long along the rows and dense across them. Line counts are
    # per image width so the pattern (and, with relief ∝ size, the normals) is resolution independent.
    streak = torch.zeros(size, size)
    norm = 0.0
    for octave, weight in enumerate((1.0, 0.6, 0.35)):
        cells_v = min(lines * 2**octave, size)
        streak += weight * stretched_value_noise(size, 2 * 2**octave, cells_v, generator)
        norm += weight
    streak = streak / norm - 0.5  # roughly [-0.5, 0.5]

    strength = params["brush_strength"]
    smudge_field = fbm(size, 3, generator, octaves=4)
    count = round(params["scratch_density"] * MAX_SCRATCHES)
    scratch = _scratches(size, count, params["scratch_depth"], generator)
    if params["vertical"] >= 0.5:
        # Brushing runs along the columns; transposing keeps the field periodic.
        streak = streak.T.contiguous()

    height = size * (params["relief"] * (0.3 + 0.7 * strength) * streak - params["scratch_depth"] * scratch)
    # Brushing streaks and smudges modulate the micro-roughness; scratches tear the surface and
    # scatter light more widely, so they are rougher than the brushed metal around them.
    base_rough = params["roughness"]
    roughness = (
        base_rough
        + 0.25 * strength * streak
        + 0.12 * params["smudge"] * smudge_field
        + (0.35 + 0.3 * base_rough) * scratch
    ).clamp(0.04, 0.95)

    color = torch.tensor(metal).view(3, 1, 1)
    # Slight darkening in smudges / deep scratches (oxide, dirt) and ±1.5 % along the brushing:
    # the colour stays the metal's F0 up to that shading.
    shade = (
        1.0 - 0.06 * params["smudge"] * (smudge_field + 1.0) / 2.0 - 0.08 * scratch + 0.03 * strength * streak
    )
    basecolor = (color * shade[None]).clamp(0.0, 1.0)
    return MaterialLayers(
        basecolor=basecolor,
        height=height[None],
        roughness=roughness[None],
        metallic=torch.ones(1, size, size),
    )


FAMILY = MaterialFamily(
    name="brushed_metal",
    parameters={
        "metal": Parameter(1.0, 0.0, 3.99, "metal type (floor): 0 steel, 1 aluminium, 2 brass, 3 copper"),
        "roughness": Parameter(0.32, 0.12, 0.55, "mean perceptual roughness of the brushed surface"),
        "brush_lines": Parameter(300.0, 100.0, 800.0, "brushing grooves per image width"),
        "brush_strength": Parameter(
            0.6, 0.15, 1.0, "contrast of the brushing streaks (low = nearly polished)"
        ),
        "relief": Parameter(0.0012, 0.0006, 0.003, "brushing groove depth, fraction of the image width"),
        "vertical": Parameter(0.0, 0.0, 1.0, "brushing direction: < 0.5 horizontal, otherwise vertical"),
        "scratch_density": Parameter(0.3, 0.0, 1.0, f"scratch count as a fraction of {MAX_SCRATCHES}"),
        "scratch_depth": Parameter(0.0008, 0.0002, 0.002, "scratch depth, fraction of the image width"),
        "smudge": Parameter(0.4, 0.0, 1.0, "low-frequency roughness and tint variation (handling)"),
    },
    generate=_generate,
    description="Brushed steel, aluminium, brass or copper with streaky brushing and random scratches.",
    tags=("metal", "brushed", "scratched", "metallic", "tileable"),
)

__all__ = ["FAMILY", "METALS", "METAL_COLORS"]
