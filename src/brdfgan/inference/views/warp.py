"""A view photo resampled into the reference's texture frame, with the texels it actually shows.

The registration gives a homography from the reference texture's pixels to the view's pixels
(both in the project's convention, pixel j's centre at j + ½, :mod:`brdfgan.core.homography`);
each texel centre is sampled there bilinearly (``grid_sample``). A view much finer than the
texture is first area-averaged by an integer factor, so that a texel averages the photo pixels
under it instead of picking one (an oblique or close view would alias otherwise). Values stay
linear and unscaled: the exposure is each view's gain in the fit (:mod:`brdfgan.inference.views.fit`).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.homography import apply_homography

# The view is pre-shrunk when a texel spans at least this many view pixels (linear scale).
PRE_SHRINK_FROM = 2.0
# Texels this close to the edge of the view's footprint are not counted as seen: bilinear samples
# there mix in pixels past the photo's edge, and a registration error of a pixel or two moves it.
SEEN_EROSION_PX = 2


def local_scale(homography: np.ndarray, point: np.ndarray) -> float:
    """View pixels per texture pixel (linear, the square root of the area scale) of a homography
    at a point of its source.

    Shape:
        - homography: ``(3, 3)``; point: ``(2,)``
    """
    h = np.asarray(homography, dtype=np.float64)
    w = float(h[2] @ np.append(point, 1.0))
    mapped = apply_homography(h, np.asarray(point, dtype=np.float64)[None])[0]
    # The Jacobian of p ↦ (H p)_xy / w is (H[:2, :2] − mapped ⊗ H[2, :2]) / w.
    jacobian = (h[:2, :2] - np.outer(mapped, h[2, :2])) / w
    return math.sqrt(abs(float(np.linalg.det(jacobian))))


def warp_to_reference(linear: Tensor, view_from_reference: np.ndarray, side: int) -> tuple[Tensor, Tensor]:
    """The view resampled at every texel of the ``side × side`` reference texture, and where it
    shows the texel: inside the photo and in front of its camera, eroded by
    :data:`SEEN_EROSION_PX` texels (the texture's own border is not eroded).

    Args:
        linear: the view photo, linear RGB as read (any scale).
        view_from_reference: reference texture pixels → view pixels (project convention).
        side: the reference texture's side in pixels.

    Shape:
        - linear: ``(3, H, W)``; view_from_reference: ``(3, 3)``
        - output: image ``(3, side, side)`` (0 where unseen), seen ``(1, side, side)`` float 0/1
    """
    check_shape(linear, "3 H W", name="view photo")
    if side < 1:
        raise ValueError(f"side must be positive, got {side}")
    homography = np.asarray(view_from_reference, dtype=np.float64)
    height, width = linear.shape[-2:]
    centre = np.array([side / 2.0, side / 2.0])
    if float(homography[2] @ np.append(centre, 1.0)) < 0:  # the overall sign is arbitrary
        homography = -homography
    scale = local_scale(homography, centre)
    factor = int(scale) if scale >= PRE_SHRINK_FROM else 1
    image = linear.float()
    if factor > 1 and min(height, width) >= factor:
        # Pixel j' of the pooled image spans view pixels [j'k, (j'+1)k]: x' = x / k.
        image = F.avg_pool2d(image[None], factor)[0]
    else:
        factor = 1
    shrunk_height, shrunk_width = image.shape[-2:]

    texel = np.arange(side, dtype=np.float64) + 0.5
    xs, ys = np.meshgrid(texel, texel)
    points = np.stack([xs.ravel(), ys.ravel(), np.ones(side * side)], axis=1) @ homography.T
    w = points[:, 2]
    in_front = w > 0
    safe_w = np.where(in_front, w, 1.0)
    x = points[:, 0] / safe_w / factor
    y = points[:, 1] / safe_w / factor
    inside = in_front & (x >= 0) & (x <= shrunk_width) & (y >= 0) & (y <= shrunk_height)
    # grid_sample's (-1, 1) are the outer pixel edges with align_corners=False.
    grid = np.stack([np.where(inside, 2.0 * x / shrunk_width - 1.0, -2.0),
                     np.where(inside, 2.0 * y / shrunk_height - 1.0, -2.0)], axis=-1)  # fmt: skip
    grid_tensor = torch.from_numpy(grid.reshape(1, side, side, 2)).to(image)
    sampled = F.grid_sample(
        image[None], grid_tensor, mode="bilinear", padding_mode="border", align_corners=False
    )
    seen = torch.from_numpy(inside.reshape(1, 1, side, side)).to(image)
    if SEEN_EROSION_PX > 0:
        # Erosion as a max-pool of the unseen texels; max_pool2d pads with −inf, so the texture's
        # own border counts as seen.
        kernel = 2 * SEEN_EROSION_PX + 1
        seen = 1.0 - F.max_pool2d(1.0 - seen, kernel, stride=1, padding=SEEN_EROSION_PX)
    return (sampled * seen)[0].to(linear.dtype), seen[0]
