"""The flash mark (``core/flash_mark.py``): a synthetic hotspot is detected in the maps it leaked
into and repaired there, clean maps stay untouched (also near the image's edge), a smooth grey disc
is levelled given the highlight's radius (not on a metal surface, not on a plain texture), and what
a clipped disc whose texture was lost gets texture back (only where the photo clipped it), and what
was done round-trips through ``material.json``."""

from __future__ import annotations

import json

import pytest
import torch
from torch import Tensor

from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.flash_geometry import hotspot_distance
from brdfgan.core.flash_mark import (
    CLIPPED_DISK_SHARE,
    LEAK_THRESHOLD,
    LEVEL_THRESHOLD,
    REPAIR_INNER,
    REPAIR_OUTER,
    FlashMark,
    leak_scores,
    level_scores,
    mark_radius,
    patch_candidates,
    repair_flash_mark,
)
from brdfgan.core.svbrdf import join_maps, normalize_normal, split_maps, validate_maps
from brdfgan.inference.pipeline import TileableRecord, make_tileable
from tests.conftest import random_maps

SIZE = 128


def surface(seed: int = 0) -> Tensor:
    """Valid maps with a texture a few pixels across everywhere (blurred noise)."""
    maps = gaussian_blur(random_maps(SIZE, SIZE, seed=seed, dtype=torch.float64)[None], 1.5, "reflect")[0]
    parts = split_maps(maps)
    return join_maps(parts.basecolor, normalize_normal(parts.normal), parts.roughness, parts.metallic)


def with_mark(maps: Tensor, centre: tuple[float, float]) -> Tensor:
    """``maps`` with a flash mark baked into the base colour and the normals: a blotch of strong
    pixel-scale detail in a disk of 0.8 × the scoring radius around ``centre``."""
    generator = torch.Generator().manual_seed(7)
    inside = hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] <= 0.8 * mark_radius(SIZE, SIZE)
    marked = maps.clone()
    speckle = torch.rand(5, SIZE, SIZE, generator=generator, dtype=torch.float64) - 0.5
    marked[0:3] = torch.where(inside, (0.6 + 0.8 * speckle[0:3]).clamp(0, 1), marked[0:3])
    tilted = marked[3:6] + torch.cat([1.2 * speckle[3:5], torch.zeros(1, SIZE, SIZE, dtype=torch.float64)])
    marked[3:6] = torch.where(inside, normalize_normal(tilted), marked[3:6])
    return marked


def test_a_clipped_disc_that_lost_its_texture_gets_texture_back_only_where_the_photo_clipped() -> None:
    centre = (64.0, 60.0)
    distance = hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0]
    clipped = distance <= 0.9 * mark_radius(SIZE, SIZE)
    clean = surface()
    planks = torch.sin(torch.arange(SIZE, dtype=torch.float64) * 2.1).view(SIZE, 1)  # a fine grain
    clean[0:3] = (clean[0:3] + 0.15 * planks).clamp(0.0, 1.0)
    smooth = clean.clone()  # the clipped pixels brought into range: their texture gone
    smooth[0:3] = torch.where(clipped, clean[0:3, ~clipped].mean(dim=-1).view(3, 1, 1), clean[0:3])
    assert leak_scores(smooth, centre)["basecolor"] < 1.0 / LEAK_THRESHOLD
    # Without clipping a smooth disc is no mark (a plain tile among grout lines).
    unchanged, plain = repair_flash_mark(smooth, centre)
    assert plain.repaired == () and torch.equal(unchanged, smooth) and plain.clipped_share == 0.0
    repaired, mark = repair_flash_mark(smooth, centre, clipped=clipped)
    assert mark.clipped_share > CLIPPED_DISK_SHARE and "basecolor" in mark.repaired
    assert "normal" not in mark.repaired  # its texture was never lost
    validate_maps(repaired)
    assert 0.5 < leak_scores(repaired, centre)["basecolor"] < 2.0
    assert FlashMark.from_json(json.loads(json.dumps(mark.to_json()))) == mark


@pytest.mark.parametrize("centre", [(64.0, 60.0), (9.5, 120.0)], ids=["centre", "near a corner"])
def test_a_hotspot_mark_is_detected_and_repaired_where_it_leaked(centre: tuple[float, float]) -> None:
    clean = surface()
    marked = with_mark(clean, centre)
    scores = leak_scores(marked, centre)
    assert scores["basecolor"] > 3 * LEAK_THRESHOLD and scores["normal"] > 3 * LEAK_THRESHOLD, scores
    assert scores["roughness"] < 1.5 and scores["metallic"] < 1.5, scores
    repaired, mark = repair_flash_mark(marked, centre)
    assert mark.repaired == ("basecolor", "normal") and mark.patch_offset is not None
    validate_maps(repaired)
    # The mark is gone: the repaired disk is as busy as its surroundings.
    after = leak_scores(repaired, centre)
    assert after["basecolor"] < 1.5 and after["normal"] < 1.5, after
    # The patch came from far enough that it does not copy the mark itself.
    dy, dx = mark.patch_offset
    assert (dy * dy + dx * dx) ** 0.5 > (REPAIR_OUTER + REPAIR_INNER) * mark.radius
    # The clean maps are untouched, and so is everything outside the repaired disk.
    assert torch.equal(repaired[6:8], marked[6:8])
    outside = hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] > REPAIR_OUTER * mark.radius
    assert torch.equal(repaired[:, outside], marked[:, outside])


def test_a_patch_that_would_read_as_a_disc_gives_way_to_the_next_best() -> None:
    # A terrazzo chip as large as the disc where the best patch comes from: copied onto the hotspot
    # it is a bright disc of its own, which a tile would repeat. Where the level is checked, the next
    # best patch is taken; without a level check (no highlight), the best as before.
    centre = (64.0, 60.0)
    radius = mark_radius(SIZE, SIZE)
    marked = with_mark(surface(), centre)
    dy, dx = patch_candidates(marked, centre)[0]
    chip = hotspot_distance(torch.tensor([(centre[0] + dx, centre[1] + dy)]), SIZE, SIZE)[0] <= radius
    marked[0:3] = torch.where(chip, torch.full_like(marked[0:3], 0.95), marked[0:3])
    assert patch_candidates(marked, centre)[0] == (dy, dx)
    unchecked, plain = repair_flash_mark(marked, centre)
    assert plain.patch_offset == (dy, dx)
    assert level_scores(unchecked, centre, radius)["basecolor"] > LEVEL_THRESHOLD
    repaired, mark = repair_flash_mark(marked, centre, radius=radius)
    assert mark.patch_offset not in (None, (dy, dx)) and "basecolor" in mark.repaired
    assert level_scores(repaired, centre, radius)["basecolor"] <= LEVEL_THRESHOLD
    assert leak_scores(repaired, centre)["basecolor"] < LEAK_THRESHOLD


def test_clean_maps_are_left_alone() -> None:
    clean = surface(seed=3)
    repaired, mark = repair_flash_mark(clean, (64.0, 64.0))
    assert max(mark.scores.values()) < LEAK_THRESHOLD, mark.scores
    assert mark.repaired == () and mark.patch_offset is None
    assert repaired is clean or torch.equal(repaired, clean)
    # A hotspot far outside the maps scores nothing.
    assert set(leak_scores(clean, (-500.0, 40.0)).values()) == {1.0}


def test_bad_centre_is_one_line() -> None:
    with pytest.raises(ValueError, match="finite"):
        repair_flash_mark(surface(), (float("nan"), 3.0))


def test_the_tileable_record_round_trips_through_material_json() -> None:
    centre = (64.0, 60.0)
    maps = with_mark(surface(seed=1), centre)
    tiled, record = make_tileable(maps, centre)
    validate_maps(tiled)
    document = json.loads(json.dumps(record.to_json()))
    assert TileableRecord.from_json(document) == record
    assert FlashMark.from_json(document["flash_mark"]) == record.flash_mark
    assert document["flash_mark"]["repaired"] == ["basecolor", "normal"]
    assert set(document["copied_fraction"]) == {"basecolor", "normal", "roughness", "metallic"}
    assert min(document["copied_fraction"].values()) > 0.9
    assert max(max(pair) for pair in document["wrap_ratio_after"].values()) <= 1.2
    assert len(document["shifts"]) == 4 and document["shifts"][-1] == [0, 0]


def test_maps_too_small_to_tile_are_a_user_error() -> None:
    from brdfgan.errors import UserError

    with pytest.raises(UserError, match="--tileable needs maps of at least 16×16, got 12×12"):
        make_tileable(random_maps(12, 12), (6.0, 6.0))


def with_grey_disc(maps: Tensor, centre: tuple[float, float], radius: float) -> Tensor:
    """``maps`` with the smooth disc a clipped hotspot leaves (the wood-plank sample's): base colour
    pulled towards grey and metallic raised, fading out to ``radius``, the texture still under it."""
    strength = (1.0 - hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] / radius).clamp(0.0, 1.0)
    marked = maps.clone()
    marked[0:3] = maps[0:3] + 0.6 * strength * (0.8 - maps[0:3])
    marked[7] = maps[7] * (1.0 - strength) + 0.7 * strength
    return marked


def dielectric_surface(seed: int = 0) -> Tensor:
    """:func:`surface` with a wood-like contrast (base colour 0.45 ± a third of its noise) and
    almost no metal."""
    maps = surface(seed)
    maps[0:3] = 0.45 + (maps[0:3] - 0.5) / 3.0
    maps[7] = 0.02 * maps[7]
    return maps


def test_a_smooth_grey_disc_is_levelled_given_the_highlight_radius() -> None:
    centre, radius = (60.0, 66.0), 30.0
    clean = dielectric_surface(seed=4)
    marked = with_grey_disc(clean, centre, radius)
    # Today's detail scores miss it (the texture is still there), as on the wood-plank sample.
    assert max(leak_scores(marked, centre).values()) < LEAK_THRESHOLD
    unchanged, record = repair_flash_mark(marked, centre)
    assert torch.equal(unchanged, marked) and record.levelled == ()
    scores = level_scores(marked, centre, 1.2 * radius)
    assert scores["basecolor"] > 2 * LEVEL_THRESHOLD and scores["metallic"] > 2 * LEVEL_THRESHOLD, scores
    assert scores["roughness"] < LEVEL_THRESHOLD, scores
    repaired, record = repair_flash_mark(marked, centre, radius=1.2 * radius)
    validate_maps(repaired)
    assert set(record.levelled) == {"basecolor", "metallic"}, record.level_scores
    inside = hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] <= radius
    before = (marked[0:3, inside] - clean[0:3, inside]).abs().mean()
    after = (repaired[0:3, inside] - clean[0:3, inside]).abs().mean()
    assert after < 0.25 * before, (float(after), float(before))
    assert float(repaired[7, inside].mean()) < 0.05
    # The texture under the disc stays: its fine detail matches the clean map's.
    detail = lambda m: (m - gaussian_blur(m[None], 2.0, "reflect")[0])[0:3, inside].flatten()  # noqa: E731
    assert torch.corrcoef(torch.stack([detail(repaired), detail(clean)]))[0, 1] > 0.8
    # Normals, and everything beyond the radius, are untouched.
    beyond = ~(hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] < 1.2 * radius)
    assert torch.equal(repaired[3:6], marked[3:6]) and torch.equal(repaired[:, beyond], marked[:, beyond])


def test_a_bright_disc_in_a_metals_base_colour_is_levelled_too() -> None:
    # A metal's highlight belongs in the render, not in its base colour map (brushed and polished
    # metal renders kept such a disc where the level check stood down on metal surroundings).
    centre, radius = (64.0, 64.0), 30.0
    clean = dielectric_surface(seed=2)
    clean[7] = 1.0
    marked = clean.clone()
    strength = (1.0 - hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] / radius).clamp(0.0, 1.0)
    marked[0:3] = clean[0:3] + 0.3 * strength
    repaired, record = repair_flash_mark(marked, centre, radius=1.2 * radius)
    assert "basecolor" in record.levelled and "metallic" not in record.levelled, record.level_scores
    inside = hotspot_distance(torch.tensor([centre]), SIZE, SIZE)[0] <= radius
    before = (marked[0:3, inside] - clean[0:3, inside]).abs().mean()
    after = (repaired[0:3, inside] - clean[0:3, inside]).abs().mean()
    assert after < 0.25 * before, (float(after), float(before))
    assert torch.equal(repaired[7], marked[7])


def test_a_stationary_texture_is_not_levelled() -> None:
    for seed in range(3):
        clean = dielectric_surface(seed=seed)
        _, record = repair_flash_mark(clean, (64.0, 64.0), radius=36.0)
        assert record.levelled == () and max(record.level_scores.values()) < LEVEL_THRESHOLD, (
            record.level_scores
        )


def test_a_record_from_before_the_level_check_reads_back() -> None:
    old = {
        "centre": [1.0, 2.0],
        "radius": 25.6,
        "threshold": 2.0,
        "leak_scores": {"basecolor": 0.35},
        "repaired": [],
        "patch_offset": None,
    }
    mark = FlashMark.from_json(old)
    assert mark.levelled == () and mark.level_radius == 0.0
    _, record = repair_flash_mark(
        with_grey_disc(dielectric_surface(), (64.0, 64.0), 30.0), (64.0, 64.0), radius=36.0
    )
    assert FlashMark.from_json(json.loads(json.dumps(record.to_json()))) == record
