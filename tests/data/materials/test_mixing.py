"""Material mixing and recolouring (brdfgan.data.materials.mixing / recolor / data.materials.source)."""

from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.svbrdf import split_maps, srgb_to_linear, validate_maps
from brdfgan.data.materials.albedo import DIELECTRIC_ALBEDO_LINEAR, metal_basecolor
from brdfgan.data.materials.base import MaterialLayers
from brdfgan.data.materials.families import FAMILIES
from brdfgan.data.materials.mixing import (
    MASK_KINDS,
    MixDraw,
    MixingConfig,
    mask_field,
    mix_layers,
    mixture_mask,
)
from brdfgan.data.materials.recolor import RecolorConfig, RecolorDraw, draw_recolor, recolor_basecolor
from brdfgan.data.materials.source import paint_procedural
from brdfgan.data.storage.spec_checks import DatasetConfigError

SIZE = 64


def _layers(value: float, height: torch.Tensor, metallic: float = 0.0) -> MaterialLayers:
    return MaterialLayers(
        basecolor=torch.full((3, SIZE, SIZE), value),
        height=height[None],
        roughness=torch.full((1, SIZE, SIZE), value),
        metallic=torch.full((1, SIZE, SIZE), metallic),
    )


def _ramp() -> torch.Tensor:
    u = (torch.arange(SIZE, dtype=torch.float32) + 0.5) / SIZE
    return (3.0 * torch.sin(2 * math.pi * u)).view(1, SIZE).expand(SIZE, SIZE).clone()


def test_mix_layers_puts_the_upper_material_on_top() -> None:
    lower = _layers(0.2, _ramp())
    upper = _layers(0.8, torch.full((SIZE, SIZE), 5.0), metallic=1.0)
    mask = torch.zeros(1, SIZE, SIZE)
    mask[:, :, SIZE // 2 :] = 1.0
    mixed = mix_layers(lower, upper, mask, thickness=0.01)
    left, right = (
        (slice(None), slice(None), slice(0, SIZE // 2)),
        (slice(None), slice(None), slice(SIZE // 2, None)),
    )
    assert torch.equal(mixed.basecolor[left], lower.basecolor[left])
    assert torch.equal(mixed.height[left], lower.height[left])
    assert torch.allclose(mixed.basecolor[right], torch.tensor(0.8))
    assert torch.allclose(mixed.metallic[right], torch.tensor(1.0))
    # Upper relief about its mean (flat here) plus the layer thickness, standing on the lower surface.
    assert torch.allclose(mixed.height[right], lower.height[right] + 0.01 * SIZE)
    with pytest.raises(ValueError, match="one size"):
        mix_layers(lower, upper, mask[:, :32], 0.01)


@pytest.mark.parametrize("kind", MASK_KINDS)
def test_mask_coverage_tiling_and_height_awareness(kind: str) -> None:
    height = _ramp()[None]
    for bias in (0.0, 1.5, -1.5):
        mask = mixture_mask(height, MixDraw(kind, 0.3, bias), torch.Generator().manual_seed(3))
        assert mask.shape == (1, SIZE, SIZE) and mask.min() >= 0 and mask.max() <= 1
        assert mask.mean().item() == pytest.approx(0.3, abs=0.06)
        if bias:
            # Positive bias: the upper material settles into the lower one's cavities.
            under, elsewhere = (
                (height * mask).sum() / mask.sum(),
                (height * (1 - mask)).sum() / (1 - mask).sum(),
            )
            assert (under < elsewhere) == (bias > 0), (kind, bias)
    field = mask_field(kind, 128, torch.Generator().manual_seed(0))
    assert field.mean().abs() < 1e-4 and field.std().item() == pytest.approx(1.0, rel=1e-4)
    for dim in (0, 1):
        steps = (field - torch.roll(field, 1, dims=dim)).abs().mean(dim=1 - dim)
        assert steps[0] <= 1.5 * steps[1:].max() + 1e-3  # no seam: the mask tiles


def test_mixing_config_errors_name_the_key() -> None:
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.mixing\.fraction=1\.5: must be in \[0, 1\]"):
        MixingConfig(fraction=1.5)
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.mixing\.masks: unknown mask 'stripes'"):
        MixingConfig(masks=("noise", "stripes"))
    with pytest.raises(DatasetConfigError, match=r"coverage_min=0\.7 > \S+coverage_max=0\.6"):
        MixingConfig(coverage_min=0.7)


def test_recolor_golden_hue_rotation_and_metal_untouched() -> None:
    red = torch.tensor([0.8, 0.2, 0.2]).view(3, 1, 1).expand(3, 2, 2)
    metallic = torch.tensor([[0.0, 1.0], [0.0, 1.0]]).view(1, 2, 2)
    out = recolor_basecolor(red, metallic, RecolorDraw(hue_shift=1.0 / 3.0, saturation=1.0, value=1.0))
    # A third of a turn takes red to green with the same saturation and value.
    torch.testing.assert_close(out[:, 0, 0], torch.tensor([0.2, 0.8, 0.2]), atol=1e-5, rtol=0)
    assert torch.equal(out[:, :, 1], red[:, :, 1])  # metallic texels keep their colour exactly


def test_recolor_stays_within_the_albedo_bounds() -> None:
    low, high = DIELECTRIC_ALBEDO_LINEAR
    generator = torch.Generator().manual_seed(0)
    # Extreme inputs (black, white, saturated) and extreme factors.
    colours = torch.rand(3, 32, 32, generator=generator)
    colours[:, 0] = 0.0
    colours[:, 1] = 1.0
    colours[:, 2] = torch.tensor([1.0, 0.0, 0.0]).view(3, 1)
    dielectric = torch.zeros(1, 32, 32)
    config = RecolorConfig(probability=1.0, saturation_max=10.0, value_max=10.0)
    for _ in range(20):
        linear = srgb_to_linear(recolor_basecolor(colours, dielectric, draw_recolor(config, generator)))
        assert linear.min() >= low - 1e-5 and linear.max() <= high + 1e-5
    gold = torch.tensor(metal_basecolor("gold")).view(3, 1, 1).expand(3, 4, 4)
    assert torch.equal(recolor_basecolor(gold, torch.ones(1, 4, 4), draw_recolor(config, generator)), gold)


def _paint(index: int, **options: object) -> torch.Tensor:
    families = tuple(FAMILIES.values())[:4]
    return paint_procedural(
        families,
        index,
        SIZE,
        torch.Generator().manual_seed(1000 + index),
        choice_seed=77 + index,
        partner_seed=lambda i: 1000 + i,
        **options,  # type: ignore[arg-type]
    ).maps


def test_paint_procedural_without_mixing_is_the_family_draw() -> None:
    families = tuple(FAMILIES.values())[:4]
    generator = torch.Generator().manual_seed(1002)
    family = families[2]
    expected = family.make_maps(family.sample_parameters(generator), SIZE, generator)
    assert torch.equal(_paint(2), expected)


def test_mixed_material_partner_comes_from_the_split_and_is_painted_as_itself() -> None:
    families = tuple(FAMILIES.values())[:4]
    split = (1, 2, 5, 9)
    painted = paint_procedural(
        families, 2, SIZE, torch.Generator().manual_seed(1002), choice_seed=5,
        partner_seed=lambda i: 1000 + i, split_indices=split, mixing=MixingConfig(fraction=1.0),
        recolor=RecolorConfig(probability=1.0),
    )  # fmt: skip
    mix = painted.extra["mix"]
    assert mix["partner_index"] in split and mix["partner_index"] != 2
    partner = mix["partner_index"]
    assert mix["partner_family"] == families[partner % 4].name
    partner_generator = torch.Generator().manual_seed(1000 + partner)
    assert mix["partner_parameters"] == families[partner % 4].sample_parameters(partner_generator)
    assert set(painted.extra["recolor"]) == {"hue_shift", "saturation", "value"}
    validate_maps(painted.maps)
    assert not torch.equal(painted.maps, _paint(2))
    dielectric = split_maps(painted.maps).metallic == 0
    linear = srgb_to_linear(split_maps(painted.maps).basecolor)
    assert linear[:, dielectric[0]].min() >= DIELECTRIC_ALBEDO_LINEAR[0] - 1e-5
