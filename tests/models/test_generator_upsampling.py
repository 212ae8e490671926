"""The generator's ``upsampling`` option: the paper's transposed convs (default, unchanged) and
resize-convolution (nearest ×2 + 3×3 conv, ``model=default_resize``) against checkerboard."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import torch
from torch import Tensor, nn

from brdfgan.errors import UserError
from brdfgan.models.generator import Generator
from brdfgan.runs import load_weights, network_from_config, network_weights, save_weights
from tests.conftest import compose_train

TINY: dict[str, Any] = {"width": 8, "downsamplings": 3, "residual_blocks": 2}
TARGET = "brdfgan.models.generator.Generator"


def count(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def periodic_2x2_fraction(maps: Tensor) -> float:
    """Share of the (mean-free) maps' energy in their 2×2-periodic component: the pattern that
    repeats every 2 pixels in both axes, i.e. the energy at the Nyquist frequencies (0, ½), (½, 0)
    and (½, ½). 1 for a pure checkerboard, 4/(H W) on average for white noise.

    Shape: maps ``(B, C, H, W)``, H and W even.
    """
    centred = maps - maps.mean(dim=(-2, -1), keepdim=True)
    b, c, h, w = centred.shape
    pattern = centred.reshape(b, c, h // 2, 2, w // 2, 2).mean(dim=(2, 4))  # (B, C, 2, 2)
    return float(pattern.square().mean() / centred.square().mean())


def smooth_photo(size: int, seed: int) -> Tensor:
    """A photo ``(1, 3, size, size)`` of a few cosines of frequency <= 3 cycles per image: no 2×2
    component of its own, and not constant (a constant photo is all zero after the first
    InstanceNorm, and the output is amplified float rounding residue)."""
    g = torch.Generator().manual_seed(seed)
    y, x = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    photo = torch.full((1, 3, size, size), 0.5)
    for _ in range(4):
        ky, kx = torch.randint(-3, 4, (2,), generator=g).tolist()
        phase = torch.rand(3, 1, 1, generator=g) * 2 * math.pi
        amplitude = 0.1 * torch.rand(3, 1, 1, generator=g)
        photo = photo + amplitude * torch.cos(2 * math.pi * (ky * y + kx * x) / size + phase)
    return photo.clamp(0.0, 1.0)


def test_transposed_is_unchanged_from_before_the_option() -> None:
    # Golden values computed with the generator as it was before `upsampling` existed.
    torch.manual_seed(0)
    g = Generator(**TINY).eval()
    photo = torch.rand(1, 3, 32, 40, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        maps = g(photo)
    expected_pixel = [
        0.47884232,
        0.33974421,
        0.50715923,
        -0.50570637,
        -0.22783533,
        0.83207697,
        0.39110106,
        0.53607672,
    ]
    expected_mean = [
        0.51730466,
        0.45885935,
        0.48053774,
        -0.29648018,
        -0.02354996,
        0.87644255,
        0.51945120,
        0.50081193,
    ]
    assert maps[0, :, 10, 11].tolist() == pytest.approx(expected_pixel, abs=1e-5)
    assert maps.mean(dim=(0, 2, 3)).tolist() == pytest.approx(expected_mean, abs=1e-5)
    assert list(g.state_dict()) == [
        "down.0.weight", "down.3.weight", "down.6.weight", "down.9.weight",
        "residual.0.body.2.weight", "residual.0.body.5.weight",
        "residual.1.body.2.weight", "residual.1.body.5.weight",
        "up.0.weight", "up.3.weight", "up.6.weight", "out.weight", "out.bias",
    ]  # fmt: skip
    assert g.config() == {"in_channels": 3, **TINY}  # no upsampling key: configs stored before it match


def test_weights_stored_before_the_option_load_strictly_as_transposed(tmp_path: Path) -> None:
    # v3 (brdfgan-default-v3, shipped until v4) was stored with no upsampling key in its config.
    torch.manual_seed(0)
    g = Generator(**TINY).eval()
    old = save_weights(tmp_path / "v3.safetensors", g, target=TARGET, config=TINY, model_id="v3-era")
    assert "upsampling" not in load_weights(old)[1]["config"]
    rebuilt = Generator(**TINY)
    rebuilt.load_state_dict(network_weights(old)["generator"], strict=True)
    assert rebuilt.upsampling == "transposed"
    loaded, _ = load_weights(old)
    assert isinstance(loaded, Generator) and loaded.upsampling == "transposed"
    photo = torch.rand(1, 3, 32, 32)
    torch.testing.assert_close(loaded(photo), g(photo))


def test_resize_layers_and_parameter_count() -> None:
    with torch.device("meta"):
        paper = {up: Generator(upsampling=up) for up in ("transposed", "resize")}
    # Conv2d(C, C/2, 3) and ConvTranspose2d(C, C/2, 3) hold the same C·C/2·9 weights.
    assert count(paper["resize"]) == count(paper["transposed"]) == 45_598_408
    assert count(Generator(width=16, residual_blocks=4, upsampling="resize")) == 1_381_816
    up = paper["resize"].up
    assert not any(isinstance(m, nn.ConvTranspose2d) for m in paper["resize"].modules())
    upsamplers = [m for m in up if isinstance(m, nn.Upsample)]
    convs = [m for m in up if isinstance(m, nn.Conv2d)]
    assert [(m.scale_factor, m.mode) for m in upsamplers] == [(2.0, "nearest")] * 3
    assert [(c.in_channels, c.out_channels) for c in convs] == [(512, 256), (256, 128), (128, 64)]
    assert all(
        (c.kernel_size, c.stride, c.padding_mode, c.bias) == ((3, 3), (1, 1), "reflect", None) for c in convs
    )
    # Each conv is followed by the same InstanceNorm + ReLU as the transposed conv was.
    kinds = [type(m).__name__ for m in up]
    assert kinds == ["Upsample", "Conv2d", "InstanceNorm2d", "ReLU"] * 3


@pytest.mark.parametrize("size", [(16, 16), (32, 40), (64, 24)])
def test_both_keep_the_input_size(size: tuple[int, int]) -> None:
    photo = torch.rand(2, 3, *size, generator=torch.Generator().manual_seed(0))
    for up in ("transposed", "resize"):
        with torch.no_grad():
            maps = Generator(**TINY, upsampling=up).eval()(photo)
        assert maps.shape == (2, 8, *size)
        assert torch.isfinite(maps).all()
    g2 = Generator(width=8, downsamplings=2, residual_blocks=1, upsampling="resize")
    assert g2(torch.rand(1, 3, 12, 20)).shape == (1, 8, 12, 20)


@pytest.mark.parametrize("size", [(36, 40), (32, 30), (8, 8)])
def test_unsupported_sizes_are_refused_the_same_way(size: tuple[int, int]) -> None:
    # Today's behaviour: no padding inside; a ValueError that says what to pad to.
    messages = []
    for up in ("transposed", "resize"):
        with pytest.raises(ValueError, match="Pad the photo to") as error:
            Generator(**TINY, upsampling=up)(torch.rand(1, 3, *size))
        messages.append(str(error.value))
    assert messages[0] == messages[1]


def test_resize_has_far_less_checkerboard_at_initialisation() -> None:
    # Measured on seeds 0-15 (tiny generator, 32²): transposed 0.049-0.333, resize 0.00033-0.0028,
    # per seed resize at least 27× lower. Resize is not exactly 0: ReLUs after the convs and the
    # reflection-padded borders are not shift-invariant.
    for seed in range(4):
        fractions = {}
        for up in ("transposed", "resize"):
            torch.manual_seed(seed)
            g = Generator(**TINY, upsampling=up).eval()
            with torch.no_grad():
                fractions[up] = periodic_2x2_fraction(g(smooth_photo(32, 100 + seed)))
        assert fractions["transposed"] > 0.025, fractions
        assert fractions["resize"] < 0.01, fractions
        assert fractions["transposed"] > 10 * fractions["resize"], fractions


def test_periodic_fraction_measures_a_checkerboard() -> None:
    rows, cols = torch.meshgrid(torch.arange(8), torch.arange(8), indexing="ij")
    checker = ((rows + cols) % 2).float().expand(1, 2, 8, 8)
    assert periodic_2x2_fraction(checker) == pytest.approx(1.0)
    assert periodic_2x2_fraction(smooth_photo(32, 0)) < 1e-6


def test_invalid_upsampling_is_a_one_line_user_error() -> None:
    with pytest.raises(
        UserError, match=r"^model\.generator\.upsampling='bilinear': must be 'transposed' or 'resize'$"
    ):
        Generator(**TINY, upsampling="bilinear")  # type: ignore[arg-type]


@pytest.mark.integration
def test_resize_config_round_trips(tmp_path: Path) -> None:
    cfg = compose_train(["model=default_resize"], tmp_path)
    assert cfg.model.generator.upsampling == "resize"
    assert "upsampling" not in compose_train(["model=paper"], tmp_path).model.generator
    # A checkpoint's generator is rebuilt from the run's model.generator node.
    from_run = network_from_config(cfg.model.generator, "config.yaml")
    assert isinstance(from_run, Generator) and from_run.upsampling == "resize"
    # export-weights stores that node (less _target_) as the weights file's config.
    g = Generator(**TINY, upsampling="resize").eval()
    assert g.config() == {"in_channels": 3, **TINY, "upsampling": "resize"}
    path = save_weights(tmp_path / "resize.safetensors", g, target=TARGET, config=g.config(), model_id="r")
    loaded, meta = load_weights(path)
    assert isinstance(loaded, Generator) and loaded.upsampling == "resize"
    assert meta["config"]["upsampling"] == "resize"
    photo = smooth_photo(32, 1)
    with torch.no_grad():
        assert torch.equal(loaded(photo), g(photo))
