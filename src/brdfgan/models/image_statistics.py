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
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.delit import HOTSPOT_CLIP_FACTOR, HOTSPOT_CLIP_QUANTILE, hotspot_cap
from brdfgan.core.exposure import SATURATION_LEVEL, luminance
from brdfgan.core.flash_geometry import flash_offset_channels

MOMENTS_EPS = 1e-5  # as InstanceNorm2d's eps: the log standard deviation of a constant map is finite
# Inner edges of the highlight profile's rings in |o|, the tangent of a pixel's angle from the
# hotspot seen from the camera (for a flash at the lens, the tilt of the half vector from the
# normal of a flat surface). A GGX lobe of roughness r (alpha = r²) is ~alpha wide in that tangent:
# r 0.1 → 0.01, r 0.2 → 0.04, r 0.4 → 0.16; the rings double in width from there.
PROFILE_EDGES = (0.005, 0.01, 0.02, 0.04, 0.08, 0.16, 0.32)
PROFILE_RINGS = len(PROFILE_EDGES) + 1
PROFILE_LOG_EPS = 1e-3  # as the anchored network's log of linear values


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


class HighlightProfile(ImageStatistic):
    """The flash highlight's profile: per ring around the hotspot (:data:`PROFILE_EDGES`, in
    tangents of the angle from it), the de-lit photo's mean log luminance over the whole image's,
    the share of the ring's pixels the sensor clipped, and whether the ring is in view at all.
    It reads the de-lit photo its network has already computed (:func:`~brdfgan.core.delit.delit_photo`,
    ``clip=False``) beside the photo it came from.

    Why: roughness and specular level are read from the width and height of the highlight, a
    feature at one place in the photo. A network of affine-free instance norms and a few
    downsamplings sees it only from pixels within its receptive field and passes an image-wide
    level only through feature moments, which pass it on poorly (the runs with and without it:
    ``docs/default_model.md``, "Design" and "The highlight profile"). The de-lit photo has the flat-surface
    falloff divided out, so a matte surface's profile is ~0 in every ring and a glossy one rises
    towards the hotspot over a width that grows with roughness. Empty rings (a crop or tile that
    does not reach them) read 0 with their flag 0.

    Shape:
        - delit: ``(B, 3, H, W)`` the de-lit photo, hotspot not clipped
        - photo: ``(B, 3, H, W)`` linear LDR
        - frame: ``(B, 3)`` flash frame ``(x, y, s)``
        - output: ``(B, 3 · PROFILE_RINGS)``: the relative log luminances, the clipped shares, the flags
    """

    def forward(self, delit: Tensor, photo: Tensor, frame: Tensor) -> Tensor:
        height, width = photo.shape[-2:]
        log_lum = (luminance(delit) + PROFILE_LOG_EPS).log().flatten(1)
        radius = flash_offset_channels(frame, height, width).norm(dim=1).flatten(1)
        edges = torch.tensor(PROFILE_EDGES, dtype=radius.dtype, device=radius.device)
        rings = F.one_hot(torch.bucketize(radius, edges), PROFILE_RINGS).to(photo.dtype)  # (B, HW, K)
        count = rings.sum(dim=1)
        share = rings / count.clamp_min(1.0).unsqueeze(1)
        relative = torch.einsum("bp,bpk->bk", log_lum - log_lum.mean(dim=1, keepdim=True), share)
        clipped = (photo.amax(dim=1) >= SATURATION_LEVEL).to(photo.dtype).flatten(1)
        clipped_share = torch.einsum("bp,bpk->bk", clipped, share)
        return torch.cat([relative, clipped_share, (count > 0).to(photo.dtype)], dim=1)


__all__ = [
    "MOMENTS_EPS",
    "PROFILE_EDGES",
    "PROFILE_RINGS",
    "HighlightProfile",
    "HotspotCap",
    "ImageMoments",
    "ImageStatistic",
]
