"""Material mixing: one material laid over another through a procedural, height-aware mask.

Deschaintre et al. (2018) multiplied ~1 850 artist materials into ~200 k by blending random pairs;
real surfaces are mixtures too (paint over plaster, moss in a pavement's joints, rust on steel,
dust on tiles). A mixed material here is the *lower* material with the *upper* one laid on top
where a mask says:

- **Mask kinds** (all periodic, so mixed materials still tile): ``noise`` (fBm blotches: dirt,
  wear, stains), ``cracks`` (the network of Worley cell borders: paint or plaster cracking, moss
  in joints) and ``patches`` (whole random cells: patched repairs, flaking layers).
- **Height-aware**: the lower material's height shifts the mask, so the upper material settles
  into its cavities (dirt, moss, sand, water: positive ``bias``) or sits on its crests (wear,
  dust caught on ridges: negative ``bias``). ``coverage`` is the share of the area the upper
  material covers; the threshold is that quantile of the shifted field.
- **The upper material sits on top**: the mixed height is the lower height plus, under the mask,
  the upper material's own relief and a layer ``thickness``, so the layer's edge is a real step
  in the normals, as a paint chip or a moss cushion is.

Base colour, roughness and metallic blend with the mask (soft only across the mask's edge).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from brdfgan.data.materials.base import MaterialLayers
from brdfgan.data.materials.noise import fbm, random_per_cell, worley
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range, ordered

MASK_KINDS = ("noise", "cracks", "patches")


@dataclass(frozen=True)
class MixingConfig:
    """How many materials are mixtures of two, and the ranges of their masks.

    ``fraction``: share of the materials that are a mixture (0 = none, today's data).
    ``masks``: mask kinds drawn from (uniformly). ``coverage_min/max``: share of the area the
    upper material covers. ``bias_max``: largest weight of the lower height in the mask (sign
    random). ``thickness``: the upper layer's thickness as a fraction of the image width.
    """

    fraction: float = 0.0
    masks: tuple[str, ...] = MASK_KINDS
    coverage_min: float = 0.15
    coverage_max: float = 0.6
    bias_max: float = 1.5
    thickness: float = 0.002

    def __post_init__(self) -> None:
        key = "dataset_spec.mixing"
        object.__setattr__(self, "masks", tuple(self.masks))
        in_range(f"{key}.fraction", self.fraction, 0.0, 1.0)
        if not self.masks:
            raise DatasetConfigError(f"{key}.masks: must name at least one of {', '.join(MASK_KINDS)}")
        unknown = [m for m in self.masks if m not in MASK_KINDS]
        if unknown:
            raise DatasetConfigError(
                f"{key}.masks: unknown mask {unknown[0]!r}; known: {', '.join(MASK_KINDS)}"
            )
        in_range(f"{key}.coverage_min", self.coverage_min, 0.0, 1.0, low_open=True, high_open=True)
        in_range(f"{key}.coverage_max", self.coverage_max, 0.0, 1.0, low_open=True, high_open=True)
        ordered(key, self, "coverage_min", "coverage_max")
        in_range(f"{key}.bias_max", self.bias_max, 0.0, 10.0)
        in_range(f"{key}.thickness", self.thickness, 0.0, 0.05)


@dataclass(frozen=True)
class MixDraw:
    """The drawn mask of one mixture (recorded in the sample metadata)."""

    mask: str
    coverage: float
    bias: float

    def to_json(self) -> dict[str, float | str]:
        return {"mask": self.mask, "coverage": self.coverage, "bias": self.bias}


def draw_mix(config: MixingConfig, generator: torch.Generator) -> MixDraw:
    """Mask kind, coverage and height bias of one mixture."""
    u = torch.rand(3, generator=generator, dtype=torch.float64).tolist()
    mask = config.masks[min(int(u[0] * len(config.masks)), len(config.masks) - 1)]
    coverage = config.coverage_min + (config.coverage_max - config.coverage_min) * u[1]
    return MixDraw(mask, coverage, config.bias_max * (2.0 * u[2] - 1.0))


def mask_field(kind: str, size: int, generator: torch.Generator) -> Tensor:
    """A periodic field whose upper values are where the upper material goes, standardised
    (mean 0, std 1). Shape: ``(size, size)``."""
    if kind == "noise":
        field = fbm(size, 4, generator, octaves=5)
    elif kind == "cracks":
        f1, f2, _ = worley(size, 6, generator)
        # Near a cell border f2 − f1 → 0; a little fBm makes the crack width irregular.
        field = -(f2 - f1) + 0.15 * fbm(size, 16, generator, octaves=3)
    elif kind == "patches":
        cells = 5
        _, _, cell_id = worley(size, cells, generator)
        field = random_per_cell(cell_id, cells * cells, generator)[0] + 0.25 * fbm(
            size, 8, generator, octaves=4
        )
    else:
        raise ValueError(f"unknown mask kind {kind!r}; known: {', '.join(MASK_KINDS)}")
    return _standardised(field)


def _standardised(x: Tensor) -> Tensor:
    return (x - x.mean()) / x.std().clamp(min=1e-8)


def mixture_mask(lower_height: Tensor, draw: MixDraw, generator: torch.Generator) -> Tensor:
    """The upper material's coverage in [0, 1]: the mask field shifted by the (standardised)
    lower height — towards its cavities for ``bias > 0`` — thresholded at the quantile that
    leaves ``coverage`` of the area above, with an edge a few texels soft.

    Shape: lower_height ``(1, H, W)`` → ``(1, H, W)``.
    """
    size = lower_height.shape[-1]
    field = mask_field(draw.mask, size, generator) - draw.bias * _standardised(lower_height[0])
    # kthvalue instead of torch.quantile: quantile refuses inputs above 16 M elements.
    flat = field.flatten()
    k = max(1, min(flat.numel(), round((1.0 - draw.coverage) * flat.numel())))
    threshold = flat.kthvalue(k).values
    softness = 0.05 * field.std().clamp(min=1e-8)
    return torch.sigmoid((field - threshold) / softness)[None]


def mix_layers(
    lower: MaterialLayers, upper: MaterialLayers, mask: Tensor, thickness: float
) -> MaterialLayers:
    """``upper`` laid over ``lower`` where ``mask`` is 1: colours, roughness and metallic blend
    with the mask; the height is the lower one plus, under the mask, the upper relief (about its
    mean) and a layer ``thickness`` (fraction of the width), so the layer stands on the lower
    surface.

    Shape: every layer ``(C, H, W)`` of one size, mask ``(1, H, W)``.
    """
    if lower.height.shape != upper.height.shape or mask.shape != lower.height.shape:
        raise ValueError(
            f"layers and mask must share one size, got {tuple(lower.height.shape)}, "
            f"{tuple(upper.height.shape)}, mask {tuple(mask.shape)}"
        )
    size = lower.height.shape[-1]
    layer = upper.height - upper.height.mean() + thickness * size
    return MaterialLayers(
        basecolor=torch.lerp(lower.basecolor, upper.basecolor, mask),
        height=lower.height + mask * layer,
        roughness=torch.lerp(lower.roughness, upper.roughness, mask),
        metallic=torch.lerp(lower.metallic, upper.metallic, mask),
    )


__all__ = ["MASK_KINDS", "MixDraw", "MixingConfig", "draw_mix", "mask_field", "mix_layers", "mixture_mask"]
