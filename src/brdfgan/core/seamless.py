"""Tileable maps (``brdfgan predict --tileable``): a map set that wraps without a seam, cut from its
own copies the way image quilting joins patches (the minimum-error boundary cut, Efros & Freeman
2001), so that every pixel of the tile is a pixel of the maps and a grout line stays one line.

1. **Roll.** The map set ``M`` (``H × W``) rolled left by ``cx`` columns, ``R[:, j] = M[:, j + cx]``,
   wraps exactly like the maps' own interior step ``cx − 1 → cx``; its only seam is the maps'
   border, now inside at column ``s = W − cx``. :func:`rank_rolls` takes ``cx`` in the middle half
   among the quiet steps (no larger than the maps' typical step, so the wrap does not show) where
   the copies agree best (``M`` and ``M`` shifted by ``cx`` differ least: for a regular pattern a
   whole number of periods, so that grout and plank edges of the two copies coincide), and among
   equally agreeing ones the quietest.
2. **Cut.** In a band around ``s`` the tile takes each pixel from exactly one of two copies: ``R``
   outside two paths, the unrolled ``M`` between them (continuous there: its border is far away).
   Each path runs from the first row to the last, one pixel per row, moving at most one column per
   row, through the half band on its side of ``s``, and follows the pixels where ``R`` and ``M``
   agree: the minimum summed error, by dynamic programming (:func:`min_error_path`). The error is
   computed on all maps together, each normalised by its typical step (:func:`map_scales`), so the
   four maps share one cut and stay aligned; a tie-break (:data:`CONTRAST_WEIGHT`) on the local
   contrast makes the cut avoid edges among equally cheap paths, where a small mismatch would
   show most. The two copies are blended over :data:`FEATHER` pixels across each path only.
3. **The other axis.** The same on the rows of that result, with paths that close around the
   horizontal wrap (the result already tiles horizontally). The crossing of the two seams needs
   nothing more: the second cut is computed on the first's result, so both of its copies carry the
   first cut and the error it sees includes where they differ. The second cut takes some rows of
   the first's result twice and drops others, which can make the column wrap louder than the step
   it was chosen for; then the next column roll in line is tried (:data:`ROLL_ATTEMPTS`).

Every pixel is thus a pixel of one of four copies of ``M`` shifted by ``(0 or cy, 0 or cx)``
(:class:`SeamlessTile`: ``shifts``, ``labels``), except the feathered pixels next to a path.
:func:`copied_fraction` measures that (a cut gives ~1); :func:`blend_reference` keeps the previous
method, a variance-preserving blend of the four copies that shows features twice where copies
overlap, for comparison (``benchmarks/bench_tiling.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import check_single_maps, encode_normal, join_maps, normalize_normal, split_maps

# Channels of each map in a map set, and the maps' names: base colour, normal, roughness, metallic.
MAP_GROUPS = (3, 3, 1, 1)
MAP_NAMES = ("basecolor", "normal", "roughness", "metallic")
# Pixels over which a cut blends its two copies: "a few pixels of feathering" softens a residual
# step along the path without turning the tile into blends (two pixels per path at 2).
FEATHER = 2.0
# Weight of the local contrast in a cut's cost: a tie-break (the error between the copies is what
# decides), so that among equally cheap paths the cut runs through flat areas, not along edges.
CONTRAST_WEIGHT = 0.1
# A map's typical step is floored at one 8-bit level: differences below it do not show, and a
# nearly constant map (metallic 0 with noise) must not steer the cut with its noise.
STEP_FLOOR = 1.0 / 255.0
# copied_fraction's default tolerance, in file units ([0, 1]; normals encoded as (n + 1) / 2):
# two 8-bit levels, so that a feathered pixel where the two copies agree still counts as a copy.
COPY_TOLERANCE = 2.0 / 255.0
# rank_rolls's score: the copies' disagreement over its median among the candidates, plus this
# weight × the wrap step's loudness. A pattern's period (disagreement a fraction of the median)
# outweighs any loudness; where no shift agrees better than another (no period in the photo) the
# quieter wrap wins, with room below the 1.2 goal for the rows (columns) the second cut repeats.
LOUDNESS_WEIGHT = 0.5
# Column rolls tried at most (make_seamless): each costs a whole tile.
ROLL_ATTEMPTS = 6
MIN_SIDE = 16  # each path needs a few positions in a band of a quarter side, clear of the edges


@dataclass(frozen=True)
class SeamlessTile:
    """A tileable map set and how it was cut from the untiled one.

    ``shifts[k] = (dy, dx)``: copy ``k`` is the untiled maps shifted so that its pixel ``(i, j)``
    is ``maps[:, (i + dy) % H, (j + dx) % W]`` (``torch.roll(maps, (-dy, -dx), (-2, -1))``); ``k``
    = 0 is the fully rolled copy, 3 the untiled maps. ``labels[i, j]`` names the copy pixel
    ``(i, j)`` comes from (pixels within a feather of a cut also hold some of the other copy).
    ``cuts``: the four paths, ``(left, right)`` columns per row of the first (vertical) seam — the
    unrolled-in-x copy fills ``left ≤ j < right`` — and ``(top, bottom)`` rows per column of the
    second (horizontal) seam likewise.

    Shape:
        - maps: ``(8, H, W)``
        - labels: ``(H, W)`` int64 in ``0..3``
        - cuts: ``(H,)``, ``(H,)``, ``(W,)``, ``(W,)`` int64
    """

    maps: Tensor
    shifts: tuple[tuple[int, int], ...]
    labels: Tensor
    cuts: tuple[Tensor, Tensor, Tensor, Tensor]


def _group_mean(values: Tensor, groups: Sequence[int]) -> Tensor:
    """The mean over each group's channels. Shape: ``(C, *)`` → ``(len(groups), *)``."""
    return torch.stack([part.mean(dim=0) for part in values.split(list(groups))])


def _groups(image: Tensor, groups: Sequence[int] | None) -> tuple[int, ...]:
    """``groups``, checked against the image's channels (default: every channel its own group)."""
    chosen = tuple(groups) if groups is not None else (1,) * image.shape[0]
    if sum(chosen) != image.shape[0] or min(chosen) < 1:
        raise ValueError(f"channel groups {chosen} do not split {image.shape[0]} channels")
    return chosen


def map_scales(image: Tensor, groups: Sequence[int] | None = None) -> Tensor:
    """Each channel group's typical step: the mean absolute difference between neighbouring pixels
    (rows and columns), at least :data:`STEP_FLOOR`. Errors divided by it weigh every map alike.

    Shape: ``(C, H, W)`` → ``(G,)``.
    """
    check_shape(image, "C H W", name="image")
    chosen = _groups(image, groups)
    steps_x = (image[..., :, 1:] - image[..., :, :-1]).abs().mean(dim=(-2, -1))
    steps_y = (image[..., 1:, :] - image[..., :-1, :]).abs().mean(dim=(-2, -1))
    return _group_mean(0.5 * (steps_x + steps_y), chosen).clamp_min(STEP_FLOOR)


def copy_error(first: Tensor, second: Tensor, scales: Tensor, groups: Sequence[int]) -> Tensor:
    """Per pixel, how much two copies disagree: per channel group the mean squared difference over
    the squared typical step (:func:`map_scales`), summed over the groups.

    Shape: ``(C, H, W)``, ``(C, H, W)``, ``(G,)`` → ``(H, W)``.
    """
    squared = _group_mean((first - second).square(), groups)
    return (squared / scales.square().view(-1, 1, 1)).sum(dim=0)


def local_contrast(image: Tensor, scales: Tensor, groups: Sequence[int]) -> Tensor:
    """Per pixel, the mean absolute step to its four neighbours (missing ones outside the image
    count as no step) over the typical step, summed over the channel groups.

    Shape: ``(C, H, W)``, ``(G,)`` → ``(H, W)``.
    """
    steps = torch.zeros_like(image)
    dx = (image[..., :, 1:] - image[..., :, :-1]).abs()
    dy = (image[..., 1:, :] - image[..., :-1, :]).abs()
    steps[..., :, 1:] += dx
    steps[..., :, :-1] += dx
    steps[..., 1:, :] += dy
    steps[..., :-1, :] += dy
    return (_group_mean(steps / 4.0, groups) / scales.view(-1, 1, 1)).sum(dim=0)


def seam_cost(first: Tensor, second: Tensor, scales: Tensor, groups: Sequence[int]) -> Tensor:
    """What a cut between two copies pays at each pixel: their disagreement (:func:`copy_error`)
    plus :data:`CONTRAST_WEIGHT` × the mean local contrast of the two (:func:`local_contrast`).

    Shape: ``(C, H, W)``, ``(C, H, W)``, ``(G,)`` → ``(H, W)``.
    """
    contrast = 0.5 * (local_contrast(first, scales, groups) + local_contrast(second, scales, groups))
    return copy_error(first, second, scales, groups) + CONTRAST_WEIGHT * contrast


def min_error_path(cost: Tensor, cyclic: bool = False) -> Tensor:
    """The path through ``cost`` from its first row to its last, one position per row, moving at
    most one position between rows, with the least summed cost (dynamic programming). Among equal
    costs it keeps straight. ``cyclic``: the last row's position is also the first row's, so the
    path closes when the rows wrap around (and a tile's wrap joins the same copies on both sides);
    found by fixing the start where the free path starts.

    Shape: ``(N, K)`` → ``(N,)`` int64 positions in ``0..K-1``.

    Example:
        The zero-cost column wins; a zero-cost diagonal is followed one step per row:

        >>> min_error_path(torch.tensor([[1.0, 0.0, 1.0]] * 3)).tolist()
        [1, 1, 1]
        >>> min_error_path(torch.tensor([[0.0, 9.0, 9.0], [9.0, 0.0, 9.0], [9.0, 9.0, 0.0]])).tolist()
        [0, 1, 2]
    """
    check_shape(cost, "N K", name="cost")
    path = _trace(cost, start=None)
    if cyclic and int(path[0]) != int(path[-1]):
        path = _trace(cost, start=int(path[0]))
    return path


def _trace(cost: Tensor, start: int | None) -> Tensor:
    """:func:`min_error_path` without the cycle: from any start, or from ``start`` ending there."""
    rows, width = cost.shape
    inf = torch.tensor(math.inf, dtype=cost.dtype, device=cost.device)
    total = cost[0].clone()
    if start is not None:
        total = torch.where(torch.arange(width, device=cost.device) == start, total, inf)
    back = torch.zeros(rows, width, dtype=torch.int64, device=cost.device)
    columns = torch.arange(width, device=cost.device)
    pad = inf.view(1)
    for row in range(1, rows):
        # Candidates: straight on first, so that ties keep the path straight.
        options = torch.stack([total, torch.cat([pad, total[:-1]]), torch.cat([total[1:], pad])])
        best, choice = options.min(dim=0)
        back[row] = columns + torch.tensor([0, -1, 1], device=cost.device)[choice]
        total = cost[row] + best
    if start is not None:
        total = torch.where(columns == start, total, inf)
    path = torch.empty(rows, dtype=torch.int64, device=cost.device)
    path[-1] = int(torch.argmin(total))
    for row in range(rows - 1, 0, -1):
        path[row - 1] = back[row, path[row]]
    return path


def rank_rolls(image: Tensor, dim: int, groups: Sequence[int] | None = None) -> list[int]:
    """How far to roll ``image`` along ``dim`` (-1: columns, -2: rows) before cutting, best first:
    ``c`` in the middle half, so that line ``c`` comes first and the step ``c − 1 → c`` becomes the
    tile's wrap.

    Candidates are the quiet steps: each channel group's step there (its mean absolute difference
    between the two lines, ``groups`` as in :func:`map_scales`) at most the group's mean step, so
    the wrap is no more visible than a typical step. Among them the one where the copies agree
    best — the least mean squared difference between ``image`` and ``image`` rolled by ``c``
    (normalised per group), e.g. a whole number of a pattern's periods — and, among shifts that
    agree alike, the quietest (:data:`LOUDNESS_WEIGHT`); after the quiet steps, the others from the
    quietest.

    Shape: ``(C, H, W)`` → indices.
    """
    check_shape(image, "C H W", name="image")
    if dim not in (-1, -2):
        raise ValueError(f"dim must be -1 (columns) or -2 (rows), got {dim}")
    chosen = _groups(image, groups)
    length = image.shape[dim]
    low, high = max(1, length // 4), max(2, (3 * length) // 4)
    lines = image.movedim(dim, -1).double()  # (C, other, length)
    steps = (lines[..., 1:] - lines[..., :-1]).abs().mean(dim=-2)  # (C, length − 1): step c−1 → c at c−1
    per_group = _group_mean(steps, chosen)
    loudness = (per_group / per_group.mean(dim=-1, keepdim=True).clamp_min(1e-12)).amax(dim=0)
    # Mean over pixels of (x_j − x_{j+c})² for every c at once: 2 (energy − circular autocorrelation).
    centred = lines - lines.mean(dim=-1, keepdim=True)
    spectrum = torch.fft.rfft(centred, dim=-1)
    autocorrelation = torch.fft.irfft(spectrum.abs().square(), n=length, dim=-1).mean(dim=-2) / length
    energy = centred.square().mean(dim=(-2, -1))
    squared = 2.0 * (energy.unsqueeze(-1) - autocorrelation)  # (C, length)
    scales = map_scales(image.double(), chosen)
    disagreement = (_group_mean(squared, chosen) / scales.square().unsqueeze(-1)).sum(dim=0)
    candidates = torch.arange(low, high)
    wrap = loudness[candidates - 1]
    quiet = wrap <= 1.0
    agreement = disagreement[candidates] / disagreement[candidates].median().clamp_min(1e-12)
    # Quiet candidates by score; then the loud ones by loudness (offset to come after them all).
    score = torch.where(quiet, agreement + LOUDNESS_WEIGHT * wrap, 1e6 + wrap)
    return [int(c) for c in candidates[torch.argsort(score, stable=True)]]


def _ramp(position: Tensor) -> Tensor:
    """0 before a cut, 1 after it, linear over :data:`FEATHER` pixels centred on it: ``position``
    is a pixel centre's signed distance from the cut, in pixels."""
    return (position / FEATHER + 0.5).clamp(0.0, 1.0)


def _cut_columns(
    image: Tensor, shift: int, scales: Tensor, groups: Sequence[int], cyclic: bool
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """One seam (module docstring, steps 1–2): ``image`` rolled left by ``shift`` columns, with the
    band around its seam taken from the unrolled ``image`` between two minimum-error paths.
    ``cyclic``: the paths close around the rows' wrap.

    Shape: ``(C, H, W)`` → the result ``(C, H, W)``, where the unrolled copy is used ``(H, W)``
    bool, the left and right paths ``(H,)`` (the unrolled copy fills ``left ≤ j < right``).
    """
    height, width = image.shape[-2:]
    rolled = torch.roll(image, -shift, dims=-1)
    seam = width - shift  # rolled's columns seam − 1 | seam are the image's last | first column
    # The band stays two columns clear of the tile's first and last (a path's feather reaches one
    # column before it): the wrap is then the rolled copy's own, the maps' interior step.
    half = min(width // 4, seam - 2, width - seam - 2)
    # The cost of the band only, computed with a column of context on each side (the contrast
    # looks at neighbours).
    low, high = seam - half, seam + half
    outer_low, outer_high = max(0, low - 1), min(width, high + 1)
    cost = seam_cost(rolled[..., outer_low:outer_high], image[..., outer_low:outer_high], scales, groups)
    cost = cost[:, low - outer_low : high - outer_low]
    # Left path: the first column from the unrolled copy, in [seam − half, seam − 1] so that the
    # rolled copy never shows both sides of its seam; right path: the first column from the rolled
    # copy again, in [seam, seam + half − 1].
    left = min_error_path(cost[:, :half], cyclic) + low
    right = min_error_path(cost[:, half:], cyclic) + seam
    centres = torch.arange(width, dtype=image.dtype, device=image.device).view(1, width) + 0.5
    left_f = left.to(image.dtype).view(height, 1)
    right_f = right.to(image.dtype).view(height, 1)
    weight = torch.minimum(_ramp(centres - left_f), 1.0 - _ramp(centres - right_f))  # (H, W)
    result = rolled + weight.unsqueeze(0) * (image - rolled)
    columns = torch.arange(width, device=image.device).view(1, width)
    unrolled = (columns >= left.view(height, 1)) & (columns < right.view(height, 1))
    return result, unrolled, left, right


def make_seamless(maps: Tensor) -> SeamlessTile:
    """The map set made tileable by rolling it and cutting each seam along a minimum-error path
    through the copies (module docstring); normals renormalised after the feathering.

    Shape: ``(8, H, W)`` → :class:`SeamlessTile` with ``maps`` ``(8, H, W)``, H and W ≥ 8.
    """
    check_single_maps(maps)
    height, width = maps.shape[-2:]
    if min(height, width) < MIN_SIDE:
        raise ValueError(
            f"maps of {height}x{width} are too small to tile: need at least {MIN_SIDE}x{MIN_SIDE}"
        )
    work = maps.detach().double()
    scales = map_scales(work, MAP_GROUPS)
    # The column wrap is the maps' step at the roll only up to which rows the second cut repeats
    # (it takes some of them twice and drops others): if the tile's wrap comes out louder than a
    # typical step, the next roll in line is tried, and the quietest tile kept.
    best: tuple[float, SeamlessTile] | None = None
    for shift_x in rank_rolls(work, -1, MAP_GROUPS)[:ROLL_ATTEMPTS]:
        tile = _cut_both(work, shift_x, scales)
        loudest = max(max(wrap_ratios(part)) for part in tile.maps.split(list(MAP_GROUPS)))
        if best is None or loudest < best[0]:
            best = (loudest, tile)
        if loudest <= 1.0:
            break
    assert best is not None  # rank_rolls returns at least one candidate
    tile = best[1]
    parts = split_maps(tile.maps)
    tiled = join_maps(parts.basecolor, normalize_normal(parts.normal), parts.roughness, parts.metallic)
    return replace(tile, maps=tiled.to(maps.dtype))


def _cut_both(work: Tensor, shift_x: int, scales: Tensor) -> SeamlessTile:
    """The tile of :func:`make_seamless` for the column roll ``shift_x`` (maps unnormalised)."""
    height = work.shape[-2]
    first, from_x, left, right = _cut_columns(work, shift_x, scales, MAP_GROUPS, cyclic=False)
    # The rows: the same on the transposed result, whose rows (the columns) now wrap.
    shift_y = rank_rolls(first, -2, MAP_GROUPS)[0]
    second, from_y, top, bottom = _cut_columns(
        first.transpose(-2, -1), shift_y, scales, MAP_GROUPS, cyclic=True
    )
    second, from_y = second.transpose(-2, -1), from_y.transpose(-2, -1)
    # Which x copy each pixel holds: its own row's first-pass label where the second pass kept the
    # unrolled rows, else that of the row the vertical roll brought there.
    source_rows = (torch.arange(height, device=work.device) + shift_y) % height
    x_unrolled = torch.where(from_y, from_x, from_x[source_rows])
    labels = 2 * from_y.long() + x_unrolled.long()
    shifts = ((shift_y, shift_x), (shift_y, 0), (0, shift_x), (0, 0))
    return SeamlessTile(second, shifts, labels, (left, right, top, bottom))


def copied_fraction(
    tiled: Tensor, untiled: Tensor, shifts: Sequence[tuple[int, int]], tolerance: float = COPY_TOLERANCE
) -> float:
    """The fraction of ``tiled``'s pixels that are a copy of ``untiled`` at one of ``shifts``: every
    channel within ``tolerance`` of ``untiled[:, (i + dy) % H, (j + dx) % W]``. A cut tile gives ~1,
    a blend of copies much less (a blended pixel equals no copy). The shifts are the copies a tile
    claims to be made of (:class:`SeamlessTile`'s); a wrong claim can only lower the fraction.

    Shape: ``(C, H, W)``, ``(C, H, W)`` → a number in [0, 1].

    Example:
        >>> image = torch.rand(1, 8, 8, generator=torch.Generator().manual_seed(0))
        >>> copied_fraction(torch.roll(image, (-2, -3), (-2, -1)), image, [(2, 3)])
        1.0
        >>> copied_fraction(0.5 * (image + torch.roll(image, 4, -1)), image, [(0, 0), (0, 4)]) < 0.2
        True
    """
    check_shape(tiled, "C H W", name="tiled")
    channels, height, width = tiled.shape
    check_shape(untiled, "C H W", name="untiled", dims={"C": channels, "H": height, "W": width})
    if not tolerance >= 0:
        raise ValueError(f"tolerance must be >= 0, got {tolerance}")
    copied = torch.zeros(height, width, dtype=torch.bool, device=tiled.device)
    for dy, dx in shifts:
        copy = torch.roll(untiled, (-dy, -dx), dims=(-2, -1))
        copied |= (tiled - copy).abs().amax(dim=0) <= tolerance
    return float(copied.double().mean())


@dataclass(frozen=True)
class TilingMeasures:
    """How well a tile wraps and how much of it is copied, per map (:data:`MAP_NAMES`):
    ``wrap_ratio[name] = (columns, rows)`` (:func:`wrap_ratios`, ~1 or less: the wrap looks like an
    interior step) and ``copied_fraction[name]`` (:func:`copied_fraction` in file units)."""

    wrap_ratio: dict[str, tuple[float, float]]
    copied_fraction: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        return {
            "wrap_ratio": {name: list(pair) for name, pair in self.wrap_ratio.items()},
            "copied_fraction": dict(self.copied_fraction),
        }

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> TilingMeasures:
        return cls(
            wrap_ratio={
                str(name): (float(pair[0]), float(pair[1])) for name, pair in record["wrap_ratio"].items()
            },
            copied_fraction={str(name): float(value) for name, value in record["copied_fraction"].items()},
        )


def file_units(maps: Tensor) -> list[Tensor]:
    """Each map of a map set as written to its texture file (normals encoded as ``(n + 1) / 2``),
    in :data:`MAP_NAMES` order. Shape: ``(8, H, W)`` → ``(3|1, H, W)`` each."""
    parts = split_maps(maps)
    return [parts.basecolor, encode_normal(parts.normal), parts.roughness, parts.metallic]


def tiling_measures(
    tiled: Tensor, untiled: Tensor, shifts: Sequence[tuple[int, int]], tolerance: float = COPY_TOLERANCE
) -> TilingMeasures:
    """:class:`TilingMeasures` of the map set ``tiled`` made from copies of ``untiled`` at ``shifts``.

    Shape: ``(8, H, W)``, ``(8, H, W)``.
    """
    check_single_maps(tiled)
    check_single_maps(untiled)
    wrap: dict[str, tuple[float, float]] = {}
    copied: dict[str, float] = {}
    for name, after, before in zip(MAP_NAMES, file_units(tiled), file_units(untiled), strict=True):
        wrap[name] = wrap_ratios(after)
        copied[name] = copied_fraction(after, before, shifts, tolerance)
    return TilingMeasures(wrap, copied)


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


# The previous method, kept as the reference the benchmark compares with.


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
    ``c − 1 → c`` (the worst channel group, relative to its mean step, decides).

    Shape: ``(C, H, W)`` → an index.
    """
    length = image.shape[dim]
    steps = torch.diff(image, dim=dim).abs()  # (C, H, W - 1) for columns
    other = -2 if dim == -1 else -1
    per_line = steps.mean(dim=other)  # (C, length - 1): step i is between lines i and i + 1
    per_group = _group_mean(per_line, groups or (1,) * len(per_line))
    relative = (per_group / per_group.mean(dim=-1, keepdim=True).clamp_min(1e-12)).amax(dim=0)
    low, high = length // 4, (3 * length) // 4
    return int(low + torch.argmin(relative[low - 1 : high - 1])) if high > low else length // 2


def seamless_blend(image: Tensor, cuts: tuple[int, int] | None = None) -> Tensor:
    """The variance-preserving blend of ``image`` with its copies rolled so that line ``cut`` of
    each axis comes first (default: the middle), unclipped. Each copy's weight vanishes on its own
    seam: ``w(M) = wx·wy``, ``w(Rx) = (1 − wx)·wy``, ``w(Ry) = wx·(1 − wy)``, ``w(Rxy) = (1 − wx)·(1
    − wy)`` with ``wx``, ``wy`` rising as ``sin²`` from the borders; ``μ + Σ wᵢ (Lᵢ − μ) / √(Σ wᵢ²)``
    keeps the contrast where copies meet (Burley 2019; Heitz & Neyret 2018).

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


def blend_reference(maps: Tensor) -> tuple[Tensor, tuple[tuple[int, int], ...]]:
    """The previous ``--tileable``: :func:`seamless_blend` of every map with the same weights, rolled
    at :func:`quiet_cut`, clipped, normals renormalised; with the shifts of its four copies (as
    :class:`SeamlessTile`'s) for :func:`copied_fraction`.

    Shape: ``(8, H, W)`` → ``(8, H, W)``.
    """
    check_single_maps(maps)
    cuts = (quiet_cut(maps, -2, MAP_GROUPS), quiet_cut(maps, -1, MAP_GROUPS))
    parts = split_maps(seamless_blend(maps, cuts))
    normal = parts.normal.clone()
    normal[2:3] = normal[2:3].clamp_min(0.05)
    blended = join_maps(
        parts.basecolor.clamp(0.0, 1.0),
        normalize_normal(normal),
        parts.roughness.clamp(0.0, 1.0),
        parts.metallic.clamp(0.0, 1.0),
    )
    cut_y, cut_x = cuts
    return blended, ((cut_y, cut_x), (cut_y, 0), (0, cut_x), (0, 0))
