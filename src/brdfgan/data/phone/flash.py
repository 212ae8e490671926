"""The simulated phone flash: black-body colour temperature → linear sRGB, random flash draws.

Colour temperature follows the Planckian locus in CIE 1931 xy with the cubic-spline
approximation of Kim et al. (2002; valid 1667–25000 K, error ~1e-3 in xy), lifted to XYZ with
Y = 1 and converted to linear sRGB (D65). Phone LED flashes sit around 4000–6500 K.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from brdfgan.core.exposure import luminance_value
from brdfgan.core.sampling import log_uniform
from brdfgan.data.storage.spec_checks import in_range, ordered

MIN_TEMPERATURE_K = 1667.0
MAX_TEMPERATURE_K = 25000.0
# XYZ → linear sRGB (IEC 61966-2-1, D65 white).
_XYZ_TO_LINEAR_SRGB = (
    (3.2404542, -1.5371385, -0.4985314),
    (-0.9692660, 1.8760108, 0.0415560),
    (0.0556434, -0.2040259, 1.0572252),
)


def planckian_xy(temperature_k: float) -> tuple[float, float]:
    """CIE 1931 chromaticity of a black body at ``temperature_k`` (Kim et al. 2002)."""
    t = float(temperature_k)
    if not MIN_TEMPERATURE_K <= t <= MAX_TEMPERATURE_K:
        raise ValueError(
            f"colour temperature must lie in [{MIN_TEMPERATURE_K:g}, {MAX_TEMPERATURE_K:g}] K, got {t:g}"
        )
    if t <= 4000.0:
        x = -0.2661239e9 / t**3 - 0.2343589e6 / t**2 + 0.8776956e3 / t + 0.179910
    else:
        x = -3.0258469e9 / t**3 + 2.1070379e6 / t**2 + 0.2226347e3 / t + 0.240390
    if t <= 2222.0:
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif t <= 4000.0:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    return x, y


def blackbody_rgb(temperature_k: float) -> tuple[float, float, float]:
    """Linear sRGB colour of a black body, scaled to luminance 1 (negative components, which only
    the reddest temperatures produce, are clipped to the gamut first)."""
    x, y = planckian_xy(temperature_k)
    xyz = (x / y, 1.0, (1.0 - x - y) / y)
    rgb = [max(0.0, sum(m * c for m, c in zip(row, xyz, strict=True))) for row in _XYZ_TO_LINEAR_SRGB]
    luminance = luminance_value(rgb)
    return (rgb[0] / luminance, rgb[1] / luminance, rgb[2] / luminance)


@dataclass(frozen=True)
class FlashSampling:
    """Ranges of the random flash: radiant intensity (W/sr, log-uniform) and colour temperature
    (uniform, within the range of :func:`planckian_xy`). Checked on construction, naming the keys
    under ``dataset_spec.flash``, the only place a flash spec is configured."""

    intensity_min: float = 0.5
    intensity_max: float = 4.0
    temperature_min_k: float = 4000.0
    temperature_max_k: float = 6500.0

    def __post_init__(self) -> None:
        key = "dataset_spec.flash"
        ordered(key, self, "intensity_min", "intensity_max")
        in_range(f"{key}.intensity_min", self.intensity_min, 0.0, low_open=True)  # log-uniform
        ordered(key, self, "temperature_min_k", "temperature_max_k")
        for name in ("temperature_min_k", "temperature_max_k"):  # where the locus fit holds
            in_range(f"{key}.{name}", getattr(self, name), MIN_TEMPERATURE_K, MAX_TEMPERATURE_K)

    def sample(self, generator: torch.Generator) -> tuple[float, float]:
        """``(intensity, temperature_k)``."""
        u = torch.rand(2, generator=generator, dtype=torch.float64)
        intensity = log_uniform(u[0], self.intensity_min, self.intensity_max)
        temperature = self.temperature_min_k + float(u[1]) * (self.temperature_max_k - self.temperature_min_k)
        return intensity, temperature
