"""Pattern-true tiling (``core/lattice.py``): a synthetic lattice's vectors are found at any angle
and in mild perspective, textures without a 2-D lattice (noise, stripes, wood grain) are not
periodic, and a whole-cell tile keeps every cell whole across its seams while still wrapping like
its interior; today's cut does not, which is what the cell test catches."""

from __future__ import annotations

import json
import math

import pytest
import torch
from torch import Tensor

from brdfgan.core import lattice as lattice_module
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.lattice import (
    ALL_FEATURES,
    MIN_BAND,
    MIN_PERIOD,
    RETRY_KEYSTONE,
    SELF_MATCH,
    SELF_MATCH_GAIN,
    WINDOW_SHARE,
    CellTiling,
    Lattice,
    Perspective,
    _perspective_in_windows,
    cell_match,
    central_lattice,
    choose_cells,
    cut_wrap,
    detection_features,
    feature_groups,
    find_lattice,
    find_perspective,
    fold_inside,
    rectify,
    reduce_basis,
    refine_lattice,
    refine_perspective,
    sample_cells,
    tile_whole_cells,
)
from brdfgan.core.seamless import file_units, make_seamless, wrap_ratios
from brdfgan.core.svbrdf import flat_maps, join_maps, normalize_normal, validate_maps

SIZE = 192
Vector = tuple[float, float]


def polar(length: float, degrees: float) -> Vector:
    """``(dx, dy)`` of a vector ``length`` long at ``degrees`` (clockwise on screen from +x)."""
    return (length * math.cos(math.radians(degrees)), length * math.sin(math.radians(degrees)))


def lattice_maps(
    a: Vector,
    b: Vector,
    *,
    size: int = SIZE,
    perspective: Vector = (0.0, 0.0),
    noise: float = 0.05,
    seed: int = 0,
) -> Tensor:
    """Maps of tiles on the lattice ``a``, ``b``: dark grout 1.5 px wide along the cells' edges
    (recessed: the normals tilt into it), a bright dot at each cell's centre, blurred noise and a
    shading ramp (so that the photo itself does not wrap). ``perspective = (gx, gy)``: the plane
    is seen through ``q = c + (x − c) / (1 + g·(x − c))`` around the centre ``c``, a homography whose
    scale changes by ``±g·side/2`` across the image and whose Jacobian at ``c`` is the identity."""
    generator = torch.Generator().manual_seed(seed)
    axis = torch.arange(size, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    dx, dy = xx - size / 2, yy - size / 2
    depth = 1.0 + perspective[0] * dx + perspective[1] * dy
    qx, qy = size / 2 + dx / depth, size / 2 + dy / depth
    inverse = torch.linalg.inv(torch.tensor([a, b], dtype=torch.float64).T)
    coords = torch.stack([qx, qy], dim=-1) @ inverse.T  # lattice coordinates of each pixel
    offset = coords - torch.round(coords)  # within the cell, centred on a lattice point
    # Distances in pixels to the cell's edges (half a cell from its lattice point) and to its centre.
    edge = (0.5 - offset.abs()) * torch.tensor([math.hypot(*a), math.hypot(*b)], dtype=torch.float64)
    grout = torch.exp(-((edge.amin(dim=-1) / 1.5) ** 2))
    centre = torch.exp(
        -(offset.square() * torch.tensor([math.hypot(*a) ** 2, math.hypot(*b) ** 2])).sum(-1) / 8.0
    )
    speckle = gaussian_blur(
        torch.rand(1, 2, size, size, generator=generator, dtype=torch.float64), 1.0, "reflect"
    )
    speckle = (speckle[0] - 0.5) * 2.0 * noise
    ramp = 0.1 * xx / size
    luminance = 0.65 - 0.4 * grout + 0.25 * centre + speckle[0] + ramp
    basecolor = luminance.clamp(0, 1) * torch.tensor([1.0, 0.92, 0.85], dtype=torch.float64).view(3, 1, 1)
    gy, gx = torch.gradient(-grout)
    normal = normalize_normal(torch.stack([-0.5 * gx, 0.5 * gy, torch.ones_like(gx)]))
    roughness = (0.5 + 0.3 * grout + speckle[1]).clamp(0, 1)[None]
    return join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))


def noise_maps(seed: int, sigma: float = 3.0) -> Tensor:
    """Blurred noise in every map: texture with no period."""
    generator = torch.Generator().manual_seed(seed)
    field = gaussian_blur(
        torch.rand(1, 5, SIZE, SIZE, generator=generator, dtype=torch.float64), sigma, "reflect"
    )[0]
    field = 0.5 + (field - 0.5) * 4.0
    tilt = torch.cat([field[3:5] - 0.5, torch.ones(1, SIZE, SIZE, dtype=torch.float64)])
    return join_maps(
        field[0:3].clamp(0, 1),
        normalize_normal(tilt),
        field[0:1].clamp(0, 1),
        torch.zeros(1, SIZE, SIZE, dtype=torch.float64),
    )


def stripe_maps(seed: int, *, wavy: bool) -> Tensor:
    """A 1-D pattern: stripes every 9 px at 20° (``wavy``: wood grain, the stripes' phase and width
    wandering with position and noise over it; else perfect stripes)."""
    generator = torch.Generator().manual_seed(seed)
    axis = torch.arange(SIZE, dtype=torch.float64)
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    across = -math.sin(math.radians(20)) * xx + math.cos(math.radians(20)) * yy
    along = math.cos(math.radians(20)) * xx + math.sin(math.radians(20)) * yy
    phase = 2 * math.pi * across / 9.0
    if wavy:
        phase = phase + 1.5 * torch.sin(along / 23.0) + 0.8 * torch.sin(across / 31.0 + along / 57.0)
    grain = 0.5 + 0.5 * torch.cos(phase)
    speckle = gaussian_blur(
        torch.rand(1, 1, SIZE, SIZE, generator=generator, dtype=torch.float64), 1.0, "reflect"
    )[0, 0]
    luminance = (0.35 + 0.3 * grain + (0.3 * (speckle - 0.5) if wavy else 0.0)).clamp(0, 1)
    gy, gx = torch.gradient(grain)
    normal = normalize_normal(torch.stack([-0.2 * gx, 0.2 * gy, torch.ones_like(gx)]))
    roughness = (0.6 - 0.2 * grain)[None]
    basecolor = luminance * torch.tensor([0.8, 0.5, 0.3], dtype=torch.float64).view(3, 1, 1)
    return join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))


def assert_same_lattice(found: Lattice, truth: tuple[Vector, Vector], tolerance: float) -> None:
    """``found`` is periodic and each true vector is one of ``±a``, ``±b`` within ``tolerance`` of
    its length (which bounds both the length's and the angle's error)."""
    assert found.periodic and found.vectors is not None, found
    candidates = [sign * torch.tensor(vector) for vector in found.vectors for sign in (1.0, -1.0)]
    for vector in reduce_basis(*truth):
        true = torch.tensor(vector, dtype=torch.float64)
        error = min(float((candidate - true).norm()) for candidate in candidates)
        assert error <= tolerance * float(true.norm()), (found.vectors, truth, error)


def test_a_lattice_at_30_degrees_is_found_within_one_percent() -> None:
    # Vectors half a pixel from the integer grid: the nearest whole-pixel peaks are 1.7 % off, so
    # only the sub-pixel fit passes.
    truth = (polar(23.3, 30.0), polar(29.1, 120.0))
    found = find_lattice(lattice_maps(*truth))
    assert_same_lattice(found, truth, 0.01)
    assert found.score > 0.3 and not found.ambiguous


def test_a_lattice_only_the_colour_repeats_is_read_from_the_colour() -> None:
    # A scanned checkerboard of marble: the slabs' colour repeats, their relief is each slab's own.
    # Both groups together blur the lattice's peaks (the scan: 0.7 % off, or none found at 15°);
    # the colour alone finds it, and the relief's own lattice is kept where the relief repeats too.
    truth = (polar(34.3, 30.0), polar(34.3, 120.0))
    maps = lattice_maps(*truth, seed=2)
    assert find_lattice(maps).features == ALL_FEATURES
    height = gaussian_blur(
        torch.rand(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(52), dtype=torch.float64),
        1.0,
        "reflect",
    )[0, 0]
    slope_y, slope_x = torch.gradient(20.0 * height)
    maps[3:6] = normalize_normal(torch.stack([-slope_x, slope_y, torch.ones_like(slope_x)]))
    found = find_lattice(maps)
    assert found.features == "colour" and Lattice.from_json(found.to_json()) == found
    assert_same_lattice(found, truth, 0.005)
    # Their cells are matched and closed on the colour too (the relief does not match).
    assert cell_match(maps, truth, "colour") > 0.5 > cell_match(maps, truth)


def test_a_45_degree_grid_like_the_ceramic_sample_is_found() -> None:
    truth = (polar(40.0, 45.0), polar(40.0, 135.0))
    assert_same_lattice(find_lattice(lattice_maps(*truth, seed=1)), truth, 0.01)


def test_mild_perspective_still_finds_the_lattice() -> None:
    # ±4 % scale from one side to the other, along a diagonal: the peaks broaden and drift, and the
    # fit over several multiples recovers the lattice at the centre.
    truth = (polar(22.0, 10.0), polar(26.0, 100.0))
    maps = lattice_maps(*truth, perspective=(0.04 / (SIZE / 2), 0.03 / (SIZE / 2)), seed=2)
    assert_same_lattice(find_lattice(maps), truth, 0.03)


def sheet_residual(maps: Tensor) -> float:
    """How far (px) the cells' dots of the maps' whole-cell tile, repeated 2 × 2, lie off one
    lattice (the maps' own, carried through the tiling's resampling)."""
    lattice = find_lattice(maps)
    assert lattice.vectors is not None
    tiling = choose_cells(lattice.vectors, SIZE, SIZE)
    assert tiling is not None
    a, b = (tiling.affine() @ torch.tensor(vector, dtype=torch.float64) for vector in lattice.vectors)
    sheet = tile_whole_cells(maps, tiling).maps.repeat(1, 2, 2)
    return float(lattice_residual(cell_centres(sheet), a, b).max())


def test_mild_perspective_is_measured_and_taken_out_so_that_every_cell_stays_whole() -> None:
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    g = (0.02 / (SIZE / 2), -0.015 / (SIZE / 2))  # ±2 % and ∓1.5 % to the edges: ~2° of tilt
    maps = lattice_maps(*truth, perspective=g, seed=7)
    lattice = find_lattice(maps)
    perspective = find_perspective(maps, lattice)
    assert perspective is not None and perspective.spread_after < 0.5 * perspective.spread_before
    assert perspective.keystone == pytest.approx((0.02, -0.015), abs=0.003)
    assert Perspective.from_json(json.loads(json.dumps(perspective.to_json()))) == perspective
    straight = rectify(maps, perspective)
    validate_maps(straight)
    assert find_perspective(straight, find_lattice(straight)) is None  # nothing left to take out
    # Tiled from the rectified maps, every dot of the 2 × 2 sheet is on one lattice; from the maps
    # as they are, the cells drift by the keystone and the wrap joins them out of step.
    assert sheet_residual(straight) < 1.0 < 1.5 < sheet_residual(maps)
    # A lattice seen square-on has no perspective to take out.
    flat = lattice_maps(*truth, seed=7)
    assert find_perspective(flat, find_lattice(flat)) is None


def test_a_lattice_too_foreshortened_to_pass_is_found_once_rectified() -> None:
    # A 6 % keystone broadens the autocorrelation's peaks until the score falls under the threshold;
    # the perspective is still measured from the candidate lattice, and the rectified maps pass.
    g = (0.06 / (SIZE / 2), -0.045 / (SIZE / 2))
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=1)
    found = find_lattice(maps)
    assert found.ambiguous and not found.periodic, found
    perspective = find_perspective(maps, found)
    assert perspective is not None and perspective.keystone == pytest.approx((0.06, -0.045), abs=0.005)
    assert find_lattice(rectify(maps, perspective)).score > 4 * found.score


def test_a_lattice_perspective_hides_from_the_whole_maps_is_seeded_from_their_centre() -> None:
    # An 8 % keystone smears the far peaks past even the ambiguous band over the whole maps; in their
    # central half the scale varies half as much and the lattice stands out. It seeds the perspective,
    # and the rectified maps show the lattice on their own.
    truth = (0.08, -0.06)
    g = (truth[0] / (SIZE / 2), truth[1] / (SIZE / 2))
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=1)
    whole = find_lattice(maps)
    assert not (whole.periodic or whole.ambiguous), whole
    assert find_perspective(maps, whole) is None
    centre = central_lattice(maps)
    assert_same_lattice(centre, (polar(24.0, 30.0), polar(30.0, 120.0)), 0.03)
    perspective = find_perspective(maps, centre)
    assert perspective is not None
    refined, _, straight = refine_perspective(maps, perspective)
    assert refined.keystone == pytest.approx(truth, abs=0.003)
    assert straight.periodic and straight.score > 4 * whole.score


def test_the_central_lattice_is_sought_at_the_whole_maps_detection_scale(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Maps larger than the detection side: their centre is shrunk as the whole maps are for
    # detection, and the vectors come back in the maps' pixels.
    monkeypatch.setattr(lattice_module, "DETECT_SIDE", SIZE)
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    maps = lattice_maps(*truth, seed=3)
    doubled = torch.nn.functional.interpolate(maps[None], scale_factor=2, mode="bilinear")[0]
    centre = central_lattice(doubled)
    assert centre.periodic
    (ax, ay), (bx, by) = truth
    assert_same_lattice(centre, ((2 * ax, 2 * ay), (2 * bx, 2 * by)), 0.02)


def test_one_window_of_other_tiles_does_not_hold_the_perspective_back() -> None:
    # A corner of tiles 6 % larger (a patch of another batch): its window's lattice is off the
    # keystone's trend, and with all nine windows the fit leaves more than half their spread. Fitted
    # without that window, the keystone is the rest's.
    truth = (0.02, -0.015)
    g = (truth[0] / (SIZE / 2), truth[1] / (SIZE / 2))
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=7)
    larger = lattice_maps(polar(24.0 * 1.06, 30.0), polar(30.0 * 1.06, 120.0), perspective=g, seed=8)
    maps[:, -64:, -64:] = larger[:, -64:, -64:]
    lattice = find_lattice(maps)
    perspective = find_perspective(maps, lattice)
    assert perspective is not None and perspective.keystone == pytest.approx(truth, abs=0.002)
    assert perspective.spread_after < 0.5 * perspective.spread_before


def test_windows_too_small_to_agree_on_the_keystone_give_way_to_the_largest() -> None:
    # Tiles of uneven shade (a blurred random field across them, as on a scanned floor): in windows
    # of half the side (two and a half cells) each lattice is a pixel or so off, as much as the
    # keystone moves it, and no perspective explains them; windows of three quarters agree.
    truth = (0.02, -0.015)
    g = (truth[0] / (SIZE / 2), truth[1] / (SIZE / 2))
    maps = lattice_maps(polar(38.0, 15.0), polar(38.0, 105.0), perspective=g, seed=0)
    field = torch.rand(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(100), dtype=torch.float64)
    field = gaussian_blur(field, 6.0, "reflect")[0]
    maps[0:3] = (maps[0:3] * (1 + 0.25 * (field - field.mean()) / field.std())).clamp(0, 1)
    lattice = find_lattice(maps)
    assert lattice.periodic and lattice.vectors is not None
    assert WINDOW_SHARE == (0.5, 0.75)
    features, factor = detection_features(maps)
    features, groups = feature_groups(features, lattice.features)
    start = torch.tensor(lattice.vectors, dtype=torch.float64) / factor
    small, seen = _perspective_in_windows(features, groups, factor, start, 0.5, (SIZE, SIZE))
    assert small is None and seen >= RETRY_KEYSTONE  # they see a keystone, and the larger are tried
    perspective = find_perspective(maps, lattice)
    assert perspective is not None and perspective.keystone == pytest.approx(truth, abs=0.002)


def test_a_square_on_lattice_is_measured_in_one_grid_of_windows(monkeypatch: pytest.MonkeyPatch) -> None:
    # The smallest windows agree that there is no keystone: the largest are not tried (their nine
    # autocorrelations were most of find_perspective's time at 2048²).
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), seed=7)
    calls: list[float] = []

    def counted(*args: object) -> tuple[Perspective | None, float]:
        calls.append(args[4])  # type: ignore[arg-type]
        return _perspective_in_windows(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(lattice_module, "_perspective_in_windows", counted)
    assert find_perspective(maps, find_lattice(maps)) is None
    assert calls == [WINDOW_SHARE[0]]


@pytest.mark.parametrize("working_side", [256, 96])
def test_a_lattice_of_two_cells_a_side_has_its_perspective_fitted_to_the_whole_maps(
    monkeypatch: pytest.MonkeyPatch, working_side: int
) -> None:
    # Cells of 88 px in 192² (a checkerboard of marble slabs two to a crop): no window holds two
    # cells, so the maps' match with themselves one lattice vector on measures the keystone; also
    # where the maps are larger than the fit's working side (shrunk first, as 2048² maps are).
    monkeypatch.setattr(lattice_module, "SELF_MATCH_SIDE", working_side)
    truth = (0.02, -0.015)
    g = (truth[0] / (SIZE / 2), truth[1] / (SIZE / 2))
    cells = (polar(88.0, 30.0), polar(88.0, 120.0))
    maps = lattice_maps(*cells, perspective=g, seed=3)
    lattice = find_lattice(maps)
    perspective = find_perspective(maps, lattice)
    assert perspective is not None and perspective.method == SELF_MATCH
    assert perspective.keystone == pytest.approx(truth, abs=0.003)
    assert perspective.spread_after <= SELF_MATCH_GAIN * perspective.spread_before
    assert Perspective.from_json(json.loads(json.dumps(perspective.to_json()))) == perspective
    # Fitted to the whole maps, it is not measured a second time.
    assert refine_perspective(maps, perspective)[0] == perspective
    # Square-on, the same lattice shows no perspective.
    square_on = lattice_maps(*cells, seed=3)
    assert find_perspective(square_on, find_lattice(square_on)) is None


def test_a_windows_perspective_completed_by_a_self_match_keeps_its_own_spreads() -> None:
    # A windows' spread (px) and a self-match residual do not compare: the composition keeps the
    # first fit's pair and names both methods.
    windows = Perspective((1e-4, 0.0), (96.0, 96.0), (0.0096, 0.0), 1.2, 0.3)
    rest = Perspective((2e-5, 1e-5), (96.0, 96.0), (0.00192, 0.00096), 0.5, 0.4, method=SELF_MATCH)
    both = windows.then(rest)
    assert both.g == pytest.approx((1.2e-4, 1e-5)) and both.keystone == pytest.approx((0.01152, 0.00096))
    assert (both.spread_before, both.spread_after) == (1.2, 0.3)
    assert both.method == "windows, then self-match"
    assert Perspective.from_json(json.loads(json.dumps(both.to_json()))) == both
    assert windows.then(windows).spread_after == 0.3 and windows.then(windows).method == "windows"


def test_a_perspective_that_overshoots_is_measured_again_on_the_maps_it_rectifies() -> None:
    truth = (0.02, -0.015)
    g = (truth[0] / (SIZE / 2), truth[1] / (SIZE / 2))
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=7)
    centre = (SIZE / 2, SIZE / 2)
    overshot = Perspective((1.3 * g[0], 1.3 * g[1]), centre, (1.3 * truth[0], 1.3 * truth[1]), 1.0, 0.5)
    refined, rectified, straight = refine_perspective(maps, overshot)
    assert torch.equal(rectified, rectify(maps, refined)) and straight.vectors is not None
    again = find_lattice(rectified).vectors
    assert again is not None and torch.allclose(
        torch.tensor(straight.vectors), torch.tensor(again), atol=1e-6
    )
    assert refined.keystone == pytest.approx(truth, abs=0.002) and refined.spread_before == 1.0
    assert refined.g == pytest.approx((refined.keystone[0] / (SIZE / 2), refined.keystone[1] / (SIZE / 2)))
    # A perspective that leaves nothing to measure is returned as it is.
    assert refine_perspective(maps, refined)[0] == refined


def brick_maps(width: float, height: float, degrees: float, *, size: int = SIZE, seed: int = 0) -> Tensor:
    """Running-bond bricks ``width × height`` (every other course shifted by half a brick), turned
    ``degrees``: the horizontal mortar runs through (a ridge in the autocorrelation), only the
    head joints make the lattice's peaks."""
    generator = torch.Generator().manual_seed(seed)
    axis = torch.arange(size, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    cosine, sine = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    x, y = cosine * xx + sine * yy, -sine * xx + cosine * yy
    course = torch.floor(y / height)
    shifted = x + 0.5 * width * (course % 2)
    to_joint = torch.minimum(
        (shifted - width * torch.round(shifted / width)).abs(), (y - height * torch.round(y / height)).abs()
    )
    mortar = torch.exp(-((to_joint / 1.5) ** 2))
    speckle = gaussian_blur(
        torch.rand(1, 1, size, size, generator=generator, dtype=torch.float64), 1.0, "reflect"
    )
    luminance = (0.6 - 0.35 * mortar + 0.1 * (speckle[0, 0] - 0.5) + 0.05 * torch.sin(1.7 * course)).clamp(
        0, 1
    )
    gy, gx = torch.gradient(-mortar)
    normal = normalize_normal(torch.stack([-0.5 * gx, 0.5 * gy, torch.ones_like(gx)]))
    basecolor = luminance * torch.tensor([0.8, 0.45, 0.35], dtype=torch.float64).view(3, 1, 1)
    roughness = (0.6 + 0.2 * mortar)[None]
    return join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))


def setts_maps(seed: int = 3) -> Tensor:
    """Setts: courses 16 px high of stones 32 px long, each its own grey, whose head joints wander
    (a random shift per course): the bed joints make a ridge, the stones only echo a lattice."""
    generator = torch.Generator().manual_seed(seed)
    axis = torch.arange(SIZE, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    course = torch.floor(yy / 16.0).long()
    shifted = xx + 32.0 * torch.rand(int(course.max()) + 1, generator=generator, dtype=torch.float64)[course]
    stone = torch.rand(int(course.max()) + 1, SIZE // 32 + 2, generator=generator, dtype=torch.float64)
    along, across = shifted % 32.0, yy % 16.0
    joint = torch.minimum(torch.minimum(along, 32.0 - along), torch.minimum(across, 16.0 - across))
    grey = 0.25 + 0.5 * stone[course, torch.floor(shifted / 32.0).long()]
    setts = flat_maps(SIZE, SIZE)
    setts[0:3] = 0.1 + (grey - 0.1) * (1.0 - torch.exp(-((joint / 1.5) ** 2)))
    return setts


def test_running_bond_bricks_are_a_lattice_of_half_offset_courses() -> None:
    # Bricks 40 × 15 turned 20°: the lattice is (40, 0) and (20, 15) in the wall, turned; the
    # through-running bed joints are a ridge that the head joints' peaks stand out from.
    turn = math.radians(20.0)

    def wall(x: float, y: float) -> Vector:
        return (math.cos(turn) * x - math.sin(turn) * y, math.sin(turn) * x + math.cos(turn) * y)

    maps = brick_maps(40.0, 15.0, 20.0)
    lattice = find_lattice(maps)
    assert_same_lattice(lattice, (wall(40.0, 0.0), wall(20.0, 15.0)), 0.01)
    assert lattice.vectors is not None
    # Tiled by whole cells, the sheet of 2 × 2 tiles is one wall: its lattice is the tile's.
    tiling = choose_cells(lattice.vectors, SIZE, SIZE)
    assert tiling is not None
    sheet = tile_whole_cells(maps, tiling).maps.repeat(1, 2, 2)
    a, b = (
        (tiling.affine() @ torch.tensor(vector, dtype=torch.float64)).tolist() for vector in lattice.vectors
    )
    assert_same_lattice(find_lattice(sheet), ((a[0], a[1]), (b[0], b[1])), 0.02)


def test_a_lattice_finer_than_the_shortest_period_is_read_by_whole_multiples() -> None:
    # Periods under MIN_PERIOD are texture (a scanned tile's grain, resampled at 45° in perspective,
    # made a peak at 3.7 px that hid Tiles065's 64 px lattice): a 4.5 px grid is read as a coarser
    # lattice of its own, whose cells are whole numbers of its cells.
    found = find_lattice(lattice_maps((4.5, 0.0), (0.0, 4.5), noise=0.0))
    assert found.periodic and found.vectors is not None
    for dx, dy in found.vectors:
        assert math.hypot(dx, dy) >= MIN_PERIOD
        assert abs(dx / 4.5 - round(dx / 4.5)) < 0.02 and abs(dy / 4.5 - round(dy / 4.5)) < 0.02


@pytest.mark.parametrize(
    "maps",
    [noise_maps(3), noise_maps(4, sigma=8.0), stripe_maps(5, wavy=False), stripe_maps(6, wavy=True)],
    ids=["fine noise", "coarse noise", "stripes", "wood grain"],
)
def test_textures_without_a_2d_lattice_are_not_periodic(maps: Tensor) -> None:
    # Stripes repeat along one direction only: a ridge in the autocorrelation, no isolated peak.
    # They are classed non-periodic on purpose and keep the minimum-error cut (module docstring).
    found = find_lattice(maps)
    assert not found.periodic, found
    assert found.score < 0.1


def test_blurred_noise_is_not_periodic_over_many_seeds_and_grain_sizes() -> None:
    # Coarse noise in small maps has few independent blobs, so its autocorrelation has chance
    # bumps; a chance pair of them has no peak at its sum and difference (measured: 0 of 240
    # draws periodic, the highest score 0.092 with 25-pixel grain at 192²).
    for seed in range(6):
        for sigma in (2.0, 6.0):
            found = find_lattice(noise_maps(300 + seed, sigma=sigma))
            assert not found.periodic, (seed, sigma, found)


def test_constant_maps_are_not_periodic() -> None:
    maps = flat_maps(32, 32, basecolor=(0.5, 0.5, 0.5))
    found = find_lattice(maps)
    assert found.vectors is None and not found.periodic and found.score == 0.0


def test_reduce_basis_finds_the_shortest_basis_of_the_same_lattice() -> None:
    generator = torch.Generator().manual_seed(0)
    a, b = polar(10.0, 17.0), polar(13.0, 95.0)
    for _ in range(20):
        # A random unimodular change of basis: the same lattice, long and skewed vectors.
        m = torch.randint(-5, 6, (2,), generator=generator).tolist()
        unimodular = [[1, m[0]], [0, 1]] if m[1] % 2 else [[1, 0], [m[0], 1]]
        skew = [[1, 0], [m[1], 1]]
        matrix = torch.tensor(unimodular, dtype=torch.float64) @ torch.tensor(skew, dtype=torch.float64)
        basis = matrix @ torch.tensor([a, b], dtype=torch.float64)
        reduced = reduce_basis(
            (float(basis[0, 0]), float(basis[0, 1])), (float(basis[1, 0]), float(basis[1, 1]))
        )
        lengths = sorted(math.hypot(*vector) for vector in reduced)
        assert lengths == pytest.approx([10.0, 13.0], abs=1e-9)
        ax, ay = reduced[0]
        bx, by = reduced[1]
        assert ax * by - ay * bx > 0 and (ay > 0 or (ay == 0 and ax > 0))
    with pytest.raises(ValueError, match="parallel"):
        reduce_basis((2.0, 1.0), (4.0, 2.0))


def cell_centres(tile: Tensor) -> Tensor:
    """The cells' bright centre dots in a tile, found as the tile repeats (local maxima of the
    luminance over their 7 × 7 neighbourhood with wrap-around): a dot cut by a seam is found twice
    or at a wrong place. Shape: ``(8, H, W)`` → ``(N, 2)`` positions ``(x, y)``, sub-pixel."""
    luminance = tile[0:3].mean(dim=0)
    height, width = luminance.shape
    padded = torch.cat([luminance[-3:], luminance, luminance[:3]])
    padded = torch.cat([padded[:, -3:], padded, padded[:, :3]], dim=1)
    pooled = torch.nn.functional.max_pool2d(padded[None, None], 7, stride=1)[0, 0]
    level = luminance.quantile(0.98)
    ys, xs = torch.nonzero((luminance >= pooled) & (luminance >= level), as_tuple=True)
    # Each dot's centroid over its 5 × 5 neighbourhood (wrapping) for sub-pixel positions.
    offsets = torch.arange(-2, 3)
    positions = []
    for y, x in zip(ys.tolist(), xs.tolist(), strict=True):
        rows, cols = (y + offsets) % height, (x + offsets) % width
        patch = (luminance[rows][:, cols] - level).clamp_min(0)
        total = float(patch.sum())
        positions.append(
            (
                x + float((patch.sum(0) * offsets).sum()) / total,
                y + float((patch.sum(1) * offsets).sum()) / total,
            )
        )
    return torch.tensor(positions, dtype=torch.float64)


def lattice_residual(points: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """How far each point is from the lattice ``a``, ``b`` through the first one, in pixels.
    Shape: ``(N, 2)``, ``(2,)``, ``(2,)`` → ``(N,)``."""
    relative = points - points[0]
    coordinates = relative @ torch.linalg.inv(torch.stack([a, b]))
    snapped = torch.round(coordinates) @ torch.stack([a, b])
    return (relative - snapped).norm(dim=-1)


def test_whole_cell_tiles_keep_every_cell_across_the_seams_and_wrap() -> None:
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    maps = lattice_maps(*truth, seed=7)
    lattice = find_lattice(maps)
    assert lattice.vectors is not None
    tiling = choose_cells(lattice.vectors, SIZE, SIZE)
    assert isinstance(tiling, CellTiling) and tiling.cells >= 10 and tiling.stretch <= 0.1
    tile = tile_whole_cells(maps, tiling)
    validate_maps(tile.maps)
    # The lattice as the tile shows it: the affine map of the resampling applied to the vectors.
    affine = tiling.affine()
    a, b = (affine @ torch.tensor(vector, dtype=torch.float64) for vector in lattice.vectors)
    # Tiled 2 × 2: one dot per cell, every dot on one lattice, across the seams too.
    sheet = tile.maps.repeat(1, 2, 2)
    centres = cell_centres(sheet)
    assert centres.shape[0] == 4 * tiling.cells, (centres.shape, tiling.cells)
    assert float(lattice_residual(centres, a, b).max()) < 1.0
    # The sheet's own lattice is the tile's: whole periods of it span the tile.
    assert_same_lattice(find_lattice(sheet), ((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))), 0.02)
    # Today's wrap measure still holds, and the tile is copied pixels of the resampled maps.
    for image in file_units(tile.maps):
        assert max(wrap_ratios(image)) <= 1.2
    assert min(tile.measures.copied_fraction.values()) >= 0.9
    # The test can fail: today's cut joins copies shifted by a fraction of a cell.
    a, b = (torch.tensor(vector, dtype=torch.float64) for vector in lattice.vectors)
    assert float(lattice_residual(cell_centres(make_seamless(maps).maps.repeat(1, 2, 2)), a, b).max()) > 2.0


def test_the_residual_cut_routes_the_wrap_around_what_does_not_repeat() -> None:
    # A dark stain on the tile's left edge (in the photo, where the tile will start): the copy one
    # period on has none. Resampled alone, the tile's wrap cuts through the stain; the residual
    # cut takes the band around the wrap from one copy where they disagree, so the wrap shows no
    # step there (measured before the final roll, where the wrap was).
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    maps = lattice_maps(*truth, seed=9, noise=0.02)
    lattice = find_lattice(maps)
    assert lattice.vectors is not None
    tiling = choose_cells(lattice.vectors, SIZE, SIZE)
    assert tiling is not None
    mx, my = tiling.margin
    axis = torch.arange(SIZE, dtype=torch.float64) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    # Tile coordinates (s, t) in [0, 1)² of every photo pixel, from the tiling's affine map.
    offset = torch.stack([xx - tiling.origin[0], yy - tiling.origin[1]], dim=-1)
    s, t = (offset @ tiling.affine().T / torch.tensor([SIZE, SIZE], dtype=torch.float64)).unbind(-1)
    stain = (s.abs() < 0.5 * mx / SIZE) & (t > 0.3) & (t < 0.6)
    stained = maps.clone()
    stained[0:3] = torch.where(stain, 0.6 * stained[0:3], stained[0:3])
    tile = tile_whole_cells(stained, tiling)
    rows = slice(round(0.35 * SIZE), round(0.55 * SIZE))

    def wrap_step(image: Tensor) -> float:
        """The base colour's step across the wrap in the stain's rows over its mean interior step."""
        interior = (image[0:3, :, 1:] - image[0:3, :, :-1]).abs().mean()
        return float((image[0:3, rows, 0] - image[0:3, rows, -1]).abs().mean() / interior)

    unrolled = torch.roll(tile.maps, tile.tiling.roll, dims=(-2, -1))
    uncut = tile.resampled[:, my : my + SIZE, mx : mx + SIZE]
    assert wrap_step(uncut) > 3.0  # the test can fail: without the cut the stain is cut through
    assert wrap_step(unrolled) < 1.5


def test_align_turns_the_lattice_onto_the_axes() -> None:
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    maps = lattice_maps(*truth, seed=8)
    lattice = find_lattice(maps)
    assert lattice.vectors is not None
    tiling = choose_cells(lattice.vectors, SIZE, SIZE, align=True)
    assert tiling is not None and tiling.aligned
    # The lattice's direction nearest an axis (b at 120°, 30° from vertical) becomes vertical: the
    # rectangular cells come out as axis-aligned rectangles, hardly stretched.
    assert tiling.turn_deg == pytest.approx(-30.0, abs=1.0)
    assert tiling.stretch < 0.03
    for vector in lattice.vectors:
        x, y = (tiling.affine() @ torch.tensor(vector, dtype=torch.float64)).tolist()
        assert min(abs(x), abs(y)) < 0.02 * math.hypot(x, y), (x, y)
    tile = tile_whole_cells(maps, tiling)
    assert cell_centres(tile.maps).shape[0] == tiling.cells


def test_a_45_degree_grid_tiles_with_exact_diagonal_combinations() -> None:
    # The ceramic sample's case: a + b is horizontal and a − b vertical, so whole cells need
    # neither stretch nor turn.
    vectors = (polar(40.0, 45.0), polar(40.0, 135.0))
    tiling = choose_cells(vectors, SIZE, SIZE)
    assert tiling is not None
    assert tiling.stretch < 1e-9 and abs(tiling.turn_deg) < 1e-6
    assert tiling.cells == 18 and tiling.u[1] == pytest.approx(0.0, abs=1e-9)


def test_no_cell_fits_a_lattice_coarser_than_the_maps() -> None:
    assert choose_cells(((165.0, 0.0), (0.0, 165.0)), 160, 160) is None
    # One cell that fits only without room for the seam band would fetch its margin from itself.
    assert choose_cells(((155.0, 0.0), (0.0, 155.0)), 160, 160) is None
    tiling = choose_cells(((78.0, 0.0), (0.0, 155.0)), 160, 160)
    assert tiling is not None and tiling.margin_fetched and tiling.cells == 2


def test_bricks_two_to_the_maps_tile_the_whole_maps_with_their_margin_fetched() -> None:
    # Bricks 96 × 32 in 192²: whole cells span two bricks (192) and three pairs of courses (192),
    # the whole maps, with no room for the seam's margin; one brick and a few courses would be
    # stretched by a third or more. The margin is fetched from the next cell in.
    lattice = ((96.0, 0.0), (48.0, 32.0))
    maps = brick_maps(96.0, 32.0, 0.0)
    tiling = choose_cells(lattice, SIZE, SIZE)
    assert tiling is not None and tiling.margin_fetched
    assert tiling.u == pytest.approx((192.0, 0.0)) and tiling.v == pytest.approx((0.0, 192.0))
    assert tiling.cells == 12 and tiling.stretch < 1e-9 and min(tiling.margin) >= MIN_BAND
    assert CellTiling.from_json(json.loads(json.dumps(tiling.to_json()))) == tiling
    # The margin beyond the right edge is the same place in the nearest cell inside, half a brick
    # back and a course down (in the last course, up), not the maps' last column stretched out.
    mx, my = tiling.margin
    beyond = sample_cells(maps, tiling)[:, my : my + SIZE, mx + SIZE :]
    columns = slice(144, 144 + mx)
    fetched = torch.cat([maps[:, 32:SIZE, columns], maps[:, SIZE - 64 : SIZE - 32, columns]], dim=1)
    assert float((beyond - fetched).abs().max()) < 1e-6
    tile = tile_whole_cells(maps, tiling)
    validate_maps(tile.maps)
    # The tile is the maps, rolled, but for the residual seams' bands: every brick whole.
    unrolled = torch.roll(tile.maps, tile.tiling.roll, dims=(-2, -1))
    inner = slice(2 * tiling.margin[0], SIZE - 2 * tiling.margin[0])
    assert float((unrolled - maps.float())[:, inner, inner].abs().max()) < 1e-4
    # Across the wrap, too: the sheet of 2 × 2 tiles is one wall whose mortar lies where the
    # maps' does (rows of bed joints every 32 px, head joints every 96 px), and it wraps.
    level = 0.5 * float(maps[0:3].mean(dim=0).max())
    sheet = tile.maps.repeat(1, 2, 2)
    truth = torch.roll(maps, [-shift for shift in tile.tiling.roll], dims=(-2, -1)).repeat(1, 2, 2)
    agreement = ((sheet[0:3].mean(dim=0) < level) == (truth[0:3].mean(dim=0) < level)).double().mean()
    assert float(agreement) > 0.995
    for image in file_units(tile.maps):
        assert max(wrap_ratios(image)) <= 1.2
    # The test can fail: with room for a margin demanded, there is no whole-cell tile.
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lattice_module, "FETCH_AREA", 0.5)
        assert choose_cells(lattice, SIZE, SIZE) is None


def test_cells_that_repeat_match_each_other_and_wandering_joints_do_not() -> None:
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    assert cell_match(lattice_maps(*truth, seed=7), truth) > 0.9
    assert cell_match(brick_maps(40.0, 15.0, 0.0), ((40.0, 0.0), (20.0, 15.0))) > 0.8
    assert cell_match(setts_maps(), ((32.0, 0.0), (16.0, 16.0))) < 0.4


def test_bricks_turned_45_degrees_tile_by_a_turned_parallelogram_whose_corners_are_fetched() -> None:
    # Bricks 96 × 32 turned 45° in 192²: no combination of their vectors near an axis is short
    # enough for a tile inside the maps; one of at most the maps' area, reaching past them at its
    # corners, keeps every brick, its corners fetched from the cells inside.
    maps = brick_maps(96.0, 32.0, 45.0)
    lattice = find_lattice(maps)
    assert lattice.vectors is not None
    tiling = choose_cells(lattice.vectors, SIZE, SIZE)
    assert tiling is not None and tiling.margin_fetched and tiling.cells >= 4
    cross = abs(tiling.u[0] * tiling.v[1] - tiling.u[1] * tiling.v[0])
    assert SIZE * SIZE * 0.5 < cross <= SIZE * SIZE * 1.02 and tiling.stretch <= 0.15
    origin, edges = torch.tensor(tiling.origin), torch.tensor([tiling.u, tiling.v])
    corners = origin + torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]) @ edges
    assert bool(((corners < 0) | (corners > SIZE)).any())  # it does reach past them
    tile = tile_whole_cells(maps, tiling)
    sheet = tile.maps.repeat(1, 2, 2)
    affine = tile.tiling.affine()
    a, b = ((affine @ torch.tensor(vector, dtype=torch.float64)).tolist() for vector in lattice.vectors)
    assert_same_lattice(find_lattice(sheet), ((a[0], a[1]), (b[0], b[1])), 0.02)
    # The test can fail: with cells held inside the maps there is no such tile.
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lattice_module, "FETCH_AREA", 0.3)
        assert choose_cells(lattice.vectors, SIZE, SIZE) is None


def test_a_sample_outside_the_maps_is_fetched_from_the_nearest_cell_inside() -> None:
    # Bricks 96 × 32: the shortest lattice vectors are the four (±48, ±32), then (±96, 0).
    basis = torch.tensor([[96.0, 0.0], [48.0, 32.0]], dtype=torch.float64)
    px = torch.tensor([-3.0, 195.0, 170.0, 100.0, 0.5], dtype=torch.float64)
    py = torch.tensor([10.0, 180.0, 194.0, 100.0, 191.5], dtype=torch.float64)
    x, y = fold_inside(px, py, basis, SIZE, SIZE)
    # Each moved by the one short vector that brings it in; those inside (on the outer pixel
    # centres, too) stay.
    assert x.tolist() == [45.0, 147.0, 122.0, 100.0, 0.5]
    assert y.tolist() == [42.0, 148.0, 162.0, 100.0, 191.5]


def test_the_wrap_closes_on_the_maps_whatever_the_lattices_precision() -> None:
    truth = (polar(24.0, 30.0), polar(30.0, 120.0))
    maps = lattice_maps(*truth, seed=7)
    # A lattice 1.5 % too long (a crop of two periods measured Tiles074 0.7 % off): the tile's edges,
    # several cells long, miss the true period by ~2 px, and the wrap joins the cells out of step.
    off = tuple((1.015 * x, 1.015 * y) for x, y in truth)
    tiling = choose_cells(off, SIZE, SIZE)  # type: ignore[arg-type]
    assert tiling is not None
    true_edges = torch.tensor(tiling.counts, dtype=torch.float64) @ torch.tensor(truth, dtype=torch.float64)
    assert float((torch.tensor([tiling.u, tiling.v]) - true_edges).norm(dim=1).min()) > 1.5
    tile = tile_whole_cells(maps, tiling)
    closed = torch.tensor([tile.tiling.u, tile.tiling.v], dtype=torch.float64)
    assert float((closed - true_edges).norm(dim=1).max()) < 0.25
    assert min(tile.tiling.closure) > 1.5 and tile.tiling.counts == tiling.counts
    assert CellTiling.from_json(json.loads(json.dumps(tile.tiling.to_json()))) == tile.tiling
    a, b = (tile.tiling.affine() @ torch.tensor(vector, dtype=torch.float64) for vector in truth)
    sheet = tile.maps.repeat(1, 2, 2)
    assert float(lattice_residual(cell_centres(sheet), a, b).max()) < 1.0
    # The test can fail: the same tiling left as the lattice gave it breaks the cells at the wrap.
    unclosed = cut_wrap(sample_cells(maps, tiling), tiling.margin).repeat(1, 2, 2)
    a, b = (tiling.affine() @ torch.tensor(vector, dtype=torch.float64) for vector in truth)
    assert float(lattice_residual(cell_centres(unclosed), a, b).max()) > 1.5


def test_the_records_round_trip() -> None:
    lattice = Lattice(((24.5, 1.25), (-0.5, 30.0)), 0.25, True, notes="2-D lattice")
    assert Lattice.from_json(lattice.to_json()) == lattice
    tiling = choose_cells(lattice.vectors, SIZE, SIZE)  # type: ignore[arg-type]
    assert tiling is not None and CellTiling.from_json(tiling.to_json()) == tiling


def test_refining_a_basis_whose_second_vector_is_no_peak_uses_only_positive_peaks() -> None:
    # A real scan (Concrete002 at 512²) reduced to a basis whose second vector sits where ρ < 0:
    # the refinement took every local maximum above a negative level, square roots of negative
    # weights made the least squares NaN, and make_tileable crashed.
    generator = torch.Generator().manual_seed(0)
    height, width = 64, 64
    rho = -0.02 * torch.rand(2 * height, 2 * width, generator=generator, dtype=torch.float64)
    a = (5.0, 4.0)
    ys, xs = torch.meshgrid(
        torch.arange(2 * height, dtype=torch.float64) - height,
        torch.arange(2 * width, dtype=torch.float64) - width,
        indexing="ij",
    )
    for i in range(-6, 7):  # ρ's peaks on the multiples of a only
        rho += 0.3 * torch.exp(-((xs - i * a[0]) ** 2 + (ys - i * a[1]) ** 2) / 0.8)
    refined_a, refined_b = refine_lattice(rho, a, (-20.0, 25.0), (height, width))
    assert all(math.isfinite(v) for v in (*refined_a, *refined_b))
