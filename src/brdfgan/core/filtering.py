"""Image filters shared by the inference stages (the hotspot detector, test-time refinement) and
the photo-anchored generator (its anchor, :mod:`brdfgan.models.anchored`)."""

from __future__ import annotations

import math
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape

Border = Literal["zeros", "reflect"]


def gaussian_blur(image: Tensor, sigma: float, border: Border = "zeros") -> Tensor:
    """Separable Gaussian blur of every channel, radius ⌈3σ⌉ (for ``"reflect"`` at most the
    image's side − 1, what reflection allows).

    Args:
        image: the images.
        sigma: standard deviation in pixels, > 0.
        border: ``"zeros"`` (the image continues black) or ``"reflect"`` (mirrored at the edge).

    Shape:
        - image: ``(B, C, H, W)``
        - output: same

    Example:
        An impulse spreads into ``exp(−(x² + y²)/2σ²)``, normalised: its centre keeps about
        ``1 / (2πσ²)`` and the total is kept; a constant image stays constant with ``"reflect"``:

        >>> impulse = torch.zeros(1, 1, 9, 9)
        >>> impulse[0, 0, 4, 4] = 1.0
        >>> blurred = gaussian_blur(impulse, 1.0)
        >>> round(blurred[0, 0, 4, 4].item(), 3), round(1 / (2 * math.pi), 3), round(blurred.sum().item(), 4)
        (0.159, 0.159, 1.0)
        >>> torch.allclose(gaussian_blur(torch.ones(1, 2, 5, 5), 2.0, "reflect"), torch.ones(1, 2, 5, 5))
        True
    """
    if not sigma > 0:
        raise ValueError(f"sigma must be positive, got {sigma}")
    radius = max(1, math.ceil(3.0 * sigma))
    if border == "reflect":
        radius = max(1, min(radius, image.shape[-1] - 1, image.shape[-2] - 1))
    taps = torch.arange(-radius, radius + 1, dtype=image.dtype, device=image.device)
    kernel = torch.exp(-0.5 * (taps / sigma) ** 2)
    kernel = kernel / kernel.sum()
    channels = image.shape[1]
    mode = "constant" if border == "zeros" else "reflect"
    rows = kernel.view(1, 1, 1, -1).expand(channels, 1, 1, -1)
    columns = kernel.view(1, 1, -1, 1).expand(channels, 1, -1, 1)
    image = F.conv2d(F.pad(image, (radius, radius, 0, 0), mode=mode), rows, groups=channels)
    return F.conv2d(F.pad(image, (0, 0, radius, radius), mode=mode), columns, groups=channels)


def binomial_blur(image: Tensor) -> Tensor:
    """The 3 × 3 binomial filter ``[1, 2, 1] ⊗ [1, 2, 1] / 16`` of every channel, mirrored at the
    edges: the smallest blur whose response is zero at the period-2 frequencies (a checkerboard,
    or alternating rows or columns, becomes flat, also at the borders) and ~0.8 at a quarter of
    the sampling rate.

    Shape:
        - image: ``(B, C, H, W)``, H and W >= 2
        - output: same

    Example:
        A checkerboard becomes its mean, borders included:

        >>> checkerboard = (torch.arange(4).view(4, 1) + torch.arange(4)).remainder(2).float()
        >>> binomial_blur(checkerboard.view(1, 1, 4, 4)).unique().tolist()
        [0.5]
    """
    check_shape(image, "B C H W", name="image")
    if min(image.shape[-2:]) < 2:
        raise ValueError(f"expected (B, C, H, W) images with H, W >= 2, got {tuple(image.shape)}")
    channels = image.shape[1]
    kernel = torch.tensor([0.25, 0.5, 0.25], dtype=image.dtype, device=image.device)
    rows = kernel.view(1, 1, 1, 3).expand(channels, 1, 1, 3)
    columns = kernel.view(1, 1, 3, 1).expand(channels, 1, 3, 1)
    image = F.conv2d(F.pad(image, (1, 1, 0, 0), mode="reflect"), rows, groups=channels)
    return F.conv2d(F.pad(image, (0, 0, 1, 1), mode="reflect"), columns, groups=channels)
