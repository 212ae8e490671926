"""Tests of the paper, plaster, terrazzo, pavers, asphalt and leaves material families."""

from __future__ import annotations

import colorsys
import importlib
from collections.abc import Callable

import pytest
import torch

from brdfgan.core.svbrdf import split_maps, srgb_to_linear
from brdfgan.data.materials.albedo import DIELECTRIC_ALBEDO_LINEAR
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers
from brdfgan.data.materials.families import asphalt, leaves, paper, pavers, plaster, terrazzo
from tests.conftest import family_maps

SIZE = 64
MODULES = ("paper", "plaster", "terrazzo", "pavers", "asphalt", "leaves")
# Polished terrazzo is flat but for its pits (which may be absent); its own test checks that.
FLAT = ("terrazzo",)


def _family(module: str) -> MaterialFamily:
    return importlib.import_module(f"brdfgan.data.materials.families.{module}").FAMILY


def _layers(
    family: MaterialFamily, params: dict[str, float], seed: int = 0, size: int = SIZE
) -> MaterialLayers:
    return family.generate({**family.defaults(), **params}, size, torch.Generator().manual_seed(seed))


def _tilt(maps: torch.Tensor) -> float:
    """Mean normal tilt 1 − n_z: 0 for a flat surface."""
    return (1.0 - split_maps(maps).normal[2]).mean().item()


def _mean_hue(basecolor: torch.Tensor) -> float:
    r, g, b = basecolor.mean(dim=(1, 2)).tolist()
    return colorsys.rgb_to_hsv(r, g, b)[0]


def _texel_hsv(basecolor: torch.Tensor) -> torch.Tensor:
    """HSV (hue in turns) of every texel. Shape: ``(3, H, W)`` → ``(H·W, 3)``."""
    return torch.tensor([colorsys.rgb_to_hsv(*rgb) for rgb in basecolor.flatten(1).T.tolist()])


def _texel_hues(basecolor: torch.Tensor) -> torch.Tensor:
    """HSV hue in turns of every texel. Shape: ``(3, H, W)`` → ``(H·W,)``."""
    return _texel_hsv(basecolor)[:, 0]


def _hue_distance(a: float, b: float) -> float:
    d = abs(a - b) % 1.0
    return min(d, 1.0 - d)


@pytest.mark.parametrize("module", MODULES)
def test_dielectric_with_plausible_albedo_and_relief(module: str) -> None:
    family = _family(module)
    generator = torch.Generator().manual_seed(3)
    low, high = DIELECTRIC_ALBEDO_LINEAR
    for params in [family.defaults()] + [family.sample_parameters(generator) for _ in range(3)]:
        maps = family.make_maps(params, SIZE, generator)
        parts = split_maps(maps)
        assert torch.equal(parts.metallic, torch.zeros_like(parts.metallic)), params
        linear = srgb_to_linear(parts.basecolor)
        assert linear.min() >= low - 1e-4 and linear.max() <= high + 1e-4, params
        if module not in FLAT:
            assert (parts.normal[2] < 0.9999).float().mean() > 0.05, params  # some relief
        assert parts.roughness.std() > 1e-3, params


# --- paper, cardboard, cork -------------------------------------------------------------------

PAPER, CARDBOARD, CORK = 0.5, 1.5, 2.5


def test_cork_is_rougher_and_deeper_than_cardboard_and_paper() -> None:
    family = paper.FAMILY
    for seed in range(3):
        maps = {
            mode: family_maps(family, {"mode": mode, "creases": 0.0}, seed, size=SIZE)
            for mode in (PAPER, CARDBOARD, CORK)
        }
        tilts = {mode: _tilt(m) for mode, m in maps.items()}
        assert tilts[PAPER] < tilts[CARDBOARD] < tilts[CORK], tilts
        rough = {mode: split_maps(m).roughness.mean().item() for mode, m in maps.items()}
        assert rough[CORK] > max(rough[PAPER], rough[CARDBOARD]) + 0.05, rough


@pytest.mark.parametrize("flutes", [9, 16])
def test_cardboard_flutes_repeat_scale_times_per_width(flutes: int) -> None:
    for seed in range(2):
        height = _layers(paper.FAMILY, {"mode": CARDBOARD, "scale": flutes, "creases": 0.0}, seed).height[0]
        # The flutes run along rows or columns: the axis whose profile varies most crosses them.
        profiles = (height.mean(dim=0), height.mean(dim=1))
        profile = max(profiles, key=lambda p: p.std().item())
        spectrum = torch.fft.rfft(profile - profile.mean()).abs()
        assert int(spectrum.argmax()) == flutes


@pytest.mark.parametrize("hue", [0.0, 0.33, 0.62, 0.85])
def test_paper_colour_follows_hue(hue: float) -> None:
    maps = family_maps(paper.FAMILY, {"mode": PAPER, "hue": hue, "saturation": 0.6, "ink": 0.0}, size=SIZE)
    assert _hue_distance(_mean_hue(split_maps(maps).basecolor), hue) < 0.02


@pytest.mark.parametrize("mode", [PAPER, CARDBOARD])
def test_print_is_darker_and_smoother_than_the_sheet(mode: float) -> None:
    # Print is painted last, so the same seed gives the same sheet with and without it: the texels
    # that change are the printed ones.
    params = {"mode": mode, "saturation": 0.5, "value": 0.85}
    blank = split_maps(family_maps(paper.FAMILY, {**params, "ink": 0.0}, seed=4, size=SIZE))
    printed = split_maps(family_maps(paper.FAMILY, {**params, "ink": 1.0}, seed=4, size=SIZE))
    ink = (printed.basecolor - blank.basecolor).abs().sum(dim=0) > 1e-4
    assert 0.05 < ink.float().mean() < 0.8
    assert printed.basecolor[:, ink].mean() < blank.basecolor[:, ink].mean() - 0.2
    assert (printed.roughness[0][ink] < blank.roughness[0][ink]).all()
    assert torch.equal(printed.normal, blank.normal)  # ink has no thickness


def test_folds_are_narrow_ridges_or_grooves() -> None:
    assert torch.equal(paper.crease_field(32, 0, torch.Generator()), torch.zeros(32, 32))
    for seed in range(4):
        fold = paper.crease_field(128, 1, torch.Generator().manual_seed(seed))
        assert 0.8 < fold.abs().max() <= 1.0  # peak ±1 on the fold line
        assert fold.abs().median() < 0.3  # most of the sheet is away from the fold
        assert (fold >= 0).all() or (fold <= 0).all()  # one fold: a ridge or a groove


# --- plaster ----------------------------------------------------------------------------------

ORANGE_PEEL, TROWEL, KNOCK_DOWN = 0.5, 1.5, 2.5
CLEAN = {"cracks": 0.0, "dirt": 0.0}


@pytest.mark.parametrize("hue", [0.05, 0.3, 0.58, 0.8])
def test_plaster_paint_follows_hue_and_value(hue: float) -> None:
    maps = family_maps(plaster.FAMILY, {**CLEAN, "hue": hue, "saturation": 0.7, "value": 0.6}, size=SIZE)
    basecolor = split_maps(maps).basecolor
    assert _hue_distance(_mean_hue(basecolor), hue) < 0.02
    assert basecolor.amax(dim=0).mean().item() == pytest.approx(0.6, abs=0.03)  # HSV value


@pytest.mark.parametrize("stucco", [ORANGE_PEEL, TROWEL, KNOCK_DOWN])
def test_plaster_roughness_follows_the_paint(stucco: float) -> None:
    means = []
    for roughness in (0.3, 0.6, 0.9):
        maps = family_maps(plaster.FAMILY, {**CLEAN, "stucco": stucco, "roughness": roughness}, size=SIZE)
        means.append(split_maps(maps).roughness.mean().item())
        assert means[-1] == pytest.approx(roughness, abs=0.12)  # trowelling only polishes a little
    assert means[0] < means[1] < means[2]


def test_knock_down_plateaus_are_raised_and_burnished() -> None:
    for seed in range(3):
        params = {**CLEAN, "stucco": KNOCK_DOWN}
        height = _layers(plaster.FAMILY, params, seed).height.flatten()
        roughness = split_maps(family_maps(plaster.FAMILY, params, seed, size=SIZE)).roughness.flatten()
        plateau, base = height >= height.quantile(0.7), height <= height.quantile(0.3)
        assert roughness[plateau].mean() < roughness[base].mean() - 0.05


def test_cracks_are_dark_rough_grooves() -> None:
    # Cracks are drawn after the stucco, so the same seed gives the same wall with and without
    # them (no dirt, whose blotches are drawn after the cracks): the texels that change are cracks.
    params = {"dirt": 0.0, "stucco": ORANGE_PEEL, "roughness": 0.5}
    whole = _layers(plaster.FAMILY, {**params, "cracks": 0.0}, seed=2)
    cracked = _layers(plaster.FAMILY, {**params, "cracks": 1.0}, seed=2)
    crack = (cracked.height - whole.height)[0] < -0.1
    assert 0.005 < crack.float().mean() < 0.2
    assert (cracked.roughness[0][crack] > whole.roughness[0][crack]).all()
    assert cracked.basecolor[:, crack].mean() < whole.basecolor[:, crack].mean() - 0.1


def test_dirt_darkens_and_roughens_the_paint() -> None:
    for seed in range(3):
        clean = split_maps(family_maps(plaster.FAMILY, {**CLEAN, "roughness": 0.5}, seed, size=SIZE))
        dirty = split_maps(
            family_maps(plaster.FAMILY, {"cracks": 0.0, "dirt": 1.0, "roughness": 0.5}, seed, size=SIZE)
        )
        assert dirty.basecolor.mean() < clean.basecolor.mean() - 0.05
        assert dirty.roughness.mean() > clean.roughness.mean() + 0.02


def test_plaster_relief_parameter_deepens_the_texture() -> None:
    for stucco in (ORANGE_PEEL, TROWEL, KNOCK_DOWN):
        tilts = [
            _tilt(family_maps(plaster.FAMILY, {**CLEAN, "stucco": stucco, "relief": r}, size=128))
            for r in (0.002, 0.008)
        ]
        assert tilts[1] > 2.0 * tilts[0], stucco


# --- terrazzo ---------------------------------------------------------------------------------


def _chip_coverage(params: dict[str, float], seed: int = 0) -> torch.Tensor:
    """Chip coverage in [0, 1] read off the height: without pits it is ``_CHIP_PROUD·size·chips``."""
    height = _layers(terrazzo.FAMILY, {**params, "pits": 0.0}, seed).height[0]
    return height / (terrazzo._CHIP_PROUD * SIZE)


def test_terrazzo_is_polished_flat_and_pits_are_dark_rough_hollows() -> None:
    for seed in range(3):
        flat = split_maps(family_maps(terrazzo.FAMILY, {"pits": 0.0}, seed, size=SIZE))
        assert flat.roughness.mean() < 0.3
        assert (1.0 - flat.normal[2]).max() < 1e-3  # chips stand only a hair proud
        layers = _layers(terrazzo.FAMILY, {"pits": 1.0}, seed, size=128)
        pit = layers.height[0] < 0.0
        assert 0.005 < pit.float().mean() < 0.1
        assert (layers.roughness[0][pit] > 0.6).all()
        assert layers.basecolor[:, pit].mean() < 0.5 * layers.basecolor[:, ~pit].mean()


def test_terrazzo_matrix_is_rougher_than_its_chips() -> None:
    for seed in range(3):
        params = {"roughness": 0.1}
        chips = _chip_coverage(params, seed)
        roughness = _layers(terrazzo.FAMILY, {**params, "pits": 0.0}, seed).roughness[0]
        assert roughness[chips < 0.01].mean() > roughness[chips > 0.99].mean() + 0.05


@pytest.mark.parametrize("density", [0.2, 0.4, 0.65])
def test_terrazzo_chip_density_is_the_covered_fraction(density: float) -> None:
    for seed in range(2):
        assert _chip_coverage({"chip_density": density}, seed).mean().item() == pytest.approx(
            density, abs=0.06
        )


@pytest.mark.parametrize("hue", [0.0, 0.35, 0.7])
def test_terrazzo_colours_follow_chip_and_matrix_hues(hue: float) -> None:
    params = {
        "chip_hue": hue,
        "chip_saturation": 0.9,
        "matrix_hue": (hue + 0.25) % 1.0,
        "matrix_saturation": 0.3,
    }
    chips = _chip_coverage(params).flatten()
    hues = _texel_hues(_layers(terrazzo.FAMILY, {**params, "pits": 0.0}).basecolor)
    chip_hues = hues[chips > 0.99]
    near_chip_hue = torch.tensor([_hue_distance(h, hue) < 0.1 for h in chip_hues.tolist()])
    # The palette's own shades and the analogous hue make up 50 % of its weight, whites, blacks,
    # greys (hue of no consequence) and the complement the rest.
    assert near_chip_hue.float().mean() > 0.35
    matrix_hues = hues[chips < 0.01].tolist()
    assert sorted(_hue_distance(h, params["matrix_hue"]) for h in matrix_hues)[len(matrix_hues) // 2] < 0.02


# --- pavers -----------------------------------------------------------------------------------

COBBLES, RUNNING_BOND, HERRINGBONE = 0.5, 1.5, 2.5


@pytest.mark.parametrize("layout", [COBBLES, RUNNING_BOND, HERRINGBONE])
def test_paver_joints_are_lower_and_rougher(layout: float) -> None:
    generator = torch.Generator().manual_seed(5)
    for seed in range(3):
        params = {**pavers.FAMILY.sample_parameters(generator), "layout": layout, "joint_width": 0.1}
        layers = _layers(pavers.FAMILY, params, seed, size=128)
        height, roughness = layers.height.flatten(), layers.roughness.flatten()
        low, high = height <= height.quantile(0.1), height >= height.quantile(0.5)
        assert roughness[low].mean() > roughness[high].mean() + 0.05, params


@pytest.mark.parametrize("pattern", [pavers.running_bond, pavers.herringbone])
def test_pavers_are_two_by_one_and_each_stone_is_one_paver(
    pattern: Callable[[int, int, float], pavers.Paving],
) -> None:
    # 8 paver widths on 96 texels: a unit square is 12 × 12 texels, a paver two of them.
    paving = pattern(96, 8, 0.1)
    ids, counts = torch.unique(paving.stone, return_counts=True)
    assert len(ids) == 8 * 8 // 2 and ids.max() < paving.count
    assert (counts == 2 * 12 * 12).all()
    for stone in ids[:8].tolist():
        rows, cols = torch.nonzero(paving.stone == stone, as_tuple=True)
        extent = sorted((rows.max() - rows.min() + 1, cols.max() - cols.min() + 1))
        if rows.max() - rows.min() < 90 and cols.max() - cols.min() < 90:  # not wrapped round
            assert extent == [12, 24]


def test_herringbone_lays_half_the_pavers_each_way() -> None:
    paving = pavers.herringbone(64, 8, 0.1)
    vertical = (paving.stone % 2 == 1).float().mean()
    assert vertical == pytest.approx(0.5, abs=1e-6)


def test_cobbles_are_domed_with_polished_tops() -> None:
    for seed in range(3):
        cobbles = {"layout": COBBLES, "count": 6, "moss": 0.0, "relief": 0.02}
        flat = {**cobbles, "layout": RUNNING_BOND}
        cobbled, laid_flat = (family_maps(pavers.FAMILY, p, seed, size=SIZE) for p in (cobbles, flat))
        assert _tilt(cobbled) > 1.5 * _tilt(laid_flat)
        layers = _layers(pavers.FAMILY, cobbles, seed, size=128)
        height, roughness = layers.height.flatten(), layers.roughness.flatten()
        top = height >= height.quantile(0.9)
        side = (height > height.quantile(0.4)) & (height < height.quantile(0.6))
        assert roughness[top].mean() < roughness[side].mean() - 0.03


def test_moss_greens_the_joints() -> None:
    for seed in range(3):
        joints = {"layout": RUNNING_BOND, "joint_width": 0.15, "saturation": 0.0}
        bare = _layers(pavers.FAMILY, {**joints, "moss": 0.0}, seed).basecolor
        mossy = _layers(pavers.FAMILY, {**joints, "moss": 1.0}, seed).basecolor
        greenness = [(c[1] - c[0]).mean().item() for c in (bare, mossy)]
        assert greenness[1] > greenness[0] + 0.01


@pytest.mark.parametrize("hue", [0.0, 0.07, 0.14])
def test_paver_colour_follows_hue(hue: float) -> None:
    params = {"hue": hue, "saturation": 0.45, "color_variation": 0.0, "moss": 0.0, "joint_width": 0.03}
    basecolor = _layers(pavers.FAMILY, {**params, "layout": RUNNING_BOND}).basecolor
    assert _hue_distance(_mean_hue(basecolor), hue) < 0.025


# --- asphalt ----------------------------------------------------------------------------------

NO_MARKING, WHITE, YELLOW = 0.5, 1.5, 2.5


@pytest.mark.parametrize("marking", [WHITE, YELLOW])
@pytest.mark.parametrize("width", [0.1, 0.3])
def test_road_marking_is_a_bright_smooth_stripe_of_its_width(marking: float, width: float) -> None:
    params = {"marking": marking, "marking_width": width, "wear": 0.0, "cracks": 0.0, "aggregate_value": 0.4}
    for seed in range(2):
        maps = split_maps(family_maps(asphalt.FAMILY, params, seed, size=128))
        hsv = _texel_hsv(maps.basecolor)
        # Only paint is saturated (yellow) or brighter than 0.75 (white): stones stay below.
        paint = hsv[:, 1] > 0.5 if marking == YELLOW else hsv[:, 2] > 0.75
        assert paint.float().mean().item() == pytest.approx(width, abs=0.03)
        if marking == YELLOW:
            assert all(_hue_distance(h, 0.13) < 0.03 for h in hsv[paint, 0].tolist())
        roughness, tilt = maps.roughness.flatten(), (1.0 - maps.normal[2]).flatten()
        assert roughness[paint].mean() < roughness[~paint].mean() - 0.25
        assert tilt[paint].mean() < tilt[~paint].mean()  # paint fills the gaps


def test_asphalt_without_marking_has_no_paint() -> None:
    for seed in range(3):
        hsv = _texel_hsv(
            _layers(asphalt.FAMILY, {"marking": NO_MARKING, "aggregate_value": 0.4}, seed).basecolor
        )
        assert hsv[:, 1].max() < 0.5 and hsv[:, 2].max() < 0.75


def test_bare_aggregate_lightens_and_wear_smooths() -> None:
    base = {"marking": NO_MARKING, "cracks": 0.0, "bitumen_value": 0.2, "aggregate_value": 0.7}
    for seed in range(3):
        coated = _layers(asphalt.FAMILY, {**base, "aggregate": 0.0, "wear": 0.0}, seed)
        bare = _layers(asphalt.FAMILY, {**base, "aggregate": 1.0, "wear": 0.0}, seed)
        assert bare.basecolor.mean() > coated.basecolor.mean() + 0.05
        worn = family_maps(asphalt.FAMILY, {**base, "aggregate": 1.0, "wear": 1.0}, seed, size=SIZE)
        fresh = family_maps(asphalt.FAMILY, {**base, "aggregate": 1.0, "wear": 0.0}, seed, size=SIZE)
        assert _tilt(worn) < 0.8 * _tilt(fresh)
        assert split_maps(worn).roughness.mean() < split_maps(fresh).roughness.mean() - 0.03


def test_asphalt_cracks_are_dark_rough_grooves() -> None:
    # Coated stones (no bare aggregate) make the colour independent of the stone tones drawn after
    # the cracks; the same seed then gives the same surface with and without cracks.
    params = {"marking": NO_MARKING, "aggregate": 0.0, "wear": 0.0}
    whole = _layers(asphalt.FAMILY, {**params, "cracks": 0.0}, seed=1, size=128)
    cracked = _layers(asphalt.FAMILY, {**params, "cracks": 1.0}, seed=1, size=128)
    crack = (cracked.height - whole.height)[0] < -0.3
    assert 0.01 < crack.float().mean() < 0.3
    assert (cracked.roughness[0][crack] > whole.roughness[0][crack]).all()
    assert cracked.basecolor[:, crack].mean() < whole.basecolor[:, crack].mean() - 0.02


def test_asphalt_relief_is_resolution_independent() -> None:
    # Grain is counted per image width and stone heights scale with the texel size of a cell, so
    # the relief measured in image widths is the same at every resolution.
    def relief(size: int) -> float:
        height = _layers(asphalt.FAMILY, {"marking": NO_MARKING}, size=size).height
        return height.std().item() / size

    assert relief(64) == pytest.approx(relief(128), rel=0.1)


# --- leaves -----------------------------------------------------------------------------------

SOIL, MOSS, BARK = 0.5, 1.5, 2.5


def _leaf_texels(
    params: dict[str, float], seed: int = 0
) -> tuple[MaterialLayers, MaterialLayers, torch.Tensor]:
    """Bare ground and the same ground under leaves, and where the leaves are.

    Every random draw happens whatever ``cover`` is, so the same seed gives the same ground and
    the texels whose colour changes are the leaves.
    """
    bare = _layers(leaves.FAMILY, {**params, "cover": 0.0}, seed)
    covered = _layers(leaves.FAMILY, {**params, "cover": params.get("cover", 0.9)}, seed)
    leaf = (covered.basecolor - bare.basecolor).abs().sum(dim=0) > 1e-3
    return bare, covered, leaf


@pytest.mark.parametrize("ground", [SOIL, MOSS, BARK])
def test_leaves_lie_on_top_of_the_ground(ground: float) -> None:
    for seed in range(2):
        bare, covered, leaf = _leaf_texels({"ground": ground, "cover": 0.9}, seed)
        assert leaf.float().mean() > 0.4  # three layers of leaves hide most of the ground
        lift = (covered.height - bare.height)[0][leaf]
        assert (lift > 0).float().mean() > 0.95
        # Overlaps stack: the pile is several leaf steps high, far more relief than the ground's.
        step = leaves.FAMILY.defaults()["relief"] * SIZE
        assert covered.height[0][leaf].std() > 0.4 * step


@pytest.mark.parametrize(
    ("season", "hue_range"), [(0.0, (0.2, 0.3)), (1 / 3, (0.1, 0.16)), (2 / 3, (0.0, 0.05))]
)
def test_leaf_colour_follows_the_season(season: float, hue_range: tuple[float, float]) -> None:
    _, covered, leaf = _leaf_texels({"season": season, "color_variation": 0.0, "veins": 0.0})
    hue = _mean_hue(covered.basecolor[:, leaf][:, :, None])
    assert hue_range[0] <= hue <= hue_range[1]


def test_fresh_leaves_are_glossier_than_dry_ones_and_the_ground() -> None:
    means = {}
    for season in (0.0, 1.0):
        bare, covered, leaf = _leaf_texels({"season": season, "color_variation": 0.0, "leaf_roughness": 0.3})
        means[season] = covered.roughness[0][leaf].mean().item()
        assert bare.roughness.mean() > 0.85
    assert means[0.0] == pytest.approx(0.3, abs=0.05)  # waxy fresh leaves (veins a little rougher)
    assert means[1.0] == pytest.approx(leaves._DRY_ROUGHNESS, abs=0.05)


def test_leaves_are_not_cut_at_the_cell_midlines() -> None:
    # Only the 2 × 2 nearest lattice cells are searched, which holds while no leaf reaches past
    # the midline of the next cell. A longer leaf would be cut off along the lines halfway between
    # cell centres, piling up outline crossings on them compared with the lines beside them.
    assert leaves._MAX_HALF_LENGTH < 0.5 + leaves._CENTRE_MARGIN
    cells, size = 4, 160
    crossings = torch.zeros(size)
    for seed in range(4):
        params = {**leaves.FAMILY.defaults(), "cover": 0.5}
        cover = leaves.leaf_layer(size, cells, params, torch.Generator().manual_seed(seed)).cover > 0.5
        for dim in (0, 1):
            # Outline crossings between texel k − 1 and k, summed along the other axis.
            crossings += (cover ^ torch.roll(cover, 1, dims=dim)).float().sum(dim=1 - dim)
    pitch = size // cells
    midlines = torch.arange(pitch // 2, size, pitch)
    beside = torch.cat([midlines - 3, midlines - 2, midlines + 2, midlines + 3])
    assert crossings[midlines].mean() < 1.5 * crossings[beside].mean()
