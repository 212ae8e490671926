"""Auto exposure of HDR renderings to linear LDR (paper appendix, docs/conventions.md#auto-exposure).

Derivation. Exposure values at ISO 100 are ``EV100 = log2(N²/t)`` (aperture N, shutter time t).
A reflected-light meter with calibration constant K = 12.5 cd·s/m²·ISO picks, for average scene
luminance L_avg and sensitivity S, the setting with ``EV = log2(L_avg·S/K)``. Saturation-based
sensitivity (ISO 12232, Kerr 2007) says the sensor saturates at photometric exposure
``H_sbs = 78/S``; with ``H = q·t·L/N²`` the luminance that just saturates is

    L_max = (78 / (S·q)) · N²/t = (78 / (S·q)) · 2^EV100.

With S = 100 and lens/vignetting attenuation q = 0.65: ``78/65 = 1.2``, hence
``L_max = 1.2 · 2^EV100`` (the paper prints "1.2·EV100²", a typo for this standard photometric
result). The image is divided by L_max and clipped:

    LDR = clip(HDR / L_max, 0, 1),   L_max = 1.2 · 2^(log2(L_avg·100/12.5)) = 9.6 · L_avg.

Because L_max is proportional to L_avg, scaling the HDR image by any constant leaves the LDR
result unchanged. No tone curve is applied: the output stays linear, like a RAW photo.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.checks import check_shape

ISO_SPEED = 100.0
METER_CALIBRATION_K = 12.5
LENS_ATTENUATION_Q = 0.65
SATURATION_CONSTANT = 78.0
# Rec. 709 / sRGB primaries, the colour space of our linear renderings.
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
# A linear value at or above this (1.0 = the file's or sensor's saturation) counts as clipped.
SATURATION_LEVEL = 0.99


def luminance(rgb: Tensor, dim: int = -3) -> Tensor:
    """Relative luminance of linear RGB along the (negative) channel dimension ``dim``, kept as size 1.

    Shape:
        - rgb: ``(*, 3, H, W)`` (``dim = -3``, images) or ``(*, 3)`` (``dim = -1``, colours)
        - output: ``(*, 1, H, W)`` or ``(*, 1)``

    Example:
        The Rec. 709 weights sum to 1 (white has luminance 1) and green carries most of it:

        >>> colours = torch.tensor([[1.0, 1.0, 1.0], [0.0, 1.0, 0.0]])
        >>> [round(v, 4) for v in luminance(colours, dim=-1).flatten().tolist()]
        [1.0, 0.7152]
        >>> tuple(luminance(torch.ones(2, 3, 4, 5)).shape)
        (2, 1, 4, 5)
    """
    if dim >= 0:
        raise ValueError(f"dim must be negative (counted from the end), got {dim}")
    trailing = "H W" if dim == -3 else " ".join(f"D{i}" for i in range(1, -dim))
    check_shape(rgb, f"* 3 {trailing}", name="linear RGB")
    weights = rgb.new_tensor(LUMINANCE_WEIGHTS).view(3, *([1] * (-dim - 1)))
    return (rgb * weights).sum(dim=dim, keepdim=True)


def log_luminance(rgb: Tensor, floor: float = 1e-3) -> Tensor:
    """``log max(Y, floor)`` of linear RGB images, ``Y`` their :func:`luminance`: the floor keeps
    black and shadowed pixels finite (1e-3 is about one 8-bit step of a photo exposed for white).

    Shape:
        - rgb: ``(*, 3, H, W)``
        - output: ``(*, 1, H, W)``

    Example:
        White is 0; black is floored:

        >>> rgb = torch.tensor([1.0, 0.0]).view(1, 1, 2, 1).expand(1, 3, 2, 1)
        >>> [round(v, 3) for v in log_luminance(rgb).flatten().tolist()]
        [0.0, -6.908]
    """
    return luminance(rgb).clamp_min(floor).log()


def luminance_value(rgb: Sequence[float] | np.ndarray) -> float:
    """:func:`luminance` of one colour given as plain numbers (light colours, irradiances)."""
    return float(luminance(torch.as_tensor(rgb, dtype=torch.float64), dim=-1))


def exposure_value_100(average_luminance: Tensor) -> Tensor:
    """EV100 = log2(L_avg · S / K). Shape: any → same.

    Example:
        ``K / S = 0.125`` is EV 0, and every doubling of the luminance is one stop more:

        >>> exposure_value_100(torch.tensor([0.125, 0.25, 1.0])).tolist()
        [0.0, 1.0, 3.0]
    """
    return torch.log2(average_luminance * ISO_SPEED / METER_CALIBRATION_K)


def saturation_luminance(ev100: Tensor) -> Tensor:
    """L_max = 78 / (S q) · 2^EV100 = 1.2 · 2^EV100. Shape: any → same."""
    return SATURATION_CONSTANT / (ISO_SPEED * LENS_ATTENUATION_Q) * torch.exp2(ev100)


def auto_exposure_scale(hdr: Tensor) -> Tensor:
    """The multiplier ``1 / L_max`` per image; 0 for an all-black image (nothing to expose).

    Shape:
        - hdr: ``(*, 3, H, W)`` linear HDR
        - output: ``(*)``

    Example:
        ``1 / L_max = 1 / (9.6 · L_avg)``, and 0 for a black image:

        >>> scale = auto_exposure_scale(torch.full((1, 3, 2, 2), 5.0))
        >>> round(scale.item() * 9.6 * 5.0, 4)
        1.0
        >>> auto_exposure_scale(torch.zeros(2, 3, 2, 2)).tolist()
        [0.0, 0.0]
    """
    if not torch.isfinite(hdr).all():
        raise ValueError("HDR image contains NaN or infinite values")
    average = luminance(hdr).mean(dim=(-3, -2, -1))
    positive = average > 0
    safe_average = torch.where(positive, average, torch.ones_like(average))
    scale = 1.0 / saturation_luminance(exposure_value_100(safe_average))
    return torch.where(positive, scale, torch.zeros_like(scale))


def auto_expose(hdr: Tensor, exposure_ev: float = 0.0) -> tuple[Tensor, Tensor]:
    """Linear HDR → linear LDR in [0, 1] with the paper's auto exposure, off by ``exposure_ev``
    stops (a camera's metering error: + brighter, − darker; 0 is the exact auto exposure).

    Returns:
        ``(ldr, scale)`` where ``ldr = clip(hdr · scale, 0, 1)`` and
        ``scale = auto_exposure_scale(hdr) · 2^exposure_ev``.

    Shape:
        - hdr: ``(*, 3, H, W)``
        - output: ldr ``(*, 3, H, W)``, scale ``(*)``

    Example:
        A uniform image lands at ``1 / 9.6`` whatever its brightness; +1 EV doubles that:

        >>> hdr = torch.full((1, 3, 2, 2), 5.0)
        >>> ldr, scale = auto_expose(hdr)
        >>> round(ldr.max().item(), 4), round(ldr.min().item(), 4), round(1 / 9.6, 4)
        (0.1042, 0.1042, 0.1042)
        >>> torch.allclose(auto_expose(100.0 * hdr)[0], ldr)
        True
        >>> round(auto_expose(hdr, exposure_ev=1.0)[0].max().item(), 4)
        0.2083
    """
    if not math.isfinite(exposure_ev):
        raise ValueError(f"exposure_ev must be finite, got {exposure_ev}")
    scale = auto_exposure_scale(hdr) * math.pow(2.0, exposure_ev)  # · 1.0 at 0: bit for bit
    return (hdr * scale[..., None, None, None]).clamp(0.0, 1.0), scale


def ev100_to_scale(ev100: float) -> float:
    """The exposure multiplier for a given EV100, for metadata and manual exposure.

    Example:
        ``1 / (1.2 · 2^EV100)``:

        >>> round(ev100_to_scale(0.0), 4), round(ev100_to_scale(3.0), 4)
        (0.8333, 0.1042)
    """
    return 1.0 / (SATURATION_CONSTANT / (ISO_SPEED * LENS_ATTENUATION_Q) * math.pow(2.0, ev100))
