"""Tests of the mosaic, relief tile, painted wood, plastic and fabric material families.

The generic standards (valid maps, seeding, tiling, parameter ranges) are in
tests/data/materials/test_material_library.py; these check what each surface is physically made of.
"""

from __future__ import annotations

import importlib
import math

import kornia
import pytest
import torch
from torch import Tensor

from brdfgan.core.svbrdf import split_maps, srgb_to_linear
from brdfgan.data.materials.albedo import DIELECTRIC_ALBEDO_LINEAR
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers
from brdfgan.data.materials.families import mosaic
from brdfgan.data.materials.noise import worley
from tests.conftest import family_maps

SIZE = 128
MODULES = ("mosaic", "relief_tiles", "painted_wood", "plastic", "fabric")
# Least mean 1 − n_z at 128² for defaults and samples: deep grout and embossed motifs tilt the
# normals a lot; boards are flat apart from grooves, chips and grain (like wood_planks); smooth
# plastic is flat, and fine plastic textures and threads are below 128²'s Nyquist limit (their
# relief is checked below at resolved scales).
MIN_TILT = {"mosaic": 0.005, "relief_tiles": 0.003, "painted_wood": 0.0005, "plastic": 0.0, "fabric": 0.0}


def _family(module: str) -> MaterialFamily:
    return importlib.import_module(f"brdfgan.data.materials.families.{module}").FAMILY


def _layers(
    module: str, params: dict[str, float] | None = None, size: int = SIZE, seed: int = 0
) -> MaterialLayers:
    family = _family(module)
    return family.generate({**family.defaults(), **(params or {})}, size, torch.Generator().manual_seed(seed))


def _hue_turns(basecolor: Tensor) -> Tensor:
    """Per-texel hue in turns. Shape: ``(3, H, W)`` → ``(H, W)``."""
    return kornia.color.rgb_to_hsv(basecolor[None])[0, 0] / (2.0 * math.pi)


def _mean_hue(hue: Tensor) -> tuple[float, float]:
    """Circular mean of hues in turns and its resultant length (1 = all the same hue)."""
    angle = 2.0 * math.pi * hue.flatten()
    s, c = angle.sin().mean(), angle.cos().mean()
    return float(torch.atan2(s, c) / (2.0 * math.pi) % 1.0), float(torch.hypot(s, c))


def _tilt(maps: Tensor) -> Tensor:
    """Per-texel 1 − n_z of a map set: 0 on flat texels. Shape: ``(8, H, W)`` → ``(H, W)``."""
    return 1.0 - split_maps(maps).normal[2]


@pytest.mark.parametrize("module", MODULES)
def test_dielectric_with_plausible_albedo_and_relief(module: str) -> None:
    family = _family(module)
    generator = torch.Generator().manual_seed(3)
    for params in [family.defaults()] + [family.sample_parameters(generator) for _ in range(3)]:
        maps = family.make_maps(params, SIZE, generator)
        parts = split_maps(maps)
        assert torch.equal(parts.metallic, torch.zeros_like(parts.metallic)), params
        linear = srgb_to_linear(parts.basecolor)
        low, high = DIELECTRIC_ALBEDO_LINEAR
        assert linear.min() >= low - 1e-4 and linear.max() <= high + 1e-4, params
        # Every one of these surfaces has visible relief: normals are not near-flat.
        assert _tilt(maps).mean() > MIN_TILT[module], params


@pytest.mark.parametrize(
    ("module", "params", "sizes"),
    [
        ("mosaic", {"irregular": 0.0}, (256, 512)),
        ("mosaic", {"irregular": 1.0}, (256, 512)),
        ("relief_tiles", {}, (256, 512)),
        # Board grooves and latewood edges are a few texels wide only from 512² up.
        ("painted_wood", {"chipping": 0.6}, (512, 1024)),
        ("plastic", {"mode": 4.0}, (256, 512)),
        ("fabric", {"threads": 32.0}, (256, 512)),
    ],
)
def test_relief_is_resolution_independent(
    module: str, params: dict[str, float], sizes: tuple[int, int]
) -> None:
    # Heights are in texels ∝ size and features per image width, so once features span a few
    # texels the mean normal tilt barely changes with the resolution.
    tilts = [_tilt(family_maps(_family(module), params, size=size)).mean().item() for size in sizes]
    assert tilts[0] == pytest.approx(tilts[1], rel=0.3)


def test_mosaic_half_resolution_cells_match_full_resolution_worley() -> None:
    f1, f2, cell = mosaic._cells(512, 20, torch.Generator().manual_seed(0))
    g1, g2, gcell = worley(512, 20, torch.Generator().manual_seed(0), jitter=0.85)
    # The distances (in pitches; a texel is 0.04 pitch) match up to the bilinear interpolation,
    # worst at their creases and at the feature points. What the mosaic uses is the distance to
    # the cell border, which shapes grout and bevel (edge < 0.2 pitch): off by well under a
    # texel on average (a one-texel misalignment would be ~0.04 everywhere).
    edge, half_res_edge = 0.5 * (g2 - g1), 0.5 * (f2 - f1)
    assert (f1 - g1).abs().max() < 0.05 and (f2 - g2).abs().max() < 0.05
    error = (half_res_edge - edge)[edge < 0.2].abs()
    assert error.max() < 0.035 and error.mean() < 0.005
    # Ids differ only right at the cell borders (edge < 0.03 pitch), where even the narrowest
    # grout (half width 0.02, bevel 0.12) leaves the tessera colour a weight below 2 %.
    differ = cell != gcell
    assert differ.float().mean() < 0.05 and edge[differ].max() < 0.03


def test_mosaic_grout_is_lower_and_rougher_than_the_tesserae() -> None:
    for irregular in (0.0, 1.0):
        layers = _layers("mosaic", {"irregular": irregular})
        height, roughness = layers.height.flatten(), layers.roughness.flatten()
        grout = height <= height.quantile(0.10)
        tesserae = height >= height.quantile(0.50)
        assert roughness[grout].mean() > 0.8 and roughness[tesserae].mean() < 0.2
        # Deep grout: most of its nominal depth (0.004 of the width) below the tessera faces.
        assert height[tesserae].mean() - height[grout].mean() > 0.8 * 0.004 * SIZE


def test_mosaic_palette_follows_hue_and_spread() -> None:
    for hue in (0.05, 0.3, 0.7):
        layers = _layers("mosaic", {"hue": hue, "hue_spread": 0.0, "saturation": 0.9})
        tesserae = layers.height[0] >= layers.height.quantile(0.5)
        mean, concentration = _mean_hue(_hue_turns(layers.basecolor)[tesserae])
        assert abs(mean - hue) < 0.015 and concentration > 0.99, hue
    for seed in range(3):
        layers = _layers("mosaic", {"hue_spread": 0.5, "saturation": 0.9}, seed=seed)
        tesserae = layers.height[0] >= layers.height.quantile(0.5)
        assert _mean_hue(_hue_turns(layers.basecolor)[tesserae])[1] < 0.95, seed


def test_mosaic_square_grid_repeats_at_the_pitch_and_cells_do_not() -> None:
    # 16 tesserae over 128 texels: a square grid repeats every 8 texels; Worley cells do not.
    def steps(irregular: float) -> tuple[float, float]:
        height = _layers("mosaic", {"irregular": irregular, "tilt": 0.0, "tesserae": 16.0}).height[0]
        return (height - height.roll(8, 1)).abs().mean().item(), (
            height - height.roll(4, 1)
        ).abs().mean().item()

    pitch, half_pitch = steps(0.0)
    assert pitch < 0.2 * half_pitch
    pitch, half_pitch = steps(1.0)
    assert pitch > 0.6 * half_pitch


def test_mosaic_tilt_tilts_the_tessera_faces() -> None:
    def face_tilt(tilt: float) -> float:
        height = _layers("mosaic", {"tilt": tilt}).height[0]
        faces = height >= height.quantile(0.6)
        return _tilt(family_maps(_family("mosaic"), {"tilt": tilt}))[faces].mean().item()

    assert face_tilt(0.7) > 1.2 * face_tilt(0.0)


def _tile_interiors(size: int, tiles: int, margin: int) -> Tensor:
    """Texels at least ``margin`` texels inside a tile of a ``tiles × tiles`` grid.

    Shape: ``(size, size)``.
    """
    local = torch.arange(size) % (size // tiles)
    inside = (local >= margin) & (local < size // tiles - margin)
    return inside[:, None] & inside[None, :]


@pytest.mark.parametrize("pattern", [0.0, 1.0, 2.0, 3.0])
def test_relief_tiles_glaze_pools_dark_and_saturated_in_recesses(pattern: float) -> None:
    faces = _tile_interiors(SIZE, 2, margin=5)  # clear of grout and bevel
    for pooling in (0.0, 1.0):
        layers = _layers("relief_tiles", {"tile_count": 2.0, "pattern": pattern, "pooling": pooling})
        hsv = kornia.color.rgb_to_hsv(layers.basecolor[None])[0]
        height = layers.height[0][faces]
        brightness = torch.corrcoef(torch.stack([height, hsv[2][faces]]))[0, 1]
        saturation = torch.corrcoef(torch.stack([height, hsv[1][faces]]))[0, 1]
        if pooling:
            assert brightness > 0.8 and saturation < -0.4
        else:  # without pooling the glaze colour ignores the relief
            assert brightness.abs() < 0.1 and saturation.abs() < 0.1


@pytest.mark.parametrize("pattern", [0.0, 1.0, 2.0, 3.0])
def test_relief_tiles_motif_relief_is_strong_and_follows_the_parameter(pattern: float) -> None:
    def tilt(relief: float) -> float:
        maps = family_maps(_family("relief_tiles"), {"tile_count": 2.0, "pattern": pattern, "relief": relief})
        return _tilt(maps)[_tile_interiors(SIZE, 2, margin=5)].mean().item()

    # A flat glazed tile face has 1 − n_z ≈ 0; these motifs tilt the face by 10–25° on average.
    assert tilt(0.05) > 0.02
    assert tilt(0.12) > 2.0 * tilt(0.02)


def test_relief_tiles_glaze_has_the_hue_and_is_smoother_than_grout() -> None:
    faces = _tile_interiors(SIZE, 2, margin=5)
    for hue in (0.1, 0.45, 0.8):
        layers = _layers("relief_tiles", {"tile_count": 2.0, "hue": hue, "saturation": 0.8})
        mean, concentration = _mean_hue(_hue_turns(layers.basecolor)[faces])
        assert abs(mean - hue) < 0.01 and concentration > 0.99, hue
        grout = layers.height[0] <= layers.height.quantile(0.02)
        assert layers.roughness[0][grout].mean() > layers.roughness[0][faces].mean() + 0.6


def _board_rows(size: int, boards: int, low: float, high: float) -> Tensor:
    """Texels whose position across their board lies in ``[low, high)`` (0 and 1 = the grooves).

    Shape: ``(size, size)``.
    """
    across = (torch.arange(size) % (size // boards)).float() / (size // boards)
    return ((across >= low) & (across < high))[:, None].expand(size, size)


def test_painted_wood_intact_paint_has_the_paint_colour_and_follows_gloss() -> None:
    faces = _board_rows(SIZE, 4, 0.07, 0.93)  # clear of the grooves
    paint = {"boards": 4.0, "chipping": 0.0, "paint": 1.0, "hue": 0.6, "saturation": 0.7, "value": 0.6}
    for gloss, coat_roughness in ((0.0, 0.7), (1.0, 0.06)):
        layers = _layers("painted_wood", {**paint, "gloss": gloss})
        hsv = kornia.color.rgb_to_hsv(layers.basecolor[None])[0]
        hue = hsv[0][faces] / (2.0 * math.pi)
        assert (hue - 0.6).abs().max() < 0.005 and (hsv[2][faces] - 0.6).abs().max() < 0.03
        coat = layers.roughness[0][faces]
        assert coat.mean().item() == pytest.approx(coat_roughness, abs=0.01)
        assert coat.min() > 0.6 * coat_roughness  # only faint brush streaks, never a mirror


def test_painted_wood_clear_lacquer_shows_the_wood_grain() -> None:
    faces = _board_rows(SIZE, 4, 0.07, 0.93)
    lacquer = _layers("painted_wood", {"boards": 4.0, "chipping": 0.0, "paint": 0.0, "hue": 0.6})
    hsv = kornia.color.rgb_to_hsv(lacquer.basecolor[None])[0]
    mean, _ = _mean_hue(hsv[0][faces] / (2.0 * math.pi))
    assert 0.04 < mean < 0.11  # orange-brown wood, not the (blue) paint hue
    assert hsv[2][faces].std() > 0.03  # rings and fibres visible
    painted = _layers("painted_wood", {"boards": 4.0, "chipping": 0.0, "paint": 1.0, "hue": 0.6})
    assert kornia.color.rgb_to_hsv(painted.basecolor[None])[0, 2][faces].std() < 0.01


def test_painted_wood_chips_expose_lower_rougher_wood_at_the_board_edges() -> None:
    faces = _board_rows(SIZE, 4, 0.07, 0.93)
    glossy = {"boards": 4.0, "gloss": 1.0, "hue": 0.6}
    intact = _layers("painted_wood", {**glossy, "chipping": 0.0})
    for chipping in (0.5, 1.0):
        worn = _layers("painted_wood", {**glossy, "chipping": chipping})
        # Same seed, same draws: the texels whose roughness changed are the chips.
        chip = (worn.roughness - intact.roughness).abs()[0] > 0.05
        assert 0.05 < chip.float().mean() < 0.95
        assert worn.roughness[0][chip].mean() > 0.7 > 0.1 > worn.roughness[0][~chip & faces].mean()
        # A paint layer (0.0012 of the width) lower, and wood-coloured.
        assert (intact.height - worn.height)[0][chip].mean() > 0.5 * 0.0012 * SIZE
        mean, _ = _mean_hue(_hue_turns(worn.basecolor)[chip & faces])
        assert 0.03 < mean < 0.15
        edges = _board_rows(SIZE, 4, 0.0, 0.2) | _board_rows(SIZE, 4, 0.8, 1.0)
        middle = _board_rows(SIZE, 4, 0.3, 0.7)
        assert chip[edges].float().mean() > 2.0 * chip[middle].float().mean()


def test_painted_wood_grain_shows_through_the_paint_as_relief() -> None:
    faces = _board_rows(SIZE, 4, 0.07, 0.93)
    plain = {"boards": 4.0, "chipping": 0.0, "paint": 1.0}
    tilts = [
        _tilt(family_maps(_family("painted_wood"), {**plain, "grain_relief": r}))[faces].mean()
        for r in (0.0002, 0.002)
    ]
    assert tilts[1] > 1e-3 and tilts[1] > 20.0 * tilts[0]


PLASTIC_MODES = {
    "smooth": 0.0,
    "leather_grain": 1.0,
    "stipple": 2.0,
    "ribbed": 3.0,
    "rubber_studs": 4.0,
    "rubber_ribs": 5.0,
}


def test_plastic_textures_have_strong_relief_and_smooth_plastic_is_flat() -> None:
    # At the coarsest scale every texture spans ≥ 8 texels at 256².
    plastic = _family("plastic")
    tilts = {
        name: _tilt(family_maps(plastic, {"mode": mode, "texture_scale": 0.0}, size=256)).mean().item()
        for name, mode in PLASTIC_MODES.items()
    }
    assert tilts["smooth"] < 1e-3
    assert all(tilt > 0.008 for name, tilt in tilts.items() if name != "smooth"), tilts
    assert min(tilts["rubber_studs"], tilts["rubber_ribs"]) > 0.04  # mats: strong relief


def test_plastic_rubber_is_dark_and_rough_plastic_keeps_its_colour_and_gloss() -> None:
    colour = {"hue": 0.3, "saturation": 0.75, "value": 0.9, "roughness": 0.1, "wear": 0.0}
    for name, mode in PLASTIC_MODES.items():
        parts = split_maps(family_maps(_family("plastic"), {**colour, "mode": mode}))
        if name.startswith("rubber"):
            assert parts.basecolor.max() < 0.3 and parts.roughness.min() > 0.6, name
        else:
            mean, concentration = _mean_hue(_hue_turns(parts.basecolor))
            assert abs(mean - 0.3) < 0.005 and concentration > 0.999, name
            assert parts.basecolor.max() > 0.85 and parts.roughness.max() < 0.16, name


def test_plastic_ribs_and_studs_are_regular() -> None:
    # texture_scale picks 16 ribs (12·5^s) and 8 studs (6·4^s) per width: pitches 8 and 16 texels.
    ribs = _layers("plastic", {"mode": 3.0, "texture_scale": math.log(16 / 12) / math.log(5)}).height[0]
    assert (ribs - ribs.roll(1, dims=0)).abs().max() < 1e-5  # straight along the rows
    assert (ribs - ribs.roll(8, dims=1)).abs().max() < 1e-4 < (ribs - ribs.roll(4, dims=1)).abs().mean()
    studs = _layers("plastic", {"mode": 4.0, "texture_scale": math.log(8 / 6) / math.log(4), "wear": 0.0})
    height = studs.height[0]
    centres, corners = height[8::16, 8::16], height[::16, ::16]
    assert centres.min() > corners.max() + 0.9 * 0.1 * 16  # relief 0.1 of the pitch


def test_plastic_wear_scuffs_plastic_and_polishes_rubber() -> None:
    for mode, rougher in ((1.0, True), (4.0, False)):
        pristine = _layers("plastic", {"mode": mode, "wear": 0.0})
        worn = _layers("plastic", {"mode": mode, "wear": 1.0})
        change = (worn.roughness - pristine.roughness)[0]
        scuffed = change.abs() > 0.05
        assert 0.05 < scuffed.float().mean() < 0.9, mode
        assert (change[scuffed].mean() > 0.1) if rougher else (change[scuffed].mean() < -0.05), mode


# 32 threads over 128 texels: a thread pitch of 4 texels.
FABRIC = {"threads": 32.0, "repeats": 2.0}
PITCH = 4


def test_fabric_is_rough_with_sheen_on_the_thread_crowns() -> None:
    generator = torch.Generator().manual_seed(5)
    family = _family("fabric")
    for params in [family.defaults()] + [family.sample_parameters(generator) for _ in range(3)]:
        layers = family.generate({**params, **FABRIC}, SIZE, generator)  # threads resolved at 128²
        assert layers.roughness.min() >= 0.6 and layers.roughness.mean() >= 0.7, params
        height, roughness = layers.height.flatten(), layers.roughness.flatten()
        crowns, gaps = height >= height.quantile(0.8), height <= height.quantile(0.2)
        assert roughness[crowns].mean() < roughness[gaps].mean() - 0.03, params


def test_fabric_threads_have_strong_relief() -> None:
    for weave in (0.0, 1.0):
        assert _tilt(family_maps(_family("fabric"), {**FABRIC, "weave": weave})).mean() > 0.02


def test_fabric_weave_structure_plain_and_twill() -> None:
    def shifted(weave: float, rows: int, cols: int) -> float:
        height = _layers("fabric", {**FABRIC, "weave": weave}).height[0]
        return (height - height.roll((rows, cols), dims=(0, 1))).abs().mean().item()

    # Both repeat one thread right and one up, where the float pattern (i + j) is unchanged ...
    scale = shifted(0.0, 0, PITCH)
    for weave in (0.0, 1.0):
        assert shifted(weave, -PITCH, PITCH) < 1e-4 * scale
        assert shifted(weave, 0, PITCH) > 0.3 * scale  # ... but not along one axis
    # ... a plain weave (1/1) repeats every two threads, a 2/2 twill every four.
    assert shifted(0.0, PITCH, PITCH) < 1e-4 * scale and shifted(0.0, 2 * PITCH, 0) < 1e-4 * scale
    assert shifted(1.0, PITCH, PITCH) > 0.3 * scale and shifted(1.0, 2 * PITCH, 0) > 0.3 * scale
    assert shifted(1.0, 4 * PITCH, 0) < 1e-4 * scale


def _band_means(basecolor: Tensor, along_columns: bool) -> Tensor:
    """Mean colour of bands four threads wide (one weave repeat, so the weave averages out),
    across the columns (``along_columns``) or across the rows. Shape: ``(3, H, W)`` → ``(3, bands)``."""
    band = 4 * PITCH
    _, height, width = basecolor.shape
    if along_columns:
        return basecolor.reshape(3, height, width // band, band).mean(dim=(1, 3))
    return basecolor.reshape(3, height // band, band, width).mean(dim=(2, 3))


def test_fabric_colour_patterns_follow_the_yarns() -> None:
    def spreads(pattern: float) -> tuple[float, float]:
        basecolor = _layers("fabric", {**FABRIC, "pattern": pattern}).basecolor
        return (
            _band_means(basecolor, along_columns=True).std(dim=1).max().item(),
            _band_means(basecolor, along_columns=False).std(dim=1).max().item(),
        )

    solid, stripes, checks = spreads(0.0), spreads(2.0), spreads(3.0)
    assert max(solid) < 0.02
    # Each band mixes the striped yarns with the crossing ones: half the colour contrast.
    assert stripes[0] > 0.05 and stripes[1] < 0.02  # warp stripes: colour changes across columns only
    assert min(checks) > 0.05  # warp and weft both striped


def test_fabric_two_tone_and_print_colours() -> None:
    params = {**FABRIC, "hue": 0.62, "saturation": 0.6, "value": 0.7, "weave": 0.0}
    two_tone = _layers("fabric", {**params, "pattern": 1.0})
    hsv = kornia.color.rgb_to_hsv(two_tone.basecolor[None])[0]
    cell, offset = torch.arange(SIZE) // PITCH, torch.arange(SIZE) % PITCH
    # Plain weave: warp floats on a checkerboard of thread crossings; their middle texels, clear
    # of the gaps where the crossing thread shows, are warp.
    floats = (cell.view(1, -1) + cell.view(-1, 1)) % 2 == 0
    middle = (offset > 0) & (offset < PITCH - 1)
    warp_over = floats & middle.view(1, -1) & middle.view(-1, 1)
    weft_over = ~floats & middle.view(1, -1) & middle.view(-1, 1)
    assert abs(_mean_hue(hsv[0][warp_over] / (2.0 * math.pi))[0] - 0.62) < 0.01
    assert hsv[1][warp_over].mean() > 0.5 > 0.15 > hsv[1][weft_over].mean()  # dyed warp, undyed weft
    printed = _layers("fabric", {**params, "pattern": 4.0, "accent_hue": 0.5})
    hue = _hue_turns(printed.basecolor)
    ink = ((hue - 0.12).abs() < 0.03).float().mean()  # the accent: 0.62 + 0.5 turns
    assert 0.05 < ink < 0.5
