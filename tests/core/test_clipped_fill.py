"""The flash's own marks (``core/clipped_fill.py``): a clipped disc is taken out of base colour and
metallic, unclipped maps and pixels stay as they were bit for bit, a periodic material is filled
from its own cells, metal in thin dark grout goes while real metal stays, and the highlight's reach
is measured on the photo."""

from __future__ import annotations

import json
import math

import pytest
import torch
from torch import Tensor

from brdfgan.core.clipped_fill import (
    CLIP_LEVEL,
    Twins,
    clipped_mask,
    fill_clipped,
    highlight_radius,
    push_pull_fill,
    remove_flash,
    suppress_false_metal,
    twin_fill,
)
from brdfgan.core.delit import flash_render, flat_flash_falloff
from brdfgan.core.exposure import auto_exposure_scale
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.flash_geometry import centred_flash_frame, hotspot_distance
from brdfgan.core.flash_mark import mark_radius
from brdfgan.core.svbrdf import flat_maps, join_maps, srgb_to_linear, validate_maps

SIZE = 128
CENTRE = (64.0, 64.0)


def wood(seed: int = 0) -> Tensor:
    """A brown dielectric with a fine grain (blurred noise): base colour ~(0.55, 0.35, 0.2) sRGB."""
    generator = torch.Generator().manual_seed(seed)
    noise = torch.rand(1, 1, SIZE, SIZE, generator=generator, dtype=torch.float64) - 0.5
    grain = gaussian_blur(noise, 1.0, "reflect")[0]
    basecolor = torch.tensor([0.55, 0.35, 0.2], dtype=torch.float64).view(3, 1, 1) + 0.3 * grain
    maps = flat_maps(SIZE, SIZE, roughness=0.5, metallic=0.0).double()
    maps[0:3] = basecolor.clamp(0.0, 1.0)
    maps[6] = (0.5 + 0.3 * grain[0]).clamp(0.0, 1.0)
    return maps


def disc(radius: float, centre: tuple[float, float] = CENTRE) -> Tensor:
    return hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] <= radius


def with_flash_disc(truth: Tensor, inside: Tensor) -> Tensor:
    """What the network makes of a clipped hotspot: grey-white base colour, metal, smooth."""
    marked = truth.clone()
    marked[0:3] = torch.where(inside, torch.full_like(marked[0:3], 0.85), marked[0:3])
    marked[6] = torch.where(inside, torch.full_like(marked[6], 0.08), marked[6])
    marked[7] = torch.where(inside, torch.full_like(marked[7], 0.8), marked[7])
    return marked


def test_push_pull_fills_a_hole_from_its_rim_and_keeps_known_pixels() -> None:
    image = torch.linspace(0.0, 1.0, SIZE, dtype=torch.float64).view(1, 1, SIZE).expand(2, SIZE, SIZE).clone()
    known = ~disc(20.0)
    image[:, ~known] = 5.0  # garbage in the hole
    filled = push_pull_fill(image, known.double())
    assert torch.equal(filled[:, known], image[:, known])
    # A ramp's hole is filled with values of the ramp's range near the ramp itself.
    ramp = torch.linspace(0.0, 1.0, SIZE, dtype=torch.float64).view(1, SIZE).expand(SIZE, SIZE)
    assert (filled[0, ~known] - ramp[~known]).abs().max() < 0.1
    assert torch.allclose(
        push_pull_fill(torch.full((1, 9, 7), 0.3), torch.rand(9, 7) > 0.5), torch.full((1, 9, 7), 0.3)
    )


def test_a_clipped_disc_is_removed_from_base_colour_metallic_and_roughness() -> None:
    truth = wood()
    inside = disc(12.0)
    marked = with_flash_disc(truth, inside)
    result = fill_clipped(marked, inside)
    validate_maps(result.maps)
    # Base colour in the disc is back near the truth around it, metal is gone, roughness is wood's.
    error = (result.maps[0:3, inside] - truth[0:3, inside]).abs().mean()
    before = (marked[0:3, inside] - truth[0:3, inside]).abs().mean()
    assert error < 0.1 * before and error < 0.05, (float(error), float(before))
    assert float(result.maps[7, inside].max()) < 0.05
    assert abs(float(result.maps[6, inside].mean()) - float(truth[6, inside].mean())) < 0.1
    # Normals and every pixel outside the clipped mask are untouched, bit for bit.
    assert torch.equal(result.maps[3:6], marked[3:6])
    assert torch.equal(result.maps[:, ~inside], marked[:, ~inside])
    assert result.method == "surroundings" and math.isclose(
        result.clipped_fraction, float(inside.float().mean())
    )
    assert json.loads(json.dumps(result.to_json()))["changed_fraction"] > 0


def test_unclipped_maps_are_unchanged_bit_for_bit() -> None:
    maps = wood(seed=2)
    result = fill_clipped(maps, torch.zeros(SIZE, SIZE, dtype=torch.bool))
    assert result.maps is maps and result.method == "none"
    # The whole chain on a matte, unclipped photo of a surface with no metal: nothing changes.
    frame = centred_flash_frame(1, SIZE, SIZE, dtype=torch.float64)
    photo = 0.4 * flat_flash_falloff(frame, SIZE, SIZE)[0].expand(3, SIZE, SIZE)
    assert not bool(clipped_mask(photo).any()) and highlight_radius(photo, frame) == 0.0
    removed, record = remove_flash(maps, photo, frame)
    assert torch.equal(removed, maps)
    assert record.mark.levelled == () and record.mark.repaired == () and record.false_metal_fraction == 0.0


def test_a_clipped_metal_patch_keeps_its_metal() -> None:
    # Bare metal in the middle of the clipped area and around it: the reading is consistent.
    maps = wood(seed=4)
    metal = disc(30.0)
    maps[0:3, metal] = 0.9
    maps[7, metal] = 1.0
    maps[6, metal] = 0.2
    result = fill_clipped(maps, disc(10.0))
    assert float(result.maps[7, disc(10.0)].min()) > 0.9
    assert float(result.maps[0:3, disc(10.0)].min()) > 0.8


def grid_tiles(vectors: tuple[tuple[float, float], tuple[float, float]]) -> Tensor:
    """Light tiles with dark grout lines on the lattice ``vectors`` (pixels), as maps."""
    (ax, ay), (bx, by) = vectors
    ys, xs = torch.meshgrid(
        torch.arange(SIZE, dtype=torch.float64), torch.arange(SIZE, dtype=torch.float64), indexing="ij"
    )
    # Cell coordinates: solve p = u·a + v·b.
    det = ax * by - ay * bx
    u = (xs * by - ys * bx) / det
    v = (ys * ax - xs * ay) / det
    line = torch.minimum(
        (u - u.round()).abs() * math.hypot(ax, ay), (v - v.round()).abs() * math.hypot(bx, by)
    )
    grout = (line < 1.5).double()
    maps = flat_maps(SIZE, SIZE, roughness=0.4).double()
    maps[0:3] = (0.8 - 0.6 * grout).expand(3, SIZE, SIZE)
    maps[6] = 0.3 + 0.5 * grout
    return maps


def test_a_periodic_material_is_filled_from_the_same_cell_elsewhere() -> None:
    angle = math.radians(30.0)
    vectors = (
        (20.0 * math.cos(angle), 20.0 * math.sin(angle)),
        (-20.0 * math.sin(angle), 20.0 * math.cos(angle)),
    )
    truth = grid_tiles(vectors)
    inside = disc(9.0, (70.0, 58.0))
    marked = with_flash_disc(truth, inside)
    from_lattice = fill_clipped(marked, inside, twins=Twins.of_lattice(vectors))
    from_surroundings = fill_clipped(marked, inside)
    assert from_lattice.method == "lattice" and from_lattice.twin_fraction == pytest.approx(
        from_lattice.clipped_fraction
    )
    lattice_error = (from_lattice.maps[0:3, inside] - truth[0:3, inside]).abs().mean()
    surroundings_error = (from_surroundings.maps[0:3, inside] - truth[0:3, inside]).abs().mean()
    # The grout lines crossing the hole come back (bilinear twins: a little blur at their edges).
    assert lattice_error < 0.05 and lattice_error < 0.5 * surroundings_error, (
        lattice_error,
        surroundings_error,
    )
    filled, found = twin_fill(marked[0:3], inside, Twins.of_lattice(vectors))
    assert bool(found[inside].all()) and not bool(found[~inside].any())
    assert torch.equal(filled[:, ~inside], marked[0:3, ~inside])
    with pytest.raises(ValueError, match="lattice vectors"):
        Twins.of_lattice(((10.0, 0.0), (20.0, 0.0)))


def test_a_periodic_materials_hotspot_dot_and_halo_come_from_its_cells_at_the_local_level() -> None:
    vectors = ((40.0, 0.0), (0.0, 40.0))  # cells four times the disc's reach across
    truth = grid_tiles(vectors)
    # The network's maps drift in level across the photo, with a dot and a dark halo on the hotspot
    # (the ceramic sample's): nothing clipped.
    drift = 0.1 * torch.linspace(-1.0, 1.0, SIZE, dtype=torch.float64).view(1, SIZE)
    network = truth.clone()
    network[0:3] = truth[0:3] + drift
    halo = disc(10.0) & ~disc(3.0)
    network[0:3, halo] -= 0.1
    network[0:3, disc(3.0)] = 0.95
    frame = centred_flash_frame(1, SIZE, SIZE, dtype=torch.float64)
    photo = 0.4 * flat_flash_falloff(frame, SIZE, SIZE)[0].expand(3, SIZE, SIZE)  # matte, unclipped
    removed, record = remove_flash(network, photo, frame, lattice=vectors)
    expected = truth[0:3] + drift  # the cells' pattern at the disc's own level
    inside = disc(10.0)
    before = float((network[0:3, inside] - expected[:, inside]).abs().mean())
    after = float((removed[0:3, inside] - expected[:, inside]).abs().mean())
    assert after < 0.02 < before, (before, after)
    far = ~disc(1.3 * 1.1 * 0.1 * SIZE + 1.0)  # beyond the blend (REPAIR_INNER × the mark's radius)
    assert torch.equal(removed[:, far], network[:, far]) and torch.equal(removed[3:6], network[3:6])
    assert record.fill.method == "none"  # nothing clipped: the disc is the lattice's, not the fill's


def plank_floor(degrees: float) -> Tensor:
    """Planks at ``degrees``: a groove every 8 px across them, a darker gap between planks every
    28 px (not a whole number of grooves: twins across the stripes would put a groove where a gap
    is), and each plank its own tone."""
    axis = torch.arange(SIZE, dtype=torch.float64) + 0.5
    ys, xs = torch.meshgrid(axis, axis, indexing="ij")
    radians = math.radians(degrees)
    across = -math.sin(radians) * (xs - CENTRE[0]) + math.cos(radians) * (ys - CENTRE[1])
    # Soft-edged lines, as a network draws them (the twins are bilinear samples).
    groove = torch.exp(-0.5 * ((torch.remainder(across + 4.0, 8.0) - 4.0) / 0.8).square())
    gap = torch.exp(-0.5 * ((torch.remainder(across + 14.0, 28.0) - 14.0) / 1.2).square())
    tone = 0.55 + 0.1 * torch.sin(1.7 * torch.floor(across / 28.0))
    luminance = tone - 0.15 * groove - 0.3 * gap
    maps = flat_maps(SIZE, SIZE, roughness=0.5).double()
    maps[0:3] = luminance * torch.tensor([1.0, 0.7, 0.5], dtype=torch.float64).view(3, 1, 1)
    maps[6] = 0.5 + 0.05 * gap
    return maps


def test_planks_clipped_streak_is_filled_along_their_stripes_and_keeps_the_gap_across_it() -> None:
    degrees = 15.0
    truth = plank_floor(degrees)
    radians = math.radians(degrees)
    along = (math.cos(radians), math.sin(radians))
    # A glossy plank's clipped highlight is a streak along the grooves, longer than the flash mark's
    # round patch (the wood-plank sample's): 30 px along, 8 across, through a gap between planks.
    axis = torch.arange(SIZE, dtype=torch.float64) + 0.5
    ys, xs = torch.meshgrid(axis, axis, indexing="ij")
    dx, dy = xs - CENTRE[0], ys - CENTRE[1]
    u, v = dx * along[0] + dy * along[1], -dx * along[1] + dy * along[0]
    streak = (u / 30.0).square() + (v / 8.0).square() <= 1.0
    network = with_flash_disc(truth, streak)
    frame = centred_flash_frame(1, SIZE, SIZE, dtype=torch.float64)
    photo = 0.4 * flat_flash_falloff(frame, SIZE, SIZE)[0].expand(3, SIZE, SIZE)
    along_stripes, record = remove_flash(network, photo, frame, clipped=streak, stripes=along)
    surroundings = remove_flash(network, photo, frame, clipped=streak)[0]
    assert record.fill.method == "stripes"

    def error(maps: Tensor) -> float:
        return float((maps[0:3, streak] - truth[0:3, streak]).abs().mean())

    errors = (error(along_stripes), error(surroundings))
    assert errors[0] < 0.02 < 0.5 * errors[1], errors
    gap = streak & (truth[0] < 0.3)  # the gap between planks, where it crosses the streak
    assert bool(gap.any()) and float((along_stripes[0, gap] - truth[0, gap]).abs().mean()) < 0.03
    assert float(along_stripes[7, streak].max()) < 0.05  # the streak's metal gone
    assert torch.equal(along_stripes[3:6], network[3:6])  # normals kept
    with pytest.raises(ValueError, match="not both"):
        remove_flash(network, photo, frame, lattice=((8.0, 0.0), (0.0, 8.0)), stripes=along)
    with pytest.raises(ValueError, match="stripes' direction"):
        Twins.along_stripes((0.0, 0.0), 10.0)


def test_metal_in_thin_dark_grout_is_suppressed_and_real_metal_stays() -> None:
    truth = grid_tiles(((24.0, 0.0), (0.0, 24.0)))
    grout = truth[0] < 0.5
    network = truth.clone()
    network[7] = torch.where(grout, 0.6, 0.0)  # bluish metal lines between the tiles
    # A bare metal plate in one corner: bright, metal, with a dark scratch across it that is metal.
    plate = torch.zeros(SIZE, SIZE, dtype=torch.bool)
    plate[80:, 80:] = True
    network[0:3, plate] = 0.9
    network[7, plate] = 1.0
    network[0:3, 100:102, 80:] = 0.3
    result, weight = suppress_false_metal(network)
    validate_maps(result)
    # (A line along the image's edge cannot be told from a dark border: the check stays inside.)
    away_from_plate = grout.clone()
    away_from_plate[64:, 64:] = False
    away_from_plate[:8], away_from_plate[-8:], away_from_plate[:, :8], away_from_plate[:, -8:] = (
        False,
        False,
        False,
        False,
    )
    assert float(result[7, away_from_plate].max()) < 0.05, float(result[7, away_from_plate].max())
    assert float(weight[away_from_plate].mean()) > 0.9
    interior = torch.zeros_like(plate)
    interior[88:, 88:] = True
    assert float(result[7, interior].min()) > 0.99  # the scratch at rows 100-101 included
    # Only the metallic changes, and only downwards.
    assert torch.equal(result[0:7], network[0:7]) and bool((result[7] <= network[7]).all())
    # The same from the photo of the tiles (the grout dark in it) and at twice the size, where the
    # lowering is found on a half-size copy.
    photo = srgb_to_linear(truth[0:3])
    assert float(suppress_false_metal(network, photo)[0][7, away_from_plate].max()) < 0.05
    large = torch.nn.functional.interpolate(network[None], scale_factor=8, mode="nearest")[0]
    lowered = suppress_false_metal(large)[0]
    assert (
        float(
            lowered[7][
                torch.nn.functional.interpolate(away_from_plate[None, None].float(), scale_factor=8)[0, 0] > 0
            ].mean()
        )
        < 0.05
    )
    assert float(lowered[7, 8 * 88 :, 8 * 88 :].min()) > 0.99


def test_the_highlight_radius_follows_the_glossy_lobe() -> None:
    frame = centred_flash_frame(1, SIZE, SIZE, fov_deg=60.0, dtype=torch.float64)
    matte = flat_maps(SIZE, SIZE, basecolor=(0.5, 0.5, 0.5), roughness=1.0).double()[None]
    radii = []
    for roughness in (0.25, 0.4):
        glossy = matte.clone()
        glossy[:, 6] = roughness
        linear = srgb_to_linear(glossy[:, 0:3])
        photo = flash_render(linear, glossy[:, 3:6], glossy[:, 6:7], glossy[:, 7:8], frame)[0]
        radii.append(highlight_radius(photo / photo.max(), frame))
    # A rougher surface spreads its highlight further; both stay under the cap.
    assert 0.0 < radii[0] < radii[1] < 0.3 * SIZE, radii


def clipped_render(truth: Tensor, ev: float) -> tuple[Tensor, Tensor]:
    """A flash photo of ``truth``, the training's auto exposure raised by ``ev`` stops, clipped."""
    frame = centred_flash_frame(1, SIZE, SIZE, fov_deg=60.0, dtype=torch.float64)
    parts = truth[None]
    hdr = flash_render(srgb_to_linear(parts[:, 0:3]), parts[:, 3:6], parts[:, 6:7], parts[:, 7:8], frame)
    return (hdr * auto_exposure_scale(hdr)[:, None, None, None] * 2.0**ev).clamp(0.0, 1.0)[0], frame


def test_remove_flash_takes_a_grey_disc_and_its_metal_out_of_a_clipped_render() -> None:
    truth = wood(seed=5)
    truth[6] = 0.3  # glossy: the hotspot clips
    photo, frame = clipped_render(truth, 1.5)  # 3.7 % of the pixels clipped
    clipped = (photo >= CLIP_LEVEL).any(dim=0)
    assert 0.005 < float(clipped.float().mean()) < 0.1
    radius = highlight_radius(photo, frame)
    assert radius > 10.0
    # The network's disc: greyed base colour and metal, fading out to the highlight's reach.
    reach = hotspot_distance(frame[:, :2], SIZE, SIZE)[0]
    strength = (1.0 - reach / radius).clamp(0.0, 1.0)
    network = truth.clone()
    network[0:3] = truth[0:3] + strength * (0.75 - truth[0:3])
    network[7] = 0.6 * strength
    maps, record = remove_flash(network, photo, frame)
    validate_maps(maps)
    inside = disc(0.1 * SIZE)
    rest = reach > 0.2 * SIZE
    error = lambda m, where: float((m[0:3, where] - truth[0:3, where]).abs().mean())  # noqa: E731
    assert error(network, inside) > 5 * error(maps, inside)
    assert error(maps, inside) < 0.03
    assert float(maps[7, inside].mean()) < 0.05
    assert torch.equal(maps[:, rest], network[:, rest])
    assert "basecolor" in record.mark.levelled and "metallic" in record.mark.levelled
    document = json.loads(json.dumps(record.to_json()))
    assert document["highlight_radius"] == pytest.approx(radius)
    assert document["clipped_fill"]["clipped_fraction"] > 0


def test_a_metallic_disc_wider_than_a_narrow_highlight_is_levelled_out_to_the_marks_radius() -> None:
    # A glossy paint's highlight reaches 8 px; the network's metallic disc spans the mark's radius.
    truth = wood(seed=5)
    truth[6] = 0.1
    photo, frame = clipped_render(truth, 1.0)
    radius, mark = highlight_radius(photo, frame), mark_radius(SIZE, SIZE)
    assert 0.0 < radius < 0.75 * mark
    network = truth.clone()
    network[7] = torch.where(disc(mark), 0.6, 0.0)
    maps, record = remove_flash(network, photo, frame)
    assert record.mark.level_radius == mark and "metallic" in record.mark.levelled
    assert float(maps[7, disc(mark)].mean()) < 0.05


def test_a_darker_disc_around_a_photo_without_a_highlight_is_levelled() -> None:
    # A matte surface (or a glossy tile's pinpoint glint) shows no highlight ring, but the network
    # may still darken the base colour around the hotspot out to the mark's radius.
    truth = wood(seed=5)
    truth[6] = 1.0
    photo, frame = clipped_render(truth, 0.0)
    assert highlight_radius(photo, frame) == 0.0
    inside = disc(mark_radius(SIZE, SIZE))
    network = truth.clone()
    network[0:3] = torch.where(inside, 0.8 * truth[0:3], truth[0:3])
    maps, record = remove_flash(network, photo, frame)
    assert record.mark.levelled == ("basecolor",)
    error = lambda m: float((m[0:3, inside] - truth[0:3, inside]).abs().mean())  # noqa: E731
    assert error(maps) < 0.2 * error(network)


def test_bad_shapes_are_refused() -> None:
    maps = wood()
    with pytest.raises(ValueError, match="clipped"):
        fill_clipped(maps, torch.zeros(SIZE, SIZE + 1, dtype=torch.bool))
    with pytest.raises(ValueError, match="photo"):
        remove_flash(maps, torch.zeros(3, SIZE, 8), centred_flash_frame(1, SIZE, SIZE))
    with pytest.raises(ValueError):
        suppress_false_metal(join_maps(maps[0:3], maps[3:6], maps[6:7], maps[7:8])[None])
