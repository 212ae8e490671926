"""Where each pixel lies relative to the flash: the input channels a flash-aware network reads.

Why a network needs this. Under the flash, a surface tilted by ``t = (n_x, n_y)`` brightens or
darkens to first order by ``t · l_xy / l_z``, where ``l`` is the direction towards the flash: the
sign of the shading caused by a bump depends on which side of the flash it lies. A fully
convolutional network with reflection padding sees only a window of the photo and cannot tell
where that window is (training uses random crops, inference tiles), so a bump lit from the left
and a dent lit from the right look alike to it: the conditional mean of the tilt is ~0 and the
predicted normals come out flat. Handing it ``-l_xy / l_z`` per pixel resolves that sign
(CoordConv, Liu et al. 2018, with the coordinates made physical).

The **flash frame** of a photo is three numbers per photo, ``(x, y, s)``:

- ``(x, y)``: the flash hotspot in the photo's continuous pixel coordinates (``x`` along columns
  from the left edge, ``y`` along rows from the top; pixel ``(i, j)`` spans ``[j, j+1) × [i, i+1)``,
  the convention of :func:`brdfgan.metrics.hotspot_centres`). For a flash at the lens the hotspot
  is the foot of the perpendicular from the flash to the surface, the point the flash faces.
- ``s``: the tangent of the viewing angle per pixel, ``2 tan(fov/2) / photo_width`` for the
  horizontal field of view ``fov`` across the whole photo.

:func:`flash_offset_channels` turns a frame into two channels, the offset of each pixel centre
from the hotspot in units of the camera distance: ``((j + ½ − x) s, −(i + ½ − y) s)`` — +X right,
+Y up like the normals (docs/conventions.md#maps-and-encodings). For a camera parallel to the
surface with the flash at the lens this is exactly ``(p − f)_xy / f_z = −l_xy / l_z``.

A frame follows the image through crops (:func:`crop_flash_frame`: the hotspot moves, ``s``
stays) and resizes (:func:`resize_flash_frame`: both scale), so a tile, a padded photo or a
downscaled photo keeps the geometry of the whole.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from brdfgan.core.checks import check_shape

# The horizontal field of view a photo is assumed to have when nothing says otherwise: the centre
# of the v3 training captures' 40–75° (conf/dataset_spec/procedural.yaml, capture.fov_*), after
# the preprocessing's centre crop. Photos without EXIF focal length get it.
DEFAULT_FOV_DEG = 57.5
FLASH_FRAME_SIZE = 3
FLASH_CHANNELS = 4  # flash_side_channels: the offsets split by sign


def check_flash_frame(frame: Tensor, batch: int | None = None) -> None:
    """Raise ``ValueError`` unless ``frame`` is a finite ``(B, 3)`` floating tensor with ``s > 0``."""
    if not isinstance(frame, Tensor):
        name = type(frame).__name__
        raise ValueError(f"a flash frame must be a (B, {FLASH_FRAME_SIZE}) tensor (x, y, s), got {name}")
    check_shape(frame, f"B {FLASH_FRAME_SIZE}", name="a flash frame (x, y, s)")
    if batch is not None and frame.shape[0] != batch:
        raise ValueError(f"flash frame for {frame.shape[0]} photos, but the batch holds {batch}")
    if not frame.is_floating_point() or not torch.isfinite(frame).all() or (frame[:, 2] <= 0).any():
        raise ValueError("a flash frame must hold finite floats with a positive scale s")


def pixel_scale(fov_deg: float, photo_width: float) -> float:
    """``s`` of a photo ``photo_width`` pixels wide with horizontal field of view ``fov_deg``.

    Example:
        ``2 tan(fov/2) / W``: a 90° photo 2 pixels wide spans one camera distance per pixel:

        >>> round(pixel_scale(90.0, 2), 4), round(pixel_scale(90.0, 512), 6)
        (1.0, 0.003906)
    """
    if not 0.0 < fov_deg < 180.0 or not photo_width > 0:
        raise ValueError(f"need 0 < fov_deg < 180 and photo_width > 0, got {fov_deg=}, {photo_width=}")
    return 2.0 * math.tan(math.radians(fov_deg) / 2.0) / photo_width


def field_of_view(scale: float, photo_width: float) -> float:
    """The horizontal field of view in degrees of a photo ``photo_width`` pixels wide whose frame has
    scale ``s``: the inverse of :func:`pixel_scale`.

    Example:
        >>> round(field_of_view(pixel_scale(57.5, 640), 640), 6)
        57.5
        >>> round(field_of_view(1.0, 2), 4)
        90.0
    """
    if not scale > 0 or not photo_width > 0:
        raise ValueError(f"need scale > 0 and photo_width > 0, got {scale=}, {photo_width=}")
    return math.degrees(2.0 * math.atan(scale * photo_width / 2.0))


def hotspot_position(frame: Tensor, height: int, width: int, plane_half_size: float = 1.0) -> Tensor:
    """Where the hotspot of each frame lies on the sample square the photo shows (world x, y; the
    square's centre at 0, +Y at row 0): the point below the camera and flash when the photo is
    a crop whose hotspot is off its centre (``render_flash(..., camera_xy=)``).

    Shape:
        - frame: ``(B, 3)``
        - output: ``(B, 2)``
    """
    check_flash_frame(frame)
    x = plane_half_size * (2.0 * frame[:, 0] / width - 1.0)
    y = plane_half_size * (1.0 - 2.0 * frame[:, 1] / height)
    return torch.stack([x, y], dim=1)


def centred_flash_frame(
    batch: int,
    height: int,
    width: int,
    fov_deg: float = DEFAULT_FOV_DEG,
    *,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
) -> Tensor:
    """The frame of photos whose hotspot is their centre (what ``brdfgan predict``'s hotspot crop
    produces) with field of view ``fov_deg`` across their width.

    Shape:
        - output: ``(batch, 3)``

    Example:
        The hotspot at the centre of a 4 × 6 photo, ``s = 2 tan 45° / 6 = 1/3``:

        >>> frame = centred_flash_frame(2, 4, 6, fov_deg=90.0)
        >>> tuple(frame.shape), [round(v, 4) for v in frame[0].tolist()]
        ((2, 3), [3.0, 2.0, 0.3333])
    """
    row = [width / 2.0, height / 2.0, pixel_scale(fov_deg, width)]
    return (
        torch.tensor(row, device=device, dtype=dtype or torch.float32).expand(batch, FLASH_FRAME_SIZE).clone()
    )


def crop_flash_frame(frame: Tensor, x0: float | Tensor, y0: float | Tensor) -> Tensor:
    """The frame of the window whose top-left pixel corner is ``(x0, y0)`` (a crop, a tile, or a
    negative offset for padding on the top/left).

    Shape:
        - frame: ``(B, 3)``; x0, y0: numbers or ``(B,)``
        - output: ``(B, 3)``
    """
    check_flash_frame(frame)
    shift = torch.stack(
        torch.broadcast_tensors(
            *(torch.as_tensor(v, dtype=frame.dtype, device=frame.device) for v in (x0, y0))
        ),
        -1,
    )
    return torch.cat([frame[:, :2] - shift, frame[:, 2:]], dim=1)


def resize_flash_frame(frame: Tensor, factor: float) -> Tensor:
    """The frame of the photo resized by ``factor`` (new pixels per old pixel): the hotspot's
    coordinates scale by it, the tangent per pixel by its inverse.

    Shape:
        - frame: ``(B, 3)``
        - output: ``(B, 3)``
    """
    check_flash_frame(frame)
    if not factor > 0:
        raise ValueError(f"resize factor must be positive, got {factor}")
    return torch.cat([frame[:, :2] * factor, frame[:, 2:] / factor], dim=1)


def flash_side_channels(frame: Tensor, height: int, width: int) -> Tensor:
    """:func:`flash_offset_channels` split by sign, ``(relu(o_x), relu(o_y), relu(−o_x), relu(−o_y))``:
    what a network with an InstanceNorm after its first convolution can use.

    Why split: an InstanceNorm subtracts every channel's mean over the image, and a convolution
    of the plain offsets turns a move of the hotspot into exactly such a constant, so the network
    would see where a pixel lies relative to the *crop*, never relative to the flash (measured: the
    maps of a flash-aware generator did not change by 1e-6 when the hotspot moved). Split by sign,
    a crop right of the flash has its ramp in the first channel and a crop left of it in the third:
    which channel varies says the side, and no normalisation removes that.

    Shape:
        - frame: ``(B, 3)``
        - output: ``(B, 4, height, width)``
    """
    offsets = flash_offset_channels(frame, height, width)
    return torch.cat([offsets.clamp_min(0.0), (-offsets).clamp_min(0.0)], dim=1)


def flash_offset_channels(frame: Tensor, height: int, width: int) -> Tensor:
    """Per pixel, the offset of its centre from the flash hotspot in units of the camera distance
    (module docstring): ``((j + ½ − x) s, −(i + ½ − y) s)``.

    Shape:
        - frame: ``(B, 3)`` ``(x, y, s)``
        - output: ``(B, 2, height, width)`` in the frame's dtype and device

    Example:
        With the hotspot at the centre of a 2 × 2 photo (s = 1), the top-left pixel lies half a
        camera distance left (−x) and up (+y) of it, the bottom-right one right and down:

        >>> offsets = flash_offset_channels(torch.tensor([[1.0, 1.0, 1.0]]), 2, 2)
        >>> offsets[0, :, 0, 0].tolist(), offsets[0, :, 1, 1].tolist()
        ([-0.5, 0.5], [0.5, -0.5])
    """
    check_flash_frame(frame)
    if height < 1 or width < 1:
        raise ValueError(f"need a positive size, got {height}x{width}")
    columns = torch.arange(width, device=frame.device, dtype=frame.dtype) + 0.5
    rows = torch.arange(height, device=frame.device, dtype=frame.dtype) + 0.5
    x, y, s = (frame[:, k, None, None] for k in range(FLASH_FRAME_SIZE))
    offset_x = (columns[None, None, :] - x) * s
    offset_y = (y - rows[None, :, None]) * s
    return torch.stack(torch.broadcast_tensors(offset_x, offset_y), dim=1)


def _squared_hotspot_distance(centres: Tensor, height: int, width: int) -> Tensor:
    """:func:`hotspot_distance` squared (what a disk compares: exact on its boundary)."""
    check_shape(centres, "B 2", name="hotspot centres (x, y)")
    cx = centres[:, 0].to(torch.float64).view(-1, 1, 1)
    cy = centres[:, 1].to(torch.float64).view(-1, 1, 1)
    xs = torch.arange(width, dtype=torch.float64, device=centres.device).view(1, 1, width) + 0.5
    ys = torch.arange(height, dtype=torch.float64, device=centres.device).view(1, height, 1) + 0.5
    return (xs - cx).square() + (ys - cy).square()


def hotspot_distance(centres: Tensor, height: int, width: int) -> Tensor:
    """Each pixel's distance in pixels from each sample's hotspot, in float64.

    Pixel ``(i, j)`` has its centre at ``(j + 0.5, i + 0.5)`` (the coordinates of the flash frame
    and of :func:`brdfgan.metrics.hotspot_centres`).

    Shape:
        - centres: ``(B, 2)`` ``(x, y)``
        - output: ``(B, H, W)`` float64, on ``centres``' device

    Example:
        >>> hotspot_distance(torch.tensor([[1.0, 0.5]]), 1, 3)[0].tolist()
        [[0.5, 0.5, 1.5]]
    """
    return _squared_hotspot_distance(centres, height, width).sqrt()


def hotspot_disk(centres: Tensor, height: int, width: int, radius: float) -> Tensor:
    """Pixels whose centre lies within ``radius`` pixels of each sample's hotspot
    (:func:`hotspot_distance`).

    Shape:
        - centres: ``(B, 2)`` ``(x, y)``
        - output: ``(B, H, W)`` bool, on ``centres``' device
    """
    return _squared_hotspot_distance(centres, height, width) <= radius * radius
