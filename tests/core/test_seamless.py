"""Tileable maps (``core/seamless.py``): regular patterns keep one line where the input has one, the
cut avoids edges among equally cheap paths, every map shares one cut, a cut tile is copied pixels
(a blend is not), the wrap looks like an interior step, the measures and bad input."""

from __future__ import annotations

import pytest
import torch
from torch import Tensor

from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.seamless import (
    MAP_GROUPS,
    blend_reference,
    copied_fraction,
    copy_error,
    make_seamless,
    map_scales,
    min_error_path,
    seam_cost,
    seamless_blend,
    tiling_measures,
    wrap_ratios,
)
from brdfgan.core.svbrdf import join_maps, normalize_normal, split_maps, validate_maps
from tests.conftest import random_maps

SIZE = 96


def _grid(size: int) -> tuple[Tensor, Tensor]:
    axis = torch.arange(size, dtype=torch.float64)
    return torch.meshgrid(axis, axis, indexing="ij")


def textured_maps(seed: int) -> Tensor:
    """Valid maps with a texture a few pixels across (blurred noise, like a network's maps rather
    than per-pixel noise) and a ramp, so that they do not wrap."""
    maps = gaussian_blur(random_maps(SIZE, SIZE, seed=seed, dtype=torch.float64)[None], 2.0, "reflect")[0]
    _, columns = _grid(SIZE)
    parts = split_maps(maps)
    ramp = 0.3 * columns / SIZE
    return join_maps(
        (parts.basecolor + ramp).clamp(0, 1),
        normalize_normal(parts.normal),
        (parts.roughness + ramp).clamp(0, 1),
        parts.metallic,
    )


def stripe_maps(generator: torch.Generator) -> Tensor:
    """A regular pattern that does not wrap: dark vertical lines 3 px wide every 24 columns in the
    base colour, dark horizontal lines every 32 rows in the roughness, over faint noise and a ramp
    (the photo's left and right edges differ). Lines sit away from the image's own border."""
    rows, columns = _grid(SIZE)
    ramp = 0.1 * columns / SIZE + 0.05 * rows / SIZE
    vertical = ((columns - 8) % 24 < 3).double()
    horizontal = ((rows - 12) % 32 < 3).double()
    noise = 0.02 * torch.rand(4, SIZE, SIZE, generator=generator, dtype=torch.float64)
    base = (0.75 - 0.5 * vertical + ramp + noise[0]).clamp(0, 1).expand(3, -1, -1)
    roughness = (0.7 - 0.5 * horizontal + ramp + noise[1]).clamp(0, 1)
    normal = normalize_normal(torch.stack([0.05 * noise[2], 0.05 * noise[3], torch.ones_like(ramp)]))
    return join_maps(base, normal, roughness[None], torch.zeros(1, SIZE, SIZE, dtype=torch.float64))


def dark_runs(line: Tensor, threshold: float) -> list[tuple[int, int]]:
    """``(start, length)`` of each cyclic run of values below ``threshold`` along a 1-D line."""
    dark = (line < threshold).tolist()
    if all(dark) or not any(dark):
        return [(0, len(dark))] if all(dark) else []
    first_light = dark.index(False)
    order = dark[first_light:] + dark[:first_light]  # starts light: no run straddles the wrap
    runs, start = [], None
    for index, value in enumerate(order):
        if value and start is None:
            start = index
        if not value and start is not None:
            runs.append(((start + first_light) % len(dark), index - start))
            start = None
    if start is not None:
        runs.append(((start + first_light) % len(dark), len(order) - start))
    return runs


def lines_are_intact(image: Tensor, period: int, count: int) -> bool:
    """Every row of ``image`` (``(H, W)``) crosses ``count`` dark lines 2–4 px wide, ``period`` ± 1
    apart around the wrap: one line where the pattern has one, none doubled, broken or lost."""
    for row in image:
        runs = dark_runs(row, 0.5)
        if len(runs) != count or any(not 2 <= length <= 4 for _, length in runs):
            return False
        starts = sorted(start for start, _ in runs)
        gaps = [(b - a) % image.shape[-1] for a, b in zip(starts, starts[1:] + starts[:1], strict=True)]
        if any(abs(gap - period) > 1 for gap in gaps):
            return False
    return True


def test_stripes_tile_with_one_line_where_the_input_has_one() -> None:
    maps = stripe_maps(torch.Generator().manual_seed(0))
    tile = make_seamless(maps)
    parts = split_maps(tile.maps)
    # Vertical lines along every row of the base colour, horizontal ones along every column of the roughness.
    assert lines_are_intact(parts.basecolor[0], period=24, count=SIZE // 24)
    assert lines_are_intact(parts.roughness[0].T, period=32, count=SIZE // 32)
    # Also across the tile's wraps: tiled 2 × 2, the pattern keeps its period.
    doubled = torch.cat([torch.cat([parts.basecolor[0]] * 2, -1)] * 2, -2)
    assert lines_are_intact(doubled, period=24, count=2 * SIZE // 24)
    # The check can fail: the blend of copies (the previous method) shows lines twice or faded.
    blended, _ = blend_reference(maps)
    assert not lines_are_intact(split_maps(blended).basecolor[0], period=24, count=SIZE // 24)


def test_the_cut_avoids_a_high_contrast_feature_when_an_equally_cheap_path_exists() -> None:
    # Two copies that agree everywhere (every path costs nothing in error) with a bright line at
    # columns 1-2 of the band: only the contrast tie-break tells the paths apart.
    band = torch.full((3, 40, 12), 0.4, dtype=torch.float64)
    band[:, :, 1:3] = 0.9
    band[:, 10:30, 8] = 0.1  # and a short dark mark the path must also step around
    scales = map_scales(band, (3,))
    cost = seam_cost(band, band.clone(), scales, (3,))
    path = min_error_path(cost)
    assert (path >= 4).all(), path  # off the line and its edges
    assert ((path[10:30] - 8).abs() >= 2).all(), path  # around the mark
    # Without the tie-break every path is equally cheap and the straight one at column 0, on the bar, wins.
    assert (min_error_path(copy_error(band, band.clone(), scales, (3,))) == 0).all()


def test_min_error_path_follows_the_cheap_pixels_and_closes_when_asked() -> None:
    cost = torch.ones(6, 8, dtype=torch.float64)
    for row in range(6):
        cost[row, row] = 0.0  # a zero-cost diagonal from column 0 to column 5
    assert min_error_path(cost).tolist() == [0, 1, 2, 3, 4, 5]
    closed = min_error_path(cost, cyclic=True)
    assert int(closed[0]) == int(closed[-1])
    assert (closed[1:] - closed[:-1]).abs().max() <= 1


def test_all_maps_share_one_cut_and_every_pixel_away_from_it_is_a_copy() -> None:
    maps = random_maps(SIZE, SIZE, seed=5).double()
    tile = make_seamless(maps)
    labels = tile.labels
    assert labels.shape == (SIZE, SIZE) and set(labels.unique().tolist()) == {0, 1, 2, 3}
    copies = torch.stack([torch.roll(maps, (-dy, -dx), dims=(-2, -1)) for dy, dx in tile.shifts])
    chosen = copies.gather(0, labels.view(1, 1, SIZE, SIZE).expand(1, 8, SIZE, SIZE))[0]
    # Away from a cut (the label constant over the 3 × 3 neighbourhood, wrapping), every channel of
    # every map is exactly the labelled copy: one cut for all maps.
    same = torch.ones(SIZE, SIZE, dtype=torch.bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            same &= torch.roll(labels, (dy, dx), dims=(0, 1)) == labels
    assert same.double().mean() > 0.85
    assert torch.allclose(tile.maps[:, same], chosen[:, same], atol=1e-6)
    # And the paths are the label boundaries: the first seam's unrolled copy fills left <= j < right.
    left, right, top, bottom = tile.cuts
    assert left.shape == right.shape == (SIZE,) and top.shape == bottom.shape == (SIZE,)
    assert (left < right).all() and (top < bottom).all()
    validate_maps(tile.maps.float())


def test_a_cut_tile_is_copied_pixels_and_a_blend_is_not() -> None:
    maps = textured_maps(seed=2)
    tile = make_seamless(maps)
    cut = tiling_measures(tile.maps, maps, tile.shifts)
    # Only the feathered pixels can be blends: two per row or column for each of the four paths,
    # 8 / 96 of the tile at most; on this busy texture most of them differ by more than the tolerance.
    assert min(cut.copied_fraction.values()) > 1.0 - 8 / SIZE - 0.01
    blended, shifts = blend_reference(maps)
    blend = tiling_measures(blended, maps, shifts)
    assert blend.copied_fraction["basecolor"] < 0.3
    # A tile's claim about its copies can only lower the fraction: other shifts explain little.
    wrong = tiling_measures(tile.maps, maps, [(dy + 5, dx + 7) for dy, dx in tile.shifts])
    assert wrong.copied_fraction["basecolor"] < 0.3


def test_seamless_maps_wrap_like_their_interior_and_stay_valid() -> None:
    # A map with a strong left-right and top-bottom seam: a ramp plus texture.
    generator = torch.Generator().manual_seed(0)
    rows, columns = _grid(SIZE)
    ramp = (columns / SIZE * 0.6 + rows / SIZE * 0.3).float()
    maps = random_maps(SIZE, SIZE, seed=3)
    maps[0:3] = (0.2 * maps[0:3] + ramp).clamp(0, 1)
    maps[6] = (0.5 * ramp + 0.3 * torch.rand(SIZE, SIZE, generator=generator)).clamp(0, 1)
    assert min(wrap_ratios(maps[0:3])) > 3.0
    tile = make_seamless(maps)
    assert tile.maps.dtype == maps.dtype
    validate_maps(tile.maps)
    measures = tiling_measures(tile.maps, maps, tile.shifts)
    for name, (columns_ratio, rows_ratio) in measures.wrap_ratio.items():
        assert columns_ratio <= 1.2 and rows_ratio <= 1.2, (name, columns_ratio, rows_ratio)


def test_the_reference_blend_preserves_contrast() -> None:
    # Variance-preserving: the blend keeps the texture's contrast (a plain average would halve it
    # where four copies meet).
    noise = torch.rand(1, SIZE, SIZE, generator=torch.Generator().manual_seed(0))
    blended = seamless_blend(noise)
    centre = blended[0, SIZE // 4 - 8 : SIZE // 4 + 8, SIZE // 4 - 8 : SIZE // 4 + 8]
    assert centre.std() == pytest.approx(float(noise.std()), rel=0.25)


def test_copied_fraction_counts_pixels_within_the_tolerance() -> None:
    image = torch.rand(2, 16, 16, generator=torch.Generator().manual_seed(0))
    shifted = torch.roll(image, (-3, -5), dims=(-2, -1))
    assert copied_fraction(shifted, image, [(3, 5)]) == 1.0
    assert copied_fraction(shifted, image, [(0, 0)]) < 0.1
    nudged = shifted.clone()
    nudged[:, :4] += 0.5  # a quarter of the rows off by more than the tolerance
    assert copied_fraction(nudged, image, [(3, 5)]) == pytest.approx(0.75)
    assert copied_fraction(nudged, image, [(3, 5)], tolerance=0.6) == 1.0
    assert copied_fraction(nudged, image, [(0, 0), (3, 5)]) == pytest.approx(0.75)


def test_bad_input_is_one_line() -> None:
    with pytest.raises(ValueError, match="too small to tile"):
        make_seamless(random_maps(6, 32))
    with pytest.raises(ValueError, match="maps"):
        make_seamless(torch.zeros(7, 32, 32))
    with pytest.raises(ValueError, match="untiled must have shape"):
        copied_fraction(torch.zeros(3, 8, 8), torch.zeros(3, 8, 9), [(0, 0)])
    with pytest.raises(ValueError, match="tolerance"):
        copied_fraction(torch.zeros(3, 8, 8), torch.zeros(3, 8, 8), [(0, 0)], tolerance=-1.0)
    with pytest.raises(ValueError, match="channel groups"):
        map_scales(torch.zeros(4, 8, 8), MAP_GROUPS)
