"""The material of one dataset index: a procedural family draw (optionally mixed with a partner
material of the same split and recoloured) or a scanned set — maps plus what to record about it.

Draws for mixing and recolouring come from their own generator (seeded from the material seed),
so a spec with both switched off paints exactly the materials it painted before they existed,
and a material's crops, lighting and flash draws do not shift when they are switched on.

A mixed material's partner is another material index **of the same split**, painted from its
own seed exactly as that material is on its own: the mixture's parents are real materials of the
split, and a test material can never borrow a training material's pattern (or vice versa).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from brdfgan.data.materials.base import MaterialFamily, layers_to_maps
from brdfgan.data.materials.mixing import MixingConfig, draw_mix, mix_layers, mixture_mask
from brdfgan.data.materials.recolor import RecolorConfig, draw_recolor, recolor_layers
from brdfgan.data.scanned import read_scanned_material


@dataclass(frozen=True)
class PaintedMaterial:
    """A material's maps ``(8, R, R)`` and its metadata: ``family``, ``parameters`` and, when
    they apply, ``mix`` (partner index, family, parameters, mask draw) and ``recolor``."""

    maps: Tensor
    family: str
    parameters: dict[str, float]
    extra: dict[str, Any] = field(default_factory=dict)


def family_draw(
    families: Sequence[MaterialFamily], material_index: int, generator: torch.Generator
) -> tuple[MaterialFamily, dict[str, float]]:
    """The family of a material index (round-robin, so small datasets stay balanced) and its
    parameters, the first draws of the material's generator."""
    family = families[material_index % len(families)]
    return family, family.sample_parameters(generator)


def paint_procedural(
    families: Sequence[MaterialFamily],
    material_index: int,
    resolution: int,
    generator: torch.Generator,
    *,
    choice_seed: int,
    partner_seed: Callable[[int], int],
    split_indices: Sequence[int] = (),
    mixing: MixingConfig | None = None,
    recolor: RecolorConfig | None = None,
) -> PaintedMaterial:
    """Paint material ``material_index`` at ``resolution``² with its own ``generator`` (which
    then continues with the crop draws).

    ``choice_seed`` seeds the mixing and recolouring draws; ``partner_seed(index)`` is the seed
    of another material (to paint a partner exactly as it is painted on its own);
    ``split_indices`` are the material indices of this material's split, the partners' pool.
    """
    mixing = mixing or MixingConfig()
    recolor = recolor or RecolorConfig()
    family, params = family_draw(families, material_index, generator)
    layers = family.make_layers(params, resolution, generator)
    extra: dict[str, Any] = {}
    choices = torch.Generator().manual_seed(choice_seed)
    partners = [i for i in split_indices if i != material_index]
    if mixing.fraction > 0 and partners and torch.rand((), generator=choices).item() < mixing.fraction:
        partner = partners[int(torch.randint(len(partners), (), generator=choices))]
        partner_generator = torch.Generator().manual_seed(partner_seed(partner))
        partner_family, partner_params = family_draw(families, partner, partner_generator)
        upper = partner_family.make_layers(partner_params, resolution, partner_generator)
        mix = draw_mix(mixing, choices)
        layers = mix_layers(layers, upper, mixture_mask(layers.height, mix, choices), mixing.thickness)
        extra["mix"] = {
            "partner_index": partner,
            "partner_family": partner_family.name,
            "partner_parameters": partner_params,
            **mix.to_json(),
        }
    if recolor.probability > 0 and torch.rand((), generator=choices).item() < recolor.probability:
        draw = draw_recolor(recolor, choices)
        layers = recolor_layers(layers, draw)
        extra["recolor"] = draw.to_json()
    return PaintedMaterial(layers_to_maps(layers), family.name, params, extra)


def paint_scanned(folder: Path, resolution: int) -> PaintedMaterial:
    """A scanned set as a material (family ``scanned/<folder name>``, no parameters)."""
    return PaintedMaterial(read_scanned_material(folder, resolution), f"scanned/{folder.name}", {})


__all__ = ["PaintedMaterial", "family_draw", "paint_procedural", "paint_scanned"]
