"""Image filters shared by the inference stages (the hotspot detector, test-time refinement)."""

from __future__ import annotations

import math
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor

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
