"""Tests of the metal families: polished_metal, metallic_paint, anodized_metal and tread_plate."""

from __future__ import annotations

import torch

from brdfgan.core.svbrdf import srgb_to_linear
from brdfgan.data.materials.albedo import (
    DIELECTRIC_ALBEDO_LINEAR,
    METAL_F0_LINEAR,
    clamp_dielectric_albedo,
    metal_basecolor,
)
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers
from brdfgan.data.materials.families import anodized_metal, metallic_paint, polished_metal, tread_plate
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, worley
from tests.conftest import family_maps

SIZE = 128


def _tilt_degrees(maps: torch.Tensor) -> torch.Tensor:
    """Angle of every normal from +Z. Shape: ``(8, H, W)`` → ``(H, W)``."""
    return torch.rad2deg(torch.acos(maps[5].clamp(-1.0, 1.0)))


def _f0(name: str) -> torch.Tensor:
    return torch.tensor(metal_basecolor(name)).view(3, 1, 1)


def test_polished_metal_is_exactly_the_named_metal_everywhere() -> None:
    assert set(polished_metal.METALS) <= set(METAL_F0_LINEAR)
    assert len(polished_metal.METALS) == 9
    for index, name in enumerate(polished_metal.METALS):
        # Fingerprints, haze and swirls at their strongest still leave the colour alone.
        maps = family_maps(
            polished_metal.FAMILY, {"metal": index + 0.5, "smudge": 1.0, "swirl": 1.0}, size=64
        )
        assert torch.allclose(maps[0:3], _f0(name).expand(3, 64, 64), atol=1e-6), name
        assert torch.equal(maps[7], torch.ones(64, 64)), name
    # Gold is yellow, chrome neutral: the index really picks different measured colours.
    gold = srgb_to_linear(_f0("gold").flatten())
    assert gold[0] > 1.5 * gold[2]


def test_hammered_dents_tilt_the_normals_strongly() -> None:
    flat = {"hammered": 0.0, "waviness": 0.0, "swirl": 0.0}
    assert _tilt_degrees(family_maps(polished_metal.FAMILY, flat)).max() < 1e-3
    half = _tilt_degrees(family_maps(polished_metal.FAMILY, {**flat, "hammered": 0.5}))
    full = _tilt_degrees(family_maps(polished_metal.FAMILY, {**flat, "hammered": 1.0}))
    assert 10.0 < full.mean() < 25.0 and full.flatten().quantile(0.95) > 20.0
    assert full.mean() > 1.7 * half.mean()
    # Relief is in image-width units: the tilt is alike at twice the resolution.
    full_256 = _tilt_degrees(family_maps(polished_metal.FAMILY, {**flat, "hammered": 1.0}, size=256))
    assert abs(full_256.mean() - full.mean()) < 0.2 * full.mean()


def test_polished_metal_half_resolution_dents_match_full_resolution() -> None:
    # From 512² the dents are computed at half resolution: same dent centres, same field
    # (wrapping included: the borders agree as well as the interior).
    full = worley(512, 10, torch.Generator().manual_seed(3), jitter=0.8)[0]
    half = polished_metal._dent_distance(512, 10, torch.Generator().manual_seed(3))
    assert (full - half).abs().max() < 0.03 and (full - half).abs().mean() < 1e-3
    assert (full - half)[[0, -1]].abs().mean() < 2e-3


def test_smooth_fbm_is_fbm_evaluated_coarsely() -> None:
    # 12 cells in the finest octave, 8 texels each: computed at 128² and upsampled to 512².
    exact = fbm(512, 3, torch.Generator().manual_seed(5), octaves=3)
    smooth = polished_metal.smooth_fbm(512, 3, torch.Generator().manual_seed(5), octaves=3, texels_per_cell=8)
    assert (exact - smooth).abs().max() < 0.01 < exact.abs().max()
    small = polished_metal.smooth_fbm(64, 3, torch.Generator().manual_seed(5), octaves=3, texels_per_cell=8)
    assert torch.equal(small, fbm(64, 3, torch.Generator().manual_seed(5), octaves=3))


def test_polished_metal_smudges_and_swirls_only_roughen() -> None:
    clean = {"roughness": 0.1, "smudge": 0.0, "swirl": 0.0}
    assert torch.allclose(family_maps(polished_metal.FAMILY, clean, size=256)[6], torch.full((256, 256), 0.1))
    smudged = family_maps(polished_metal.FAMILY, {**clean, "smudge": 1.0}, size=256)[6]
    swirled = family_maps(polished_metal.FAMILY, {**clean, "swirl": 1.0}, size=256)[6]
    for roughness in (smudged, swirled):
        assert roughness.min() >= 0.1 - 1e-6
        assert (roughness > 0.15).float().mean() > 0.005
    assert smudged.mean() > 0.11
    # Swirls are thin lines: they touch little of the surface.
    assert (swirled > 0.11).float().mean() < 0.15


def _layers(
    family: MaterialFamily, params: dict[str, float], size: int = SIZE, seed: int = 0
) -> MaterialLayers:
    return family.generate({**family.defaults(), **params}, size, torch.Generator().manual_seed(seed))


def test_tread_plate_lozenges_are_raised_and_alternate() -> None:
    # 8 lozenges over 128 texels: a 16-texel pitch, so cells line up with texels.
    clean = {"lozenge_count": 8.0, "dirt": 0.0, "rust": 0.0, "relief": 0.06}
    height = _layers(tread_plate.FAMILY, clean).height[0]
    profile, _, _ = tread_plate.lozenge_profile(SIZE, 8, tread_plate.FAMILY.defaults()["width"])
    on, off = profile > 0.5, profile == 0.0
    assert 0.05 < on.float().mean() < 0.3 and off.float().mean() > 0.6
    # Lozenges stand 6 % of the 16-texel pitch above the plate.
    assert height[on].mean() > height[off].mean() + 0.5
    assert abs(height.max().item() - 0.06 * 16) < 0.05
    cell = height[:16, :16]
    assert torch.allclose(height[:16, 16:32], cell.flip(1), atol=1e-5)  # neighbour: other diagonal
    assert torch.allclose(height[16:32, 16:32], cell, atol=1e-5)  # diagonal neighbour: same
    assert not torch.allclose(cell, cell.flip(1), atol=0.1)
    # An odd count is made even, so the alternation also holds across the wrap.
    odd = _layers(tread_plate.FAMILY, {**clean, "lozenge_count": 7.0}).height[0]
    assert torch.equal(odd, height)


def test_tread_plate_clean_is_bare_metal_with_polished_tops() -> None:
    for index, name in enumerate(tread_plate.METALS):
        maps = family_maps(tread_plate.FAMILY, {"metal": index + 0.5, "dirt": 0.0, "rust": 0.0})
        assert torch.equal(maps[7], torch.ones(SIZE, SIZE)), name
        assert torch.allclose(maps[0:3], _f0(name).expand(3, SIZE, SIZE), atol=1e-6), name
    profile, _, _ = tread_plate.lozenge_profile(SIZE, 8, tread_plate.FAMILY.defaults()["width"])
    tops, plate = profile > 0.9, profile == 0.0
    clean = {"dirt": 0.0, "rust": 0.0, "lozenge_count": 8.0, "roughness": 0.4}
    unworn = family_maps(tread_plate.FAMILY, {**clean, "wear": 0.0})[6]
    worn = family_maps(tread_plate.FAMILY, {**clean, "wear": 1.0})[6]
    assert abs(unworn[tops].mean() - unworn[plate].mean()) < 0.02
    assert worn[tops].mean() < worn[plate].mean() - 0.1
    assert torch.equal(worn[plate], unworn[plate])  # traffic polishes only what it touches


def test_tread_plate_dirt_and_rust_only_in_the_valleys() -> None:
    profile, _, _ = tread_plate.lozenge_profile(SIZE, 8, tread_plate.FAMILY.defaults()["width"])
    for metal in (0.5, 1.5):
        params = {"metal": metal, "dirt": 0.5, "rust": 0.4, "lozenge_count": 8.0}
        maps = family_maps(tread_plate.FAMILY, params)
        metallic, rough = maps[7], maps[6]
        covered = metallic < 0.01
        assert 0.2 < covered.float().mean() < 0.8
        assert torch.all(metallic[profile > 0.2] == 1.0)  # lozenges stay bare metal
        # Metallic is 0 or 1 except along the boundaries of the dirt and rust patches.
        assert ((metallic > 0.02) & (metallic < 0.98)).float().mean() < 0.06
        assert rough[covered].mean() > rough[metallic == 1.0].mean() + 0.3
        # Where the metal shows, it is the metal's F0; where covered, a dielectric albedo.
        f0 = _f0(tread_plate.METALS[int(metal)])
        bare = metallic == 1.0
        assert torch.allclose(maps[0:3][:, bare], f0.flatten()[:, None].expand(3, int(bare.sum())), atol=1e-6)
        linear = srgb_to_linear(maps[0:3][:, covered])
        assert (
            linear.min() >= DIELECTRIC_ALBEDO_LINEAR[0] - 1e-4 and linear.max() <= DIELECTRIC_ALBEDO_LINEAR[1]
        )
    # Rust on steel is orange (red well above blue); the oxide on aluminium is not.
    steel = family_maps(tread_plate.FAMILY, {"metal": 0.5, "dirt": 0.0, "rust": 0.5})
    aluminium = family_maps(tread_plate.FAMILY, {"metal": 1.5, "dirt": 0.0, "rust": 0.5})
    for maps, orange in ((steel, True), (aluminium, False)):
        rust = maps[7] < 0.01
        assert ((maps[0] - maps[2])[rust].mean() > 0.15) == orange


def test_anodized_metal_is_dyed_aluminium_of_the_chosen_hue() -> None:
    aluminium = torch.tensor(METAL_F0_LINEAR["aluminium"]).view(3, 1, 1)
    # Red, green and blue dyes: the dominant channel of the base colour follows the hue.
    for hue, channel in ((0.0, 0), (1 / 3, 1), (2 / 3, 2)):
        params = {"hue": hue, "saturation": 0.9, "value": 0.8}
        maps = family_maps(anodized_metal.FAMILY, params, size=64)
        assert torch.equal(maps[7], torch.ones(64, 64))
        mean = maps[0:3].mean(dim=(1, 2))
        assert mean.argmax() == channel and mean.max() - mean.min() > 0.4, hue
        assert torch.allclose(mean, torch.tensor(anodized_metal.anodised_color(hue, 0.9, 0.8)), atol=0.02)
        # A dye only absorbs: 4 % oxide reflection ≤ F0 ≤ the bare aluminium F0.
        linear = srgb_to_linear(maps[0:3])
        assert linear.min() >= 0.04 - 1e-4 and torch.all(linear <= aluminium + 1e-3)
    clear = family_maps(anodized_metal.FAMILY, {"saturation": 0.0, "value": 1.0}, size=64)[0:3]
    assert torch.allclose(clear.mean(dim=(1, 2)), _f0("aluminium").flatten(), atol=0.02)
    black = family_maps(anodized_metal.FAMILY, {"saturation": 0.0, "value": 0.15}, size=64)[0:3]
    assert 0.04 <= srgb_to_linear(black).mean() < 0.07


def test_anodized_metal_brushed_is_streaky_and_blasted_is_isotropic() -> None:
    def anisotropy(params: dict[str, float]) -> float:
        rough = family_maps(anodized_metal.FAMILY, params)[6]
        along_rows = (rough[:, 1:] - rough[:, :-1]).abs().mean()
        along_columns = (rough[1:] - rough[:-1]).abs().mean()
        ratio = float(along_rows / along_columns)
        return max(ratio, 1.0 / ratio)

    assert anisotropy({"finish": 0.0, "texture": 1.0}) < 1.3
    for texture in (0.4, 1.0):
        assert anisotropy({"finish": 1.0, "texture": texture}) > 3.0


def test_anodized_metal_holes_are_dark_voids_with_bright_chamfers() -> None:
    params = {"holes": 4.0, "hole_size": 0.25, "saturation": 0.9, "value": 0.6}
    maps = family_maps(anodized_metal.FAMILY, params)
    height = _layers(anodized_metal.FAMILY, params).height[0]
    metallic, basecolor = maps[7], maps[0:3]
    void = metallic < 0.01
    # π·0.25² of every cell is hole; its edge is one texel soft.
    assert abs(void.float().mean() - torch.pi * 0.25**2) < 0.03
    assert ((metallic > 0.01) & (metallic < 0.99)).float().mean() < 0.05
    assert srgb_to_linear(basecolor[:, void]).max() < 0.03 and torch.all(maps[6][void] > 0.95)
    # Chamfers: bare aluminium (its measured F0), smoother than the anodising, sloping into the hole.
    bare = (basecolor - _f0("aluminium")).abs().amax(dim=0) < 1e-4
    assert 0.03 < bare.float().mean() < 0.25
    assert maps[6][bare].mean() < maps[6][~bare & ~void].mean() - 0.1
    assert height[void].mean() < height[bare].mean() < height[~bare & ~void].mean()
    assert _tilt_degrees(maps)[bare].mean() > 30.0


def test_metallic_paint_is_paint_with_metal_flakes() -> None:
    params = {"mode": 0.0, "hue": 0.0, "saturation": 0.9, "value": 0.7, "flake_count": 40.0, "tint": 0.0}
    maps = family_maps(metallic_paint.FAMILY, params, size=256)
    metallic, basecolor = maps[7], maps[0:3]
    flake, paint = metallic == 1.0, metallic == 0.0
    # Flakes cover about the flake density; metallic is 0 or 1 but along their one-texel edges.
    assert abs((metallic > 0.5).float().mean() - 0.12) < 0.02
    assert flake.any() and (flake | paint).float().mean() > 0.85
    # The paint is the chosen colour, a plausible dielectric albedo; untinted flakes are aluminium.
    red = clamp_dielectric_albedo(
        hsv_to_rgb(torch.zeros(1, 1), torch.full((1, 1), 0.9), torch.full((1, 1), 0.7))
    )
    assert torch.allclose(basecolor[:, paint], red.view(3, 1).expand(3, int(paint.sum())), atol=1e-6)
    assert torch.allclose(
        basecolor[:, flake], _f0("aluminium").view(3, 1).expand(3, int(flake.sum())), atol=1e-6
    )
    # Every flake lies at its own tilt, so flakes scatter the normals; the paint is nearly flat.
    tilt = _tilt_degrees(maps)
    assert tilt[flake].mean() > 3.0 * tilt[paint].mean() and tilt[paint].mean() < 2.0
    assert maps[3][flake].std() > 0.05
    # A fully tinted coat colours the flakes with the paint's hue.
    tinted = family_maps(metallic_paint.FAMILY, {**params, "tint": 1.0}, size=256)
    flake_color = tinted[0:3][:, tinted[7] == 1.0].mean(dim=1)
    assert flake_color[0] > flake_color[2] + 0.3


def test_metallic_paint_hue_moves_the_paint_hue() -> None:
    for hue, channel in ((0.0, 0), (1 / 3, 1), (2 / 3, 2)):
        maps = family_maps(metallic_paint.FAMILY, {"mode": 0.0, "hue": hue, "saturation": 0.8}, size=64)
        paint = maps[7] == 0.0
        assert maps[0:3][:, paint].mean(dim=1).argmax() == channel, hue


def test_foil_is_exactly_the_named_metal_with_strong_crinkles() -> None:
    for index, name in enumerate(metallic_paint.FOIL_METALS):
        maps = family_maps(metallic_paint.FAMILY, {"mode": 1.0, "foil_metal": index + 0.5}, size=64)
        assert torch.equal(maps[7], torch.ones(64, 64)), name
        assert torch.allclose(maps[0:3], _f0(name).expand(3, 64, 64), atol=1e-6), name
    tilts = [
        _tilt_degrees(family_maps(metallic_paint.FAMILY, {"mode": 1.0, "crinkle": c})).mean()
        for c in (0.0, 1.0)
    ]
    assert tilts[1] > 18.0 and tilts[1] > 3.0 * tilts[0]
    # The mode switches at 0.5: just below it is paint with dielectric texels.
    assert (family_maps(metallic_paint.FAMILY, {"mode": 0.49}, size=64)[7] == 0.0).any()
