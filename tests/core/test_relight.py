"""Relighting a map set under point lights and the procedural sky (core/relight.py, core/sky.py)."""

from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.relight import SKY_LIGHT_DISTANCE, relight, render_sky
from brdfgan.core.render import FlashCapture, PointLights, render_point_lights
from brdfgan.core.sky import ProceduralSky, sample_sky
from brdfgan.inference.outputs.preview import preview_lights
from tests.conftest import random_maps, relative_l1, tilted_plane

SIZE = 32


# ------------------------------------------------------------------------------------------ relight


def test_relight_light_above_centre_is_centred_and_symmetric() -> None:
    image = relight(tilted_plane(), torch.tensor([[0.0, 0.0, 2.0]]))
    assert image.shape == (1, 3, SIZE, SIZE)
    image = image[0]
    torch.testing.assert_close(image, image.flip(-1), rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(image, image.flip(-2), rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(image, image.transpose(-1, -2), rtol=1e-5, atol=1e-7)
    gray = image.mean(dim=0)
    centre = slice(SIZE // 2 - 1, SIZE // 2 + 1)
    assert gray[centre, centre].min() == gray.max()
    assert gray.max() > 2.0 * gray[0, 0]


def test_relight_orientation_convention() -> None:
    """+X is the right of the image, +Y its top (row 0), as in the renderer
    (docs/conventions.md#scene-and-orientation)."""
    plane = tilted_plane()
    right, up = relight(plane, torch.tensor([[1.5, 0.0, 2.0], [0.0, 1.5, 2.0]])).mean(dim=1)
    half = SIZE // 2
    assert right[:, half:].mean() > 1.5 * right[:, :half].mean()
    assert up[:half].mean() > 1.5 * up[half:].mean()


def test_relight_normals_tilted_to_plus_x_face_a_plus_x_light() -> None:
    lights = torch.tensor([[2.0, 0.0, 1.0], [-2.0, 0.0, 1.0]])
    plus, minus = relight(tilted_plane(normal=(0.5, 0.0, 1.0)), lights).mean(dim=(1, 2, 3))
    assert plus > 2.0 * minus
    flat_plus, flat_minus = relight(tilted_plane(), lights)
    torch.testing.assert_close(flat_plus, flat_minus.flip(-1), rtol=1e-5, atol=1e-7)  # control: mirror images


def test_relight_intensity_forms_and_sky_term() -> None:
    maps = random_maps(16, 16, seed=1)
    lights = preview_lights(2)
    unit = relight(maps, lights)
    torch.testing.assert_close(
        relight(maps, lights, intensity=torch.tensor([2.0, 0.5])),
        unit * torch.tensor([2.0, 0.5]).view(2, 1, 1, 1),
    )
    rgb = torch.tensor([[1.0, 0.0, 0.5], [0.0, 3.0, 1.0]])
    torch.testing.assert_close(relight(maps, lights, intensity=rgb), unit * rgb.view(2, 3, 1, 1))
    env = ProceduralSky()
    with_env = relight(maps, lights, sky=env, samples=8)
    torch.testing.assert_close(with_env, unit + render_sky(maps, env, samples=8))
    with pytest.raises(ValueError, match="intensity"):
        relight(maps, lights, intensity=torch.ones(3))
    with pytest.raises(ValueError, match="light_positions"):
        relight(maps, torch.ones(3))
    with pytest.raises(ValueError, match=r"\(8, H, W\)"):
        relight(maps[None], lights)


def test_relight_is_differentiable() -> None:
    maps = random_maps(8, 8, seed=2).requires_grad_(True)
    relight(maps, preview_lights(2)).sum().backward()
    assert maps.grad is not None and torch.isfinite(maps.grad).all() and maps.grad.abs().sum() > 0


# ------------------------------------------------------------------------------------------- sky


def test_sample_sky_estimates_horizontal_irradiance() -> None:
    # A uniform sky of radiance c gives irradiance π·c on an upward surface.
    directions, irradiance = sample_sky(
        ProceduralSky(zenith=(0.5,) * 3, horizon=(0.5,) * 3, sun_irradiance=0.0), 64
    )
    assert directions.shape == irradiance.shape == (64, 3)
    torch.testing.assert_close(directions.norm(dim=-1), torch.ones(64, dtype=torch.float64))
    estimate = (irradiance * directions[:, 2:3]).sum(dim=0)
    torch.testing.assert_close(
        estimate, torch.full((3,), 0.5 * math.pi, dtype=torch.float64), rtol=0.02, atol=0
    )

    # Default sky + sun against a fine quadrature of ∫ L(ω) cos θ dω.
    env = ProceduralSky()
    rows, cols = 1000, 2000
    u = (torch.arange(rows, dtype=torch.float64) + 0.5) / rows
    phi = (torch.arange(cols, dtype=torch.float64) + 0.5) * (2 * math.pi / cols)
    sin_theta = (1 - u * u).sqrt()[:, None]
    grid = torch.stack([sin_theta * phi.cos(), sin_theta * phi.sin(), u[:, None].expand(-1, cols)], dim=-1)
    reference = (env.radiance(grid) * u[:, None, None]).sum(dim=(0, 1)) * (2 * math.pi / (rows * cols))
    directions, irradiance = sample_sky(env, 64)
    torch.testing.assert_close((irradiance * directions[:, 2:3]).sum(dim=0), reference, rtol=0.03, atol=0)

    # Fixed seed: the same lights every time; another seed: other lights.
    again = sample_sky(env, 64)
    torch.testing.assert_close(again[0], directions, rtol=0, atol=0)
    assert not torch.allclose(sample_sky(env, 64, seed=1)[0], directions)


def test_concentrated_sky_acts_as_one_distant_light() -> None:
    # All energy in a tiny sun lobe (angular radius ~0.2°) and a black sky.
    env = ProceduralSky(
        zenith=(0.0, 0.0, 0.0),
        horizon=(0.0, 0.0, 0.0),
        sun_irradiance=2.0,
        sun_color=(1.0, 0.8, 0.6),
        sun_elevation_deg=55.0,
        sun_azimuth_deg=30.0,
        sun_sharpness=1e5,
    )
    maps = random_maps(SIZE, SIZE, seed=3)
    maps[6] = 0.3 + 0.7 * maps[6]  # roughness ≥ 0.3: a 0.2° lobe is then indistinguishable from a delta
    rendered = render_sky(maps, env, samples=16)
    # Independent reference: one light in the sun direction, 100× farther, float64.
    distance = 100.0 * SKY_LIGHT_DISTANCE
    direction = env.sun_direction()
    lights = PointLights(
        position=(distance * direction).view(1, 1, 1, 3),
        intensity=torch.full((1, 1, 1), distance**2, dtype=torch.float64),
        color=(2.0 * torch.tensor([1.0, 0.8, 0.6], dtype=torch.float64)).view(1, 1, 1, 3),
    )
    camera = torch.tensor([0.0, 0.0, FlashCapture().camera_height], dtype=torch.float64).view(1, 1, 3)
    reference = render_point_lights(maps[None].double(), camera, lights)[0, 0]
    assert relative_l1(rendered.double(), reference) < 0.01


def test_render_sky_converges_and_chunks_agree() -> None:
    maps = random_maps(16, 16, seed=4)
    maps[6] = 0.5 + 0.5 * maps[6]
    env = ProceduralSky()
    coarse = render_sky(maps, env, samples=64)
    torch.testing.assert_close(render_sky(maps, env, samples=64, chunk=64), coarse, rtol=1e-4, atol=1e-6)
    fine = render_sky(maps, env, samples=512)
    assert relative_l1(coarse, fine) < 0.05
    assert coarse.shape == (3, 16, 16) and (coarse >= 0).all()


def test_sky_rejects_bad_parameters() -> None:
    with pytest.raises(ValueError, match="zenith"):
        ProceduralSky(zenith=(-1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="sun_elevation_deg"):
        ProceduralSky(sun_elevation_deg=0.0)
    with pytest.raises(ValueError, match="sun_sharpness"):
        ProceduralSky(sun_sharpness=0.0)
    with pytest.raises(ValueError, match="samples"):
        sample_sky(ProceduralSky(), 0)
