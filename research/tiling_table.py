"""Lattice preservation of ``--tileable`` (issue 60, item 3): on regular materials framed as a photo
frames them, how many lattice cells the tiled output keeps whole, whether it repeats with the
material's period, and today's wrap and copied-fraction measures; beside today's cut on the same
inputs.

**Inputs.** Each material's *true* maps stand in for a prediction, which isolates the tiling from
the network. The procedural families (``brdfgan.data.materials.families``) are painted at 512² with
their layout parameters fixed so that a 256² crop shows three to eight cells a side (the rest drawn
from a seeded generator); the scans (``../shared/scans``; training scans, fine for measuring) are
read at 512² (half their side). Each is framed as a phone photo frames it (:class:`Frame`,
:func:`photo_frame`): turned 0, 15, 30 or 45°, in mild perspective (the scale changes by ±2 % from
the centre to the left and right edges and ±1.5 % to the top and bottom), cropped to 256² around the
material's centre, the normals turned with the frame; and a flat 0° crop as the control.

**The truth** (:func:`true_lattice`): the lattice of the flat material, found by
:func:`~brdfgan.core.lattice.find_lattice` on it unturned and snapped onto the material's own period
where whole numbers of the vectors make it (every family tiles on its square: exact there). Groups:
*periodic families* and *periodic scans* (a 2-D lattice on the flat material), *1-D regular* (planks
and rows of setts: regular to an artist, with no 2-D lattice; ``core.stripes`` finds them, and their
truth (:func:`true_stripes`) is the flat material's stripes, the period snapped onto its side) and
*non-periodic*.

**Tilings.** ``new``: :func:`brdfgan.inference.pipeline.make_tileable` with the flash-mark repair
held off (there is no flash in true maps; where the shipped repair fires on them anyway, a second
table says so and what it costs); ``today``: :func:`brdfgan.core.seamless.make_seamless` alone.

**Measures** (per case, then per group):

- ``periodic``: the cases that took the whole-cell path (a lattice found and its cells fitting);
- ``cells whole`` (:func:`match_probes`, :func:`cells_whole`): the tile repeated 3 × 3; the true
  lattice as the tile shows it (through the tiling's resampling); the cells of that lattice through
  the sheet's centre (where four tiles meet) whose centres lie in its middle tile, one per cell of
  the periodic sheet. Each cell is *probed* at its centre, the midpoints of its edges and its
  corners: a window of the cell's own shape and size centred there is matched against every window
  of the untiled maps (resampled as the tile was) by normalised cross-correlation of the pattern
  features (the base colour's luminance and the normal's slopes,
  :func:`~brdfgan.core.lattice.pattern_features`, each over its standard deviation). A cell-sized
  window always holds a whole period, so its best match sits where the pattern has the same phase
  (its own source where the tile copied it); a window across a seam matches where its larger part
  came from. The matched places are taken to material coordinates through the known frame, and a
  cell is *whole* when all its probes agree there: each pair's material offset, less what their
  distance on the sheet gives (the local Jacobian), lies within :data:`PHASE_TOLERANCE` (1 output
  pixel) of a lattice vector. So a seam that joins copies a whole period apart does not break a
  cell, one that shifts the pattern by more than a pixel breaks every cell it crosses (from about
  half a cell beyond), and different stains or grain on either side of a well-placed seam do not
  count. For materials with a true 2-D lattice, and for the 1-D ones with squares of one period as
  the cells and phases compared modulo a period across the stripes and any shift along them (whole
  *stripes*: a seam may join different planks' ends, not shift the rows);
- ``period err`` (:func:`lattice_period_error`): :func:`~brdfgan.core.lattice.find_lattice` on the
  tile repeated 2 × 2, each found vector against the nearest vector of the true lattice as the tile
  shows it (``A·a``, ``A·b``: ``A`` the tiling's affine map, the identity for the cut; the lattice
  at the crop's centre): the larger relative length error and the larger angle. The sheet repeats
  every tile exactly, and ``find_lattice`` there sometimes reports a coarser lattice (whole
  combinations of the true vectors: ``×2``, ``×3`` in the table, "coarser" in the summary), which
  still repeats with the material's period; "not found" where it reports none. For 1-D materials
  :func:`~brdfgan.core.stripes.find_stripes` on the sheet against the true stripes as the tile
  shows them (:func:`stripes_period_error`: the period across and the direction);
- ``found err`` (:func:`period_error`): ``find_lattice`` on the untiled crop against the true vectors
  (reduced bases, strict), where it found a lattice: the detection alone; ``score`` its score;
- ``stretch``: the whole-cell tiling's stretch (log of its singular values' ratio, in %);
- ``wrap``: the worst of every map's wrap ratio (:func:`~brdfgan.core.seamless.wrap_ratios`,
  columns and rows; ≤ 1.2 is today's goal);
- ``copied``: the least of the maps' copied fractions
  (:func:`~brdfgan.core.seamless.copied_fraction` for the cut,
  :func:`~brdfgan.core.lattice.period_copied_fraction` on the whole-cell path).

    OMP_NUM_THREADS=1 python -m research.tiling_table --out outputs/tiling/table.md
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from unittest import mock

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.lattice import (
    ALL_FEATURES,
    PROMINENCE_THRESHOLD,
    find_lattice,
    pattern_features,
    rectify,
    reduce_basis,
)
from brdfgan.core.seamless import file_units
from brdfgan.core.stripes import Stripes, find_stripes
from brdfgan.core.svbrdf import check_single_maps, join_maps, normalize_normal, split_maps
from brdfgan.data.spec.determinism import derive_seed

Vector = tuple[float, float]
Basis = tuple[Vector, Vector]
# Positions → positions (``(N, 2)`` ``(x, y)`` → ``(N, 2)``): where a reference pixel lies in the
# crop, or a crop point in the material.
PointMap = Callable[[Tensor], Tensor]

# Copies are found with squares of this side (small enough to fit in the narrowest band a cut
# takes from one copy; large enough to match one place only), this many pixels apart.
PROBE_SIDE = 24
PROBE_STEP = 20
# A cell is whole when its probes agree on the pattern's phase within this many output pixels.
PHASE_TOLERANCE = 1.0
# A square whose best match reaches this correlation is a copy of the reference (1.0 for a pixel
# copy; a feathered seam through the square brings it a little down).
EXACT_NCC = 0.995
# A pixel is a copy where its largest channel difference from the reference, averaged over its
# 3 × 3 neighbourhood, is at most this (file units; copied_fraction's two 8-bit levels).
COPY_TOLERANCE = 2.0 / 255.0
# A copy counts in a cell from this share of its pixels (a stray pixel that happens to agree with
# another copy does not); a cell more than MAX_UNEXPLAINED of which no copy explains (a blend, a
# repaired disc) is not whole.
MIN_SHARE = 0.02
MAX_UNEXPLAINED = 0.25
# A feature channel whose standard deviation is below this carries no pattern (a flat normal map).
FEATURE_FLOOR = 1e-4
# The goals of issue 60 (Must show) for regular materials.
CELLS_GOAL = 0.95
PERIOD_GOAL = 0.01
WRAP_GOAL = 1.2


def rotation(degrees: float) -> Tensor:
    """The rotation by ``degrees`` clockwise on screen (``x`` right, ``y`` down). Shape: ``(2, 2)``."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return torch.tensor([[c, -s], [s, c]], dtype=torch.float64)


@dataclass(frozen=True)
class Frame:
    """How a photo frames a material: a ``size``² crop around the material's centre, turned
    ``degrees`` (crop vector ``d`` shows material vector ``scale·R(degrees)·d`` at the centre) and
    in perspective ``q = d / (1 + g·d)``, ``g = perspective / (size / 2)``: the scale changes by
    ``±perspective`` (x, y) from the centre to the crop's edges, the Jacobian at the centre is
    ``scale·R``. Positions are pixel coordinates, pixel centres at ``index + 0.5``."""

    size: int
    degrees: float
    perspective: Vector = (0.0, 0.0)
    scale: float = 1.0

    def to_material(self, points: Tensor, material_size: tuple[int, int]) -> Tensor:
        """Crop positions → material positions (not wrapped). Shape: ``(N, 2)`` → ``(N, 2)``."""
        d = points.double() - self.size / 2
        depth = 1.0 + (d * torch.tensor(self.perspective, dtype=torch.float64)).sum(dim=-1) / (self.size / 2)
        q = d / depth.unsqueeze(-1)
        centre = torch.tensor([material_size[1] / 2, material_size[0] / 2], dtype=torch.float64)
        return centre + self.scale * q @ rotation(self.degrees).T

    def crop_vectors(self, vectors: Basis) -> Basis:
        """The material's lattice vectors as the crop shows them at its centre, reduced."""
        return transform_vectors(rotation(self.degrees).T / self.scale, vectors)


def _sample_periodic(material: Tensor, points: Tensor) -> Tensor:
    """A material, periodic on its own side, sampled bilinearly at positions ``(x, y)``.
    Shape: ``(C, S, S')``, ``(*, 2)`` → ``(C, *)``."""
    size_y, size_x = material.shape[-2:]
    fx, fy = points[..., 0] - 0.5, points[..., 1] - 0.5
    x0, y0 = torch.floor(fx), torch.floor(fy)
    wx, wy = (fx - x0).to(material.dtype), (fy - y0).to(material.dtype)
    x0, y0 = x0.long(), y0.long()
    out = torch.zeros(material.shape[0], *points.shape[:-1], dtype=material.dtype)
    for dy, weight_y in ((0, 1.0 - wy), (1, wy)):
        for dx, weight_x in ((0, 1.0 - wx), (1, wx)):
            out += material[:, (y0 + dy) % size_y, (x0 + dx) % size_x] * (weight_x * weight_y)
    return out


def photo_frame(material: Tensor, frame: Frame) -> Tensor:
    """The crop of a periodic material that ``frame`` describes, float64; normals turned with the
    frame (their slopes are vectors in the image: a slope along the material's x shows along
    ``R⁻¹x``). Shape: ``(8, S, S')`` → ``(8, size, size)``."""
    check_single_maps(material)
    work = material.double()
    axis = torch.arange(frame.size, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    size = (work.shape[-2], work.shape[-1])
    points = frame.to_material(torch.stack([xx, yy], dim=-1).view(-1, 2), size)
    sampled = _sample_periodic(work, points).view(8, frame.size, frame.size)
    parts = split_maps(sampled)
    # The normal's x is the image's x, its y the image's up (−y).
    slopes = torch.stack([parts.normal[0], -parts.normal[1]], dim=-1) @ rotation(frame.degrees)
    normal = normalize_normal(torch.stack([slopes[..., 0], -slopes[..., 1], parts.normal[2]]))
    return join_maps(parts.basecolor, normal, parts.roughness, parts.metallic)


def _pair(values: Tensor) -> Vector:
    return (float(values[0]), float(values[1]))


def transform_vectors(matrix: Tensor, vectors: Basis) -> Basis:
    """``matrix`` applied to both vectors, reduced. Shape: ``(2, 2)``, two ``(dx, dy)``."""
    moved = [matrix.double() @ torch.tensor(vector, dtype=torch.float64) for vector in vectors]
    return reduce_basis(_pair(moved[0]), _pair(moved[1]))


def snap_to_period(vectors: Basis, size: int, tolerance: float = 0.05) -> Basis | None:
    """The lattice nearest ``vectors`` that holds a material's own period ``(size, 0)`` and
    ``(0, size)`` (a texture that tiles on its square repeats by it), reduced; ``None`` where the
    period's coefficients in ``vectors`` are not within ``tolerance`` of whole numbers.

    Shape: two ``(dx, dy)`` → two ``(dx, dy)`` or ``None``.

    Example:
        >>> snap_to_period(((32.02, 0.0), (0.01, 31.97)), 128)
        ((32.0, 0.0), (0.0, 32.0))
    """
    basis = torch.tensor(vectors, dtype=torch.float64).T  # columns a, b
    period = torch.tensor([[float(size), 0.0], [0.0, float(size)]], dtype=torch.float64)
    coefficients = torch.linalg.solve(basis, period)  # period = basis @ coefficients
    whole = torch.round(coefficients)
    if float((coefficients - whole).abs().max()) > tolerance or abs(float(torch.det(whole))) < 0.5:
        return None
    exact = period @ torch.linalg.inv(whole)
    a, b = reduce_basis(_pair(exact[:, 0]), _pair(exact[:, 1]))
    return (_rounded(a), _rounded(b))


def _rounded(vector: Vector) -> Vector:
    """Shape: ``(dx, dy)``; to 1e-9 px, so that exact lattices print as they are (-0.0 as 0.0)."""
    return (round(vector[0], 9) + 0.0, round(vector[1], 9) + 0.0)


def period_error(found: Basis | None, truth: Basis) -> tuple[float, float]:
    """How far a found lattice is from the truth: of the two reduced true vectors, the larger
    relative length error and the larger angle (degrees) to the nearest of ``±`` the found ones
    (the same vector of the lattice, whichever sign and order); ``(inf, inf)`` without one.

    Shape: two ``(dx, dy)`` each → two numbers.

    Example:
        >>> period_error(((10.1, 0.0), (0.0, -20.0)), ((0.0, 20.0), (10.0, 0.0)))
        (0.01, 0.0)
    """
    if found is None:
        return math.inf, math.inf
    candidates = [s * torch.tensor(v, dtype=torch.float64) for v in reduce_basis(*found) for s in (1, -1)]
    worst_length, worst_angle = 0.0, 0.0
    for vector in reduce_basis(*truth):
        true = torch.tensor(vector, dtype=torch.float64)
        nearest = min(candidates, key=lambda c: float((c - true).norm()))
        length = abs(float(nearest.norm()) / float(true.norm()) - 1.0)
        cosine = float(nearest @ true) / (float(nearest.norm()) * float(true.norm()))
        angle = math.degrees(math.acos(max(-1.0, min(1.0, cosine))))
        worst_length, worst_angle = max(worst_length, length), max(worst_angle, angle)
    return round(worst_length, 12), round(worst_angle, 9)


def lattice_period_error(found: Basis | None, truth: Basis) -> tuple[float, float, int]:
    """Whether a found lattice's vectors are periods of the true lattice: for each found vector,
    the nearest non-zero true lattice vector, the relative length error and the angle (degrees)
    between them, the larger of each over the two; and the index of the found lattice in the true
    one (1: the same lattice; 2, 3, ...: a coarser one, whose vectors are whole combinations of
    the true ones, as :func:`~brdfgan.core.lattice.find_lattice` can pick on a sheet where every
    tile repeats exactly); ``(inf, inf, 0)`` without one.

    Shape: two ``(dx, dy)`` each → two numbers and a count.

    Example:
        A found lattice twice as long one way is a coarser lattice of the same periods:

        >>> lattice_period_error(((20.0, 0.0), (0.0, 10.1)), ((10.0, 0.0), (0.0, 10.0)))
        (0.01, 0.0, 2)
    """
    if found is None:
        return math.inf, math.inf, 0
    basis = torch.tensor(truth, dtype=torch.float64)  # rows a, b
    inverse = torch.linalg.inv(basis)
    steps = torch.tensor([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)], dtype=torch.float64)
    worst_length, worst_angle, rows = 0.0, 0.0, []
    for vector in found:
        f = torch.tensor(vector, dtype=torch.float64)
        candidates = torch.round(f @ inverse) + steps  # the rounded coefficients and their neighbours
        candidates = candidates[candidates.abs().sum(dim=-1) > 0]
        points = candidates @ basis
        nearest = int((points - f).norm(dim=-1).argmin())
        t = points[nearest]
        rows.append(candidates[nearest])
        worst_length = max(worst_length, abs(float(f.norm()) / float(t.norm()) - 1.0))
        cosine = float(f @ t) / (float(f.norm()) * float(t.norm()))
        worst_angle = max(worst_angle, math.degrees(math.acos(max(-1.0, min(1.0, cosine)))))
    index = round(abs(float(torch.det(torch.stack(rows)))))
    return round(worst_length, 12), round(worst_angle, 9), index


def stripes_period_error(found: Stripes | None, cells: Basis) -> tuple[float, float]:
    """How far found stripes are from the true ones whose square cells (one period across and
    along, as a tile shows them: a parallelogram after its affine map) are ``cells``: the relative
    error of the period across, and the angle (degrees) between the directions; ``(inf, inf)``
    without stripes. The true period across is the cells' area over their side along the stripes
    (the one nearer the found direction; either side where none was found).

    Shape: two ``(dx, dy)`` → two numbers.

    Example:
        >>> found = Stripes(across=(0.0, 10.1), along=(1.0, 0.0), ridge=0.5, peak=0.5)
        >>> stripes_period_error(found, ((0.0, 10.0), (10.0, 0.0)))
        (0.01, 0.0)
    """
    if found is None:
        return math.inf, math.inf
    sides = [torch.tensor(side, dtype=torch.float64) for side in cells]
    direction = torch.tensor(found.along, dtype=torch.float64)
    along = max(sides, key=lambda side: abs(float(side @ direction)) / float(side.norm()))
    area = abs(float(sides[0][0] * sides[1][1] - sides[0][1] * sides[1][0]))
    period = area / float(along.norm())
    cosine = abs(float(along @ direction)) / float(along.norm())
    angle = math.degrees(math.acos(max(-1.0, min(1.0, cosine))))
    return round(abs(found.period / period - 1.0), 12), round(angle, 9)


def feature_image(maps: Tensor) -> Tensor:
    """What the probes compare: luminance and normal slopes
    (:func:`~brdfgan.core.lattice.pattern_features`). Shape: ``(8, H, W)`` → ``(3, H, W)`` float64."""
    return pattern_features(maps.detach().double())


def tile_frame_reference(maps: Tensor, affine: Tensor, origin: Vector) -> tuple[Tensor, Tensor, PointMap]:
    """The untiled maps as a whole-cell tile's frame shows them: a canvas holding the whole input
    mapped by ``affine`` (crop offset from ``origin`` → tile offset), sampled bilinearly on the
    tile's own pixel grid (the tile's pixels are samples at these very points), where each sample
    lies inside the input, and the map from canvas positions to crop positions.

    Shape: ``(8, N, N')``, ``(2, 2)``, ``(x, y)`` → ``(8, Hc, Wc)`` float64, ``(Hc, Wc)`` bool, map.
    """
    check_single_maps(maps)
    height, width = maps.shape[-2:]
    corners = torch.tensor([[0.0, 0.0], [width, 0.0], [0.0, height], [width, height]], dtype=torch.float64)
    start = torch.tensor(origin, dtype=torch.float64)
    mapped = (corners - start) @ affine.double().T
    low = torch.floor(mapped.amin(dim=0)) - 1
    high = torch.ceil(mapped.amax(dim=0)) + 1
    xs = torch.arange(int(low[0]), int(high[0]), dtype=torch.float64) + 0.5
    ys = torch.arange(int(low[1]), int(high[1]), dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(ys, xs, indexing="ij")
    inverse = torch.linalg.inv(affine.double())
    points = start + torch.stack([xx, yy], dim=-1) @ inverse.T
    grid = 2.0 * points / torch.tensor([width, height], dtype=torch.float64) - 1.0
    sampled = F.grid_sample(
        maps.double()[None], grid[None], mode="bilinear", padding_mode="border", align_corners=False
    )[0]
    valid = (
        (points[..., 0] >= 0.5)
        & (points[..., 0] <= width - 0.5)
        & (points[..., 1] >= 0.5)
        & (points[..., 1] <= height - 0.5)
    )
    parts = split_maps(sampled)
    canvas = join_maps(parts.basecolor, normalize_normal(parts.normal), parts.roughness, parts.metallic)

    def to_crop(positions: Tensor) -> Tensor:
        return start + (positions.double() + low) @ inverse.T

    return canvas, valid, to_crop


def _correlate(image: Tensor, kernels: Tensor, spectrum: Tensor | None = None) -> Tensor:
    """``Σ_p kernel(p)·image(t + p)`` for every shift ``t`` where the kernel lies in the image, per
    kernel, summed over channels (FFT; exact for those shifts); ``spectrum``: the image's
    ``rfft2``, when already at hand.

    Shape: ``(C, H, W)``, ``(K, C, h, w)`` → ``(K, H − h + 1, W − w + 1)``.
    """
    height, width = image.shape[-2:]
    h, w = kernels.shape[-2:]
    if spectrum is None:
        spectrum = torch.fft.rfft2(image, s=(height, width))
    kernel_spectrum = torch.fft.rfft2(kernels.to(image.dtype), s=(height, width))
    product = (spectrum.unsqueeze(0) * kernel_spectrum.conj()).sum(dim=1)
    return torch.fft.irfft2(product, s=(height, width))[:, : height - h + 1, : width - w + 1]


def find_copies(
    tile: Tensor, reference: Tensor, valid: Tensor, side: int = PROBE_SIDE, chunk: int = 64
) -> Tensor:
    """The shifts by which a tile copies the reference (its pixels at ``x − o``): every
    ``side``-pixel square of the tile, :data:`PROBE_STEP` apart (wrapping around the tile), is
    matched against every square of the reference lying wholly where ``valid``, by normalised
    cross-correlation of the pattern features (:func:`feature_image`, each over the reference's
    standard deviation); a square that matches at :data:`EXACT_NCC` or better is a copy, its shift
    found. Returned modulo the tile's size, with every combination of one shift's x and another's y
    (a tile cut along both axes holds copies shifted along each axis alone), unique.

    Shape: ``(8, H, W)``, ``(8, Hr, Wr)``, ``(Hr, Wr)`` bool → ``(N, 2)`` int64 ``(dx, dy)``.
    """
    height, width = tile.shape[-2:]
    weight = valid.double()
    features = feature_image(reference)
    count = weight.sum().clamp_min(1.0)
    mean = (features * weight).sum(dim=(-2, -1), keepdim=True) / count
    spread = (((features - mean) * weight).square().sum(dim=(-2, -1), keepdim=True) / count).sqrt()
    used = spread.flatten() > FEATURE_FLOOR
    scale = spread.clamp_min(FEATURE_FLOOR)
    source = ((features - mean) * weight / scale)[used]
    # The tile repeated, so that squares reach across its wrap.
    sheet = ((feature_image(tile).repeat(1, 2, 2) - mean) / scale)[used]
    ones = torch.ones(1, 1, side, side, dtype=torch.float64)
    size = float(side * side)
    sums = torch.stack([_correlate(channel[None], ones)[0] for channel in source])
    squares = torch.stack([_correlate(channel.square()[None], ones)[0] for channel in source])
    energy_source = (squares - sums.square() / size).sum(dim=0).clamp_min(0.0)
    usable = (_correlate(weight[None], ones)[0] >= size - 0.5) & (energy_source > 1e-6 * size)
    corners = [(x, y) for y in range(0, height, PROBE_STEP) for x in range(0, width, PROBE_STEP)]
    found: list[tuple[int, int]] = []
    # The search itself in single precision (twice as fast; a copy still scores 1 to 1e-5).
    source32 = source.float()
    spectrum = torch.fft.rfft2(source32)
    for start in range(0, len(corners), chunk):
        batch = corners[start : start + chunk]
        windows = torch.stack([sheet[:, y : y + side, x : x + side] for x, y in batch])
        centred = windows - windows.mean(dim=(-2, -1), keepdim=True)
        energy = centred.square().sum(dim=(-3, -2, -1))
        numerator = _correlate(source32, centred, spectrum).double()
        ncc = numerator / (energy.view(-1, 1, 1) * energy_source).sqrt().clamp_min(1e-12)
        ncc = torch.where(usable, ncc, torch.tensor(-1.0, dtype=ncc.dtype))
        best, where = ncc.flatten(1).max(dim=1)
        flat = energy <= 1e-6 * size  # a featureless square matches anywhere: no evidence
        for (x, y), value, index, blank in zip(
            batch, best.tolist(), where.tolist(), flat.tolist(), strict=True
        ):
            if value >= EXACT_NCC and not blank:
                my, mx = divmod(index, ncc.shape[-1])
                found.append(((x - mx) % width, (y - my) % height))
    if not found:
        return torch.zeros(0, 2, dtype=torch.int64)
    shifts = torch.tensor(found, dtype=torch.int64)
    xs, ys = torch.unique(shifts[:, 0]), torch.unique(shifts[:, 1])
    return torch.cartesian_prod(xs, ys).view(-1, 2)


def _jacobians(to_material: PointMap, points: Tensor, step: float = 0.5) -> Tensor:
    """The Jacobian of ``to_material`` at each point, by central differences.
    Shape: ``(N, 2)`` → ``(N, 2, 2)`` (``[:, :, 0]`` along x)."""
    columns = []
    for axis in range(2):
        delta = torch.zeros(2, dtype=torch.float64)
        delta[axis] = step
        columns.append((to_material(points + delta) - to_material(points - delta)) / (2 * step))
    return torch.stack(columns, dim=-1)


def attribute_pixels(
    sheet: Tensor, reference: Tensor, valid: Tensor, offsets: Tensor, box: tuple[int, int, int, int]
) -> Tensor:
    """Which copy each pixel of the sheet's ``box`` ``(x0, y0, x1, y1)`` is: the offset ``o`` for
    which the reference at ``x − o`` (valid there) equals the sheet at ``x`` within
    :data:`COPY_TOLERANCE` (the largest channel difference, averaged over the 3 × 3 pixels around:
    a single chance agreement in a flat area does not count), the closest if several; −1 where
    none does (a feathered pixel on a seam, a blend).

    Shape: ``(C, Hs, Ws)`` (file units), ``(C, Hr, Wr)``, ``(Hr, Wr)`` bool, ``(N, 2)`` → ``(y1 − y0,
    x1 − x0)`` int64 indices into ``offsets``.
    """
    x0, y0, x1, y1 = box
    height, width = y1 - y0, x1 - x0
    ref_h, ref_w = reference.shape[-2:]
    target = sheet[:, y0:y1, x0:x1]
    best = torch.full((height, width), math.inf, dtype=torch.float64)
    label = torch.full((height, width), -1, dtype=torch.int64)
    for k, (dx, dy) in enumerate(offsets.tolist()):
        # Reference pixel (r, c) = sheet pixel (r + dy, c + dx): the box's overlap with it.
        rows = slice(max(y0 - dy, 0), min(y1 - dy, ref_h))
        cols = slice(max(x0 - dx, 0), min(x1 - dx, ref_w))
        if rows.start >= rows.stop or cols.start >= cols.stop:
            continue
        out_rows = slice(rows.start + dy - y0, rows.stop + dy - y0)
        out_cols = slice(cols.start + dx - x0, cols.stop + dx - x0)
        error = (target[:, out_rows, out_cols] - reference[:, rows, cols]).abs().amax(dim=0)
        error = torch.where(valid[rows, cols], error, torch.tensor(math.inf, dtype=error.dtype))
        smooth = F.avg_pool2d(error[None, None], 3, stride=1, padding=1, count_include_pad=False)[0, 0]
        closer = (smooth <= COPY_TOLERANCE) & (smooth < best[out_rows, out_cols])
        best[out_rows, out_cols] = torch.where(closer, smooth, best[out_rows, out_cols])
        label[out_rows, out_cols] = torch.where(closer, k, label[out_rows, out_cols])
    return label


@dataclass(frozen=True)
class CellCheck:
    """Per cell of the sheet (:func:`check_cells`): the largest phase jump between the copies it
    holds, in output pixels (0 for a cell of one copy), and the share of its pixels no copy
    explains. Shape: ``(K,)``, ``(K,)``."""

    jumps: Tensor
    unexplained: Tensor

    def whole(self, tolerance: float = PHASE_TOLERANCE) -> Tensor:
        """Which cells are whole: every jump within ``tolerance`` pixels and at most
        :data:`MAX_UNEXPLAINED` of the cell no copy. Shape: ``(K,)`` bool."""
        return (self.jumps <= tolerance) & (self.unexplained <= MAX_UNEXPLAINED)

    def share(self, tolerance: float = PHASE_TOLERANCE) -> float:
        """The share of whole cells; NaN without cells."""
        return float(self.whole(tolerance).double().mean()) if self.jumps.numel() else math.nan


def _cell_jumps(
    centres: Tensor,
    counts: Tensor,
    sizes: Tensor,
    offsets: Tensor,
    to_material: PointMap,
    material_lattice: Basis,
) -> Tensor:
    """Per cell, the largest phase difference at its centre between the copies that hold at least
    :data:`MIN_SHARE` of it (:func:`check_cells`), in output pixels.

    Shape: ``(K, 2)``, ``(K, N)`` pixel counts per copy, ``(K,)``, ``(N, 2)`` → ``(K,)``.
    """
    material_basis = torch.tensor(material_lattice, dtype=torch.float64)
    inverse_material = torch.linalg.inv(material_basis)
    jumps = torch.zeros(centres.shape[0], dtype=torch.float64)
    for k in range(centres.shape[0]):
        present = torch.nonzero(counts[k] >= MIN_SHARE * float(sizes[k])).flatten()
        if present.numel() < 2:
            continue
        sources = centres[k] - offsets[present].double()  # where each copy takes the centre from
        material = to_material(sources)
        to_output = torch.linalg.inv(_jacobians(to_material, sources[:1])[0])
        # Every pair: the material each copy puts at the centre, modulo the lattice.
        difference = (material.unsqueeze(1) - material.unsqueeze(0)).reshape(-1, 2)
        difference = difference - torch.round(difference @ inverse_material) @ material_basis
        jumps[k] = float((difference @ to_output.T).norm(dim=-1).max())
    return jumps


def check_cells(
    tile: Tensor,
    reference: Tensor,
    valid: Tensor,
    lattice: Basis,
    to_material: PointMap,
    material_lattice: Basis,
) -> CellCheck:
    """Whether each lattice cell of a tiled output is whole (module docstring). ``tile``: the
    output ``(8, H, W)``; ``reference``: the untiled maps on the tile's own grid with where they
    are ``valid``, and ``to_material`` from its positions (pixel centres at ``index + 0.5``) to
    the material's; ``lattice``: the true lattice as the tile shows it, ``material_lattice`` in
    the material.

    The tile is repeated 3 × 3; the cells of ``lattice`` through the middle tile's top-left corner
    (where four tiles meet) partition the plane, and those centred in the middle tile are checked,
    each cell of the periodic sheet once. Small squares find the copies the tile is made of
    (:func:`find_copies`), each pixel of the sheet is attributed to one
    (:func:`attribute_pixels`), and a cell's jump is the largest, over pairs of copies that each
    hold at least :data:`MIN_SHARE` of it, of their phase difference at its centre: where the two
    copies put the material there, modulo its lattice, in output pixels.

    Shape: ``(8, H, W)``, ``(8, Hr, Wr)``, ``(Hr, Wr)`` bool, two ``(dx, dy)``, map, two
    ``(dx, dy)`` → :class:`CellCheck`.
    """
    check_single_maps(tile)
    height, width = tile.shape[-2:]
    sheet_maps = tile.detach().double().repeat(1, 3, 3)
    base = find_copies(tile.detach().double(), reference.double(), valid)
    # On the sheet, tile (i, j) holds each copy moved by (i·W, j·H).
    moves = torch.tensor([(i * width, j * height) for i in range(-1, 4) for j in range(-1, 4)])
    offsets = torch.unique((base.unsqueeze(1) + moves.unsqueeze(0)).reshape(-1, 2), dim=0)
    sheet = torch.cat(file_units(sheet_maps))
    source = torch.cat(file_units(reference.double()))
    # The cells: each pixel's nearest lattice point (its cell's centre) from the corner.
    a = torch.tensor(lattice[0], dtype=torch.float64)
    b = torch.tensor(lattice[1], dtype=torch.float64)
    corner = torch.tensor([float(width), float(height)], dtype=torch.float64)
    reach = 0.5 * (a.abs() + b.abs())
    x0, y0 = (torch.floor(corner - reach).clamp_min(0)).long().tolist()
    x1 = min(3 * width, math.ceil(2 * width + float(reach[0])) + 1)
    y1 = min(3 * height, math.ceil(2 * height + float(reach[1])) + 1)
    labels = attribute_pixels(sheet, source, valid, offsets, (x0, y0, x1, y1))
    ys = torch.arange(y0, y1, dtype=torch.float64) + 0.5
    xs = torch.arange(x0, x1, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(ys, xs, indexing="ij")
    basis = torch.stack([a, b])  # rows a, b
    coordinates = torch.round((torch.stack([xx, yy], dim=-1) - corner) @ torch.linalg.inv(basis)).long()
    centres = corner + coordinates.double() @ basis
    counted = (
        (centres[..., 0] >= width)
        & (centres[..., 0] < 2 * width)
        & (centres[..., 1] >= height)
        & (centres[..., 1] < 2 * height)
    )
    cell_keys, cell_index = torch.unique(coordinates[counted], dim=0, return_inverse=True)
    cell_labels = labels[counted]
    cells = cell_keys.shape[0]
    sizes = torch.bincount(cell_index, minlength=cells).double()
    unexplained = torch.bincount(cell_index[cell_labels < 0], minlength=cells).double() / sizes
    counts = torch.zeros(cells, max(offsets.shape[0], 1), dtype=torch.float64)
    explained = cell_labels >= 0
    counts.index_put_(
        (cell_index[explained], cell_labels[explained]),
        torch.ones(int(explained.sum()), dtype=torch.float64),
        accumulate=True,
    )
    jumps = _cell_jumps(
        corner + cell_keys.double() @ basis, counts, sizes, offsets, to_material, material_lattice
    )
    return CellCheck(jumps, unexplained)


# The table: materials, frames, the two tilings and the report.

SCANS = Path(os.environ.get("BRDFGAN_SCANS_DIR", Path(__file__).resolve().parents[2] / "shared" / "scans"))
MATERIAL_SIDE = 512
CROP = 256
# Layout parameters that count cells across the material: scaled with the side it is painted at,
# so that a larger crop (--crop 512, painted at 1024) shows more cells of the same size.
COUNT_PARAMETERS = frozenset(
    {
        "tile_count",
        "tesserae",
        "count",
        "lozenge_count",
        "brick_rows",
        "bricks_per_row",
        "plank_rows",
        "planks_per_row",
    }
)
ANGLES = (0.0, 15.0, 30.0, 45.0)
# ±2 % scale from the centre to the left and right edges, ±1.5 % to the top and bottom: about
# 2° of camera tilt with a phone's field of view, "mild perspective".
PERSPECTIVE = (0.02, 0.015)
GROUPS = ("periodic families", "periodic scans", "1-D regular", "non-periodic")
PERIODIC_GROUPS = GROUPS[:2]
# The groups whose cells are checked: the periodic ones and the 1-D (whole stripes).
MEASURED_GROUPS = GROUPS[:3]


@dataclass(frozen=True)
class Material:
    """A material of the table: its name, group (:data:`GROUPS`), how to paint its maps at a side
    (``(8, S, S)``, periodic on its square) and whether it is a procedural family's (those paint
    the same cells at any side: their count parameters scale, :data:`COUNT_PARAMETERS`)."""

    name: str
    group: str
    paint: Callable[[int], Tensor]
    procedural: bool = False


def family_material(
    name: str, group: str, overrides: dict[str, float], family: str | None = None
) -> Material:
    """A procedural family's material: its parameters drawn from a generator seeded by the name,
    the layout ones fixed (``overrides``) so that a crop shows a few cells."""
    from brdfgan.data.materials.families import FAMILIES

    chosen = FAMILIES[family or name]

    def paint(side: int) -> Tensor:
        generator = torch.Generator().manual_seed(derive_seed("tiling table", name))
        scale = side / MATERIAL_SIDE
        fixed = {key: value * scale if key in COUNT_PARAMETERS else value for key, value in overrides.items()}
        params = {**chosen.sample_parameters(generator), **fixed}
        return chosen.make_maps(params, side, generator).double()

    return Material(name, group, paint, procedural=True)


def scan_material(name: str, group: str) -> Material:
    """A scanned set of :data:`SCANS`, read at the side asked for (ambientCG scans tile on it)."""
    from brdfgan.data.materials.scanned import read_scanned_material

    return Material(name, group, lambda side: read_scanned_material(SCANS / name, side).double())


def materials() -> list[Material]:
    """The table's materials: layouts fixed for cells of 32-90 px at :data:`MATERIAL_SIDE`."""
    families, scans = GROUPS[0], GROUPS[1]
    return [
        family_material("ceramic_tiles", families, {"tile_count": 8}),
        family_material("mosaic", families, {"irregular": 0.0, "tesserae": 16}),
        family_material("relief_tiles", families, {"tile_count": 8, "motif_repeat": 1}),
        family_material("pavers (running bond)", families, {"layout": 1.0, "count": 16}, "pavers"),
        family_material("pavers (herringbone)", families, {"layout": 2.0, "count": 16}, "pavers"),
        family_material("tread_plate", families, {"lozenge_count": 12}),
        family_material("bricks", families, {"brick_rows": 12, "bricks_per_row": 4}),
        scan_material("Tiles033", scans),
        scan_material("Tiles036", scans),
        scan_material("Tiles065", scans),
        scan_material("Tiles074", scans),
        family_material("wood_planks", GROUPS[2], {"plank_rows": 8, "planks_per_row": 2}),
        scan_material("PavingStones010", GROUPS[2]),
        family_material("concrete", GROUPS[3], {}),
        family_material("rough_stone", GROUPS[3], {}),
        family_material("ground", GROUPS[3], {}),
        family_material("leather", GROUPS[3], {"weave": 0.0}),
        scan_material("Concrete002", GROUPS[3]),
        scan_material("Rock001", GROUPS[3]),
        scan_material("Bricks075A", GROUPS[3]),
    ]


def true_lattice(maps: Tensor) -> tuple[Basis, str]:
    """The lattice of a flat material (module docstring) and how it was had: ``snapped`` onto the
    material's period, or ``measured`` where whole numbers of the found vectors do not make it.
    Shape: ``(8, S, S)`` → two ``(dx, dy)``, a word."""
    found = find_lattice(maps)
    if not found.periodic or found.vectors is None:
        raise ValueError(f"the flat material shows no 2-D lattice: {found}")
    snapped = snap_to_period(found.vectors, maps.shape[-1])
    return (snapped, "snapped") if snapped is not None else (found.vectors, "measured")


# A 1-D material's phases are compared modulo one period across its stripes and any shift along
# them: its "lattice" for the cell check has a second vector this short (px) along the stripes.
ALONG_EPSILON = 1e-3


def true_stripes(maps: Tensor) -> tuple[Basis, Basis, str]:
    """A flat 1-D material's stripes (:func:`~brdfgan.core.stripes.find_stripes`), the period
    snapped onto the material's side where a whole number of periods makes it: the cells checked
    (squares of one period, across and along) and the lattice phases are compared modulo (one
    period across, :data:`ALONG_EPSILON` along), and how it was had.
    Shape: ``(8, S, S)`` → two bases, a word."""
    found = find_stripes(maps)
    if found is None:
        raise ValueError("the flat material shows no stripes")
    along = found.along
    normal = (-along[1], along[0])
    period, how = found.period, "measured"
    # Whole periods across the material's side (along whichever axis the stripes cross more).
    side = maps.shape[-1] * max(abs(normal[0]), abs(normal[1]))
    count = round(side / period)
    if count > 0 and abs(side / period - count) <= 0.05:
        period, how = side / count, "snapped"
    across = (normal[0] * period, normal[1] * period)
    cells = (across, (along[0] * period, along[1] * period))
    material = (across, (along[0] * ALONG_EPSILON, along[1] * ALONG_EPSILON))
    return cells, material, how


@contextmanager
def repair_held_off() -> Iterator[list[Any]]:
    """``make_tileable`` with the flash-mark repair held off: the maps go on unrepaired, and what
    the repair would have done is kept (the list yields its records, one per call)."""
    from brdfgan.core import flash_mark
    from brdfgan.inference import pipeline

    records: list[Any] = []

    def measure_only(maps: Tensor, centre: tuple[float, float]) -> tuple[Tensor, Any]:
        _, record = flash_mark.repair_flash_mark(maps, centre)
        records.append(record)
        return maps, record

    with mock.patch.object(pipeline, "repair_flash_mark", measure_only):
        yield records


def repair_fired(record: Any) -> bool:
    """Whether a flash-mark record repaired or levelled any map."""
    return bool(getattr(record, "repaired", ())) or bool(getattr(record, "levelled", ()))


def _worst_wrap(measures: Any) -> float:
    return max(max(pair) for pair in measures.wrap_ratio.values())


def _least_copied(measures: Any) -> float:
    return min(measures.copied_fraction.values())


@dataclass
class Row:
    """One tiling of one framed material (module docstring's measures); NaN where not measured."""

    material: str
    group: str
    angle: float
    perspective: bool
    path: str
    whole_cells: bool = False
    score: float = math.nan
    found_error: tuple[float, float] = (math.nan, math.nan)
    period_error: tuple[float, float] = (math.nan, math.nan)
    period_index: int = 0
    stretch: float = math.nan
    cells: float = math.nan
    worst_jump: float = math.nan
    wrap: float = math.nan
    copied: float = math.nan
    seconds: float = math.nan
    repair: bool = False
    note: str = ""
    error: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def measure_tile(
    row: Row,
    tile: Tensor,
    reference: Tensor,
    valid: Tensor,
    to_material: PointMap,
    tile_lattice: Basis | None,
    material_lattice: Basis | None,
    stripes: bool = False,
) -> None:
    """The lattice measures of one tile into ``row``: cells whole and the period error (periodic
    and 1-D materials only; ``stripes``: a 1-D one, :func:`true_stripes`)."""
    if tile_lattice is None or material_lattice is None:
        return
    check = check_cells(tile, reference, valid, tile_lattice, to_material, material_lattice)
    row.cells = check.share()
    row.worst_jump = float(check.jumps.max()) if check.jumps.numel() else math.nan
    row.extra["unexplained"] = float(check.unexplained.max()) if check.unexplained.numel() else math.nan
    if stripes:
        row.period_error = stripes_period_error(find_stripes(tile.detach().repeat(1, 2, 2)), tile_lattice)
        return
    try:
        found = find_lattice(tile.detach().repeat(1, 2, 2))
    except RuntimeError as error:  # core.lattice's refinement can fail (the note's failing cases)
        row.period_error = (math.inf, math.inf)
        row.extra["sheet_error"] = f"find_lattice on the 2x2 sheet: {type(error).__name__}"
        return
    length, angle, index = lattice_period_error(found.vectors if found.periodic else None, tile_lattice)
    row.period_error, row.period_index = (length, angle), index


def run_case(
    material: Material,
    maps: Tensor,
    truth: Basis | None,
    frame: Frame,
    cells: Basis | None = None,
) -> list[Row]:
    """The new and today's tiling of one framed material, measured; and, where the shipped
    flash-mark repair fires on the true maps, the new tiling as shipped. ``truth``: the material's
    lattice; ``cells``: the cells checked where they are not its cells (a 1-D material's,
    :func:`true_stripes`; the material is then taken as 1-D)."""
    from brdfgan.core.seamless import make_seamless, tiling_measures
    from brdfgan.inference.pipeline import make_tileable

    crop = photo_frame(maps, frame).float()  # the pipeline's maps are float32
    size = (maps.shape[-2], maps.shape[-1])
    stripes = cells is not None
    cells = cells if cells is not None else truth
    crop_truth = frame.crop_vectors(cells) if cells is not None else None
    base: dict[str, Any] = {"material": material.name, "group": material.group, "angle": frame.degrees}
    base["perspective"] = frame.perspective != (0.0, 0.0)
    identity = torch.ones(frame.size, frame.size, dtype=torch.bool)

    def crop_to_material(points: Tensor) -> Tensor:
        return frame.to_material(points, size)

    rows = []
    new = Row(**base, path="new")
    _detect(new, crop, None if stripes else crop_truth)
    start = time.process_time()
    try:
        with repair_held_off() as records:
            tiled, record = make_tileable(crop, (frame.size / 2, frame.size / 2))
        new.seconds = time.process_time() - start
        new.repair = repair_fired(records[0])
        _fill_new(new, record, crop, tiled, crop_truth, truth, crop_to_material, identity, stripes)
    except Exception as error:  # a crash is a row of the table, not the end of it
        new.error = f"{type(error).__name__}: {str(error).splitlines()[0][:120]}"
    rows.append(new)

    today = Row(**base, path="today")
    start = time.process_time()
    tile = make_seamless(crop)
    today.seconds = time.process_time() - start
    measures = tiling_measures(tile.maps, crop, tile.shifts)
    today.wrap, today.copied = _worst_wrap(measures), _least_copied(measures)
    measure_tile(today, tile.maps, crop.double(), identity, crop_to_material, crop_truth, truth, stripes)
    rows.append(today)

    if new.repair and not new.error:
        rows.append(_shipped_row(base, new, crop, crop_truth, truth, crop_to_material, identity, stripes))
    return rows


def _detect(row: Row, crop: Tensor, crop_truth: Basis | None) -> None:
    """The detection on its own into ``row`` (make_tileable records a lattice only where it uses
    one): its score and accuracy whichever path the maps take."""
    try:
        detected = find_lattice(crop)
    except RuntimeError as error:  # the note's failing cases of core.lattice
        row.extra["detection"] = f"find_lattice: {type(error).__name__}"
        return
    row.score = detected.score
    row.extra["detection"] = detected.notes
    row.extra["features"] = detected.features
    if crop_truth is not None and detected.vectors is not None:
        row.found_error = period_error(detected.vectors, crop_truth)


def _shipped_row(
    base: dict[str, Any],
    new: Row,
    crop: Tensor,
    crop_truth: Basis | None,
    truth: Basis | None,
    crop_to_material: PointMap,
    identity: Tensor,
    stripes: bool = False,
) -> Row:
    """The new tiling with the flash-mark repair as it stands (where it fires on the true maps):
    what it repaired or levelled, how far its patch's shift is from a lattice vector, the cells."""
    from brdfgan.inference.pipeline import make_tileable

    shipped = Row(**base, path="shipped", score=new.score, found_error=new.found_error)
    try:
        tiled, record = make_tileable(crop, (crop.shape[-1] / 2, crop.shape[-2] / 2))
        _fill_new(shipped, record, crop, tiled, crop_truth, truth, crop_to_material, identity, stripes)
        offset = record.flash_mark.patch_offset  # (dy, dx)
        if offset is not None and crop_truth is not None:
            shift = torch.tensor([[float(offset[1]), float(offset[0])]])
            shipped.extra["patch_off_lattice_px"] = float(lattice_residual(shift, crop_truth)[0])
        shipped.extra["repaired"] = list(record.flash_mark.repaired)
        shipped.extra["levelled"] = list(getattr(record.flash_mark, "levelled", ()))
    except Exception as error:  # a crash is a row of the table
        shipped.error = f"{type(error).__name__}: {str(error).splitlines()[0][:120]}"
    return shipped


def lattice_residual(offsets: Tensor, lattice: Basis) -> Tensor:
    """How far each offset ``(dx, dy)`` is from the nearest vector of ``lattice``, in pixels.
    Shape: ``(N, 2)``, two ``(dx, dy)`` → ``(N,)``."""
    basis = torch.tensor(lattice, dtype=torch.float64)  # rows a, b
    coefficients = offsets.double() @ torch.linalg.inv(basis)
    return (offsets.double() - torch.round(coefficients) @ basis).norm(dim=-1)


def _fill_new(
    row: Row,
    record: Any,
    crop: Tensor,
    tiled: Tensor,
    crop_truth: Basis | None,
    truth: Basis | None,
    crop_to_material: PointMap,
    identity: Tensor,
    stripes: bool = False,
) -> None:
    """The new tiling's row: its lattice decision, measures and lattice measures."""
    row.whole_cells = record.cells is not None
    row.note = record.note or ""
    row.wrap, row.copied = _worst_wrap(record.after), _least_copied(record.after)
    row.extra["stripes"] = None if record.stripes is None else round(record.stripes.period, 3)
    if record.cells is None:
        measure_tile(row, tiled, crop.double(), identity, crop_to_material, crop_truth, truth, stripes)
        return
    affine = record.cells.affine()
    row.stretch = record.cells.stretch
    # A rectified perspective: the cells were cut from the rectified crop, whose Jacobian at the
    # centre is the identity (the crop's lattice there is the truth's), and whose positions lead
    # back to the crop's through the perspective.
    perspective = record.perspective
    source = crop if perspective is None else rectify(crop, perspective)
    reference, valid, to_source = tile_frame_reference(source, affine, record.cells.origin)
    tile_lattice = transform_vectors(affine, crop_truth) if crop_truth is not None else None
    row.extra["keystone"] = None if perspective is None else list(perspective.keystone)

    def to_material(points: Tensor) -> Tensor:
        positions = to_source(points)
        return crop_to_material(positions if perspective is None else perspective.to_image(positions))

    measure_tile(row, tiled, reference, valid, to_material, tile_lattice, truth, stripes)


def _finite(values: list[float]) -> list[float]:
    return [value for value in values if math.isfinite(value)]


def _fmt(value: float, digits: int = 2, scale: float = 1.0, suffix: str = "") -> str:
    return f"{value * scale:.{digits}f}{suffix}" if math.isfinite(value) else "—"


def summarise(rows: list[Row]) -> dict[str, Any]:
    """A group's numbers for one path (module docstring's measures over its cases)."""
    cells = _finite([row.cells for row in rows])
    periods = [row.period_error[0] for row in rows if not math.isnan(row.period_error[0])]
    found = _finite(periods)
    angles = _finite([row.period_error[1] for row in rows])
    wraps = _finite([row.wrap for row in rows])
    copied = _finite([row.copied for row in rows])
    jumps = _finite([row.worst_jump for row in rows])
    # The detection's accuracy where it found a lattice (a rejected one's vectors mean nothing).
    detected = [
        row.found_error[0]
        for row in rows
        if math.isfinite(row.found_error[0]) and row.score >= PROMINENCE_THRESHOLD
    ]
    return {
        "cases": len(rows),
        "whole_cell_path": sum(row.whole_cells for row in rows),
        "errors": sum(bool(row.error) for row in rows),
        "cells_mean": statistics.fmean(cells) if cells else math.nan,
        "cells_min": min(cells) if cells else math.nan,
        "cells_goal_met": sum(value >= CELLS_GOAL for value in cells),
        "cells_cases": len(cells),
        "jump_median": statistics.median(jumps) if jumps else math.nan,
        "period_median": statistics.median(found) if found else math.nan,
        "period_max": max(found) if found else math.nan,
        "period_goal_met": sum(value <= PERIOD_GOAL for value in found),
        "period_cases": len(periods),
        "angle_max": max(angles) if angles else math.nan,
        "coarser": sum(row.period_index > 1 for row in rows),
        "found_median": statistics.median(detected) if detected else math.nan,
        "found_max": max(detected) if detected else math.nan,
        "wrap_max": max(wraps) if wraps else math.nan,
        "wrap_median": statistics.median(wraps) if wraps else math.nan,
        "copied_min": min(copied) if copied else math.nan,
        "copied_median": statistics.median(copied) if copied else math.nan,
    }


def _group_cells(summary: dict[str, Any], periodic: bool, path: str) -> list[str]:
    """A summary row's cells after its labels (:func:`report`)."""
    s = summary
    dash = "—"
    lattice_cells = [
        f"{_fmt(s['cells_mean'], 1, 100, ' %')} ({_fmt(s['cells_min'], 0, 100, ' %')})",
        f"{s['cells_goal_met']}/{s['cells_cases']}",
        _fmt(s["jump_median"], 1),
        f"{_fmt(s['period_median'], 2, 100, ' %')} ({_fmt(s['period_max'], 1, 100, ' %')}), "
        f"{s['period_goal_met']}/{s['period_cases']}, coarser {s['coarser']}",
        _fmt(s["angle_max"], 2),
        f"{_fmt(s['found_median'], 2, 100, ' %')} ({_fmt(s['found_max'], 1, 100, ' %')})"
        if path == "new"
        else dash,
    ]
    return [
        str(s["cases"]),
        str(s["whole_cell_path"]) if path == "new" else dash,
        *(lattice_cells if periodic else [dash] * len(lattice_cells)),
        f"{_fmt(s['wrap_max'])} ({_fmt(s['wrap_median'])})",
        f"{_fmt(s['copied_min'], 3)} ({_fmt(s['copied_median'], 3)})",
        str(s["errors"]),
    ]


SUMMARY_HEADER = (
    "| group | frames | path | cases | whole-cell path | cells whole: mean (min) | cases ≥ 95 % "
    "| worst jump px (median) | period err: median (max), cases ≤ 1 %, coarser | angle err max ° "
    "| found err: median (max) | wrap max (median) | copied min (median) | errors |"
)
CASE_HEADER = (
    "| material | angle | persp. | path | lattice (score) | found err | cells whole | worst jump px "
    "| period err (angle °) | stretch | wrap | copied | note |"
)
REPAIR_HEADER = (
    "| material | angle | persp. | repaired | levelled | patch off the lattice px "
    "| cells whole as shipped (held off) | wrap | copied |"
)


def _rule(header: str) -> str:
    return "|" + "---|" * (header.count("|") - 1)


def _case_line(row: Row) -> str:
    """One case of the table (:func:`report`)."""
    lattice = "—"
    if row.path == "new":
        # The feature groups the lattice was read from, where not both (core.lattice.FEATURE_CHOICES).
        features = row.extra.get("features", ALL_FEATURES)
        alone = "" if features == ALL_FEATURES else f", {features}"
        score = f" ({row.score:.2f}{alone})" if math.isfinite(row.score) else ""
        lattice = ("yes" if row.whole_cells else "no") + score
    if row.extra.get("sheet_error"):
        period = "crash"
    elif math.isinf(row.period_error[0]):
        period = "not found"
    else:
        period = f"{_fmt(row.period_error[0], 2, 100, ' %')} ({_fmt(row.period_error[1], 2)})"
        if row.period_index > 1:
            period += f" ×{row.period_index}"
    found = _fmt(row.found_error[0], 2, 100, " %") if row.path == "new" else "—"
    notes = [row.error, row.extra.get("sheet_error", ""), "repair would fire" if row.repair else ""]
    note = "; ".join(part for part in notes if part)
    cells = [
        row.material,
        f"{row.angle:.0f}",
        "yes" if row.perspective else "no",
        row.path,
        lattice,
        found,
        _fmt(row.cells, 0, 100, " %"),
        _fmt(row.worst_jump, 1),
        period,
        _fmt(row.stretch, 1, 100, " %"),
        _fmt(row.wrap),
        _fmt(row.copied, 3),
        note,
    ]
    return "| " + " | ".join(cells) + " |"


def _repair_line(row: Row, held: Row) -> str:
    """A case where the repair fires (:func:`report`): as shipped, and the cells with it held off."""
    cells = [
        row.material,
        f"{row.angle:.0f}",
        "yes" if row.perspective else "no",
        ", ".join(row.extra.get("repaired", [])) or "—",
        ", ".join(row.extra.get("levelled", [])) or "—",
        _fmt(row.extra.get("patch_off_lattice_px", math.nan), 1),
        f"{_fmt(row.cells, 0, 100, ' %')} ({_fmt(held.cells, 0, 100, ' %')})",
        _fmt(row.wrap),
        _fmt(row.copied, 3),
    ]
    return "| " + " | ".join(cells) + " |"


def report(rows: list[Row], command: str, seconds: float) -> str:
    """The markdown tables: per group, frame kind and path; every case; the repair's cases."""
    lines = [f"`{command}` ({seconds:.0f} CPU s, {torch.get_num_threads()} thread(s))", ""]
    lines += [SUMMARY_HEADER, _rule(SUMMARY_HEADER)]
    for group in GROUPS:
        for perspective in (False, True):
            for path in ("new", "today"):
                chosen = [r for r in rows if (r.group, r.perspective, r.path) == (group, perspective, path)]
                if chosen:
                    labels = [group, "perspective" if perspective else "flat", path]
                    cells = _group_cells(summarise(chosen), group in MEASURED_GROUPS, path)
                    lines.append("| " + " | ".join(labels + cells) + " |")
    lines += ["", "Every case (new / today):", "", CASE_HEADER, _rule(CASE_HEADER)]
    lines += [_case_line(row) for row in rows if row.path != "shipped"]
    shipped = [row for row in rows if row.path == "shipped"]
    lines += ["", f"The flash-mark repair as it stands fires on the true maps in {len(shipped)} cases:", ""]
    if shipped:
        held = {(r.material, r.angle, r.perspective): r for r in rows if r.path == "new"}
        lines += [REPAIR_HEADER, _rule(REPAIR_HEADER)]
        lines += [_repair_line(row, held[(row.material, row.angle, row.perspective)]) for row in shipped]
    return "\n".join(lines) + "\n"


def _rows_from_json(path: Path) -> list[Row]:
    """The rows a run wrote (``--json``), to report again without measuring."""
    rows = []
    for record in json.loads(path.read_text()):
        for key in ("found_error", "period_error"):
            record[key] = tuple(record[key])
        rows.append(Row(**record))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("outputs/tiling/table.md"))
    parser.add_argument("--json", type=Path, default=None, help="every row as JSON (default: beside --out)")
    parser.add_argument("--only", nargs="*", default=None, help="material names to run (default: all)")
    parser.add_argument("--angles", type=float, nargs="*", default=list(ANGLES))
    parser.add_argument(
        "--perspective",
        type=float,
        nargs=2,
        default=list(PERSPECTIVE),
        help="scale change from the centre to the x and y edges in the perspective frames",
    )
    parser.add_argument(
        "--crop",
        type=int,
        default=CROP,
        help="crop side; above 256 the families are painted larger with the same cells, scans left out",
    )
    parser.add_argument("--frames", choices=("both", "flat", "perspective"), default="both")
    parser.add_argument("--groups", nargs="*", default=list(GROUPS), help="groups to run (default: all)")
    parser.add_argument(
        "--report", type=Path, default=None, help="report a run's JSON again, measuring nothing"
    )
    args = parser.parse_args()
    if args.report is not None:
        print(report(_rows_from_json(args.report), f"(reported again from {args.report})", 0.0))
        return
    started = time.process_time()
    json_path = args.json or args.out.with_suffix(".json")
    rows: list[Row] = []
    side = MATERIAL_SIDE * args.crop // CROP
    chosen = [
        m
        for m in materials()
        if (args.only is None or m.name in args.only)
        and (args.crop == CROP or m.procedural)
        and m.group in args.groups
    ]
    kinds = {"both": ((0.0, 0.0), tuple(args.perspective)), "flat": ((0.0, 0.0),)}
    kinds["perspective"] = (tuple(args.perspective),)
    frames = [
        Frame(args.crop, angle, perspective) for perspective in kinds[args.frames] for angle in args.angles
    ]
    for material in chosen:
        maps = material.paint(side)
        truth, how, cells = None, "", None
        if material.group in PERIODIC_GROUPS:
            truth, how = true_lattice(maps)
        elif material.group == GROUPS[2]:
            cells, truth, how = true_stripes(maps)
        for frame in frames:
            rows.extend(run_case(material, maps, truth, frame, cells))
        # Every material's rows as soon as they are measured: a long run keeps what it has.
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps([asdict(row) for row in rows], indent=1))
        print(
            f"{material.name}: truth {how} {truth} ({time.process_time() - started:.0f} CPU s)",
            file=sys.stderr,
            flush=True,
        )
    command = "OMP_NUM_THREADS=1 python -m research.tiling_table " + " ".join(sys.argv[1:])
    text = report(rows, command.strip(), time.process_time() - started)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    (args.json or args.out.with_suffix(".json")).write_text(
        json.dumps([asdict(row) for row in rows], indent=1)
    )
    print(text)


if __name__ == "__main__":
    main()
