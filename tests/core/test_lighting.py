"""Shared lighting helpers: directions, frames, luminance, log-uniform draws, equirect checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from brdfgan.core.exposure import luminance, luminance_value
from brdfgan.core.lighting import check_equirect, orthonormal_frame, spherical_direction
from brdfgan.core.sampling import log_uniform


def test_spherical_direction_conventions_in_both_libraries() -> None:
    azimuth = np.radians([0.0, 90.0, 45.0, 180.0])
    elevation = np.radians([0.0, 0.0, 90.0, 30.0])
    expected = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-math.cos(math.pi / 6), 0, 0.5]]
    np.testing.assert_allclose(spherical_direction(azimuth, elevation), expected, atol=1e-12)
    as_torch = spherical_direction(torch.from_numpy(azimuth), torch.from_numpy(elevation))
    assert isinstance(as_torch, torch.Tensor) and as_torch.shape == (4, 3)
    np.testing.assert_allclose(as_torch.numpy(), expected, atol=1e-12)


@pytest.mark.parametrize("axis", [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (0.3, -0.5, 0.2), (1.0, 0.0, 0.0)])
def test_orthonormal_frame_is_right_handed_in_both_libraries(axis: tuple[float, float, float]) -> None:
    unit = np.asarray(axis) / np.linalg.norm(axis)
    for tangent, bitangent in (orthonormal_frame(unit), orthonormal_frame(torch.from_numpy(unit))):
        frame = np.stack([np.asarray(tangent), np.asarray(bitangent), unit])
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(frame) == pytest.approx(1.0)
    np.testing.assert_allclose(
        orthonormal_frame(torch.from_numpy(unit))[0].numpy(), orthonormal_frame(unit)[0]
    )


def test_luminance_of_colours_matches_images() -> None:
    colours = torch.rand(5, 3, dtype=torch.float64)
    image = colours.T.reshape(3, 5, 1)
    torch.testing.assert_close(luminance(colours, dim=-1)[:, 0], luminance(image)[0, :, 0])
    assert luminance_value((1.0, 1.0, 1.0)) == pytest.approx(1.0)
    assert luminance_value([0.0, 1.0, 0.0]) == 0.7152
    with pytest.raises(ValueError, match=r"linear RGB must have shape \(\*, 3\), got \(4, 2\)"):
        luminance(torch.ones(4, 2), dim=-1)


def test_log_uniform_covers_the_range_evenly_in_log() -> None:
    assert log_uniform(0.0, 0.5, 8.0) == pytest.approx(0.5)
    assert log_uniform(0.5, 0.5, 8.0) == pytest.approx(2.0)  # the geometric mean
    assert log_uniform(torch.tensor(0.5, dtype=torch.float64), 0.5, 8.0) == pytest.approx(2.0)
    assert log_uniform(0.3, 2.0, 2.0) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="0 < low"):
        log_uniform(0.5, 0.0, 1.0)


def test_equirect_check_names_the_expected_shape() -> None:
    check_equirect(np.zeros((3, 6, 3), dtype=np.float32))
    for shape in ((4, 4, 3), (2, 4, 3), (4, 8, 1), (4, 8)):
        with pytest.raises(ValueError, match=r"\(H, 2H, 3\)"):
            check_equirect(np.zeros(shape, dtype=np.float32))
