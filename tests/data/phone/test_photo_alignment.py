"""Maps resampled into the photo's pixels (brdfgan.core.render.maps_in_view,
brdfgan.data.phone.conditions.maps_as_photographed): the warp follows the camera, is the identity for the
nominal camera, and lines the maps up with what Mitsuba photographs."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from brdfgan.core.render import (
    FlashCapture,
    maps_in_view,
    nominal_camera,
    project_to_image,
    view_plane_points,
)
from brdfgan.core.svbrdf import BASECOLOR, NORMAL, flat_maps, validate_maps
from brdfgan.data.phone.conditions import (
    CaptureDraw,
    maps_as_photographed,
    max_distance_factor,
    recorded_camera,
)
from brdfgan.data.storage.shards import Sample
from tests.conftest import random_maps

TILTED = CaptureDraw(
    fov_deg=60.0,
    tilt_deg=3.0,
    tilt_axis_deg=35.0,
    distance_factor=0.93 * max_distance_factor(60.0, 3.0, 35.0),
)


def test_pixel_rays_meet_the_plane_where_the_camera_projects_them() -> None:
    points = view_plane_points(TILTED.camera, 24, 24)
    world = np.concatenate([points.reshape(-1, 2), np.zeros((24 * 24, 1))], axis=1)
    pixels = project_to_image(world, TILTED.camera, 24, 24).reshape(24, 24, 2)
    rows, cols = np.indices((24, 24))
    np.testing.assert_allclose(pixels[..., 0], cols + 0.5, atol=1e-9)
    np.testing.assert_allclose(pixels[..., 1], rows + 0.5, atol=1e-9)
    # The nominal camera's rays meet the texel centres.
    nominal = view_plane_points(nominal_camera(45.0), 8, 8)
    centres = -1.0 + (np.arange(8) + 0.5) / 4.0
    np.testing.assert_allclose(nominal[0, :, 0], centres, atol=1e-12)
    np.testing.assert_allclose(nominal[:, 0, 1], -centres, atol=1e-12)


def test_the_nominal_camera_leaves_the_maps_as_they_are() -> None:
    maps = random_maps(32, 32, seed=3)
    torch.testing.assert_close(maps_in_view(maps, nominal_camera(50.0)), maps, atol=1e-5, rtol=0)


def test_a_texel_lands_under_the_pixel_that_photographs_it() -> None:
    maps = flat_maps(64, 64, basecolor=(0.1, 0.1, 0.1))
    maps[BASECOLOR, 40:44, 12:16] = 0.9  # a marker around world (-0.5625, -0.3125)
    marker = np.array([[-1.0 + 14.0 / 32.0, 1.0 - 42.0 / 32.0, 0.0]])
    expected = project_to_image(marker, TILTED.camera, 64, 64)[0]
    warped = maps_in_view(maps, TILTED.camera)
    validate_maps(warped)
    weight = (warped[0] - 0.1).clamp_min(0)
    rows, cols = torch.meshgrid(torch.arange(64) + 0.5, torch.arange(64) + 0.5, indexing="ij")
    centroid = ((cols * weight).sum() / weight.sum(), (rows * weight).sum() / weight.sum())
    assert abs(float(centroid[0]) - expected[0]) < 0.3 and abs(float(centroid[1]) - expected[1]) < 0.3
    assert np.hypot(expected[0] - 14.0, expected[1] - 42.0) > 2.0  # the camera moved it: the check can tell
    torch.testing.assert_close(warped[NORMAL].norm(dim=0), torch.ones(64, 64))


def test_samples_without_a_recorded_camera_are_untouched() -> None:
    maps = random_maps(16, 16, seed=1)
    assert recorded_camera({}) is None
    assert maps_as_photographed(maps, {"family": "x"}) is maps
    meta = {"capture": TILTED.to_json(16)}
    pose = recorded_camera(meta)
    assert pose is not None and np.allclose(pose.origin, TILTED.camera.origin)
    Sample("k", torch.rand(3, 16, 16), maps_as_photographed(maps, meta), meta)  # valid maps


@pytest.mark.integration
@pytest.mark.mitsuba
def test_mitsuba_photographs_the_aligned_maps_pixel_for_pixel() -> None:
    """A high-frequency base colour photographed by Mitsuba through a tilted, closer camera: the
    aligned maps match the photo's detail; the texture-space maps are off by pixels."""
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    res = 64
    maps = random_maps(res, res, seed=5)
    generator = torch.Generator().manual_seed(0)
    maps[BASECOLOR] = torch.rand(1, res, res, generator=generator).expand(3, -1, -1) * 0.8 + 0.1
    maps[NORMAL] = torch.tensor([0.0, 0.0, 1.0])[:, None, None]
    maps[6:8] = torch.tensor([0.9, 0.0])[:, None, None]  # rough dielectric: the photo is the albedo
    photo = CaptureRenderer(res, 64, FlashCapture(), 16).render(
        maps, None, (1.0, 1.0, 1.0), seed=1, camera=TILTED.camera, flash_position=TILTED.flash_position
    )

    def detail(image: torch.Tensor) -> torch.Tensor:
        gray = image.mean(0, keepdim=True)[None]
        return (gray - F.avg_pool2d(gray, 5, 1, 2, count_include_pad=False)).flatten()

    def correlation(a: torch.Tensor, b: torch.Tensor) -> float:
        return float(torch.corrcoef(torch.stack([detail(a), detail(b)]))[0, 1])

    aligned = correlation(photo, maps_in_view(maps, TILTED.camera)[BASECOLOR])
    stored = correlation(photo, maps[BASECOLOR])
    assert aligned > 0.8 > 0.3 > stored, (aligned, stored)
