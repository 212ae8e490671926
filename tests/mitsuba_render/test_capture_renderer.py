"""The Mitsuba capture renderer: envmap orientation, sun, flash, scene reuse, exposure."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from brdfgan.core.lighting import (
    Environment,
    SunLight,
    equirect_directions,
    normalize_environment,
    upper_hemisphere_irradiance,
)
from brdfgan.core.render import FlashCapture
from brdfgan.core.svbrdf import CHANNELS, flat_maps, normalize_normal
from brdfgan.data.phone.conditions import CaptureDraw, max_distance_factor
from brdfgan.data.phone.environments import load_environment, room_spec, sunsky_spec
from brdfgan.mitsuba_render.environment import ENVMAP_TO_WORLD
from tests.conftest import random_maps

pytestmark = [pytest.mark.mitsuba, pytest.mark.integration]

RES = 32
ENV_RES = 64
SPP = 16
CAPTURE = FlashCapture(fov_deg=45.0, intensity=8.0)
NO_FLASH = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def renderer():  # type: ignore[no-untyped-def]
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    return CaptureRenderer(RES, SPP, CAPTURE, ENV_RES)


def _cap(direction: tuple[float, float, float], half_angle_deg: float, height: int = ENV_RES) -> np.ndarray:
    """Radiance 1 within ``half_angle_deg`` of ``direction``, 0 elsewhere."""
    d = np.asarray(direction) / np.linalg.norm(direction)
    cos = equirect_directions(height) @ d
    mask = cos >= math.cos(math.radians(half_angle_deg))
    return np.repeat(mask[..., None], 3, axis=-1).astype(np.float32)


def _tilted_direction(axis: str, angle_deg: float) -> tuple[float, float, float]:
    sign = -1.0 if axis.startswith("-") else 1.0
    s, c = sign * math.sin(math.radians(angle_deg)), math.cos(math.radians(angle_deg))
    return (s, 0.0, c) if axis.endswith("x") else (0.0, s, c)


def _expected_pixel(direction: tuple[float, float, float]) -> tuple[float, float]:
    # The mirror image of a distant light in direction D, seen from the camera at height h above
    # the centre, lies at p = h·(D_x, D_y)/D_z; pixel (row, col) with row 0 at +Y.
    h, s = CAPTURE.camera_height, CAPTURE.plane_half_size
    x, y = h * direction[0] / direction[2], h * direction[1] / direction[2]
    return (1 - y / s) / 2 * RES - 0.5, (x / s + 1) / 2 * RES - 0.5


def _highlight_centroid(image: torch.Tensor) -> tuple[float, float]:
    luminance = image.sum(0).numpy()
    weights = np.where(luminance >= 0.5 * luminance.max(), luminance, 0.0)
    rows, cols = np.indices(luminance.shape)
    return float((rows * weights).sum() / weights.sum()), float((cols * weights).sum() / weights.sum())


def _half_tilted_normals(maps: torch.Tensor, axis: str, angle_deg: float) -> torch.Tensor:
    """Normals tilted towards +axis in the +axis half of the image, towards −axis in the other."""
    maps = maps.clone()
    t = math.tan(math.radians(angle_deg))
    normal = torch.zeros(3, RES, RES)
    normal[2] = 1.0
    half = RES // 2
    if axis == "x":  # columns grow with +X
        normal[0, :, half:], normal[0, :, :half] = t, -t
    else:  # rows grow towards −Y
        normal[1, :half], normal[1, half:] = t, -t
    maps[CHANNELS["normal"]] = normalize_normal(normal)
    return maps


# ----------------------------------------------------------------------------- conventions


def test_envmap_emitter_matches_the_texel_directions() -> None:
    # Mitsuba's envmap with ENVMAP_TO_WORLD returns texel (i, j) exactly at equirect_directions[i, j].
    from brdfgan.mitsuba_render.environment import eval_emitter
    from brdfgan.mitsuba_render.variant import mitsuba

    mi = mitsuba()
    height = 8
    array = np.random.default_rng(0).uniform(0.1, 2.0, (height, 2 * height, 3)).astype(np.float32)
    emitter = mi.load_dict(
        {
            "type": "envmap",
            "bitmap": mi.Bitmap(array),
            "to_world": mi.ScalarTransform4f(np.array(ENVMAP_TO_WORLD)),
        }
    )
    # Interior rows (the pole rows collapse to one point, where Mitsuba averages the row).
    directions = equirect_directions(height)[1:-1].reshape(-1, 3)
    values = eval_emitter(emitter, directions).reshape(height - 2, 2 * height, 3)
    np.testing.assert_allclose(values, array[1:-1], rtol=1e-4)


def test_sky_above_lights_the_plane_ground_below_does_not(renderer) -> None:  # type: ignore[no-untyped-def]
    maps = flat_maps(RES, RES, basecolor=(0.8, 0.8, 0.8), roughness=1.0, metallic=0.0)
    up = equirect_directions(ENV_RES)[..., 2] > 0
    sky = np.repeat(up[..., None], 3, axis=-1).astype(np.float32)
    lit = renderer.render(maps, sky, NO_FLASH, seed=1)
    dark = renderer.render(maps, 1.0 - sky, NO_FLASH, seed=1)
    # A near-Lambertian surface of albedo ~0.6 (linear of sRGB 0.8) under L = 1 reflects ~0.6.
    assert 0.4 < lit.mean().item() < 0.9
    # Only the bilinear ramp between the last sky row and the first ground row (±1.4° around the
    # horizon) leaks a trace of the ground above the horizon; the irradiance weights count it too.
    leak = upper_hemisphere_irradiance(1.0 - sky) / upper_hemisphere_irradiance(sky)
    assert leak < 1e-3
    assert dark.mean().item() < 3 * leak * lit.mean().item()


@pytest.mark.parametrize("axis", ["+x", "-x", "+y", "-y"])
def test_environment_highlight_appears_where_the_mirror_direction_says(renderer, axis: str) -> None:  # type: ignore[no-untyped-def]
    maps = flat_maps(RES, RES, basecolor=(0.9, 0.9, 0.9), roughness=0.15, metallic=1.0)
    direction = _tilted_direction(axis, 12.0)
    image = renderer.render(maps, _cap(direction, 6.0), NO_FLASH, seed=2)
    row, col = _highlight_centroid(image)
    expected_row, expected_col = _expected_pixel(direction)
    assert abs(row - expected_row) < 1.5 and abs(col - expected_col) < 1.5, (axis, row, col)


@pytest.mark.parametrize("axis", ["+x", "-y"])
def test_sun_highlight_appears_where_the_mirror_direction_says(renderer, axis: str) -> None:  # type: ignore[no-untyped-def]
    maps = flat_maps(RES, RES, basecolor=(0.9, 0.9, 0.9), roughness=0.15, metallic=1.0)
    direction = _tilted_direction(axis, 12.0)
    image = renderer.render(maps, None, NO_FLASH, seed=3, sun=SunLight(direction, (1.0, 1.0, 1.0)))
    row, col = _highlight_centroid(image)
    expected_row, expected_col = _expected_pixel(direction)
    assert abs(row - expected_row) < 1.5 and abs(col - expected_col) < 1.5, (axis, row, col)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_normals_tilted_towards_the_light_are_brighter(renderer, axis: str) -> None:  # type: ignore[no-untyped-def]
    maps = _half_tilted_normals(flat_maps(RES, RES, roughness=1.0), axis, 35.0)
    image = renderer.render(maps, _cap(_tilted_direction(f"+{axis}", 55.0), 15.0), NO_FLASH, seed=4)
    half = RES // 2
    if axis == "x":
        towards, away = image[:, :, half:].mean(), image[:, :, :half].mean()
    else:
        towards, away = image[:, :half].mean(), image[:, half:].mean()
    assert towards > 2.0 * away


def test_sun_and_environment_of_equal_irradiance_light_alike(renderer) -> None:  # type: ignore[no-untyped-def]
    # A small cap at the zenith and a zenith sun, normalised to the same plane irradiance, light
    # a rough plane the same: upper_hemisphere_irradiance and the sun's irradiance agree with
    # what Mitsuba renders.
    maps = flat_maps(RES, RES, basecolor=(0.7, 0.7, 0.7), roughness=1.0)
    cap = normalize_environment(Environment(_cap((0.0, 0.0, 1.0), 4.0)), 1.0)
    dark = np.zeros((ENV_RES, 2 * ENV_RES, 3), np.float32)
    sun = normalize_environment(Environment(dark, SunLight((0.0, 0.0, 1.0), (1.0, 1.0, 1.0))), 1.0)
    by_cap = renderer.render(maps, cap.radiance, NO_FLASH, seed=5).mean().item()
    by_sun = renderer.render(maps, None, NO_FLASH, seed=5, sun=sun.sun).mean().item()
    assert by_cap == pytest.approx(by_sun, rel=0.02)


# ----------------------------------------------------------------------------- flash and reuse


def test_flash_only_agrees_with_render_flash_mitsuba() -> None:
    from brdfgan.mitsuba_render.photos import CaptureRenderer
    from brdfgan.mitsuba_render.scene import render_flash_mitsuba

    maps = random_maps(RES, RES, seed=7)
    reference = render_flash_mitsuba(maps, CAPTURE, spp=256, seed=1)
    renderer = CaptureRenderer(RES, 64, CAPTURE, ENV_RES)
    for environment in (None, np.zeros((ENV_RES, 2 * ENV_RES, 3), np.float32)):
        image = renderer.render(maps, environment, CAPTURE.radiant_intensity, seed=2)
        error = ((image - reference).abs().sum() / reference.abs().sum()).item()
        assert error < 0.01


def test_traverse_update_equals_a_fresh_load() -> None:
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    reused = CaptureRenderer(RES, SPP, CAPTURE, 16)
    fresh = CaptureRenderer(RES, SPP, CAPTURE, 16, reuse_scene=False)
    sky = load_environment(sunsky_spec(0, 0), 16)
    room = load_environment(room_spec(0, 0), 16)
    # Each sample with its own camera pose, field of view and flash position (data.phone.conditions).
    tilted = CaptureDraw(
        fov_deg=70.0,
        tilt_deg=6.0,
        tilt_axis_deg=40.0,
        distance_factor=max_distance_factor(70.0, 6.0, 40.0),
        flash_offset=0.05,
        flash_offset_angle_deg=120.0,
    )
    inputs = [
        (random_maps(RES, RES, seed=1), sky, (8.0, 8.0, 8.0), CaptureDraw()),
        (random_maps(RES, RES, seed=2), room.rotated(1.0).scaled(3.0), (4.0, 5.0, 6.0), CaptureDraw()),
        (random_maps(RES, RES, seed=3), sky.rotated(2.5).scaled(0.5), (1.0, 2.0, 3.0), tilted),
        (random_maps(RES, RES, seed=4), room, (2.0, 2.0, 2.0), CaptureDraw(fov_deg=50.0, flash_offset=0.08)),
        (random_maps(RES, RES, seed=5), sky, (3.0, 3.0, 3.0), CaptureDraw()),
    ]
    for seed, (maps, environment, flash, draw) in enumerate(inputs):
        a, b = (
            renderer.render(
                maps,
                environment.radiance,
                flash,
                seed=seed,
                sun=environment.sun,
                camera=draw.camera,
                flash_position=draw.flash_position,
            )
            for renderer in (reused, fresh)
        )
        assert reused.last_timing is not None and fresh.last_timing is not None
        assert reused.last_timing.loaded_scene == (seed < 2) and fresh.last_timing.loaded_scene
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)
    # Another map size reloads rather than failing.
    small = random_maps(RES // 2, RES // 2, seed=5)
    reused.render(small, room.radiance, (1.0, 1.0, 1.0), seed=0)
    assert reused.last_timing is not None and reused.last_timing.loaded_scene


def test_render_capture_auto_exposes() -> None:
    from brdfgan.mitsuba_render.photos import CaptureRenderer, render_capture

    renderer = CaptureRenderer(RES, SPP, CAPTURE, 16)
    environment = normalize_environment(load_environment(room_spec(1, 0), 16), 0.5)
    result = render_capture(renderer, random_maps(RES, RES, seed=8), environment, (2.0, 2.0, 2.0), seed=1)
    assert result.hdr.shape == result.ldr.shape == (3, RES, RES)
    assert result.exposure_scale > 0
    assert result.ldr.min() >= 0 and result.ldr.max() <= 1
    torch.testing.assert_close(result.ldr, (result.hdr * result.exposure_scale).clamp(0, 1))


def test_bad_inputs_are_rejected(renderer) -> None:  # type: ignore[no-untyped-def]
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    with pytest.raises(ValueError, match="perfect square"):
        CaptureRenderer(RES, 50)
    maps = flat_maps(RES, RES)
    with pytest.raises(ValueError, match="2H"):
        renderer.render(maps, np.ones((8, 8, 3), np.float32), NO_FLASH)
    with pytest.raises(ValueError, match="non-negative"):
        renderer.render(maps, -np.ones((8, 16, 3), np.float32), NO_FLASH)
    with pytest.raises(ValueError, match="flash"):
        renderer.render(maps, None, (1.0, -1.0, 1.0))
