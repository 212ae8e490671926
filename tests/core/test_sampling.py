from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.render import render_point_lights
from brdfgan.core.sampling import (
    RenderingLossSampling,
    log_transform,
    sample_cosine_hemisphere,
    sample_rendering_loss_configs,
)
from brdfgan.core.svbrdf import flat_maps


def _draw(seed: int, batch: int = 4, **kw):
    return sample_rendering_loss_configs(batch, generator=torch.Generator().manual_seed(seed), **kw)


def test_ten_configurations_with_the_documented_shapes() -> None:
    configs = _draw(0)
    assert configs.camera_position.shape == (4, 10, 3)
    assert configs.lights.position.shape == (4, 10, 1, 3)
    assert configs.lights.intensity.shape == (4, 10, 1)
    assert configs.lights.color.shape == (4, 10, 1, 3)
    assert (configs.camera_position[..., 2] > 0).all()
    assert (configs.lights.position[..., 2] > 0).all()
    torch.testing.assert_close(configs.lights.color.amax(-1), torch.ones(4, 10, 1))
    assert configs.lights.color.min() >= 0.3


def test_reproducible_from_a_generator() -> None:
    a, b, c = _draw(5), _draw(5), _draw(6)
    assert torch.equal(a.camera_position, b.camera_position)
    assert torch.equal(a.lights.color, b.lights.color)
    assert not torch.equal(a.camera_position, c.camera_position)


def test_specular_configurations_mirror_about_a_point_of_the_sample() -> None:
    half = 1.5
    configs = _draw(1, batch=64, plane_half_size=half, dtype=torch.float64)
    cam = configs.camera_position[:, 5:]
    light = configs.lights.position[:, 5:, 0]
    # The mirror image of the camera below the plane, joined to the light, crosses z = 0 at p.
    mirror = cam * cam.new_tensor([1.0, 1.0, -1.0])
    t = -mirror[..., 2:] / (light[..., 2:] - mirror[..., 2:])
    p = mirror + t * (light - mirror)
    assert p[..., :2].abs().max() <= half
    to_cam = torch.nn.functional.normalize(cam - p, dim=-1)
    to_light = torch.nn.functional.normalize(light - p, dim=-1)
    half_vector = torch.nn.functional.normalize(to_cam + to_light, dim=-1)
    torch.testing.assert_close(
        half_vector, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand_as(half_vector)
    )


def test_specular_configurations_show_a_highlight() -> None:
    maps = flat_maps(32, 32, roughness=0.15, metallic=1.0, basecolor=(0.9, 0.9, 0.9), batch=(16,))
    configs = _draw(2, batch=16)
    image = render_point_lights(maps, configs.camera_position, configs.lights).sum(2)
    peak_over_mean = image.amax(dim=(-2, -1)) / image.mean(dim=(-2, -1)).clamp(min=1e-12)
    assert peak_over_mean[:, 5:].median() > 4 * peak_over_mean[:, :5].median()
    assert peak_over_mean[:, 5:].min() > 20


def test_intensity_keeps_irradiance_in_range() -> None:
    configs = _draw(3, batch=32)
    distance = torch.linalg.vector_norm(configs.lights.position[:, :5, 0], dim=-1)
    normalised = configs.lights.intensity[:, :5, 0] / (math.pi * distance**2)
    assert normalised.min() >= 0.5 - 1e-6 and normalised.max() <= 1.5 + 1e-6


def test_cosine_hemisphere_has_the_right_mean_cosine() -> None:
    dirs = sample_cosine_hemisphere((200_000,), torch.Generator().manual_seed(0), dtype=torch.float64)
    torch.testing.assert_close(
        torch.linalg.vector_norm(dirs, dim=-1), torch.ones(200_000, dtype=torch.float64)
    )
    assert dirs[:, 2].mean().item() == pytest.approx(2 / 3, abs=3e-3)  # E[cos θ] under cos θ/π


def test_config_counts_and_validation() -> None:
    configs = sample_rendering_loss_configs(2, RenderingLossSampling(random_configs=3, specular_configs=0))
    assert configs.camera_position.shape == (2, 3, 3)
    with pytest.raises(ValueError, match="at least one"):
        RenderingLossSampling(random_configs=0, specular_configs=0)
    with pytest.raises(ValueError, match="distance"):
        RenderingLossSampling(distance_min=3.0, distance_max=2.0)


def test_log_transform() -> None:
    x = torch.tensor([0.0, 1.0, math.e - 1.0, 1e6])
    torch.testing.assert_close(log_transform(x), torch.tensor([0.0, math.log(2.0), 1.0, math.log1p(1e6)]))
