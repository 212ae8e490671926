from __future__ import annotations

import pytest
import torch
from torch import Tensor, nn

from brdfgan.core.svbrdf import flat_maps, validate_maps
from brdfgan.models import (
    Generator,
    MultiScaleDiscriminator,
    PatchDiscriminator,
    discriminator_input,
    downsample,
    maps_from_raw,
)
from tests.conftest import random_maps

TINY_G = {"width": 8, "downsamplings": 3, "residual_blocks": 2}


def count(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def photo(height: int, width: int, batch: int = 2, seed: int = 0) -> Tensor:
    return torch.rand(batch, 3, height, width, generator=torch.Generator().manual_seed(seed))


def random_projection(t: Tensor, seed: int) -> Tensor:
    """A scalar that depends on every element (a plain sum would be 0 after an InstanceNorm)."""
    return (t * torch.randn(t.shape, generator=torch.Generator().manual_seed(seed))).sum()


# --- generator -------------------------------------------------------------------------------------


def test_paper_generator_has_45_6_million_parameters() -> None:
    with torch.device("meta"):
        g = Generator()
    assert abs(count(g) - 45.6e6) < 0.2e6
    assert count(g) == 45_598_408  # biases cancelled by InstanceNorm removed (45,609,032 with them)
    convs = [m for m in g.modules() if isinstance(m, nn.Conv2d)]
    assert len(convs) == 1 + 3 + 2 * 9 + 1
    assert sum(isinstance(m, nn.ConvTranspose2d) for m in g.modules()) == 3
    assert [convs[i].out_channels for i in range(4)] == [64, 128, 256, 512]
    assert convs[-1].out_channels == 8 and convs[-1].kernel_size == (7, 7)


def test_config_rebuilds_the_same_architecture() -> None:
    g = Generator(**TINY_G)
    assert g.config() == {"in_channels": 3, **TINY_G}
    assert all(type(v) is int for v in g.config().values())
    rebuilt = Generator(**g.config())
    rebuilt.load_state_dict(g.state_dict())
    d = MultiScaleDiscriminator(width=8, layers=3, scales=3)
    assert d.config() == {"in_channels": 11, "width": 8, "layers": 3, "scales": 3}
    MultiScaleDiscriminator(**d.config()).load_state_dict(d.state_dict())


@pytest.mark.parametrize("size", [(16, 16), (64, 64), (96, 128), (48, 24)])
def test_generator_output_shape_for_multiples_of_eight(size: tuple[int, int]) -> None:
    g = Generator(**TINY_G)
    with torch.no_grad():
        maps = g(photo(*size))
    assert maps.shape == (2, 8, *size)
    validate_maps(maps)


@pytest.mark.parametrize("kind", ["uniform", "dark", "bright", "out_of_range"])
def test_generator_output_is_always_valid(kind: str) -> None:
    g = Generator(**TINY_G)
    x = photo(32, 40)
    x = {"uniform": x, "dark": x * 1e-3, "bright": x * 0 + 1, "out_of_range": (x - 0.5) * 200}[kind]
    with torch.no_grad():
        validate_maps(g(x))


def test_head_is_valid_for_extreme_raw_values_with_finite_gradients() -> None:
    raw = (torch.randn(2, 8, 5, 6, generator=torch.Generator().manual_seed(0)) * 60).requires_grad_()
    raw.data[0, :, 0, 0] = torch.tensor([-1e4, 1e4, 0, 0, 0, -1e4, 1e4, -1e4])  # normal collapses to +Z
    maps = maps_from_raw(raw)
    validate_maps(maps)
    torch.testing.assert_close(maps[0, :, 0, 0], torch.tensor([0.0, 1.0, 0.5, 0, 0, 1, 1, 0]))
    random_projection(maps, 1).backward()
    assert torch.isfinite(raw.grad).all()


def test_head_of_zero_is_mid_grey_with_a_flat_normal() -> None:
    maps = maps_from_raw(torch.zeros(1, 8, 2, 3))
    torch.testing.assert_close(maps, flat_maps(2, 3, metallic=0.5, batch=(1,)))


@pytest.mark.parametrize("size", [(60, 64), (64, 68), (8, 8), (8, 64)])
def test_generator_rejects_unsupported_sizes(size: tuple[int, int]) -> None:
    g = Generator(**TINY_G)
    with pytest.raises(ValueError, match="multiples of 8"):
        g(photo(*size))


def test_generator_rejects_wrong_channels() -> None:
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        Generator(**TINY_G)(torch.rand(1, 4, 32, 32))
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        Generator(**TINY_G)(torch.rand(3, 32, 32))


def test_reflection_padding_everywhere_except_down_and_up_layers() -> None:
    with torch.device("meta"):
        g = Generator()
    assert not [m for m in g.modules() if isinstance(m, nn.ZeroPad2d | nn.ReflectionPad2d | nn.ConstantPad2d)]
    for m in g.modules():
        if isinstance(m, nn.ConvTranspose2d):
            assert (m.stride, m.padding, m.output_padding) == ((2, 2), (1, 1), (1, 1))
        elif isinstance(m, nn.Conv2d) and m.stride == (2, 2):
            assert (m.kernel_size, m.padding, m.padding_mode) == ((3, 3), (1, 1), "zeros")
        elif isinstance(m, nn.Conv2d):
            assert m.stride == (1, 1) and m.padding_mode == "reflect"
            assert m.padding == (m.kernel_size[0] // 2, m.kernel_size[1] // 2)


def test_stride_one_convs_keep_a_constant_image_constant() -> None:
    # The behaviour reflection padding is for: no border artefacts from the 7×7 and residual convs.
    # (A whole-network check is meaningless: InstanceNorm turns a constant into float rounding
    # residue and amplifies it ~300× per layer, and the zero-padded d layers shape that residue.)
    g = Generator(**TINY_G)
    convs = [m for m in g.modules() if isinstance(m, nn.Conv2d) and m.stride == (1, 1)]
    assert len(convs) == 2 + 2 * TINY_G["residual_blocks"]
    with torch.no_grad():
        for conv in convs:
            out = conv(torch.full((1, conv.in_channels, 12, 10), 0.7))
            assert (out - out[..., :1, :1]).abs().max() < 1e-5
        zero_padded = nn.Conv2d(3, 8, 7, padding=3)
        out = zero_padded(torch.full((1, 3, 12, 10), 0.7))
        assert (out - out[..., 5:6, 5:6]).abs().max() > 1e-3  # the check can fail


def test_tiny_generator_overfits_one_sample() -> None:
    torch.manual_seed(0)
    g = Generator(width=32, downsamplings=2, residual_blocks=1)
    x, target = photo(32, 32, batch=1, seed=1), random_maps(32, 32, seed=2, batch=(1,))
    optimizer = torch.optim.Adam(g.parameters(), lr=2e-3)
    with torch.no_grad():
        initial = (g(x) - target).abs().mean().item()
    for _ in range(100):
        loss = (g(x) - target).abs().mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    with torch.no_grad():
        final = (g(x) - target).abs().mean().item()
    assert final < initial / 5, (initial, final)


# --- discriminators --------------------------------------------------------------------------------


def test_paper_discriminator_parameter_count() -> None:
    with torch.device("meta"):
        d = MultiScaleDiscriminator()
    assert len(d.discriminators) == 2
    # 4×4 convs 11→64 (+bias), 64→128, 128→256, 256→512 (no bias: InstanceNorm), 512→1 (+bias)
    assert [count(m) for m in d.discriminators] == [2_772_033, 2_772_033]


def test_multiscale_discriminator_output_sizes_at_512() -> None:
    d = MultiScaleDiscriminator(width=8)
    maps = random_maps(512, 512, batch=(1,))
    with torch.no_grad():
        outputs = d(photo(512, 512, batch=1), maps)
    assert len(outputs) == 2 and all(len(layers) == 5 for layers in outputs)
    assert [tuple(layers[-1].shape) for layers in outputs] == [(1, 1, 32, 32), (1, 1, 16, 16)]
    assert [tuple(t.shape[1:]) for t in outputs[0][:4]] == [
        (8, 256, 256),
        (16, 128, 128),
        (32, 64, 64),
        (64, 32, 32),
    ]
    assert [tuple(t.shape[1:]) for t in outputs[1][:4]] == [
        (8, 128, 128),
        (16, 64, 64),
        (32, 32, 32),
        (64, 16, 16),
    ]


def test_patch_discriminator_widths_cap_at_eight_times_width() -> None:
    d = PatchDiscriminator(in_channels=5, width=4, layers=6)
    with torch.no_grad():
        outputs = d(torch.randn(1, 5, 128, 128))
    assert [t.shape[1] for t in outputs] == [4, 8, 16, 32, 32, 32, 1]
    assert [t.shape[-1] for t in outputs] == [64, 32, 16, 8, 4, 2, 2]


def test_downsample_halves_exactly() -> None:
    assert downsample(torch.rand(1, 11, 512, 512)).shape[-2:] == (256, 256)
    assert downsample(torch.rand(1, 2, 5, 6)).shape[-2:] == (3, 3)
    # count_include_pad=False: a constant stays constant at the borders
    torch.testing.assert_close(downsample(torch.ones(1, 1, 7, 8)), torch.ones(1, 1, 4, 4))


def test_discriminator_input_centres_every_channel() -> None:
    maps = flat_maps(4, 4, basecolor=(0.0, 0.5, 1.0), roughness=1.0, metallic=0.0, batch=(1,))
    x = discriminator_input(torch.full((1, 3, 4, 4), 0.25), maps)
    assert x.shape == (1, 11, 4, 4)
    torch.testing.assert_close(x[0, :, 0, 0], torch.tensor([-0.5, -0.5, -0.5, -1, 0, 1, 0, 0, 1, 1, -1]))
    with pytest.raises(ValueError, match="share batch and size"):
        discriminator_input(torch.rand(1, 3, 4, 5), maps)
    with pytest.raises(ValueError):
        discriminator_input(torch.rand(1, 3, 4, 4), maps[:, :7])


def test_discriminator_rejects_too_small_inputs() -> None:
    d = MultiScaleDiscriminator(width=4)
    with pytest.raises(ValueError, match=">= 32"):
        d(photo(16, 64, batch=1), random_maps(16, 64, batch=(1,)))
    with torch.no_grad():
        assert d(photo(64, 64, batch=1), random_maps(64, 64, batch=(1,)))[1][-1].shape[-2:] == (2, 2)


def test_discriminator_gradient_reaches_both_inputs() -> None:
    d = MultiScaleDiscriminator(width=4)
    x = photo(64, 64, batch=1).requires_grad_()
    maps = random_maps(64, 64, batch=(1,)).requires_grad_()
    outputs = d(x, maps)
    sum(random_projection(layers[-1], i) for i, layers in enumerate(outputs)).backward()
    for grad in (x.grad, maps.grad):
        assert grad is not None and torch.isfinite(grad).all() and grad.abs().amax(dim=(0, 2, 3)).min() > 0


def test_gradients_reach_every_parameter() -> None:
    # No unused or dead parameters (DDP would need find_unused_parameters, Adam would never move them).
    g = Generator(**TINY_G)
    d = MultiScaleDiscriminator(width=4, layers=3)
    x = photo(64, 64, batch=1)
    maps = g(x)
    outputs = d(x, maps)
    loss = sum(
        random_projection(t, 10 * i + j) for i, layers in enumerate(outputs) for j, t in enumerate(layers)
    )
    loss.backward()
    for name, p in [*g.named_parameters(prefix="G"), *d.named_parameters(prefix="D")]:
        assert p.grad is not None, name
        assert torch.isfinite(p.grad).all() and p.grad.abs().max() > 1e-8, name


def test_unit_z_normal_head_is_the_height_gradient_form() -> None:
    from brdfgan.models.heads import maps_from_raw

    raw = torch.zeros(1, 8, 2, 2)
    raw[0, 3, 0, 0], raw[0, 4, 0, 1] = 0.5, -2.0
    raw[0, 5] = 7.0  # unused by unit_z: the softplus head would shrink every tilt by ~1/7
    unit_z = maps_from_raw(raw, "unit_z")[0, 3:6]
    expected = torch.nn.functional.normalize(torch.tensor([[[0.5, 0.0], [0.0, 0.0]],
                                                           [[0.0, -2.0], [0.0, 0.0]],
                                                           [[1.0, 1.0], [1.0, 1.0]]]), dim=0)  # fmt: skip
    torch.testing.assert_close(unit_z, expected)
    softplus_z = maps_from_raw(raw)[0, 3:6]
    assert softplus_z[0, 0, 0] < 0.5 * unit_z[0, 0, 0]
    # Same gradient scale for any raw z: the tilt's gradient at flat is 1 (tangent), not 1/z.
    raw = torch.zeros(1, 8, 1, 1, requires_grad=True)
    maps_from_raw(raw, "unit_z")[0, 3].sum().backward()
    assert raw.grad is not None and raw.grad[0, 3].item() == pytest.approx(1.0)


def test_generator_normal_head_option_round_trips_and_checks() -> None:
    from brdfgan.errors import UserError

    default = Generator(width=8, residual_blocks=1)
    assert "normal_head" not in default.config()
    unit = Generator(width=8, residual_blocks=1, normal_head="unit_z")
    assert Generator(**unit.config()).normal_head == "unit_z"
    assert set(unit.state_dict()) == set(default.state_dict())
    with pytest.raises(UserError, match=r"model\.generator\.normal_head"):
        Generator(width=8, normal_head="tanh")  # type: ignore[arg-type]


def test_raw_from_maps_inverts_the_unit_z_head() -> None:
    from brdfgan.models.heads import RAW_EPS, raw_from_maps

    maps = random_maps(16, 12, seed=3)
    back = maps_from_raw(raw_from_maps(maps), "unit_z")
    # Exact up to the logit's clamp to [eps, 1 - eps] (random_maps keeps normals well above the z clamp).
    torch.testing.assert_close(back, maps, atol=RAW_EPS, rtol=0)
    # Saturated values and grazing or flat normals stay finite and decode to valid maps.
    edge = maps.clone()
    edge[0:3], edge[6], edge[7] = 0.0, 1.0, 0.0
    edge[3:6] = torch.tensor([1.0, 0.0, 0.0]).view(3, 1, 1)
    raw = raw_from_maps(edge)
    assert torch.isfinite(raw).all() and raw[5].abs().max() == 0
    validate_maps(maps_from_raw(raw, "unit_z"))
    # Any raw value is valid maps: the parameterisation test-time refinement optimises.
    validate_maps(maps_from_raw(torch.randn(2, 8, 5, 5) * 30, "unit_z"))
