"""Tileable maps (``brdfgan predict --tileable``): a map set that wraps without a seam, made from its
own content.

The map set ``M`` is blended with its copies rolled horizontally (``Rx``), vertically (``Ry``) and
both (``Rxy``), each by about half a side: exactly, so that the line where the maps change least
(:func:`quiet_cut`, searched in the middle half) becomes the tile's edge — a grout line or a
plank's edge is then not cut through, and the wrap looks like the photo's quietest step. Each
copy's discontinuities lie on known lines — ``M``'s on the borders, ``Rx``'s on the centre column
and the top/bottom borders, ``Ry``'s on the centre row and the left/right borders, ``Rxy``'s on the
centre cross — and each copy's weight is zero on its own lines::

    w(M) = wx·wy,  w(Rx) = (1 − wx)·wy,  w(Ry) = wx·(1 − wy),  w(Rxy) = (1 − wx)·(1 − wy)

with ``wx`` rising as ``sin²`` from 0 at the left/right borders to 1 where ``Rx``'s own seam lies
(the centre column for a half roll) and ``wy`` likewise. At the left/right borders ``wx ≈ 0``: only
``Rx`` and ``Rxy`` carry weight, both continuous across that wrap, so the result wraps like an
interior column of the photo does (the top/bottom borders likewise with ``Ry`` and ``Rxy``). Plain
averaging of unrelated content washes it out (half the contrast where four copies meet), so the
blend is **variance-preserving** (Burley 2019; Heitz & Neyret 2018): ``μ + Σ wᵢ (Lᵢ − μ) / √(Σ
wᵢ²)`` with ``μ`` the map's mean, then clipped to the valid range (normals renormalised). The same
weights apply to every map, so base colour, normal, roughness and metallic stay aligned.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from brdfgan.core.svbrdf import join_maps, normalize_normal, split_maps

# Channels of each map in a map set: base colour, normal, roughness, metallic.
MAP_GROUPS = (3, 3, 1, 1)


def _window(length: int, peak: int, like: Tensor) -> Tensor:
    """A weight along one axis: ~0 at both ends (the wrap), rising as ``sin²`` to 1 between
    samples ``peak - 1`` and ``peak`` and falling back. Shape: ``(length,)``."""
    index = torch.arange(length, dtype=like.dtype, device=like.device) + 0.5
    rise = torch.sin(0.5 * math.pi * index / peak) ** 2
    fall = torch.sin(0.5 * math.pi * (length - index) / (length - peak)) ** 2
    return torch.where(index < peak, rise, fall)


def quiet_cut(image: Tensor, dim: int, groups: tuple[int, ...] | None = None) -> int:
    """Where along ``dim`` (-1: columns, -2: rows) the image changes least from one line to the
    next, searched in the middle half: the index ``c`` of the line after the quietest step
    ``c − 1 → c``. That step becomes the tile's wrap, so a grout line or an edge is not cut
    through. A step counts relative to the mean step of its channel group (``groups``: channels
    per group, e.g. base colour 3, normal 3, roughness 1, metallic 1; default: each channel), and
    the worst group decides — the cut must suit every map.

    Shape: ``(C, H, W)`` → an index.
    """
    length = image.shape[dim]
    steps = torch.diff(image, dim=dim).abs()  # (C, H, W - 1) for columns
    other = -2 if dim == -1 else -1
    per_line = steps.mean(dim=other)  # (C, length - 1): step i is between lines i and i + 1
    per_group = torch.stack(
        [part.mean(dim=0) for part in per_line.split(list(groups or [1] * len(per_line)))]
    )
    relative = (per_group / per_group.mean(dim=-1, keepdim=True).clamp_min(1e-12)).amax(dim=0)
    low, high = length // 4, (3 * length) // 4
    return int(low + torch.argmin(relative[low - 1 : high - 1])) if high > low else length // 2


def seamless_blend(image: Tensor, cuts: tuple[int, int] | None = None) -> Tensor:
    """The variance-preserving blend of ``image`` with its copies rolled so that line ``cut`` of
    each axis comes first (module docstring; default: the middle), unclipped.

    Shape: ``(C, H, W)`` → ``(C, H, W)``.
    """
    height, width = image.shape[-2:]
    cut_y, cut_x = cuts if cuts is not None else (height // 2, width // 2)
    # A rolled copy's own seam (the image's wrap) lands before line (side − cut): its weight is 0 there.
    wx = _window(width, width - cut_x, image).view(1, 1, width)
    wy = _window(height, height - cut_y, image).view(1, height, 1)
    rolled_x = torch.roll(image, -cut_x, dims=-1)
    rolled_y = torch.roll(image, -cut_y, dims=-2)
    layers = (image, rolled_x, rolled_y, torch.roll(rolled_x, -cut_y, dims=-2))
    weights = (wx * wy, (1 - wx) * wy, wx * (1 - wy), (1 - wx) * (1 - wy))
    mean = image.mean(dim=(-2, -1), keepdim=True)
    blended = sum(
        (w * (layer - mean) for w, layer in zip(weights, layers, strict=True)), torch.zeros_like(image)
    )
    norm = torch.sqrt(sum((w**2 for w in weights), torch.zeros_like(wx)))
    return mean + blended / norm


def make_seamless(maps: Tensor) -> Tensor:
    """The map set made tileable: :func:`seamless_blend` of every map with the same weights,
    clipped to ``[0, 1]``, normals renormalised (and kept facing out).

    Shape: ``(8, H, W)`` → ``(8, H, W)``.
    """
    # One pair of cuts for all maps (the same weights keep them aligned), where they change least.
    cuts = (quiet_cut(maps, -2, MAP_GROUPS), quiet_cut(maps, -1, MAP_GROUPS))
    blended = seamless_blend(maps, cuts)
    parts = split_maps(blended)
    normal = parts.normal.clone()
    normal[2:3] = normal[2:3].clamp_min(0.05)
    return join_maps(
        parts.basecolor.clamp(0.0, 1.0),
        normalize_normal(normal),
        parts.roughness.clamp(0.0, 1.0),
        parts.metallic.clamp(0.0, 1.0),
    )


def wrap_ratios(image: Tensor) -> tuple[float, float]:
    """How visible the seams are when ``image`` is tiled: the mean absolute difference between
    the last and the first column over the mean absolute difference between neighbouring columns
    inside the image; the same for rows. About 1 for a tileable image, well above 1 for a photo.

    Shape: ``(C, H, W)`` → ``(columns, rows)``.
    """
    inner_cols = (image[..., :, 1:] - image[..., :, :-1]).abs().mean()
    inner_rows = (image[..., 1:, :] - image[..., :-1, :]).abs().mean()
    wrap_cols = (image[..., :, 0] - image[..., :, -1]).abs().mean()
    wrap_rows = (image[..., 0, :] - image[..., -1, :]).abs().mean()
    return float(wrap_cols / inner_cols.clamp_min(1e-12)), float(wrap_rows / inner_rows.clamp_min(1e-12))
