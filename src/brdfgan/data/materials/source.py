"""The material of one dataset index: a procedural family draw (optionally mixed with a partner
material of the same split and recoloured) or a scanned set (optionally recoloured) — maps plus
what to record about it, and how its crops are drawn.

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

from brdfgan.core.svbrdf import BASECOLOR, METALLIC
from brdfgan.data.materials.augment import CropSampling
from brdfgan.data.materials.base import MaterialFamily, layers_to_maps
from brdfgan.data.materials.mixing import MixingConfig, draw_mix, mix_layers, mixture_mask
from brdfgan.data.materials.recolor import RecolorConfig, draw_recolor, recolor_basecolor, recolor_layers
from brdfgan.data.materials.scanned import read_scanned_material
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range, integer, ordered

SCANS_KEY = "dataset_spec.scans"
SCANNED_PREFIX = "scanned/"  # the family of a scanned set: scanned/<folder name>


def is_scanned(family: str) -> bool:
    """Whether ``family`` is a scanned set's (``scanned/<name>``) rather than a procedural one."""
    return family.startswith(SCANNED_PREFIX)


@dataclass(frozen=True)
class ScanSampling:
    """Real scanned sets (:mod:`brdfgan.data.materials.scanned`) as a share of every split's materials.

    Attributes:
        folder: a folder of scanned sets in any layout :mod:`brdfgan.data.materials.scanned` reads;
            ``None``: procedural materials only.
        fraction: the share of each split's material indices painted from a scan (each index
            decides with a draw of its own, so the procedural materials stay what they were).
        val_sets, test_sets: the scanned sets held out for validation and test: their names, or
            a number of them drawn by a seeded permutation of the sorted sets. A set belongs to
            one split only: validation and test scans are never trained on, and each split's scan
            materials are its own sets, in turn.
        resolution: the side the sets are read at (their own 1024² for ``../shared/scans``).
        scale_min, scale_max: the side of a scan's crops as a fraction of the set's, log-uniform:
            a quarter to half (a 1024² scan covers 1–2 m of surface, a phone photo at 50 cm about
            40 cm). Crops turn by any angle and stay inside the set (scans need not tile).
        mirror: mirror half the crops (the normals' x with them).
        recolor_probability: the share of scan materials recoloured with the spec's ``recolor``
            ranges (metal keeps its colour, :func:`~brdfgan.data.materials.recolor.recolor_basecolor`).
    """

    folder: str | None = None
    fraction: float = 0.0
    val_sets: int | tuple[str, ...] = 3
    test_sets: int | tuple[str, ...] = 3
    resolution: int = 1024
    scale_min: float = 0.25
    scale_max: float = 0.5
    mirror: bool = True
    recolor_probability: float = 0.0

    def __post_init__(self) -> None:
        in_range(f"{SCANS_KEY}.fraction", self.fraction, 0.0, 1.0)
        for name in ("scale_min", "scale_max"):  # log-uniform: strictly positive
            in_range(f"{SCANS_KEY}.{name}", getattr(self, name), 0.0, 1.0, low_open=True)
        ordered(SCANS_KEY, self, "scale_min", "scale_max")
        if not isinstance(self.mirror, bool):
            raise DatasetConfigError(f"{SCANS_KEY}.mirror={self.mirror!r}: must be true or false")
        in_range(f"{SCANS_KEY}.recolor_probability", self.recolor_probability, 0.0, 1.0)
        for name in ("val_sets", "test_sets"):
            value = getattr(self, name)
            if isinstance(value, list | tuple):
                if not all(isinstance(item, str) for item in value):
                    raise DatasetConfigError(f"{SCANS_KEY}.{name}={value!r}: must be a number or set names")
                object.__setattr__(self, name, tuple(value))
            else:
                integer(f"{SCANS_KEY}.{name}", value, minimum=0)
        named = set(self.named_sets("val_sets")) & set(self.named_sets("test_sets"))
        if named:
            raise DatasetConfigError(f"{SCANS_KEY}: {sorted(named)[0]!r} is both a validation and a test set")
        integer(f"{SCANS_KEY}.resolution", self.resolution, minimum=1)
        if self.fraction > 0 and self.folder is None:
            raise DatasetConfigError(f"{SCANS_KEY}.fraction={self.fraction:g} needs {SCANS_KEY}.folder")

    @property
    def enabled(self) -> bool:
        return self.folder is not None and self.fraction > 0

    @property
    def crop(self) -> CropSampling:
        """How a scan's crops are drawn."""
        return CropSampling(self.scale_min, self.scale_max, rotate=True, mirror=self.mirror, inside=True)

    def named_sets(self, which: str) -> tuple[str, ...]:
        """The names ``val_sets`` or ``test_sets`` gives (none when it gives a number)."""
        value = getattr(self, which)
        return value if isinstance(value, tuple) else ()

    def held_out_count(self, which: str) -> int:
        value = getattr(self, which)
        return len(value) if isinstance(value, tuple) else int(value)


@dataclass(frozen=True)
class PaintedMaterial:
    """A material's maps ``(8, R, R)`` and its metadata: ``family``, ``parameters`` and, when
    they apply, ``mix`` (partner index, family, parameters, mask draw) and ``recolor``."""

    maps: Tensor
    family: str
    parameters: dict[str, float]
    extra: dict[str, Any] = field(default_factory=dict)
    crop: CropSampling | None = None  # how its crops are drawn; None: the dataset spec's


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


def recolor_scan(
    maps: Tensor, recolor: RecolorConfig, generator: torch.Generator
) -> tuple[Tensor, dict[str, Any]]:
    """A scanned set recoloured by a draw of ``recolor`` from ``generator`` (metal keeps its colour,
    :func:`~brdfgan.data.materials.recolor.recolor_basecolor`), and the draw's record.

    Shape:
        - maps: ``(8, S, S)``; output: ``(8, S, S)``, a new tensor
    """
    draw = draw_recolor(recolor, generator)
    maps = maps.clone()
    maps[BASECOLOR] = recolor_basecolor(maps[BASECOLOR], maps[METALLIC], draw)
    return maps, draw.to_json()


def paint_scanned(
    folder: Path,
    resolution: int,
    *,
    crop: CropSampling | None = None,
    recolor: RecolorConfig | None = None,
    choice_seed: int = 0,
) -> PaintedMaterial:
    """A scanned set as a material (family ``scanned/<folder name>``, no parameters), recoloured
    when ``recolor.probability`` says so (drawn from ``choice_seed``), its crops drawn by ``crop``."""
    maps = read_scanned_material(folder, resolution)
    extra: dict[str, Any] = {}
    choices = torch.Generator().manual_seed(choice_seed)
    if (
        recolor is not None
        and recolor.probability > 0
        and torch.rand((), generator=choices).item() < recolor.probability
    ):
        maps, extra["recolor"] = recolor_scan(maps, recolor, choices)
    return PaintedMaterial(maps, f"{SCANNED_PREFIX}{folder.name}", {}, extra, crop)


__all__ = [
    "SCANNED_PREFIX",
    "PaintedMaterial",
    "ScanSampling",
    "family_draw",
    "is_scanned",
    "paint_procedural",
    "paint_scanned",
    "recolor_scan",
]
