"""Relief statistics and what a photo shows of the relief (research.relief): golden values,
invariants and input checks. Fast, no Mitsuba."""

from __future__ import annotations

import doctest
import math

import pytest
import torch
from torch import Tensor

import research.relief as relief
from brdfgan.core.delit import flash_render
from brdfgan.core.exposure import log_luminance
from brdfgan.core.flash_geometry import pixel_scale
from brdfgan.core.height import slope_field
from brdfgan.core.render import nominal_camera, view_grid
from brdfgan.core.svbrdf import NORMAL, flat_maps, srgb_to_linear
from brdfgan.data.loading.rendered import photograph_scenes
from brdfgan.data.materials.base import height_to_normal
from brdfgan.data.materials.noise import fbm
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.metrics import relief_shading, slope_agreement
from research.relief import (
    delivered_noise_log,
    fit_height_to_shading,
    flat_share,
    flat_window_share,
    observable_angle,
    observable_mask,
    photo_relief_residual,
    radial_slope,
    relief_share,
    scene_relief_shading,
    slope_band_energy,
    srgb8_rounding_log,
    steep_angle_share,
    tilt_deg,
)

SIZE = 64


def test_the_docstring_examples_hold() -> None:
    result = doctest.testmod(relief, optionflags=doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS)
    assert result.attempted >= 14
    assert result.failed == 0


def flat_normals(size: int = SIZE) -> Tensor:
    normal = torch.zeros(3, size, size)
    normal[2] = 1.0
    return normal


def test_a_flat_map_is_flat_everywhere() -> None:
    normal = flat_normals()
    assert tilt_deg(normal).abs().max().item() == 0.0
    assert flat_share(normal).item() == 1.0
    assert flat_window_share(normal, window=16).item() == 1.0
    assert steep_angle_share(normal).item() == 0.0
    assert slope_band_energy(normal).tolist() == [0.0] * 5


def test_tilt_is_the_angle_from_z_whatever_the_length() -> None:
    angles = torch.tensor([0.0, 5.0, 30.0, 60.0, 89.0])
    radians = torch.deg2rad(angles)
    normal = torch.stack([torch.sin(radians), torch.zeros(5), torch.cos(radians)]).view(3, 1, 5)
    assert torch.allclose(tilt_deg(normal).flatten(), angles, atol=1e-4)
    assert torch.allclose(tilt_deg(7.0 * normal), tilt_deg(normal))  # the direction's angle


@pytest.mark.parametrize(
    ("period_px", "band"),
    [(48.0, 0), (24.0, 1), (12.0, 2), (6.0, 3), (3.0, 4)],  # > 32, 16–32, 8–16, 4–8, < 4 px
)
@pytest.mark.parametrize("diagonal", [False, True])
def test_a_sinusoidal_bump_puts_its_slope_power_in_its_octave(
    period_px: float, band: int, diagonal: bool
) -> None:
    size = 256
    axis = torch.arange(size, dtype=torch.float64)
    rows, cols = torch.meshgrid(axis, axis, indexing="ij")
    # Along the columns, or along the diagonal with the same period (radial frequency 1/period).
    position = (rows + cols) / math.sqrt(2.0) if diagonal else cols
    height = 0.5 * torch.sin(2 * math.pi * position / period_px)  # texel units: slopes up to ~1
    normal = torch.stack(
        [-torch.gradient(height, dim=1)[0], torch.gradient(height, dim=0)[0], torch.ones_like(height)]
    )
    shares = slope_band_energy(normal)
    assert shares.sum().item() == pytest.approx(1.0, abs=1e-9)
    assert shares[band].item() > 0.9, shares.tolist()


def test_band_edges_are_checked() -> None:
    with pytest.raises(ValueError, match="increasing"):
        slope_band_energy(flat_normals(), bands=(0.0, 0.1, 0.1))
    with pytest.raises(ValueError, match="increasing"):
        slope_band_energy(flat_normals(), bands=(0.1,))


def thin_steep_lines(size: int = 128, spacing: int = 32, tilt: float = 40.0) -> Tensor:
    """Flat tiles with grout: every ``spacing`` texels a 2-texel groove whose walls lean ``tilt``°."""
    normal = flat_normals(size)
    slope = math.tan(math.radians(tilt))
    for start in range(spacing // 2, size, spacing):
        normal[0, :, start], normal[0, :, start + 1] = slope, -slope
        normal[1, start, :], normal[1, start + 1, :] = slope, -slope
    return normal / normal.norm(dim=0, keepdim=True)


def test_thin_steep_lines_carry_the_angle_and_leave_the_rest_flat() -> None:
    lines = thin_steep_lines()
    assert steep_angle_share(lines).item() == 1.0  # every tilted texel is a 40° wall
    assert flat_share(lines).item() == pytest.approx(
        (1 - 2 / 32) ** 2, abs=1e-6
    )  # 2 of every 32 rows and columns
    assert tilt_deg(lines).mean().item() > 4.0
    # A smooth relief of about the same mean tilt carries little of it on steep texels.
    height = 3.0 * fbm(128, 4, torch.Generator().manual_seed(0), octaves=3)[None]
    smooth = height_to_normal(height)
    assert 4.0 < tilt_deg(smooth).mean().item() < 8.0
    assert steep_angle_share(smooth).item() < 0.1
    assert flat_share(smooth).item() < 0.05
    # The grooves' power lies at their width (2 px) and spacing harmonics: mostly fine.
    assert slope_band_energy(lines)[3:].sum() > slope_band_energy(smooth)[3:].sum()


def test_flat_windows_count_windows_without_relief() -> None:
    normal = flat_normals(64)
    normal[0, 40:48, 40:48] = 1.0  # 45° on 64 texels of one of the four 32² windows: a mean of 2.8°
    assert flat_window_share(normal, window=32).item() == 0.75
    assert flat_window_share(normal.expand(2, 3, 64, 64), window=32).tolist() == [0.75, 0.75]
    with pytest.raises(ValueError, match="window"):
        flat_window_share(normal, window=65)


@pytest.mark.parametrize(
    "call",
    [
        lambda: tilt_deg(torch.zeros(2, 4, 4)),
        lambda: flat_share(flat_normals(), threshold_deg=0.0),
        lambda: steep_angle_share(flat_normals(), threshold_deg=95.0),
        lambda: relief_share(torch.ones(1, 3, 8, 8), torch.zeros(1, 1, 4, 4)),
        lambda: observable_mask(torch.zeros(4), 0.1, k=0.0),
        lambda: observable_mask(torch.zeros(4), -0.1),
        lambda: observable_angle(flat_normals(8), torch.ones(4, 4, dtype=torch.bool)),
        lambda: delivered_noise_log(torch.ones(1, 3, 8, 8), torch.ones(1, 3, 4, 4)),
    ],
)
def test_bad_inputs_are_refused(call: object) -> None:
    with pytest.raises(ValueError):
        call()  # type: ignore[operator]


# ----------------------------------------------------------------------------- photos


def bumpy_maps(size: int = SIZE, textured: bool = False, seed: int = 0) -> Tensor:
    """A grey dielectric with smooth bumps (RMS tilt ~10°), its base colour uniform or textured."""
    generator = torch.Generator().manual_seed(seed)
    maps = flat_maps(size, size, basecolor=(0.5, 0.5, 0.5), roughness=0.6, batch=(1,))
    maps[0, NORMAL] = height_to_normal(2.0 * fbm(size, 4, generator, octaves=3)[None])
    if textured:  # an albedo texture unrelated to the relief, ×0.6–×1.4
        texture = 0.5 * (1.0 + 0.4 * fbm(size, 8, generator, octaves=3))
        maps[0, :3] = texture.clamp(0.05, 0.95)
    return maps


def photo_scene(size: int = SIZE, lights: float = 1.0) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """A capture like a training photo's: the camera framing the sample at 50°, the flash 5 % of the
    distance off the lens, and a distant light low in the sky (an environment's)."""
    pose = nominal_camera(50.0)
    height = pose.origin[2]
    camera = torch.tensor([[0.0, 0.0, height]])
    light_position = torch.tensor([[[0.05 * height, 0.0, height], [300.0, 0.0, 150.0]]])
    light_rgb = lights * torch.tensor([[[1.0, 1.0, 1.0], [2e4, 2e4, 2e4]]])
    grid = view_grid(pose, size, size).float()[None]
    return camera, light_position, light_rgb, grid, torch.zeros(1)


def test_scene_relief_shading_is_zero_for_flat_normals_and_ignores_the_light_level() -> None:
    scene = photo_scene()
    flat = flat_maps(SIZE, SIZE, basecolor=(0.5, 0.5, 0.5), roughness=0.6, batch=(1,))
    assert scene_relief_shading(flat, *scene).abs().max().item() == 0.0
    maps = bumpy_maps()
    shading = scene_relief_shading(maps, *scene)
    assert shading.shape == (1, 1, SIZE, SIZE)
    assert shading.std().item() > 0.02
    brighter = photo_scene(lights=10.0)
    assert torch.allclose(scene_relief_shading(maps, *brighter), shading, atol=1e-5)


def test_scene_relief_shading_is_the_log_ratio_of_the_training_photos() -> None:
    """The relief photo it divides is :func:`photograph_scenes`' photo; the flat one is the same
    photo of flat normals (there at its own exposure, here at the relief photo's)."""
    scene = photo_scene()
    maps = bumpy_maps()
    flat = maps.clone()
    flat[:, NORMAL] = torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1)
    photo, _, scale = photograph_scenes(maps, *scene)
    flat_photo, _, flat_scale = photograph_scenes(flat, *scene)
    flat_photo = (flat_photo / flat_scale * scale).clamp(0.0, 1.0)  # nothing clipped at this exposure
    expected = log_luminance(photo, relief.LOG_FLOOR) - log_luminance(flat_photo, relief.LOG_FLOOR)
    assert torch.allclose(scene_relief_shading(maps, *scene), expected, atol=1e-4)


def test_relief_share_is_near_one_for_a_clean_render_and_drops_with_texture_and_noise() -> None:
    scene = photo_scene()
    maps = bumpy_maps()
    shading = scene_relief_shading(maps, *scene)
    photo = photograph_scenes(maps, *scene)[0]
    clean = relief_share(photo, shading).item()
    assert clean > 0.9
    textured = bumpy_maps(textured=True)
    textured_share = relief_share(
        photograph_scenes(textured, *scene)[0], scene_relief_shading(textured, *scene)
    ).item()
    assert textured_share < clean - 0.2
    noisy_sensor = SensorEffects(
        vignetting_probability=0.0, white_balance_probability=0.0, jpeg_probability=0.0,
        shot_noise_min=1e-2, shot_noise_max=1e-2, read_noise_min=1e-4, read_noise_max=1e-4,
    )  # fmt: skip
    noisy, _ = noisy_sensor.apply(photo[0], torch.Generator().manual_seed(0))
    assert relief_share(noisy[None], shading).item() < clean - 0.2
    # An unrelated "relief" explains nothing of the photo.
    assert relief_share(photo, scene_relief_shading(bumpy_maps(seed=5), *scene)).item() < 0.1


def test_nothing_is_observable_on_a_flat_map_and_noise_hides_relief() -> None:
    scene = photo_scene()
    flat = flat_maps(SIZE, SIZE, basecolor=(0.5, 0.5, 0.5), roughness=0.6, batch=(1,))
    flat_shading = scene_relief_shading(flat, *scene)
    assert not observable_mask(flat_shading, 0.0).any()
    assert observable_angle(flat[:, NORMAL], observable_mask(flat_shading, 0.0)[:, 0]).item() == 0.0
    maps = bumpy_maps()
    shading = scene_relief_shading(maps, *scene)
    normal = maps[:, NORMAL]
    total = tilt_deg(normal).mean().item()
    angles = [
        observable_angle(normal, observable_mask(shading, sigma)[:, 0]).item() for sigma in (1e-4, 1e-2, 10.0)
    ]
    assert total >= angles[0] > angles[1] > angles[2] == 0.0
    assert angles[0] > 0.8 * total  # a nearly noiseless photo shows most of the relief


def test_delivered_noise_and_rounding_are_in_log_units() -> None:
    photo = torch.full((1, 3, 32, 32), 0.3)
    assert delivered_noise_log(photo, photo).max().item() == 0.0
    # The exposure: a delivery twice as bright has no more noise.
    assert delivered_noise_log(2 * photo, photo).max().item() == pytest.approx(0.0, abs=1e-6)
    # Rounding is relative: darker values lose more, and linear-segment values follow 1/x.
    levels = torch.tensor([0.5, 0.1, 0.01]).view(1, 1, 3, 1).expand(1, 3, 3, 1)
    sigma = srgb8_rounding_log(levels).flatten().tolist()
    assert sigma[0] < sigma[1] < sigma[2]
    step = 1.0 / 255 / 12.92  # on the linear segment every code is this far apart
    dark = torch.full((1, 3, 1, 1), 0.002)
    norm = math.sqrt(sum(w * w for w in (0.2126, 0.7152, 0.0722)))
    assert srgb8_rounding_log(dark).item() == pytest.approx(norm * step / math.sqrt(12) / 0.002, rel=1e-3)


def test_dark_is_low_reads_the_sign_that_ties_the_base_colour_to_the_relief() -> None:
    height = 3.0 * fbm(SIZE, 4, torch.Generator().manual_seed(0), octaves=3)
    other = 3.0 * fbm(SIZE, 4, torch.Generator().manual_seed(1), octaves=3)
    maps = flat_maps(SIZE, SIZE, basecolor=(0.5, 0.5, 0.5), roughness=0.6, batch=(1,))
    maps[0, NORMAL] = height_to_normal(height[None])
    # A base colour darkest in the valleys: the texture and the relief agree, whatever its level.
    maps[0, :3] = (0.3 + 0.1 * height).clamp(0.05, 1.0)
    agreeing = relief.dark_is_low_cosine(maps)
    assert agreeing.shape == (1, 2) and bool((agreeing > 0.8).all())
    brighter = maps.clone()
    brighter[0, :3] = maps[0, :3] * 0.7
    torch.testing.assert_close(relief.dark_is_low_cosine(brighter), agreeing, atol=0.05, rtol=0)
    # The relief turned inside out: ridges where the base colour is dark, the sign flips exactly.
    inverted = maps.clone()
    inverted[0, 3:5] *= -1
    torch.testing.assert_close(relief.dark_is_low_cosine(inverted), -agreeing)
    # A texture drawn apart from the relief says little of it; a plain base colour says nothing.
    apart = maps.clone()
    apart[0, :3] = (0.3 + 0.1 * other).clamp(0.05, 1.0)
    assert bool((relief.dark_is_low_cosine(apart).abs() < 0.3).all())
    plain = maps.clone()
    plain[0, :3] = 0.5
    assert relief.dark_is_low_cosine(plain).tolist() == [[0.0, 0.0]]


# ----------------------------------------------------------------------------- shape from shading


def centred_frame(size: int = SIZE, fov_deg: float = 50.0) -> Tensor:
    return torch.tensor([[size / 2, size / 2, pixel_scale(fov_deg, size)]])


def test_radial_slope_is_the_slope_away_from_the_hotspot() -> None:
    maps = bumpy_maps()
    frame = centred_frame()
    radial = radial_slope(maps[:, NORMAL], frame)
    slopes = slope_field(maps[:, NORMAL])
    # Right of the hotspot on its row the radial slope is s_x; above it on its column, s_y.
    row, column = SIZE // 2 - 1, SIZE // 2 - 1  # the pixel centres just up-left of the hotspot
    assert torch.allclose(radial[0, 0, row, SIZE // 2 + 5 :], slopes[0, 0, row, SIZE // 2 + 5 :], atol=0.05)
    assert torch.allclose(
        radial[0, 0, : SIZE // 2 - 5, column], slopes[0, 1, : SIZE // 2 - 5, column], atol=0.05
    )
    assert radial_slope(flat_maps(SIZE, SIZE, batch=(1,))[:, NORMAL], frame).abs().max().item() == 0.0


def test_the_fitted_height_shades_as_observed_and_reads_the_radial_slopes() -> None:
    """Noise-free and with the rest of the surface known, the fit reproduces the shading, and its
    slopes agree with the truth's, those along the light best."""
    maps, frame = bumpy_maps(), centred_frame()
    observed = relief_shading(maps, frame)
    everywhere = torch.ones_like(observed, dtype=torch.bool)
    fitted = maps.clone()
    fitted[:, NORMAL] = fit_height_to_shading(maps, frame, observed, everywhere, steps=300)
    residual = (relief_shading(fitted, frame) - observed).square().mean() / observed.square().mean()
    assert residual.item() < 0.01
    fitted_radial, true_radial = (radial_slope(m[:, NORMAL], frame).flatten() for m in (fitted, maps))
    assert torch.nn.functional.cosine_similarity(fitted_radial, true_radial, dim=0).item() > 0.8
    cosine = slope_agreement(fitted, maps)["normal_slope_cosine"].item()
    assert cosine > 0.5


def test_no_shading_fits_a_flat_surface_and_the_ridge_flattens() -> None:
    maps, frame = bumpy_maps(), centred_frame()
    observed = relief_shading(maps, frame)
    everywhere = torch.ones_like(observed, dtype=torch.bool)
    flat = fit_height_to_shading(maps, frame, torch.zeros_like(observed), everywhere, steps=50)
    assert torch.allclose(flat, torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1).expand_as(flat), atol=1e-6)
    ratios = []
    for ridge in (0.0, 1.0):
        fitted = maps.clone()
        fitted[:, NORMAL] = fit_height_to_shading(maps, frame, observed, everywhere, ridge=ridge, steps=100)
        ratios.append(slope_agreement(fitted, maps)["normal_slope_ratio"].item())
    assert ratios[1] < 0.5 * ratios[0]
    # Pixels outside `valid` do not pull: a fit that sees none of the shading stays flat.
    nowhere = torch.zeros_like(everywhere)
    assert fit_height_to_shading(maps, frame, observed, nowhere, steps=20).sub(flat).abs().max().item() < 1e-6
    with pytest.raises(ValueError, match="ridge"):
        fit_height_to_shading(maps, frame, observed, everywhere, ridge=-1.0)


def test_each_photo_is_fitted_alone_and_only_its_valid_pixels_pull() -> None:
    """A photo's fit is the same in any batch; garbage in its invalid pixels changes nothing; with
    a free offset, a constant added to the observation changes nothing."""
    maps = torch.cat([bumpy_maps(seed=0), bumpy_maps(seed=1)])
    frame = centred_frame().expand(2, 3)
    observed = relief_shading(maps, frame)
    valid = torch.ones_like(observed, dtype=torch.bool)
    valid[:, :, :8] = False
    # Unconverged fits may be compared where both run the same float32 arithmetic, step for step:
    # the same photo alone or in a batch, or with its invalid pixels' weight of zero on garbage.
    both = fit_height_to_shading(maps, frame, observed, valid, steps=40)
    alone = fit_height_to_shading(maps[1:], frame[1:], observed[1:], valid[1:], steps=40)
    assert torch.allclose(both[1:], alone, atol=1e-5)
    garbage = torch.where(valid, observed, torch.full_like(observed, 5.0))
    assert torch.allclose(fit_height_to_shading(maps, frame, garbage, valid, steps=40), both, atol=1e-5)

    # The offset's invariance holds for the loss exactly, so for the fit only where the fit has
    # one answer and reaches it: two fits whose float32 rounding differs (the shifted observation,
    # or another CPU) then end at the same minimiser, up to what float32 resolves of it. Without a
    # ridge, shape from shading has many heights for one shading (one number for two slopes), and a
    # 40-step fit has not converged either: its path, set by rounding, picks the answer (the shift
    # moved it by up to 0.22, issue 58). With ridge 1 the fit is well posed, and L-BFGS converges
    # in ~85 iterations (100 and 300 steps give the same fit); fits of observations perturbed by
    # 1e-7-1e-6 relative noise land within 5.3e-4 of it, so 2e-3 is a 4x margin, while without the
    # free offset the same shift moves this fit by 0.18.
    def converged(observation: Tensor, free_offset: bool) -> Tensor:
        return fit_height_to_shading(
            maps, frame, observation, valid, free_offset=free_offset, ridge=1.0, steps=300
        )

    offset, shifted = (converged(o, free_offset=True) for o in (observed, observed + 0.3))
    assert torch.allclose(shifted, offset, atol=2e-3)
    assert not torch.allclose(converged(observed + 0.3, False), converged(observed, False), atol=1e-2)


def test_the_photo_residual_is_the_relief_shading_of_a_clean_flash_photo() -> None:
    """A photo that is the flash render of the maps (exposed, through a gamma-like tone curve)
    leaves exactly the relief shading once the flat render of its true maps is fitted away; the
    clipped hotspot is left out."""
    maps, frame = bumpy_maps(), centred_frame()
    photo = flash_render(srgb_to_linear(maps[:, :3]), maps[:, NORMAL], maps[:, 6:7], maps[:, 7:8], frame)
    residual, valid = photo_relief_residual(0.8 * photo / photo.max(), maps, frame)
    assert valid.all()
    toned, _ = photo_relief_residual((0.8 * photo / photo.max()).pow(0.8), maps, frame)
    assert torch.allclose(toned, residual, atol=1e-4)  # the tone curve's slope is fitted away
    # Up to the offset and the fit's slope, which the relief's chance correlation with the
    # falloff moves by a little, it is the relief shading.
    expected = relief_shading(maps, frame)
    pair = torch.stack([residual.flatten(), expected.flatten()]).double()
    assert torch.corrcoef(pair)[0, 1].item() > 0.99
    assert 0.9 < residual.std().item() / expected.std().item() < 1.1
    clipped = (1.2 * photo / photo.max()).clamp(max=1.0)
    residual, valid = photo_relief_residual(clipped, maps, frame)
    assert 0 < valid.logical_not().sum().item() < SIZE * SIZE / 4
    assert residual[~valid].abs().max().item() == 0.0
    # One channel at the clip level is enough: a saturated red hotspot shows no shading either.
    red = photo / photo.max() * 0.6
    red[:, 0] = (3.0 * red[:, 0]).clamp(max=1.0)
    _, valid = photo_relief_residual(red, maps, frame)
    assert valid.logical_not().sum().item() == (red[:, 0] >= relief.CLIP_LEVEL).sum().item() > 0
