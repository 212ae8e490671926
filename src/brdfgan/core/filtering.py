"""Image filters shared by the inference stages (the hotspot detector, test-time refinement, the
guided fast path's upsampling) and the photo-anchored generator (its anchor,
:mod:`brdfgan.models.anchored`), and the smooth step the masks and the procedural textures blend
with."""

from __future__ import annotations

import math
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape

Border = Literal["zeros", "reflect"]


def smoothstep(edge0: float, edge1: float, x: Tensor) -> Tensor:
    """Hermite step from 0 at ``edge0`` to 1 at ``edge1``. Shape: any.

    Example:
        >>> smoothstep(0.0, 2.0, torch.tensor([-1.0, 0.5, 1.0, 3.0])).tolist()
        [0.0, 0.15625, 0.5, 1.0]
    """
    t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


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
    # Shifted sums rather than a grouped convolution: the same values, and a CPU runs a grouped
    # convolution with 1 × 3 kernels slowly (the anchor is blurred at up to 2048²).
    padded = F.pad(image, (1, 1, 0, 0), mode="reflect")
    image = 0.25 * padded[..., :-2] + 0.5 * padded[..., 1:-1] + 0.25 * padded[..., 2:]
    padded = F.pad(image, (0, 0, 1, 1), mode="reflect")
    return 0.25 * padded[..., :-2, :] + 0.5 * padded[..., 1:-1, :] + 0.25 * padded[..., 2:, :]


def box_mean(image: Tensor, radius: int) -> Tensor:
    """The mean of every channel over the ``(2·radius + 1)²`` window around each pixel, windows cut
    at the image's border (each mean is over the pixels inside it): the guided filter's box.

    Shape:
        - image: ``(B, C, H, W)``
        - output: same

    Example:
        >>> box_mean(torch.arange(4.0).view(1, 1, 1, 4), 1).flatten().tolist()
        [0.5, 1.0, 2.0, 2.5]
    """
    check_shape(image, "B C H W", name="image")
    if radius < 0:
        raise ValueError(f"radius must be non-negative, got {radius}")
    side = 2 * radius + 1
    if radius <= 1:  # one 3 × 3 pass is faster than two (13 against 18 ms at 1024², 2 threads)
        return F.avg_pool2d(image, side, stride=1, padding=radius, count_include_pad=False)
    # Separable: a box cut at the border is a rectangle, so rows then columns give the same mean in
    # 2·side additions a pixel instead of side² (radius 4: 23 against 36 ms at 1024²; 16: 104
    # against 711 ms; the thin-feature rule's windows span 50+ pixels).
    rows = F.avg_pool2d(image, (1, side), stride=1, padding=(0, radius), count_include_pad=False)
    return F.avg_pool2d(rows, (side, 1), stride=1, padding=(radius, 0), count_include_pad=False)


def guided_upsample(source: Tensor, guide: Tensor, radius: int = 1, eps: float = 1e-3) -> Tensor:
    """Carry ``source`` up to ``guide``'s resolution with the guide's detail: the bilinearly
    enlarged source plus, per pixel, the guide's detail above the source's resolution times the
    local slopes of the source on the guide.

    The slopes are the guided filter's (He et al. 2013): in the ``(2·radius + 1)²`` window around
    each source pixel, the ridge regression ``source ≈ A · guide + b`` against the guide
    area-averaged to the source's size (``eps`` the ridge: a window whose guide varies less than
    ``√eps`` gets slope ~0), fitted small and enlarged bilinearly as in the fast guided filter
    (He & Sun 2015); unlike the guided filter's, they are not averaged over the windows covering
    a pixel, which would lower them beside an edge and leave it half blurred. Only the guide's
    detail, ``guide − enlarge(shrink(guide))`` (:func:`split_bands`), is multiplied by them, so
    what the source resolves is kept as it is — a constant guide gives plain bilinear
    enlargement, and equal sizes give the source itself — and where the source follows the guide
    linearly the guide's sharper edges and finer texture come through at that strength.

    Args:
        source: the values to enlarge (e.g. a network's maps at the size it ran at).
        guide: the full-resolution image whose detail is carried, 1 or 3 channels (e.g. the log of
            a photo).
        radius: the windows' radius in source pixels, >= 1.
        eps: the regression's ridge, in the guide's units squared, > 0.

    Shape:
        - source: ``(B, C, h, w)``
        - guide: ``(B, G, H, W)``, G ∈ {1, 3}, ``H >= h``, ``W >= w``
        - output: ``(B, C, H, W)``

    Example:
        A source that is twice the guide at half its resolution gets twice the guide's sharp
        step, where bilinear enlargement blurs it:

        >>> guide = torch.tensor([0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0]).view(1, 1, 1, 8).expand(1, 1, 8, 8)
        >>> source = 2 * F.interpolate(guide, size=(4, 4), mode="area")
        >>> source[0, 0, 0].tolist()
        [0.0, 1.0, 2.0, 2.0]
        >>> [round(v, 3) for v in guided_upsample(source, guide, eps=1e-6)[0, 0, 0].tolist()]
        [0.0, 0.0, 0.0, 2.0, 2.0, 2.0, 2.0, 2.0]
        >>> F.interpolate(source, size=(8, 8), mode="bilinear")[0, 0, 0].tolist()
        [0.0, 0.25, 0.75, 1.25, 1.75, 2.0, 2.0, 2.0]
    """
    check_shape(source, "B C h w", name="source")
    check_shape(guide, "B G H W", name="guide")
    (batch, _, height, width), (guide_batch, guides, out_h, out_w) = source.shape, guide.shape
    if guide_batch != batch or guides not in (1, 3):
        raise ValueError(
            f"guide must have the source's batch ({batch}) and 1 or 3 channels, got {tuple(guide.shape)}"
        )
    if out_h < height or out_w < width:
        raise ValueError(f"guide {out_h}×{out_w} is smaller than the source {height}×{width}")
    if radius < 1 or not eps > 0:
        raise ValueError(f"need radius >= 1 and eps > 0, got {radius=}, {eps=}")
    if (out_h, out_w) == (height, width):
        return source  # no detail above the source's resolution

    # Centred, so that the box means' second moments do not lose float32 digits.
    small, detail = split_bands(guide - guide.mean(dim=(-2, -1), keepdim=True), height, width)
    slopes = _local_slopes(source, small, radius, eps)  # (B, C, G, h, w)
    out = _enlarge(source, out_h, out_w)
    for g in range(guides):  # one guide channel's slopes at full size at a time
        out.addcmul_(_enlarge(slopes[:, :, g], out_h, out_w), detail[:, g : g + 1])
    return out


def split_bands(image: Tensor, height: int, width: int) -> tuple[Tensor, Tensor]:
    """The image area-averaged to ``height × width`` and what that loses: its detail above that
    resolution, ``image − enlarge(small)`` (bilinear enlargement), so ``image = enlarge(small) +
    detail``. The detail is the band :func:`guided_upsample` carries.

    Shape:
        - image: ``(B, C, H, W)``, ``H >= height``, ``W >= width``
        - output: ``(B, C, height, width)`` and ``(B, C, H, W)``

    Example:
        A smooth ramp has no detail above half its resolution (but at its ends, where the
        enlargement holds the last value); an alternating pattern is all detail:

        >>> ramp = torch.arange(8.0).view(1, 1, 1, 8).expand(1, 1, 8, 8)
        >>> split_bands(ramp, 4, 4)[1][0, 0, 0].tolist()
        [-0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5]
        >>> stripes = torch.tensor([0.0, 1.0]).repeat(4).view(1, 1, 1, 8).expand(1, 1, 8, 8)
        >>> small, detail = split_bands(stripes, 4, 4)
        >>> small.unique().tolist(), detail[0, 0, 0].tolist()
        ([0.5], [-0.5, 0.5, -0.5, 0.5, -0.5, 0.5, -0.5, 0.5])
    """
    check_shape(image, "B C H W", name="image")
    if not (1 <= height <= image.shape[-2] and 1 <= width <= image.shape[-1]):
        raise ValueError(f"cannot split {tuple(image.shape[-2:])} at a larger or empty {(height, width)}")
    small = F.interpolate(image, size=(height, width), mode="area")
    return small, image - _enlarge(small, *image.shape[-2:])


def _enlarge(image: Tensor, height: int, width: int) -> Tensor:
    return F.interpolate(image, size=(height, width), mode="bilinear", align_corners=False)


def _local_slopes(source: Tensor, guide: Tensor, radius: int, eps: float) -> Tensor:
    """Per window, the ridge-regression slopes ``A = (Σ_guide + eps·I)⁻¹ cov(guide, source)``.

    Shape: ``(B, C, h, w)``, ``(B, G, h, w)`` → ``(B, C, G, h, w)``.
    """
    guides = guide.shape[1]
    mean_guide, mean_source = box_mean(guide, radius), box_mean(source, radius)
    cov = [  # per guide channel g: cov(guide_g, source) over the window, (B, C, h, w)
        box_mean(guide[:, g : g + 1] * source, radius) - mean_guide[:, g : g + 1] * mean_source
        for g in range(guides)
    ]

    def sigma(i: int, j: int) -> Tensor:  # the guide's covariance, the ridge on its diagonal
        value = box_mean(guide[:, i : i + 1] * guide[:, j : j + 1], radius)
        value = value - mean_guide[:, i : i + 1] * mean_guide[:, j : j + 1]
        return value + eps if i == j else value

    if guides == 1:
        return (cov[0] / sigma(0, 0)).unsqueeze(2)
    # 3 × 3: the symmetric inverse from cofactors (elementwise; a batched solve is ~10× slower).
    s00, s01, s02 = sigma(0, 0), sigma(0, 1), sigma(0, 2)
    s11, s12, s22 = sigma(1, 1), sigma(1, 2), sigma(2, 2)
    c00, c01, c02 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    c11, c12, c22 = s00 * s22 - s02 * s02, s01 * s02 - s00 * s12, s00 * s11 - s01 * s01
    det = s00 * c00 + s01 * c01 + s02 * c02  # > 0: Σ is positive semi-definite, the ridge makes it definite
    inverse = ((c00, c01, c02), (c01, c11, c12), (c02, c12, c22))
    return torch.stack([sum(inverse[i][j] * cov[j] for j in range(3)) / det for i in range(3)], dim=2)
