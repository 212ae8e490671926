"""Paper, corrugated cardboard and cork board: soft fibrous sheets, seen from above.

Depicts one of three fibrous plant materials, chosen by ``mode``:

- **paper**: a sheet of white to strongly dyed paper with the faint relief and mottled
  formation of its fibres, a few straight folds (sharp ridges or valleys with tilted facets, a
  little rougher and paler where the fibres broke) and optional printed text and solid print
  blocks in dark ink;
- **corrugated cardboard**: a brown kraft liner drawn over the flutes, which show through as
  parallel rounded ridges (the "washboard" of every box), with the same fibre grain, scored folds
  and printed areas in a coloured ink (solid blocks and text);
- **cork board**: compressed cork granules (Worley cells, each its own tan-to-brown tone and
  height) with deep dark voids between them and fine pores: strong, granular relief and a very
  rough surface.

Why it is in the dataset: paper, boxes and pin boards are among the most photographed flat
surfaces (documents, packaging, desks, notice boards), and none of the other families covers a
bright, almost white, very matte sheet, nor the regular flute relief of cardboard, nor the
granular, very rough relief of cork. Dyed paper and printed ink add saturated colours of any hue.

Parameters:
    mode: which material, rounded down: 0 paper, 1 corrugated cardboard, 2 cork board.
    hue: hue of the paper dye (paper) or of the printing ink (cardboard), in turns; cork ignores it.
    saturation: saturation of the paper dye (0 = white or grey paper) or of the cardboard ink
        (0 = black print); cork ignores it.
    value: brightness of the sheet (sRGB): the paper, the kraft liner or the cork.
    roughness: perceptual roughness of the paper or liner surface; cork lies halfway between it
        and 1 (it is always very rough).
    relief: relief strength, a multiplier of each mode's typical depth (fibres and folds, flutes,
        granules).
    scale: features per image width: fibre flocs (paper), flutes (cardboard) or, doubled, granules
        (cork).
    creases: number of straight folds, as a fraction of the maximum (paper and cardboard).
    ink: fraction of the print-layout blocks that carry print (paper and cardboard).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import (
    fbm,
    hsv_to_rgb,
    random_per_cell,
    texel_coordinates,
    value_noise,
    worley,
)

MODES = ("paper", "cardboard", "cork")
MAX_CREASES = 4
# Typical depths as fractions of the image width (× ``relief``), so normals look alike at every
# resolution: paper fibres are barely there, flutes show clearly, cork is deeply granular.
_FIBRE_DEPTH = 0.0004
_CREASE_DEPTH = 0.004
_FLUTE_DEPTH = 0.003
_CORK_DEPTH = 0.008
# Print layout: the sheet is divided into _PRINT_BLOCKS² blocks, each blank, solid or text.
_PRINT_BLOCKS = 4
_TEXT_LINES = 7  # text lines per block
_LETTERS = 40  # letter places per text line
# Integer fold directions (a, b): the fold lines a·u + b·v = c (mod 1) are periodic on the unit
# square, so every fold wraps around seamlessly.
_FOLD_DIRECTIONS = ((1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2))
# Kraft liner and cork tones (hue in turns, saturation): their colours, unlike paper's, are fixed
# by the material; ``value`` sets the brightness.
_KRAFT_HUE, _KRAFT_SATURATION = 0.085, 0.48
_CORK_HUE, _CORK_SATURATION = 0.075, 0.5


def crease_field(size: int, count: int, generator: torch.Generator) -> Tensor:
    """Height of ``count`` straight folds, each ``±exp(−|d|/w)`` of the distance ``d`` to its line.

    A fold is a sharp ridge (mountain fold) or groove (valley fold) whose facets slope away over
    ``w`` (1–4 % of the width). Lines follow integer directions, so each one is periodic.

    Shape: ``(size, size)``, in units of the fold depth (peak ±1).
    """
    u, v = texel_coordinates(size)
    height = torch.zeros(size, size)
    if count == 0:
        return height
    draws = torch.rand((count, 4), generator=generator)
    for k in range(count):
        a, b = _FOLD_DIRECTIONS[int(draws[k, 0].item() * len(_FOLD_DIRECTIONS))]
        phase = a * u + b * v - draws[k, 1].item()
        distance = (phase - torch.round(phase)).abs() / math.hypot(a, b)  # image units
        width = 0.01 + 0.03 * draws[k, 2].item()
        sign = 1.0 if draws[k, 3].item() < 0.5 else -1.0
        height = height + sign * torch.exp(-distance / width)
    return height


def print_masks(size: int, coverage: float, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """Where ink lies: ``(solid, text)`` masks in {0, 1} of a block print layout.

    The sheet is a grid of blocks; each is printed with probability ``coverage`` and then holds a
    solid rectangle or lines of "words" (runs of letters with random gaps between them).

    Shape: each ``(size, size)``.
    """
    if coverage <= 0.0:
        return torch.zeros(size, size), torch.zeros(size, size)
    u, v = texel_coordinates(size)
    n = _PRINT_BLOCKS
    bu, bv = u * n, v * n
    block = bv.floor().long().clamp(max=n - 1) * n + bu.floor().long().clamp(max=n - 1)
    lu, lv = bu - bu.floor(), bv - bv.floor()
    attrs = torch.rand((6, n * n), generator=generator)
    printed = attrs[0][block] < coverage
    # Inset rectangle of the block: margins 5–30 % on each side.
    inside = (
        (lu > 0.05 + 0.25 * attrs[1][block])
        & (lu < 0.95 - 0.25 * attrs[2][block])
        & (lv > 0.05 + 0.25 * attrs[3][block])
        & (lv < 0.95 - 0.25 * attrs[4][block])
    )
    is_solid = attrs[5][block] < 0.25
    solid = printed & inside & is_solid
    # Text: the lower half of each line pitch is ink where a letter is; a tenth of the letter
    # places stay blank (word gaps and narrow letters), at random.
    lines, letters = n * _TEXT_LINES, n * _LETTERS
    line = (v * lines).floor().long().clamp(max=lines - 1)
    letter = (u * letters).floor().long().clamp(max=letters - 1)
    letter_on = torch.rand(lines * letters, generator=generator)[line * letters + letter] > 0.12
    in_line = torch.frac(v * lines) > 0.45
    in_letter = torch.frac(u * letters) < 0.75
    text = printed & inside & ~is_solid & in_line & letter_on & in_letter
    return solid.float(), text.float()


def _fibres(size: int, generator: torch.Generator) -> Tensor:
    """Fine fibre relief of paper and kraft liners, roughly in [-1, 1]; fixed in image units
    (fibres are the same size whatever the sheet). Two octaves of value noise: the relief is
    faint, so the cheaper noise is enough. Shape: ``(size, size)``."""
    coarse = value_noise(size, min(size, 96), generator)
    fine = value_noise(size, min(size, 192), generator)
    return (coarse + 0.5 * fine - 0.75) / 0.75  # [0, 1.5] → [-1, 1]


def _paper(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    relief = params["relief"]
    fibres = _fibres(size, generator)
    flocs = value_noise(size, max(2, round(params["scale"])), generator) - 0.5  # formation mottling
    folds = crease_field(size, round(params["creases"] * MAX_CREASES), generator)
    fold_line = folds.abs()
    height = size * relief * (_FIBRE_DEPTH * (fibres + 0.6 * flocs) + _CREASE_DEPTH * folds)

    value = (
        params["value"]
        * (1.0 + 0.05 * flocs + 0.02 * fibres)
        * (1.0 + 0.02 * smoothstep(0.6, 1.0, fold_line))
    )
    paper_rgb = hsv_to_rgb(
        torch.full_like(value, params["hue"]),
        torch.full_like(value, params["saturation"]),
        value.clamp(0.0, 1.0),
    )
    solid, text = print_masks(size, params["ink"], generator)
    ink = (solid + text).clamp(max=1.0)
    ink_rgb = torch.full((3, 1, 1), 0.12)  # near-black print on paper
    basecolor = torch.lerp(paper_rgb, ink_rgb.expand_as(paper_rgb), ink[None])

    # Broken fibres along a fold scatter more; ink fills the pores and is a little smoother.
    roughness = (params["roughness"] * (1.0 + 0.04 * fibres) + 0.06 * smoothstep(0.6, 1.0, fold_line)) * (
        1.0 - 0.2 * ink
    )
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


def _cardboard(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    relief = params["relief"]
    flutes = max(2, round(params["scale"]))
    # The liner drapes over the flute tips: rounded ridges, narrower than the troughs. The
    # profile depends on one coordinate only, so it is computed once per column (or row).
    u = (torch.arange(size, dtype=torch.float32) + 0.5) / size
    profile = (0.5 + 0.5 * torch.cos(2.0 * math.pi * flutes * u)) ** 1.5
    along_rows = torch.rand((), generator=generator).item() < 0.5
    ridge = (
        profile.view(1, size).expand(size, size) if along_rows else profile.view(size, 1).expand(size, size)
    )
    fibres = _fibres(size, generator)
    dents = fbm(size, 4, generator, octaves=2)  # handling dents and warping
    folds = crease_field(size, round(params["creases"] * MAX_CREASES), generator)
    height = (
        size
        * relief
        * (_FLUTE_DEPTH * (ridge + 0.3 * dents) + _FIBRE_DEPTH * 1.5 * fibres + _CREASE_DEPTH * folds)
    )

    value = params["value"] * (1.0 + 0.06 * fibres + 0.05 * dents) * (1.0 + 0.05 * (ridge - 0.5))
    liner_rgb = hsv_to_rgb(
        torch.full_like(value, _KRAFT_HUE),
        torch.full_like(value, _KRAFT_SATURATION) * (1.0 + 0.1 * dents),
        value.clamp(0.0, 1.0),
    )
    solid, text = print_masks(size, params["ink"], generator)
    ink = (solid + text).clamp(max=1.0)
    # Flexographic ink on kraft is dark and only moderately saturated; it soaks in unevenly.
    ink_value = 0.35 * (1.0 + 0.15 * fibres)
    ink_rgb = hsv_to_rgb(
        torch.full_like(value, params["hue"]),
        torch.full_like(value, params["saturation"]),
        ink_value.clamp(0.0, 1.0),
    )
    basecolor = torch.lerp(liner_rgb, ink_rgb, ink[None])
    roughness = params["roughness"] * (1.0 + 0.05 * fibres) * (1.0 - 0.15 * ink)
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


def _cork(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    # Cork granules are finer than fibre flocs or flutes at the same ``scale``: 2–5 mm each.
    granules = max(2, round(2 * params["scale"]))
    f1, f2, cell_id = worley(size, granules, generator, jitter=1.0)
    attrs = random_per_cell(cell_id, granules * granules, generator, channels=3)
    # Pressed granules meet almost everywhere; voids open only along parts of their borders.
    gaps = value_noise(size, max(2, granules // 2), generator)
    void = (1.0 - smoothstep(0.0, 0.08, f2 - f1)) * smoothstep(0.5, 0.65, gaps)
    pores = smoothstep(0.72, 0.85, value_noise(size, min(size, 6 * granules), generator))
    grain = fbm(size, min(size, 2 * granules), generator, octaves=2)
    dome = 1.0 - smoothstep(0.0, 1.0, f1)
    amplitude = _CORK_DEPTH * params["relief"] * size
    height = amplitude * (0.25 * dome + 0.45 * attrs[0] + 0.2 * grain - 1.2 * void - 0.4 * pores)

    # Granules range from pale tan (inner bark) to dark brown (outer, heat-treated).
    tone = 0.65 + 0.55 * attrs[1]
    value = params["value"] * tone * (1.0 + 0.08 * grain) * (1.0 - 0.6 * void) * (1.0 - 0.35 * pores)
    basecolor = hsv_to_rgb(
        torch.full_like(value, _CORK_HUE) + 0.02 * (attrs[2] - 0.5),
        torch.full_like(value, _CORK_SATURATION) * (0.8 + 0.4 * attrs[2]),
        value.clamp(0.0, 1.0),
    )
    cork_roughness = 0.5 * (params["roughness"] + 1.0)
    roughness = cork_roughness + 0.04 * grain + (1.0 - cork_roughness) * (void + 0.5 * pores)
    return MaterialLayers.dielectric(clamp_dielectric_albedo(basecolor), height, roughness)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    mode = MODES[min(max(int(params["mode"]), 0), len(MODES) - 1)]
    if mode == "paper":
        return _paper(params, size, generator)
    if mode == "cardboard":
        return _cardboard(params, size, generator)
    return _cork(params, size, generator)


FAMILY = MaterialFamily(
    name="paper",
    parameters={
        "mode": Parameter(
            1.5, 0.0, 2.99, "material (floor): 0 paper, 1 corrugated cardboard, 2 cork", uniform=True
        ),
        "hue": Parameter(0.6, 0.0, 1.0, "hue of the paper dye or cardboard ink, in turns", uniform=True),
        "saturation": Parameter(0.12, 0.0, 0.8, "saturation of the paper dye or cardboard ink"),
        "value": Parameter(0.75, 0.3, 0.93, "brightness of the paper, liner or cork (sRGB)"),
        "roughness": Parameter(
            0.8, 0.35, 0.95, "perceptual roughness of paper or liner (cork: halfway to 1)"
        ),
        "relief": Parameter(1.0, 0.3, 2.0, "relief strength, multiplier of the mode's typical depth"),
        "scale": Parameter(20.0, 8.0, 48.0, "fibre flocs, flutes or half the cork granules per image width"),
        "creases": Parameter(0.3, 0.0, 1.0, f"folds as a fraction of {MAX_CREASES} (paper, cardboard)"),
        "ink": Parameter(0.3, 0.0, 1.0, "fraction of print blocks carrying print (paper, cardboard)"),
    },
    generate=_generate,
    description="Dyed or white paper with folds and print, corrugated kraft cardboard, or granular cork.",
    tags=("paper", "cardboard", "cork", "fibrous", "dielectric", "tileable"),
)

__all__ = ["FAMILY"]
