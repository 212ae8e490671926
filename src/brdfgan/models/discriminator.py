"""The conditional PatchGAN discriminators of the GAN (paper §4.3), pix2pixHD-style multi-scale.

One :class:`PatchDiscriminator` is ``cn-64, c128, c256, c512, cns1-1``:

- ``cn-k``: 4×4 conv, stride 2, padding 1, LeakyReLU(0.2), no norm.
- ``ck``: 4×4 conv, stride 2, padding 1, InstanceNorm, LeakyReLU(0.2).
- ``cns1-1``: 4×4 conv, stride 1, zero padding (left 1, right 2, top 1, bottom 2) so the size is kept,
  no activation (LSGAN scores).

With padding 1 every stride-2 layer halves the size exactly, so a 512² input gives 32×32 scores
(paper: D1 32×32, D2 16×16 on the half-resolution input). The even 4×4 kernel of the last layer
needs asymmetric padding to keep the size; it shifts the score grid by half a pixel, which is harmless.
Convs followed by InstanceNorm (``affine=False``) have no bias, which the norm would cancel.

The discriminators are conditional: they see the photo concatenated with the maps,
both in centred ranges (:func:`discriminator_input`).
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import NUM_CHANNELS, check_map_shape
from brdfgan.models.heads import PHOTO_CHANNELS, encode_photo, init_weights

DISCRIMINATOR_CHANNELS = PHOTO_CHANNELS + NUM_CHANNELS
# Per-channel affine map putting the 8 map channels in [-1, 1]: basecolor, roughness and metallic
# x ↦ 2x - 1; the normal components already lie in [-1, 1] and stay as they are.
_MAP_SCALE = (2.0, 2.0, 2.0, 1.0, 1.0, 1.0, 2.0, 2.0)
_MAP_SHIFT = (-1.0, -1.0, -1.0, 0.0, 0.0, 0.0, -1.0, -1.0)


def discriminator_input(photo: Tensor, maps: Tensor) -> Tensor:
    """The conditional discriminator input: centred photo and centred maps, concatenated.

    Photo ``2x - 1``; basecolor, roughness, metallic ``2x - 1``; normal unchanged (already in [-1, 1]).

    Shape:
        - photo: ``(B, 3, H, W)``, linear LDR in [0, 1]
        - maps: ``(B, 8, H, W)``
        - output: ``(B, 11, H, W)``, channels photo 0:3, maps 3:11
    """
    check_map_shape(maps)
    check_shape(photo, f"B {PHOTO_CHANNELS} H W", name="discriminator_input photo")
    check_shape(maps, f"B {NUM_CHANNELS} H W", name="discriminator_input maps")
    if photo.shape[0] != maps.shape[0] or photo.shape[-2:] != maps.shape[-2:]:
        raise ValueError(
            f"photo and maps must share batch and size, got {tuple(photo.shape)} and {tuple(maps.shape)}"
        )
    scale = maps.new_tensor(_MAP_SCALE).view(1, NUM_CHANNELS, 1, 1)
    shift = maps.new_tensor(_MAP_SHIFT).view(1, NUM_CHANNELS, 1, 1)
    return torch.cat([encode_photo(photo), maps * scale + shift], dim=1)


def downsample(x: Tensor) -> Tensor:
    """Halve the resolution for the next scale: 3×3 average, stride 2, padding 1, border-aware (pix2pixHD).

    Shape:
        - x: ``(B, C, H, W)``
        - output: ``(B, C, ceil(H / 2), ceil(W / 2))``
    """
    return F.avg_pool2d(x, kernel_size=3, stride=2, padding=1, count_include_pad=False)


class PatchDiscriminator(nn.Module):
    """PatchGAN ``cn-64, c128, c256, c512, cns1-1``: every layer's output, patch scores last.

    Args:
        in_channels: 11 (photo 3 + maps 8).
        width: channels of the first layer, doubled per stride-2 layer, capped at ``8 * width``.
        layers: number of stride-2 layers (4: 512² → 32×32 scores).

    Shape:
        - x: ``(B, in_channels, H, W)`` with H, W >= ``2**(layers + 1)``
        - output: ``layers + 1`` tensors; layer i (0-based, i < layers) is
          ``(B, min(width · 2^i, 8 · width), H / 2^(i+1), W / 2^(i+1))`` (floor), the last is
          ``(B, 1, H / 2^layers, W / 2^layers)`` raw LSGAN scores.
    """

    def __init__(self, in_channels: int = DISCRIMINATOR_CHANNELS, width: int = 64, layers: int = 4) -> None:
        super().__init__()
        if min(in_channels, width, layers) < 1:
            raise ValueError(
                f"PatchDiscriminator needs positive sizes, got {in_channels=}, {width=}, {layers=}"
            )
        self.in_channels = in_channels
        self.width = width
        self.layers = layers

        blocks: list[nn.Module] = [
            nn.Sequential(nn.Conv2d(in_channels, width, 4, stride=2, padding=1), nn.LeakyReLU(0.2))
        ]
        channels = width
        for _ in range(layers - 1):
            out_channels = min(2 * channels, 8 * width)
            blocks.append(
                nn.Sequential(
                    nn.Conv2d(channels, out_channels, 4, stride=2, padding=1, bias=False),
                    nn.InstanceNorm2d(out_channels, affine=False),
                    nn.LeakyReLU(0.2),
                )
            )
            channels = out_channels
        blocks.append(nn.Sequential(nn.ZeroPad2d((1, 2, 1, 2)), nn.Conv2d(channels, 1, 4)))
        self.blocks = nn.ModuleList(blocks)
        init_weights(self)

    def config(self) -> dict[str, Any]:
        """Constructor arguments (plain ints), to store next to the weights."""
        return {"in_channels": self.in_channels, "width": self.width, "layers": self.layers}

    @property
    def min_size(self) -> int:
        """Smallest input side: the last InstanceNorm needs at least 2×2 pixels."""
        return 2 ** (self.layers + 1)

    def forward(self, x: Tensor) -> list[Tensor]:
        check_shape(x, f"B {self.in_channels} H W", name="PatchDiscriminator input")
        if min(x.shape[-2:]) < self.min_size:
            raise ValueError(
                f"PatchDiscriminator expects (B, {self.in_channels}, H, W) with H, W >= {self.min_size}, "
                f"got {tuple(x.shape)}"
            )
        outputs = []
        for block in self.blocks:
            x = block(x)
            outputs.append(x)
        return outputs


class MultiScaleDiscriminator(nn.Module):
    """``scales`` PatchDiscriminators of the same architecture; scale k sees the input downsampled 2^k×.

    Paper: D1 at full resolution, D2 at half. The input is built by :func:`discriminator_input`.

    Shape:
        - photo: ``(B, 3, H, W)`` in [0, 1]; maps: ``(B, 8, H, W)``; H, W >= ``2**(layers + scales)``
        - output: per scale (full resolution first), the :class:`PatchDiscriminator` output list
    """

    def __init__(
        self, in_channels: int = DISCRIMINATOR_CHANNELS, width: int = 64, layers: int = 4, scales: int = 2
    ) -> None:
        super().__init__()
        if scales < 1:
            raise ValueError(f"MultiScaleDiscriminator needs scales >= 1, got {scales}")
        self.scales = scales
        self.discriminators = nn.ModuleList(
            PatchDiscriminator(in_channels, width, layers) for _ in range(scales)
        )

    def config(self) -> dict[str, Any]:
        """Constructor arguments (plain ints), to store next to the weights."""
        first = self.discriminators[0]
        assert isinstance(first, PatchDiscriminator)
        return {**first.config(), "scales": self.scales}

    def forward(self, photo: Tensor, maps: Tensor) -> list[list[Tensor]]:
        x = discriminator_input(photo, maps)
        outputs = []
        for scale, discriminator in enumerate(self.discriminators):
            if scale > 0:
                x = downsample(x)
            outputs.append(discriminator(x))
        return outputs
