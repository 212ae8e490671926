"""Per-image statistics inside a network, frozen like InstanceNorm in tiled inference.

Some quantities a network needs are image-wide: the hotspot clip's luminance cap of the de-lit
photo, or the per-image level of a feature map, which an ``InstanceNorm2d`` without affine
parameters removes (a network built of them cannot see a whole surface's roughness or metal share
except through spatial patterns; Deschaintre et al. 2018 add a global-feature track for this
reason). An :class:`ImageStatistic` module computes such a per-image vector; tiled inference
(:mod:`brdfgan.inference.model.tiling`) records its output in the statistics pass over the whole
(downscaled) photo and every tile replays it, so all tiles share one value, as they share the
norms' statistics.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from brdfgan.core.delit import HOTSPOT_CLIP_FACTOR, HOTSPOT_CLIP_QUANTILE, hotspot_cap

MOMENTS_EPS = 1e-5  # as InstanceNorm2d's eps: the log standard deviation of a constant map is finite


class ImageStatistic(nn.Module):
    """A per-image vector computed from a whole feature map or image (subclasses: ``forward``).

    Shape:
        - output: ``(B, K)``
    """


class ImageMoments(ImageStatistic):
    """The per-channel mean and ``0.5 · log(var + eps)`` of a feature map over its height and width.

    Shape:
        - input: ``(B, C, H, W)``
        - output: ``(B, 2C)``: the C means, then the C log standard deviations
    """

    def forward(self, x: Tensor) -> Tensor:
        var, mean = torch.var_mean(x, dim=(-2, -1), correction=0)
        return torch.cat([mean, 0.5 * (var + MOMENTS_EPS).log()], dim=1)


class HotspotCap(ImageStatistic):
    """:func:`~brdfgan.core.delit.hotspot_cap` of an image: the luminance above which
    :func:`~brdfgan.core.delit.clip_hotspot` scales pixels down.

    Shape:
        - input: ``(B, 3, H, W)`` linear RGB
        - output: ``(B, 1)``
    """

    def __init__(self, factor: float = HOTSPOT_CLIP_FACTOR, quantile: float = HOTSPOT_CLIP_QUANTILE) -> None:
        super().__init__()
        self.factor, self.quantile = factor, quantile

    def forward(self, image: Tensor) -> Tensor:
        return hotspot_cap(image, self.factor, self.quantile).unsqueeze(1)


__all__ = ["MOMENTS_EPS", "HotspotCap", "ImageMoments", "ImageStatistic"]
