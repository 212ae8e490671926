"""Polished and hammered bare metal: gold, copper, brass, chrome, aluminium, steel, silver, nickel
or titanium.

Depicts a bare polished metal surface as a phone photographs it under its flash: a sheet with a
slight large-scale waviness (what makes reflections in real sheets wobble), optionally hammered
into facet-like dimples (Worley cells: each dent is a bowl around its cell's feature point, the
bowls meeting in sharp ridges, as a planishing hammer leaves them), fine circular polishing
swirls and hairline scratches, and handling marks: fingerprints (elliptical patches of oily
ridges) and faint oxidation haze. Everything is metallic 1 and the base colour is exactly the
measured F0 of the chosen metal (:data:`brdfgan.data.materials.albedo.METAL_F0_LINEAR`):
fingerprints, haze and swirls change how the surface scatters (roughness), not its colour.

Why it is in the dataset: the first ten families are almost never metallic, and their only
metals (brushed and rusted) are steel-grey or rough. Phones photograph jewellery, cookware,
taps, coins, cutlery and hardware: smooth, coloured, mirror-like metals whose highlight is the
metal's own colour and that have no diffuse colour at all. Without them the model paints polished
metal as a dark plastic.

Parameters:
    metal: metal index, rounded down, into :data:`METALS`: 0 gold, 1 copper, 2 brass, 3 chrome,
        4 aluminium, 5 steel (iron), 6 silver, 7 nickel, 8 titanium (uniform: no metal preferred).
    roughness: perceptual roughness of the clean polished metal.
    hammered: depth of the hammer dents (0 = a flat polished sheet, 1 = deep dimples whose
        ridges tilt the normal by about 20°).
    dent_count: hammer dents per image width (rounded; Worley cells per side).
    waviness: large-scale undulation of the sheet (0 = optically flat).
    swirl: density and contrast of the fine circular polishing swirls and hairline scratches.
    smudge: amount of fingerprints and oxidation haze, both rougher than the clean metal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import metal_basecolor
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import smooth_fbm, value_noise, worley, wrapped_upsample

# The metals of the ``metal`` parameter, in index order (names of albedo.METAL_F0_LINEAR).
METALS: tuple[str, ...] = (
    "gold",
    "copper",
    "brass",
    "chrome",
    "aluminium",
    "steel",
    "silver",
    "nickel",
    "titanium",
)
# Dent depth at hammered = 1 as a fraction of the dent pitch: a bowl h = depth·f1² has slope
# 2·depth·f1 per pitch, so ridges at f1 ≈ 0.5 tilt the normal by atan(0.4) ≈ 22°.
_DENT_DEPTH = 0.4
# Sheet undulation amplitude at waviness = 1, as a fraction of the image width (slopes of ~3°).
_WAVE_DEPTH = 0.004
# Hairline swirl-scratch depth as a fraction of the image width (a third of a texel at 1024²).
_SWIRL_DEPTH = 0.0003
# Swirl centres (each a buffing pad's circular marks) and polishing lines per unit radius.
_SWIRL_CENTRES = 4
_SWIRL_LINES = 240
MAX_FINGERPRINTS = 6
# Fingerprint ridges across a print's semi-major axis.
_PRINT_RIDGES = 22


def _periodic_offset(coordinate: Tensor, centre: float) -> Tensor:
    """A smooth periodic stand-in for the offset of unit-square coordinates from ``centre``:
    ``sin(π·Δ)/π``, equal to Δ near the centre and, unlike the wrapped offset, without a crease
    half a period away (rings around a point stay smooth curves everywhere).

    Shape: any → same.
    """
    return torch.sin(math.pi * (coordinate - centre)) / math.pi


def _dent_distance(size: int, dents: int, generator: torch.Generator) -> Tensor:
    """Worley f1 (distance to the nearest dent centre, in dent pitches) of ``dents`` cells per side.

    From 512² up it is computed at half resolution and upsampled: Worley noise dominates this
    family's cost, and a dent is at least 34 texels wide at 1024², so halving the resolution
    only blunts its ridges by a texel.
    Shape: ``(size, size)``.
    """
    if size < 512 or size % 2:
        return worley(size, dents, generator, jitter=0.8)[0]
    return wrapped_upsample(worley(size // 2, dents, generator, jitter=0.8)[0], 2)


def _swirls(size: int, generator: torch.Generator) -> Tensor:
    """Coverage in [0, 1] of fine circular polishing lines around a few random centres.

    Each centre contributes concentric lines at random radii (thresholded 1D value noise of the
    periodic distance to it) out to a third of the image width, visible only in patches, as a
    buffing pad leaves them. Lines are never drawn finer than about 3 texels apart: finer ones
    would only alias.
    Shape: ``(size, size)``.
    """
    c = (torch.arange(size, dtype=torch.float32) + 0.5) / size
    lines_per_unit = min(_SWIRL_LINES, size // 3)
    coverage = torch.zeros(size, size)
    # One patch field, shifted per centre (rolls keep it periodic): a noise field per pad would
    # cost as much again as the rings.
    patches = smoothstep(0.4, 0.7, value_noise(size, 4, generator))
    for _ in range(_SWIRL_CENTRES):
        cx, cy = torch.rand(2, generator=generator).tolist()
        dx, dy = _periodic_offset(c, cx).view(1, -1), _periodic_offset(c, cy).view(-1, 1)
        radius = torch.sqrt(dx * dx + dy * dy)
        ring_values = torch.rand(lines_per_unit + 2, generator=generator)
        position = radius * lines_per_unit
        index = position.long()
        ring = torch.lerp(ring_values[index], ring_values[index + 1], position - index)
        # A pad's reach: the far field of the periodic distance is no longer circular.
        shift = (round(cy * size), round(cx * size))
        reach = smoothstep(0.33, 0.2, radius) * torch.roll(patches, shift, dims=(0, 1))
        coverage = torch.maximum(coverage, smoothstep(0.85, 0.97, ring) * reach)
    return coverage


def _fingerprints(size: int, count: int, generator: torch.Generator) -> Tensor:
    """Oil coverage in [0, 1] of ``count`` fingerprints: elliptical patches of curved ridges.

    Each print is painted only in its own wrapped bounding window, so the cost is proportional to
    the printed area. Ridges closer than about two texels blur into an even oily film.
    Shape: ``(size, size)``.
    """
    oil = torch.zeros(size, size)
    if count == 0:
        return oil
    draws = torch.rand((count, 6), generator=generator)
    for k in range(count):
        cx, cy, turn, scale, aspect, phase = draws[k].tolist()
        semi_major = (0.04 + 0.04 * scale) * size  # texels: prints 8–16 % of the image width
        semi_minor = semi_major * (0.6 + 0.2 * aspect)
        angle = math.pi * turn
        extent = math.ceil(semi_major) + 1
        xs = torch.arange(math.floor(cx * size) - extent, math.floor(cx * size) + extent + 1)
        ys = torch.arange(math.floor(cy * size) - extent, math.floor(cy * size) + extent + 1)
        px = (xs.to(torch.float32) + 0.5 - cx * size).view(1, -1)
        py = (ys.to(torch.float32) + 0.5 - cy * size).view(-1, 1)
        along = (px * math.cos(angle) + py * math.sin(angle)) / semi_major
        across = (-px * math.sin(angle) + py * math.cos(angle)) / semi_minor
        rho = torch.sqrt(along * along + across * across)
        spacing = semi_major / _PRINT_RIDGES  # texels between ridges
        sharpness = min(max((spacing - 1.5) / 1.5, 0.0), 1.0)
        # Loops that flatten towards one side, like the whorl of a fingertip.
        ridges = 0.5 + 0.5 * torch.sin(2.0 * math.pi * (_PRINT_RIDGES * rho + 0.8 * along * across + phase))
        pattern = 0.5 + sharpness * (ridges - 0.5)
        # Pressed harder in the middle; the edge of a print fades out.
        print_mask = smoothstep(1.0, 0.55, rho) * (0.6 + 0.4 * smoothstep(1.0, 0.0, rho))
        rows, cols = (ys % size).view(-1, 1), (xs % size).view(1, -1)
        oil[rows, cols] = torch.maximum(oil[rows, cols], print_mask * pattern)
    return oil


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    name = METALS[min(max(int(params["metal"]), 0), len(METALS) - 1)]
    dents = max(1, round(params["dent_count"]))

    height = torch.zeros(size, size)
    if params["waviness"] > 0.0:
        # A height field: 32 texels per cell keep the bilinear slope steps far below a degree.
        waves = smooth_fbm(size, 2, generator, octaves=2, texels_per_cell=32)
        height = _WAVE_DEPTH * size * params["waviness"] * waves
    if params["hammered"] > 0.0:
        # Bowls around the feature points; where two bowls meet f1 is continuous but its slope
        # flips, giving the sharp ridges between hammer blows. Jitter < 1 keeps dents alike in size.
        f1 = _dent_distance(size, dents, generator)
        height = height + params["hammered"] * _DENT_DEPTH * (size / dents) * f1 * f1

    swirl = params["swirl"] * _swirls(size, generator) if params["swirl"] > 0.0 else torch.zeros(size, size)
    height = height - _SWIRL_DEPTH * size * swirl

    smudge = params["smudge"]
    oil = _fingerprints(size, round(smudge * MAX_FINGERPRINTS), generator)
    haze = torch.zeros_like(oil)
    if smudge > 0.0:
        haze = smudge * smoothstep(0.1, 0.6, smooth_fbm(size, 3, generator, octaves=3, texels_per_cell=8))

    # Oil ridges and oxide haze scatter light widely: both raise roughness, never lower it.
    roughness = params["roughness"] + 0.3 * oil + 0.25 * haze + 0.12 * swirl
    color = torch.tensor(metal_basecolor(name), dtype=torch.float32).view(3, 1, 1)
    return MaterialLayers(
        basecolor=color.expand(3, size, size).clone(),
        height=height[None],
        roughness=roughness.clamp(0.0, 1.0)[None],
        metallic=torch.ones(1, size, size),
    )


FAMILY = MaterialFamily(
    name="polished_metal",
    parameters={
        "metal": Parameter(
            4.5,
            0.0,
            len(METALS) - 0.01,
            "metal (floor): 0 gold, 1 copper, 2 brass, 3 chrome, 4 aluminium, 5 steel, 6 silver, "
            "7 nickel, 8 titanium",
            uniform=True,
        ),
        "roughness": Parameter(0.1, 0.03, 0.3, "perceptual roughness of the clean polished metal"),
        "hammered": Parameter(0.25, 0.0, 1.0, "hammer dent depth (0 = flat polished sheet)"),
        "dent_count": Parameter(10.0, 4.0, 30.0, "hammer dents per image width (rounded)"),
        "waviness": Parameter(0.3, 0.0, 1.0, "large-scale undulation of the sheet (0 = flat)"),
        "swirl": Parameter(0.4, 0.0, 1.0, "density and contrast of polishing swirls and hairlines"),
        "smudge": Parameter(0.3, 0.0, 1.0, "fingerprints and oxidation haze (rougher)"),
    },
    generate=_generate,
    description="Polished or hammered gold, copper, brass, chrome, aluminium, steel, silver, nickel "
    "or titanium with swirls, fingerprints and haze.",
    tags=("metal", "polished", "hammered", "metallic", "tileable"),
)

__all__ = ["FAMILY", "MAX_FINGERPRINTS", "METALS", "smooth_fbm", "wrapped_upsample"]
