from __future__ import annotations

import math

import pytest
import torch

from brdfgan.data.materials import noise
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter, height_to_normal


def test_parameter_sampling_is_clipped_normal_around_the_default() -> None:
    p = Parameter(default=0.3, low=0.0, high=1.0, doc="x")
    g = torch.Generator().manual_seed(0)
    draws = torch.tensor([p.sample(g) for _ in range(4000)])
    assert draws.min() >= 0.0 and draws.max() <= 1.0
    # Clipping is monotone, so the median of the draws stays the default.
    assert draws.median().item() == pytest.approx(0.3, abs=0.03)
    # σ = range/2 puts about a quarter of the mass of N(0.3, 0.5) below 0: clipped to the bound.
    assert (draws == 0.0).float().mean().item() == pytest.approx(0.274, abs=0.03)
    with pytest.raises(ValueError, match="outside"):
        Parameter(default=2.0, low=0.0, high=1.0, doc="bad")


def test_uniform_parameter_sampling_covers_the_range_evenly() -> None:
    hue = Parameter(default=0.5, low=0.0, high=1.0, doc="hue", uniform=True)
    g = torch.Generator().manual_seed(0)
    draws = torch.tensor([hue.sample(g) for _ in range(4000)])
    counts = torch.histc(draws, bins=10, min=0.0, max=1.0)
    # No pile-up on the bounds (a clipped normal puts ~16 % on each) and every tenth near 10 %.
    assert ((draws == 0.0) | (draws == 1.0)).sum() == 0
    assert counts.min() > 330 and counts.max() < 470


def test_height_to_normal_golden_slopes() -> None:
    # Height rising to the right (+X) by 1 texel per texel: normal (−1, 0, 1)/√2.
    ramp_x = torch.arange(8.0).view(1, 1, 8).expand(1, 8, 8)
    n = height_to_normal(ramp_x)[:, 4, 4]
    torch.testing.assert_close(n, torch.tensor([-1.0, 0.0, 1.0]) / math.sqrt(2.0))
    # Height rising towards row 0 (+Y): normal (0, −1, 1)/√2.
    ramp_up = -torch.arange(8.0).view(1, 8, 1).expand(1, 8, 8)
    torch.testing.assert_close(
        height_to_normal(ramp_up)[:, 4, 4], torch.tensor([0.0, -1.0, 1.0]) / math.sqrt(2.0)
    )
    flat = height_to_normal(torch.zeros(1, 4, 4))
    torch.testing.assert_close(flat, torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand(3, 4, 4))


def _toy_family() -> MaterialFamily:
    def generate(params, size, generator) -> MaterialLayers:
        field = noise.value_noise(size, 4, generator)[None]
        return MaterialLayers(
            field.expand(3, size, size) * params["tone"], field * size * 0.05, field, 0 * field
        )

    return MaterialFamily("toy", {"tone": Parameter(0.5, 0.1, 0.9, "brightness")}, generate)


def test_family_make_maps() -> None:
    family = _toy_family()
    maps = family.make_maps(family.sample_parameters(torch.Generator().manual_seed(1)), 32, torch.Generator())
    assert maps.shape == (8, 32, 32)
    with pytest.raises(KeyError, match="toy: unknown parameter"):
        family.make_maps({"colour": 0.2}, 8, torch.Generator())


@pytest.mark.parametrize("kind", ["value", "gradient", "fbm", "worley"])
def test_noise_is_seeded_and_tiles(kind: str) -> None:
    def field(seed: int, size: int = 64) -> torch.Tensor:
        g = torch.Generator().manual_seed(seed)
        return {
            "value": lambda: noise.value_noise(size, 4, g),
            "gradient": lambda: noise.gradient_noise(size, 4, g),
            "fbm": lambda: noise.fbm(size, 2, g, octaves=4),
            "worley": lambda: noise.worley(size, 4, g)[0],
        }[kind]()

    a = field(0)
    assert torch.equal(a, field(0)) and not torch.equal(a, field(1))
    # Periodic: the jump across the wrap-around edge is no larger than between neighbours inside.
    wrap = (a[:, 0] - a[:, -1]).abs().mean()
    inside = (a[:, 1:] - a[:, :-1]).abs().mean()
    assert wrap < 3 * inside
    wrap_rows = (a[0] - a[-1]).abs().mean()
    assert wrap_rows < 3 * (a[1:] - a[:-1]).abs().mean()


def test_worley_ids_and_distances() -> None:
    f1, f2, cell = noise.worley(64, 4, torch.Generator().manual_seed(2))
    assert (f1 <= f2).all() and f1.min() >= 0
    assert cell.min() >= 0 and cell.max() < 16 and len(cell.unique()) == 16
