from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core import svbrdf
from brdfgan.core.svbrdf import InvalidMapsError
from tests.conftest import random_maps


def test_layout_is_eight_channels_in_documented_order() -> None:
    maps = random_maps(4, 5)
    parts = svbrdf.split_maps(maps)
    assert [p.shape[-3] for p in parts] == [3, 3, 1, 1]
    assert torch.equal(svbrdf.join_maps(*parts), maps)
    assert svbrdf.MAP_NAMES == ("basecolor", "normal", "roughness", "metallic")


def test_srgb_golden_values_and_round_trip() -> None:
    srgb = torch.tensor([0.0, 0.04045, 0.5, 1.0], dtype=torch.float64)
    linear = svbrdf.srgb_to_linear(srgb)
    expected = torch.tensor([0.0, 0.04045 / 12.92, 0.21404114048223255, 1.0], dtype=torch.float64)
    torch.testing.assert_close(linear, expected, rtol=1e-9, atol=1e-12)
    values = torch.linspace(0, 1, 10001, dtype=torch.float64)
    torch.testing.assert_close(
        svbrdf.linear_to_srgb(svbrdf.srgb_to_linear(values)), values, rtol=0, atol=1e-12
    )
    torch.testing.assert_close(
        svbrdf.srgb_to_linear(svbrdf.linear_to_srgb(values)), values, rtol=0, atol=1e-12
    )


def test_srgb_gradients_are_finite_at_zero() -> None:
    x = torch.zeros(3, requires_grad=True)
    svbrdf.linear_to_srgb(x).sum().backward()
    assert torch.isfinite(x.grad).all()


def test_normal_encode_decode_round_trip_and_renormalisation() -> None:
    normal = svbrdf.split_maps(random_maps(8, 8)).normal
    encoded = svbrdf.encode_normal(normal)
    assert encoded.min() >= 0 and encoded.max() <= 1
    torch.testing.assert_close(svbrdf.decode_normal(encoded), normal, atol=1e-6, rtol=0)
    quantised = torch.round(encoded * 255) / 255
    decoded = svbrdf.decode_normal(quantised)
    torch.testing.assert_close(torch.linalg.vector_norm(decoded, dim=-3), torch.ones(8, 8), atol=1e-6, rtol=0)
    assert torch.equal(svbrdf.normalize_normal(torch.zeros(3, 1, 1)).flatten(), torch.tensor([0.0, 0.0, 1.0]))


def test_albedos_follow_the_paper() -> None:
    base = torch.tensor([0.8, 0.5, 0.2]).view(3, 1, 1)
    torch.testing.assert_close(svbrdf.diffuse_albedo(base, torch.zeros(1, 1, 1)), base)
    torch.testing.assert_close(
        svbrdf.specular_albedo(base, torch.zeros(1, 1, 1)), torch.full((3, 1, 1), 0.04)
    )
    torch.testing.assert_close(svbrdf.diffuse_albedo(base, torch.ones(1, 1, 1)), torch.zeros(3, 1, 1))
    torch.testing.assert_close(svbrdf.specular_albedo(base, torch.ones(1, 1, 1)), base)
    half = torch.full((1, 1, 1), 0.5)
    torch.testing.assert_close(svbrdf.specular_albedo(base, half), 0.02 + 0.5 * base)


def test_alpha_is_clamped_square_of_roughness() -> None:
    r = torch.tensor([0.0, 0.01, 0.5, 1.0])
    torch.testing.assert_close(svbrdf.roughness_to_alpha(r), torch.tensor([0.001, 0.001, 0.25, 1.0]))


def test_valid_maps_pass_validation() -> None:
    svbrdf.validate_maps(random_maps(6, 7, batch=(2,)))
    svbrdf.validate_maps(svbrdf.flat_maps(3, 3))


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda m: m[:7], "shape"),
        (lambda m: m[0], "shape"),
        (lambda m: m.to(torch.int32), "floating point"),
        (
            lambda m: m.index_put_(
                (torch.tensor(6), torch.tensor(0), torch.tensor(0)), torch.tensor(math.nan)
            ),
            "NaN",
        ),
        (
            lambda m: m.index_put_((torch.tensor(0), torch.tensor(1), torch.tensor(1)), torch.tensor(1.5)),
            "basecolor",
        ),
        (
            lambda m: m.index_put_((torch.tensor(7), torch.tensor(1), torch.tensor(1)), torch.tensor(-0.2)),
            "metallic",
        ),
        (
            lambda m: m.index_put_((torch.tensor(3), torch.tensor(2), torch.tensor(2)), torch.tensor(0.9)),
            "unit length",
        ),
        (lambda m: torch.cat([m[:3], svbrdf.encode_normal(m[3:6]), m[6:]]), "unit length"),
        (lambda m: torch.cat([m[:5], -m[5:6], m[6:]]), "out of the surface"),
    ],
)
def test_bad_maps_give_one_line_errors(mutate, message: str) -> None:
    maps = mutate(random_maps(4, 4))
    with pytest.raises(InvalidMapsError, match=message) as info:
        svbrdf.validate_maps(maps)
    assert "\n" not in str(info.value)
