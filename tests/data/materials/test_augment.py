from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.render import render_flash
from brdfgan.core.sampling import log_uniform
from brdfgan.core.svbrdf import CHANNELS, flat_maps, join_maps, linear_to_srgb, srgb_to_linear, validate_maps
from brdfgan.data.materials.augment import CropSampling, CropTransform, crop_maps, random_crops
from brdfgan.data.materials.base import height_to_normal
from brdfgan.data.materials.noise import fbm, value_noise


def _material(size: int = 64, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """A tileable material whose normals come from its height, and the height."""
    g = torch.Generator().manual_seed(seed)
    height = (fbm(size, 4, g, octaves=3) * size * 0.05)[None]
    base = torch.stack([value_noise(size, 4, g) for _ in range(3)])
    rough = value_noise(size, 8, g)[None]
    maps = join_maps(base, height_to_normal(height), rough, (rough > 0.6).float())
    return maps, height


def _as_maps(field: torch.Tensor) -> torch.Tensor:
    """Carry a 1-channel field through crop_maps (in the roughness slot)."""
    maps = flat_maps(*field.shape[-2:])
    maps[CHANNELS["roughness"]] = field
    return maps


def test_identity_transform_reproduces_the_source() -> None:
    maps, _ = _material()
    out = crop_maps(maps, CropTransform(center=(0.0, 0.0), scale=1.0, angle=0.0), 64)
    torch.testing.assert_close(out, maps, atol=1e-5, rtol=0)


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_rotation_rotates_normal_vectors_consistently_with_the_height(quarter_turns: int) -> None:
    # Rotating the maps must equal building normals from the rotated height: the XY of the
    # normals turns with the content. Quarter turns sample texel centres exactly.
    maps, height = _material()
    transform = CropTransform(center=(0.0, 0.0), scale=1.0, angle=quarter_turns * math.pi / 2)
    rotated = crop_maps(maps, transform, 64)
    rotated_height = crop_maps(_as_maps((height - height.min()) / 100.0), transform, 64)[
        CHANNELS["roughness"]
    ]
    expected_normals = height_to_normal(rotated_height * 100.0)
    torch.testing.assert_close(rotated[CHANNELS["normal"]], expected_normals, atol=1e-4, rtol=0)
    # The content itself turned counter-clockwise: torch.rot90 over (H, W) with +Y up.
    torch.testing.assert_close(
        rotated[CHANNELS["basecolor"]],
        torch.rot90(maps[CHANNELS["basecolor"]], quarter_turns, dims=(1, 2)),
        atol=1e-5,
        rtol=0,
    )


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_render_of_rotated_maps_is_the_rotated_render(quarter_turns: int) -> None:
    # The flash capture is symmetric under turns about the sample centre, so photographing the
    # rotated maps must give the rotated photo — shading included, which only holds if the
    # normals' XY turned with the content.
    maps, _ = _material(seed=3)
    transform = CropTransform(center=(0.0, 0.0), scale=1.0, angle=quarter_turns * math.pi / 2)
    rotated_render = render_flash(crop_maps(maps, transform, 64)[None])[0]
    render_rotated = torch.rot90(render_flash(maps[None])[0], quarter_turns, dims=(1, 2))
    error = (rotated_render - render_rotated).abs().mean() / render_rotated.abs().mean()
    assert error < 1e-4
    # Without turning the normals the same comparison fails clearly.
    unturned = crop_maps(maps, transform, 64)
    unturned[CHANNELS["normal"]] = torch.rot90(maps[CHANNELS["normal"]], quarter_turns, dims=(1, 2))
    wrong = render_flash(unturned[None])[0]
    assert (wrong - render_rotated).abs().mean() / render_rotated.abs().mean() > 50 * max(error.item(), 1e-5)


def test_render_of_maps_rotated_by_an_arbitrary_angle_matches_within_resampling_error() -> None:
    # 30°: resampling blurs a little, so compare inside the inscribed disc with a tolerance.
    maps, _ = _material(seed=4)
    angle = math.radians(30.0)
    rotated_render = render_flash(crop_maps(maps, CropTransform((0.0, 0.0), 1.0, angle), 64)[None])[0]
    photo = render_flash(maps[None])[0]
    # Rotating the photo itself with the same resampler (a 3-channel field through the maps).
    photo_maps = flat_maps(64, 64)
    scale = photo.max()
    photo_maps[CHANNELS["basecolor"]] = linear_to_srgb(photo / scale)
    render_rotated = (
        srgb_to_linear(
            crop_maps(photo_maps, CropTransform((0.0, 0.0), 1.0, angle), 64)[CHANNELS["basecolor"]]
        )
        * scale
    )
    c = (torch.arange(64) + 0.5) / 32 - 1
    disc = (c.view(1, -1) ** 2 + c.view(-1, 1) ** 2) < 0.8
    error = (rotated_render - render_rotated).abs()[:, disc].mean() / render_rotated[:, disc].mean()
    # Shading is not linear, so resampling before and after it differ a little (measured 4.9 %);
    # normals left unturned put the shading in the wrong place (measured 15 %).
    assert error < 0.07
    unturned = crop_maps(maps, CropTransform((0.0, 0.0), 1.0, angle), 64)
    n = unturned[CHANNELS["normal"]]
    cos, sin = math.cos(-angle), math.sin(-angle)
    unturned[CHANNELS["normal"]] = torch.stack([cos * n[0] - sin * n[1], sin * n[0] + cos * n[1], n[2]])
    wrong = render_flash(unturned[None])[0]
    assert (wrong - render_rotated).abs()[:, disc].mean() / render_rotated[:, disc].mean() > 2 * error


def test_rotating_without_turning_normals_would_be_caught() -> None:
    maps, _ = _material()
    rotated = crop_maps(maps, CropTransform(center=(0.0, 0.0), scale=1.0, angle=math.pi / 2), 64)
    naive = torch.rot90(maps[CHANNELS["normal"]], 1, dims=(1, 2))
    assert (rotated[CHANNELS["normal"]] - naive).abs().max() > 0.05


def test_crops_wrap_around_tileable_sources() -> None:
    maps, _ = _material()
    # A crop centred on the corner straddles all four edges; a tileable source has no seam there.
    out = crop_maps(maps, CropTransform(center=(1.0, 1.0), scale=1.0, angle=0.0), 64)
    torch.testing.assert_close(out, torch.roll(maps, shifts=(32, 32), dims=(1, 2)), atol=1e-5, rtol=0)


def test_downscaled_crops_are_antialiased() -> None:
    # A one-texel checkerboard averages to grey when reduced 8×, instead of aliasing.
    size = 256
    checker = ((torch.arange(size)[:, None] + torch.arange(size)[None]) % 2).float()
    out = crop_maps(_as_maps(checker), CropTransform(center=(0.0, 0.0), scale=1.0, angle=0.3), 32)
    roughness = out[CHANNELS["roughness"]]
    assert (roughness - 0.5).abs().max() < 0.05


def test_random_crops_are_valid_reproducible_and_diverse() -> None:
    maps, _ = _material(128)
    crops, transforms = random_crops(maps, 7, 32, torch.Generator().manual_seed(4))
    again, _ = random_crops(maps, 7, 32, torch.Generator().manual_seed(4))
    assert crops.shape == (7, 8, 32, 32) and len(transforms) == 7
    assert torch.equal(crops, again)
    validate_maps(crops)
    assert len({round(t.angle, 6) for t in transforms}) == 7
    assert all(0.125 <= t.scale <= 0.5 for t in transforms)


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="square"):
        crop_maps(flat_maps(8, 16), CropTransform((0.0, 0.0), 1.0, 0.0), 8)
    with pytest.raises(ValueError, match="scale_min"):
        CropSampling(scale_min=0.6, scale_max=0.5)


def test_render_of_mirrored_maps_is_the_mirrored_render() -> None:
    # The flash capture is symmetric under x -> -x too: photographing the mirrored (and turned)
    # maps must give the mirrored (turned) photo, which holds only if the slopes mirror as well.
    maps, _ = _material(seed=5)
    transform = CropTransform(center=(0.0, 0.0), scale=1.0, angle=math.pi / 2, mirror=True)
    cropped = crop_maps(maps, transform, 64)
    expected_content = torch.flip(torch.rot90(maps[CHANNELS["basecolor"]], 1, dims=(1, 2)), dims=(2,))
    torch.testing.assert_close(cropped[CHANNELS["basecolor"]], expected_content, atol=1e-5, rtol=0)
    render_mirrored = torch.flip(torch.rot90(render_flash(maps[None])[0], 1, dims=(1, 2)), dims=(2,))
    mirrored_render = render_flash(cropped[None])[0]
    error = (mirrored_render - render_mirrored).abs().mean() / render_mirrored.abs().mean()
    assert error < 1e-4
    unmirrored = cropped.clone()
    unmirrored[3] = -unmirrored[3]  # content mirrored, slopes not
    wrong = render_flash(unmirrored[None])[0]
    assert (wrong - render_mirrored).abs().mean() / render_mirrored.abs().mean() > 50 * max(
        error.item(), 1e-5
    )


def test_crops_inside_stay_inside_and_mirror_half_the_time() -> None:
    sampling = CropSampling(scale_min=0.25, scale_max=0.5, mirror=True, inside=True)
    generator = torch.Generator().manual_seed(0)
    draws = [sampling.sample(generator) for _ in range(400)]
    for t in draws:  # every corner of the rotated square lies inside [-1, 1]²
        for cx, cy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            x = t.center[0] + t.scale * (math.cos(t.angle) * cx + math.sin(t.angle) * cy)
            y = t.center[1] + t.scale * (-math.sin(t.angle) * cx + math.cos(t.angle) * cy)
            assert abs(x) <= 1.0 + 1e-9 and abs(y) <= 1.0 + 1e-9
    assert 150 < sum(t.mirror for t in draws) < 250
    # Without the options a draw takes its four uniforms as it always did: the same crops.
    u = torch.rand(4, generator=torch.Generator().manual_seed(1), dtype=torch.float64).tolist()
    plain = CropSampling(0.25, 0.5).sample(torch.Generator().manual_seed(1))
    assert plain == CropTransform(
        (2 * u[2] - 1, 2 * u[3] - 1), log_uniform(u[0], 0.25, 0.5), 2 * math.pi * u[1]
    )
    assert "mirror" not in plain.to_json()
