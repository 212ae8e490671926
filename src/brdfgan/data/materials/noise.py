"""Vectorised, tileable noise primitives in torch (no per-pixel Python loops).

Every field covers the unit square ``[0, 1)²`` sampled at ``size × size`` texel centres and is
periodic over it (lattices wrap), so materials tile and crops/rotations never hit a seam. Lattice
sizes are in cells per side. All randomness comes from the ``torch.Generator`` passed in.
Fields are ``(size, size)`` float32 tensors, row 0 at the top.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor


def texel_coordinates(size: int) -> tuple[Tensor, Tensor]:
    """``(u, v)`` texel-centre coordinates in [0, 1), u along columns, v along rows.

    Shape: each ``(size, size)``.
    """
    c = (torch.arange(size, dtype=torch.float32) + 0.5) / size
    return c.view(1, size).expand(size, size), c.view(size, 1).expand(size, size)


def _quintic(t: Tensor) -> Tensor:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _axis(size: int, cells: int) -> tuple[Tensor, Tensor, Tensor]:
    """Lattice cell index (wrapped to ``[0, cells)``), next index and fractional position of
    every texel centre along one axis.

    A lattice is separable: a texel's column index depends only on its column and its row index
    only on its row, so computing them on 1-D vectors (not full ``(size, size)`` grids) and
    broadcasting costs a ``size``-th of the integer work.
    Shape: each ``(size,)``.
    """
    x = (torch.arange(size, dtype=torch.float32) + 0.5) / size * cells
    floor = x.floor()
    index = floor.long() % cells
    return index, (index + 1) % cells, x - floor


def lookup(table: Tensor, index: Tensor) -> Tensor:
    """``table.flatten()[index]`` by ``index_select``, several times faster on CPU than advanced
    indexing for a per-texel lookup in a small table (lattice values, per-cell attributes).

    Shape: table any (read flattened), index any → index's shape.
    """
    return table.flatten().index_select(0, index.flatten()).view(index.shape)


def _cell_index(rows: Tensor, columns: Tensor, cells: int) -> Tensor:
    """Flat lattice index ``row·cells + column`` of every texel from 1-D row and column indices.

    Shape: rows ``(H,)``, columns ``(W,)`` → ``(H, W)``.
    """
    return rows.view(-1, 1) * cells + columns.view(1, -1)


def value_noise(size: int, cells: int, generator: torch.Generator) -> Tensor:
    """Smoothly interpolated random lattice values in [0, 1], periodic. Shape: ``(size, size)``."""
    lattice = torch.rand((cells, cells), generator=generator)
    i0, i1, fu = _axis(size, cells)
    j0, j1, fv = _axis(size, cells)
    su, sv = _quintic(fu).view(1, size), _quintic(fv).view(size, 1)
    top = torch.lerp(
        lookup(lattice, _cell_index(j0, i0, cells)), lookup(lattice, _cell_index(j0, i1, cells)), su
    )
    bottom = torch.lerp(
        lookup(lattice, _cell_index(j1, i0, cells)), lookup(lattice, _cell_index(j1, i1, cells)), su
    )
    return torch.lerp(top, bottom, sv)


def gradient_noise(size: int, cells: int, generator: torch.Generator) -> Tensor:
    """Perlin gradient noise, periodic, roughly in [-1, 1] (mean 0). Shape: ``(size, size)``."""
    angle = 2.0 * math.pi * torch.rand((cells, cells), generator=generator)
    gx, gy = torch.cos(angle), torch.sin(angle)
    i0, i1, fu_axis = _axis(size, cells)
    j0, j1, fv_axis = _axis(size, cells)
    fu, fv = fu_axis.view(1, size), fv_axis.view(size, 1)

    def corner(j: Tensor, i: Tensor, du: Tensor, dv: Tensor) -> Tensor:
        index = _cell_index(j, i, cells)
        return lookup(gx, index) * du + lookup(gy, index) * dv

    su, sv = _quintic(fu), _quintic(fv)
    top = torch.lerp(corner(j0, i0, fu, fv), corner(j0, i1, fu - 1, fv), su)
    bottom = torch.lerp(corner(j1, i0, fu, fv - 1), corner(j1, i1, fu - 1, fv - 1), su)
    return torch.lerp(top, bottom, sv) * math.sqrt(2.0)


def fbm(
    size: int,
    cells: int,
    generator: torch.Generator,
    octaves: int = 5,
    persistence: float = 0.5,
    lacunarity: int = 2,
) -> Tensor:
    """Fractal sum of gradient noise, normalised to roughly [-1, 1]. Shape: ``(size, size)``.

    ``lacunarity`` is an integer so every octave stays periodic on the unit square.
    """
    total = torch.zeros((size, size))
    amplitude, norm, frequency = 1.0, 0.0, cells
    for _ in range(octaves):
        if frequency > size:
            break  # finer than a texel: only aliasing would be added
        total += amplitude * gradient_noise(size, frequency, generator)
        norm += amplitude
        amplitude *= persistence
        frequency *= lacunarity
    return total / max(norm, 1e-8)


def wrapped_upsample(field: Tensor, factor: int) -> Tensor:
    """Bilinear upsampling of a periodic field by an integer factor, wrapping at the borders
    (texel centres stay texel centres: output texel k samples input coordinate (k + ½)/factor − ½).

    Shape: ``(n, n)`` → ``(n·factor, n·factor)``.
    """
    if factor == 1:
        return field
    padded = F.pad(field[None, None], (1, 1, 1, 1), mode="circular")
    upsampled = F.interpolate(padded, scale_factor=factor, mode="bilinear", align_corners=False)[0, 0]
    n = field.shape[-1] * factor
    return upsampled[factor : factor + n, factor : factor + n]


def _coarse_size(size: int, finest_cells: int, texels_per_cell: int) -> int:
    """The smallest halving of ``size`` that keeps ``texels_per_cell`` texels per finest cell."""
    coarse = size
    while coarse % 2 == 0 and coarse // 2 >= texels_per_cell * finest_cells:
        coarse //= 2
    return coarse


def smooth_fbm(
    size: int, cells: int, generator: torch.Generator, octaves: int, texels_per_cell: int
) -> Tensor:
    """:func:`fbm` of a smooth, low-frequency field, evaluated at a lower resolution that keeps
    ``texels_per_cell`` texels per finest cell and upsampled.

    fbm's lattices do not depend on the resolution, so this is the same field up to the
    bilinear interpolation, at a fraction of the cost (full-resolution noise of a few cells per
    image dominated the painting time of the families that use it).
    Shape: ``(size, size)``.
    """
    coarse = _coarse_size(size, cells * 2 ** (octaves - 1), texels_per_cell)
    return wrapped_upsample(fbm(coarse, cells, generator, octaves=octaves), size // coarse)


def stretched_value_noise(size: int, cells_u: int, cells_v: int, generator: torch.Generator) -> Tensor:
    """Periodic value noise on a ``cells_v × cells_u`` lattice (anisotropic cells) in [0, 1].

    With ``cells_u ≪ cells_v`` the features are long streaks along the rows, like brushing marks.
    Shape: ``(size, size)``.
    """
    lattice = torch.rand((cells_v, cells_u), generator=generator)
    c = (torch.arange(size, dtype=torch.float32) + 0.5) / size

    def axis(cells: int) -> tuple[Tensor, Tensor, Tensor]:
        x = c * cells
        i0 = x.floor()
        f = x - i0
        smooth = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
        return i0.long() % cells, (i0.long() + 1) % cells, smooth

    i0, i1, su = axis(cells_u)
    j0, j1, sv = axis(cells_v)
    top = torch.lerp(lattice[j0][:, i0], lattice[j0][:, i1], su.view(1, -1))
    bottom = torch.lerp(lattice[j1][:, i0], lattice[j1][:, i1], su.view(1, -1))
    return torch.lerp(top, bottom, sv.view(-1, 1))


def worley(
    size: int, cells: int, generator: torch.Generator, jitter: float = 1.0
) -> tuple[Tensor, Tensor, Tensor]:
    """Periodic cellular (Worley) noise with one jittered feature point per lattice cell.

    Returns:
        ``(f1, f2, cell_id)``: distances (in cell units) to the nearest and second-nearest
        feature points, and the integer id (``j·cells + i``) of the nearest point's cell — use it
        to give every cell (stone, tile, pebble) its own random attributes.

    Shape: each ``(size, size)``.
    """
    points = 0.5 + jitter * (torch.rand((cells, cells, 2), generator=generator) - 0.5)
    point_u, point_v = points[..., 0], points[..., 1]
    x = (torch.arange(size, dtype=torch.float32) + 0.5) / size * cells
    floor = x.floor()
    base = floor.long()
    fu, fv = (x - floor).view(1, size), (x - floor).view(size, 1)
    # Running nearest/second-nearest over the 3×3 neighbourhood: no (9, size, size) stack and
    # no sort, which at 2048² dominated the families that use cells.
    f1 = torch.full((size, size), float("inf"))
    f2 = torch.full((size, size), float("inf"))
    cell_id = torch.zeros((size, size), dtype=torch.long)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            index = _cell_index((base + dj) % cells, (base + di) % cells, cells)
            du = di + lookup(point_u, index) - fu
            dv = dj + lookup(point_v, index) - fv
            d = torch.sqrt(du * du + dv * dv)
            nearer = d < f1
            f2 = torch.where(nearer, f1, torch.minimum(f2, d))
            f1 = torch.where(nearer, d, f1)
            cell_id = torch.where(nearer, index, cell_id)
    return f1, f2, cell_id


def random_per_cell(cell_id: Tensor, count: int, generator: torch.Generator, channels: int = 1) -> Tensor:
    """A random value in [0, 1) per cell id, looked up per texel.

    Shape:
        - cell_id: ``(H, W)`` integers in ``[0, count)``
        - output: ``(channels, H, W)``
    """
    table = torch.rand((count, channels), generator=generator)
    # One index_select per channel row of the transposed table: contiguous output, and several
    # times faster than advanced indexing with a full-size id grid.
    return table.t().contiguous().index_select(1, cell_id.flatten()).view(channels, *cell_id.shape)


def lerp_color(a: tuple[float, float, float], b: tuple[float, float, float], t: Tensor) -> Tensor:
    """Per-texel blend of two sRGB colours. Shape: t ``(1, H, W)`` or ``(H, W)`` → ``(3, H, W)``."""
    t = t if t.ndim == 3 else t[None]
    ca = torch.tensor(a, dtype=t.dtype).view(3, 1, 1)
    cb = torch.tensor(b, dtype=t.dtype).view(3, 1, 1)
    return ca + (cb - ca) * t


def hsv_to_rgb(h: Tensor, s: Tensor, v: Tensor) -> Tensor:
    """Per-texel HSV → RGB (hue in turns, all in [0, 1]); materials pick colours in HSV because
    hue, saturation and brightness are what their parameters vary independently.

    Shape: each ``(H, W)`` → ``(3, H, W)``.
    """
    channels = []
    for n in (5.0, 3.0, 1.0):
        k = (n + h * 6.0) % 6.0
        channels.append(v - v * s * torch.minimum(k, 4.0 - k).clamp(0.0, 1.0))
    return torch.stack(channels)
