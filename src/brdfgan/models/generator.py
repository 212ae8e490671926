"""The generator of the conditional GAN (paper §4.3): photo → SVBRDF maps.

Johnson et al. (2016) layout with pre-activation residual blocks (He et al. 2016), in the paper's
notation ``c7s1-64, d128, d256, d512, 9×R512, u256, u128, u64, c7s1-8``:

- ``c7s1-k``: 7×7 conv, stride 1, reflection padding; + InstanceNorm + ReLU, except the last one
  (the output layer, whose 8 channels go through :func:`brdfgan.models.heads.maps_from_raw`).
- ``dk``: 3×3 conv, stride 2, zero padding 1, InstanceNorm, ReLU.
- ``Rk``: IN-ReLU-conv3×3-IN-ReLU-conv3×3 + identity, reflection padding.
- ``uk``: 3×3 transposed conv, stride 2, padding 1, output_padding 1 (exactly ×2), InstanceNorm, ReLU.

``upsampling="resize"`` (not the paper's; ``model=default_resize``) replaces each ``uk`` by
resize-convolution (Odena et al. 2016, "Deconvolution and Checkerboard Artifacts"): nearest ×2
upsampling, then a 3×3 conv with reflection padding to the same ``k`` channels, InstanceNorm, ReLU.
A stride-2 3×3 transposed conv gives even output pixels one kernel tap per axis and odd ones two,
so even a flat input comes out with a 2×2 pattern; nearest ×2 has a zero at the output's Nyquist
frequency and the conv after it is shift-invariant, so no such pattern is built in. The weight
shapes are the transposed ones swapped, so both variants have the same number of parameters.

Choices the paper leaves open (all parameter-free or removing dead parameters):

- After the last residual block an extra InstanceNorm + ReLU closes the pre-activation trunk, as
  He et al. (2016) do after their last unit; without it the un-normalised residual stream would go
  straight into the first transposed conv.
- Convolutions whose output goes (only) into an InstanceNorm without affine have no bias: the
  norm subtracts the per-channel mean, so such a bias gets exactly zero gradient and never trains.
  That includes both convs of every residual block, because every reader of the residual stream
  starts with an InstanceNorm. InstanceNorm is ``affine=False`` (pix2pixHD's default).
  The paper preset has 45,598,408 parameters (45.6 M as published; 45,609,032 with all biases).

The generator takes a flash frame like every generator (``forward(photo, flash)``) and ignores
it: flash-offset input channels were tried and not adopted (research/notes/2026-12-default-model-v3.md); the
anchored generator reads them.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, get_args

from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import NUM_CHANNELS
from brdfgan.models.heads import (
    PHOTO_CHANNELS,
    NormalHead,
    check_choice,
    check_normal_head,
    encode_photo,
    init_weights,
    maps_from_raw,
)

Upsampling = Literal["transposed", "resize"]
UPSAMPLINGS: tuple[str, ...] = get_args(Upsampling)


def _norm_relu(channels: int) -> list[nn.Module]:
    return [nn.InstanceNorm2d(channels, affine=False), nn.ReLU(inplace=True)]


def _upsampling_layer(upsampling: Upsampling, channels: int) -> list[nn.Module]:
    """One ``u`` layer without its norm and activation: ``channels`` → ``channels // 2``, ×2 in H, W."""
    if upsampling == "transposed":
        return [
            nn.ConvTranspose2d(channels, channels // 2, 3, stride=2, padding=1, output_padding=1, bias=False)
        ]
    # Nearest rather than bilinear: it is the variant Odena et al. report working best (they had
    # trouble making bilinear work). Against checkerboard neither has an edge: each is zero-stuffing
    # followed by a kernel with a zero at the output's Nyquist frequency ([1, 1] and
    # [1/4, 3/4, 3/4, 1/4]); bilinear's extra low-pass only blurs detail before the conv that
    # could learn any smoothing it needs. Reflection padding like every other stride-1 conv here.
    return [
        nn.Upsample(scale_factor=2, mode="nearest"),
        nn.Conv2d(channels, channels // 2, 3, padding=1, padding_mode="reflect", bias=False),
    ]


class ResidualBlock(nn.Module):
    """Pre-activation residual block ``Rk`` (He et al. 2016) with reflection padding.

    Shape:
        - x: ``(B, C, H, W)``, H and W >= 2 (reflection padding)
        - output: ``(B, C, H, W)``
    """

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.body = nn.Sequential(
            *_norm_relu(channels),
            nn.Conv2d(channels, channels, 3, padding=1, padding_mode="reflect", bias=False),
            *_norm_relu(channels),
            nn.Conv2d(channels, channels, 3, padding=1, padding_mode="reflect", bias=False),
        )

    def forward(self, x: Tensor) -> Tensor:
        return x + self.body(x)


class Generator(nn.Module):
    """Fully convolutional photo → maps network; the defaults are the paper's (45.6 M parameters).

    Args:
        in_channels: photo channels (3).
        width: channels of the first layer; doubled by every downsampling (64 → 128 → 256 → 512).
        downsamplings: number of ``d`` (and ``u``) layers; H and W must be multiples of
            ``2**downsamplings`` and at least twice that.
        residual_blocks: number of ``R`` blocks at the bottleneck.
        upsampling: the ``u`` layers: ``"transposed"`` (the paper's 3×3 stride-2 transposed convs)
            or ``"resize"`` (nearest ×2 then a 3×3 conv, against checkerboard artefacts); same
            parameter count, different state-dict keys.
        normal_head: ``"softplus_z"`` (default, the shipped models) or ``"unit_z"`` (see
            :func:`~brdfgan.models.heads.maps_from_raw`); same parameters.

    All arguments are plain ints or strings: ``Generator(**generator.config())`` rebuilds the
    architecture.

    Shape:
        - photo: ``(B, in_channels, H, W)``, linear LDR in [0, 1], encoded to ``2x - 1`` inside
        - flash: ``(B, 3)``, the photos' flash frames (optional; ignored)
        - output: ``(B, 8, H, W)``, a valid map set (sRGB basecolor, unit normals with z > 0,
          roughness and metallic in [0, 1])
    """

    # Options since removed, with the one value the network is now built with (a stored config
    # may still name it: brdfgan.runs.build_network).
    RETIRED_OPTIONS: ClassVar[dict[str, Any]] = {"flash_geometry": False}

    def __init__(
        self,
        in_channels: int = PHOTO_CHANNELS,
        width: int = 64,
        downsamplings: int = 3,
        residual_blocks: int = 9,
        upsampling: Upsampling = "transposed",
        normal_head: NormalHead = "softplus_z",
    ) -> None:
        super().__init__()
        check_choice("model.generator.upsampling", upsampling, UPSAMPLINGS)
        if min(in_channels, width) < 1 or min(downsamplings, residual_blocks) < 0:
            raise ValueError(
                f"Generator needs in_channels, width >= 1 and downsamplings, residual_blocks >= 0, got "
                f"{in_channels=}, {width=}, {downsamplings=}, {residual_blocks=}"
            )
        self.in_channels = in_channels
        self.width = width
        self.downsamplings = downsamplings
        self.residual_blocks = residual_blocks
        self.upsampling: Upsampling = upsampling
        self.normal_head: NormalHead = check_normal_head(normal_head)

        # c7s1-width: the first conv's bias is cancelled by the InstanceNorm after it.
        down: list[nn.Module] = [
            nn.Conv2d(in_channels, width, 7, padding=3, padding_mode="reflect", bias=False),
            *_norm_relu(width),
        ]
        channels = width
        for _ in range(downsamplings):
            down += [nn.Conv2d(channels, 2 * channels, 3, stride=2, padding=1, bias=False)]
            down += _norm_relu(2 * channels)
            channels *= 2
        self.down = nn.Sequential(*down)

        residual: list[nn.Module] = [ResidualBlock(channels) for _ in range(residual_blocks)]
        if residual_blocks > 0:
            residual += _norm_relu(channels)
        self.residual = nn.Sequential(*residual)

        up: list[nn.Module] = []
        for _ in range(downsamplings):
            up += _upsampling_layer(upsampling, channels)
            up += _norm_relu(channels // 2)
            channels //= 2
        self.up = nn.Sequential(*up)

        # c7s1-8, the output layer: raw channels for maps_from_raw, so no norm and no activation.
        self.out = nn.Conv2d(channels, NUM_CHANNELS, 7, padding=3, padding_mode="reflect")
        init_weights(self)

    def config(self) -> dict[str, Any]:
        """Constructor arguments (plain values), to store next to the weights.

        ``upsampling`` and ``normal_head`` only when they are not the
        defaults, so that the config of a paper generator is what it was before the options
        existed (and a stored config without a key means its default).
        """
        config: dict[str, Any] = {
            "in_channels": self.in_channels,
            "width": self.width,
            "downsamplings": self.downsamplings,
            "residual_blocks": self.residual_blocks,
        }
        if self.upsampling != "transposed":
            config["upsampling"] = self.upsampling
        if self.normal_head != "softplus_z":
            config["normal_head"] = self.normal_head
        return config

    @property
    def size_multiple(self) -> int:
        """H and W must be multiples of this (and at least twice it)."""
        return 2**self.downsamplings

    def check_input(self, photo: Tensor) -> None:
        """Raise ``ValueError`` unless ``photo`` is ``(B, in_channels, H, W)`` of a supported size."""
        check_shape(photo, f"B {self.in_channels} H W", name="Generator photo")
        height, width = photo.shape[-2:]
        multiple = self.size_multiple
        # At the bottleneck reflection padding and InstanceNorm need at least 2×2 pixels.
        if height % multiple or width % multiple or min(height, width) < 2 * multiple:
            padded_h = max(-(-height // multiple) * multiple, 2 * multiple)
            padded_w = max(-(-width // multiple) * multiple, 2 * multiple)
            raise ValueError(
                f"Generator input height and width must be multiples of {multiple} "
                f"(2**downsamplings, downsamplings={self.downsamplings}) and at least {2 * multiple}; "
                f"got {height}×{width}. Pad the photo to {padded_h}×{padded_w} and crop the maps."
            )

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        self.check_input(photo)
        x = encode_photo(photo)
        features = self.residual(self.down(x))
        return maps_from_raw(self.out(self.up(features)), self.normal_head)
