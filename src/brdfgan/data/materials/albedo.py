"""Physically plausible base colours: measured metal F0 colours and the dielectric albedo range.

One home for the colour facts every family, the material mixer and the recolour augmentation
rely on (docs/conventions.md#maps-and-encodings: base colour is stored sRGB-encoded, shaded linear):

- **Metals** take their base colour from the measured normal-incidence reflectance F0 of the
  metal. :data:`METAL_F0_LINEAR` lists linear-RGB F0 values of common metals as tabulated for
  real-time rendering from measured optical constants (Hoffman, "Physics and Math of Shading",
  SIGGRAPH 2015 course; the same values as Unreal's and Substance's metal charts). A metal whose
  base colour leaves these colours looks like painted plastic, which is why recolouring never
  touches metals.
- **Dielectrics** (everything with metallic 0) have a linear diffuse albedo between about 0.02
  (charcoal, black paint) and 0.9 (fresh snow, white paper); :data:`DIELECTRIC_ALBEDO_LINEAR`
  is that range, and :func:`clamp_dielectric_albedo` keeps an sRGB base colour inside it.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import torch
from torch import Tensor

from brdfgan.core.svbrdf import linear_to_srgb

# Linear-RGB F0 at normal incidence.
METAL_F0_LINEAR: Mapping[str, tuple[float, float, float]] = MappingProxyType(
    {
        "iron": (0.562, 0.565, 0.578),
        "steel": (0.560, 0.570, 0.580),
        "chrome": (0.549, 0.556, 0.554),
        "nickel": (0.660, 0.609, 0.526),
        "titanium": (0.542, 0.497, 0.449),
        "aluminium": (0.913, 0.922, 0.924),
        "silver": (0.972, 0.960, 0.915),
        "zinc": (0.664, 0.824, 0.850),
        "gold": (1.000, 0.766, 0.336),
        "copper": (0.955, 0.638, 0.538),
        "brass": (0.910, 0.778, 0.423),
        "platinum": (0.673, 0.637, 0.585),
    }
)

# Linear diffuse albedo of real non-metals (charcoal ≈ 0.02 … fresh snow ≈ 0.9).
DIELECTRIC_ALBEDO_LINEAR: tuple[float, float] = (0.02, 0.9)


def metal_basecolor(name: str) -> tuple[float, float, float]:
    """The sRGB-encoded base colour of a metal of :data:`METAL_F0_LINEAR` (as a texture stores it)."""
    if name not in METAL_F0_LINEAR:
        raise KeyError(f"unknown metal {name!r}; known: {', '.join(sorted(METAL_F0_LINEAR))}")
    encoded = linear_to_srgb(torch.tensor(METAL_F0_LINEAR[name], dtype=torch.float64))
    r, g, b = (float(c) for c in encoded.clamp(0.0, 1.0))
    return (r, g, b)


def metal_basecolor_tensor(names: tuple[str, ...]) -> Tensor:
    """sRGB base colours of several metals, in the given order. Shape: ``(len(names), 3)``."""
    return torch.tensor([metal_basecolor(n) for n in names], dtype=torch.float32)


def clamp_dielectric_albedo(basecolor: Tensor) -> Tensor:
    """An sRGB base colour with every linear channel inside :data:`DIELECTRIC_ALBEDO_LINEAR`.

    Shape: ``(3, H, W)`` (or any shape; applied per element) → same.
    """
    # The sRGB curve is increasing, so clamping the encoded values against the encoded bounds is
    # the same clamp, without a decode and re-encode of every texel (and exact inside the range).
    low, high = (
        float(linear_to_srgb(torch.tensor(v, dtype=torch.float64))) for v in DIELECTRIC_ALBEDO_LINEAR
    )
    return basecolor.clamp(low, high)


__all__ = [
    "DIELECTRIC_ALBEDO_LINEAR",
    "METAL_F0_LINEAR",
    "clamp_dielectric_albedo",
    "metal_basecolor",
    "metal_basecolor_tensor",
]
