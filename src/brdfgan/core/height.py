"""Height and ambient occlusion from a normal map (the artist's ``height.png`` and ``ao.png``).

Conventions (those of :func:`brdfgan.data.materials.base.height_to_normal`, the generator of the
training data): tangent-space unit normals ``n ∝ (−∂h/∂x, −∂h/∂y, 1)`` with +x along the columns
and +y *up the rows* (OpenGL). Heights are in **units of the sample side**: a map ``W`` pixels wide
spans 1, one pixel is ``1 / W``.

- :func:`height_from_normals`: the least-squares height of the normals' slopes, integrated in the
  Fourier domain (Frankot & Chellappa 1988). Periodic maps are integrated as they are; others are
  mirrored first (the even extension makes any slope field periodic without a seam), so borders
  do not bend.
- :func:`ambient_occlusion`: for every pixel and a few azimuths, the highest horizon the height
  field raises within a radius; the cosine-weighted visible part of the hemisphere is
  ``mean over azimuths of cos²(horizon elevation)`` (1: flat, open; towards 0 in a deep pit).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape

# Azimuths and distances (pixels, roughly geometric) the horizon search looks along by default.
AO_DIRECTIONS = 8
AO_RADIUS_FRACTION = 1.0 / 16.0  # of the sample side


# slope_field clamps n_z to at least this before taking slopes (tilts up to 87°, a slope of 20):
# grazing normals stay finite.
SLOPE_Z_MIN = 0.05


def slope_field(normal: Tensor) -> Tensor:
    """The surface slopes ``(s_x, s_y) = (−n_x/n_z, −n_y/n_z)``: height gained per unit of
    distance along +x and +y (+y up the rows), the slopes the normals of :func:`height_slope_channels`
    are made of, n_z clamped at :data:`SLOPE_Z_MIN`. Same dtype as ``normal``.

    Shape:
        - normal: ``(*, 3, H, W)``
        - output: ``(*, 2, H, W)``

    Example:
        >>> slope_field(torch.tensor([0.6, 0.0, 0.8]).view(3, 1, 1)).flatten().tolist()
        [-0.75, -0.0]
    """
    check_shape(normal, "* 3 H W", name="normal")
    z = normal[..., 2:3, :, :].clamp_min(SLOPE_Z_MIN)
    return -normal[..., :2, :, :] / z


def height_slope_channels(height: Tensor, *, periodic: bool = False) -> Tensor:
    """The slope channels ``(−∂h/∂x, −∂h/∂y)`` of a height field by central differences, borders
    replicated (a crop does not tile) or, ``periodic``, wrapped (a tileable height gives tileable
    slopes): ``normalize(s_x, s_y, 1)`` is its normal map, the
    convention of :func:`~brdfgan.data.materials.base.height_to_normal` (+y up the rows). A
    network that predicts a height and takes its normals from it gives integrable (curl-free)
    slopes, as a real surface's are.

    Shape:
        - height: ``(B, 1, H, W)`` in pixel units
        - output: ``(B, 2, H, W)``

    Example:
        A ramp rising along +x by 2 per pixel, and one rising up the rows by 2 per pixel:

        >>> ramp = torch.arange(4.0).mul(2).view(1, 1, 1, 4).expand(1, 1, 4, 4)
        >>> height_slope_channels(ramp)[0, :, 1, 1].add(0.0).tolist()  # + 0.0: no negative zero
        [-2.0, 0.0]
        >>> height_slope_channels(ramp.transpose(-1, -2).flip(-2))[0, :, 1, 1].add(0.0).tolist()
        [0.0, -2.0]
    """
    check_shape(height, "B 1 H W", name="height")
    padded = F.pad(height, (1, 1, 1, 1), mode="circular" if periodic else "replicate")
    dh_dx = (padded[..., 1:-1, 2:] - padded[..., 1:-1, :-2]) / 2.0
    dh_dy = (padded[..., :-2, 1:-1] - padded[..., 2:, 1:-1]) / 2.0  # row − 1 is +Y
    return torch.cat([-dh_dx, -dh_dy], dim=1)


def height_from_normals(normal: Tensor, *, periodic: bool = False) -> Tensor:
    """The height field whose normals are ``normal``, up to a constant (returned with mean 0).

    Shape: ``(..., 3, H, W)`` unit normals → ``(..., H, W)`` heights in sample-side units
    (the width is the side).

    Example:
        Waves ``h = 0.01 sin 2πx`` across and ``0.01 cos 2πy`` up a periodic 16 × 16 sample, their
        normals ``∝ (−∂h/∂x, −∂h/∂y, 1)`` (+y up the rows), integrate back to the heights:

        >>> t = (torch.arange(16, dtype=torch.float64) + 0.5) / 16  # texel centres, in sample sides
        >>> x, y = t.view(1, 16), (1 - t).view(16, 1)  # +x along the columns, +y up the rows
        >>> h = 0.01 * (torch.sin(2 * math.pi * x) + torch.cos(2 * math.pi * y))
        >>> dh_dx = (0.02 * math.pi * torch.cos(2 * math.pi * x)).expand(16, 16)
        >>> dh_dy = (-0.02 * math.pi * torch.sin(2 * math.pi * y)).expand(16, 16)
        >>> normal = torch.stack([-dh_dx, -dh_dy, torch.ones(16, 16, dtype=torch.float64)])
        >>> normal = normal / normal.norm(dim=0)
        >>> torch.allclose(height_from_normals(normal, periodic=True), h, atol=1e-9)
        True
    """
    check_shape(normal, "* 3 H W", name="normals")
    height, width = normal.shape[-2:]
    dh_dx, dh_dy = slope_field(normal.to(torch.float64)).unbind(-3)
    dh_drow = -dh_dy  # +y is up the rows: rows go down
    # A sample is a flat surface: a mean slope is a bias of the normals (a periodic field cannot
    # hold one anyway), and integrated it would become a ramp that swamps the relief.
    dh_dx = dh_dx - dh_dx.mean(dim=(-2, -1), keepdim=True)
    dh_drow = dh_drow - dh_drow.mean(dim=(-2, -1), keepdim=True)
    if not periodic:
        # Even extension of the height: x-slopes flip sign in the mirrored columns, row-slopes in
        # the mirrored rows.
        dh_dx = torch.cat([dh_dx, -dh_dx.flip(-1)], dim=-1)
        dh_dx = torch.cat([dh_dx, dh_dx.flip(-2)], dim=-2)
        dh_drow = torch.cat([dh_drow, dh_drow.flip(-1)], dim=-1)
        dh_drow = torch.cat([dh_drow, -dh_drow.flip(-2)], dim=-2)
    rows, cols = dh_dx.shape[-2:]
    # Real fields: the half spectrum (rfft2) holds everything, at half the work of the full one.
    wx = 2.0 * math.pi * torch.fft.rfftfreq(cols, dtype=torch.float64).view(1, cols // 2 + 1)
    wy = 2.0 * math.pi * torch.fft.fftfreq(rows, dtype=torch.float64).view(rows, 1)
    denominator = wx**2 + wy**2
    denominator[0, 0] = 1.0  # the mean is free: set to 0 below
    # A derivative at an axis's Nyquist frequency has no real-valued answer (its sign flips with
    # the bin's): that term is dropped, as taking the real part of the full inverse FFT does.
    wx_derivative, wy_derivative = wx.clone(), wy.clone()
    if cols % 2 == 0:
        wx_derivative[0, -1] = 0.0
    if rows % 2 == 0:
        wy_derivative[rows // 2, 0] = 0.0
    spectrum = (
        -1j * wx_derivative * torch.fft.rfft2(dh_dx) - 1j * wy_derivative * torch.fft.rfft2(dh_drow)
    ) / denominator
    spectrum[..., 0, 0] = 0.0
    heights = torch.fft.irfft2(spectrum, s=(rows, cols))[..., :height, :width]
    heights = heights - heights.mean(dim=(-2, -1), keepdim=True)
    return (heights / width).to(normal.dtype)  # pixels → sample sides


def ambient_occlusion(
    height: Tensor,
    *,
    periodic: bool = False,
    directions: int = AO_DIRECTIONS,
    radius: float = AO_RADIUS_FRACTION,
) -> Tensor:
    """Horizon-based ambient occlusion of a height field: per pixel the mean over ``directions``
    azimuths of ``cos²`` of the highest horizon elevation within ``radius`` (sample sides).

    Shape: ``(..., H, W)`` heights in sample-side units → ``(..., H, W)`` in ``[0, 1]``.

    Example:
        A flat field sees the whole sky; the bottom of a pit a quarter of the side wide sees
        less of it than the ground around the pit, within a horizon radius of a quarter side:

        >>> ambient_occlusion(torch.zeros(8, 8)).unique().tolist()
        [1.0]
        >>> pit = torch.zeros(16, 16)
        >>> pit[6:10, 6:10] = -0.05
        >>> ao = ambient_occlusion(pit, radius=0.25)
        >>> bool(ao[8, 8] < 1.0), ao[0, 0].item()
        (True, 1.0)
    """
    if directions < 1 or radius <= 0:
        raise ValueError(f"need directions >= 1 and radius > 0, got {directions} and {radius}")
    size = height.shape[-1]
    pixels = max(1, round(radius * size))
    distances = sorted({max(1, round(pixels ** (k / 7))) for k in range(8)} | {pixels})
    field = height.reshape(-1, 1, *height.shape[-2:]).to(torch.float32)
    mode = "circular" if periodic else "replicate"
    padded = F.pad(field, (pixels, pixels, pixels, pixels), mode=mode)
    rows, cols = field.shape[-2:]
    visible = torch.zeros_like(field)
    # In-place into two buffers: at 2048² the allocations cost as much as the arithmetic.
    tangent, rise = torch.empty_like(field), torch.empty_like(field)
    for index in range(directions):
        angle = 2.0 * math.pi * index / directions
        tangent.zero_()
        for distance in distances:
            dx, dy = round(distance * math.cos(angle)), round(distance * math.sin(angle))
            if dx == 0 and dy == 0:
                continue
            shifted = padded[..., pixels + dy : pixels + dy + rows, pixels + dx : pixels + dx + cols]
            run = math.hypot(dx, dy) / size  # in sample sides, like the heights
            torch.sub(shifted, field, out=rise).div_(run)
            torch.maximum(tangent, rise, out=tangent)
        visible.add_(tangent.square_().add_(1.0).reciprocal_())  # cos² of the elevation atan(tangent)
    return (visible / directions).reshape(height.shape).to(height.dtype)
