"""Baseline generator: the rendering-aware U-Net with a global-feature track of Deschaintre et al.

V. Deschaintre, M. Aittala, F. Durand, G. Drettakis, A. Bousseau: "Single-Image SVBRDF Capture with a
Rendering-Aware Deep Network", ACM Transactions on Graphics 37(4), SIGGRAPH 2018.

Architecture (their §4 and released code), for ``levels`` L (8 for 256² input):

- **Encoder** (U-Net): L convolutions 4×4 stride 2 (each halves the size), leaky ReLU 0.2 before
  every one but the first, channels ``width · min(2^(k-1), 8)`` at level k (64, 128, 256, 512, 512…).
  Instance normalisation (affine) after levels 2 … L-1; none after the first (pix2pix) and none at
  the bottleneck, which is 1×1 at 256² / L = 8.
- **Decoder**: L levels of leaky ReLU → nearest ×2 upsampling → two 4×4 convolutions (TF "SAME"
  padding, 1 before and 2 after) → instance norm (not on the output level); every level but the
  innermost reads its input concatenated with the encoder skip of the same size.
- **Global track**: a fully-connected track running alongside. Its state starts as
  ``SELU(FC(mean of the photo))``. At every normalised level (and the bottleneck) it adds
  ``FC_nobias(state)`` to the features as a per-channel bias, then moves on:
  ``state ← SELU(FC([state, per-channel means of that level's conv output]))`` — the means that the
  instance norm removes, so the global information the norm discards is carried by the track.
  The output level only receives the bias.

Differences from the original, all deliberate:

- The output is 8 raw channels in our layout through :func:`brdfgan.models.heads.maps_from_raw`
  (their net: ``tanh`` on 9 channels normal xy, diffuse, roughness, specular), so the baseline
  trains and evaluates through the same path as our model.
- No dropout (their code inherits 0.5 dropout in the three innermost decoder levels from pix2pix;
  the paper describes a dropout-free network).
- Each global state has the size of the level whose means it read (the released code sizes some by
  the next level); the feature bias FC maps it to any size, and the parameter difference is < 0.5 %.
- The bottleneck's means are taken before its global bias is added (theirs after; that bias is a
  function of the state the FC reads anyway).

Initialisation as theirs: convolutions N(0, 0.02) without bias (:func:`init_weights`), norm scales
N(1, 0.02); global FCs LeCun-normal (SELU), biases N(0, 0.002); the feature-bias FCs 100× smaller, so
the track starts as a gentle perturbation of the U-Net. ``width=64, levels=8``: 79,994,560 parameters —
encoder 19.5 M, decoder 53.0 M (two 4×4 convolutions per level), global track 7.4 M, norms 10 k.
"""

from __future__ import annotations

import math
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import NUM_CHANNELS
from brdfgan.models.heads import (
    PHOTO_CHANNELS,
    NormalHead,
    check_normal_head,
    encode_photo,
    init_weights,
    maps_from_raw,
)

LEAK = 0.2
MAX_WIDTH_FACTOR = 8  # channels stop doubling at 8 × width (512 for width 64), as in pix2pix
GLOBAL_BIAS_STD = 0.002
FEATURE_BIAS_INIT_SCALE = 0.01


class UpBlock(nn.Module):
    """Nearest ×2 upsampling then two 4×4 convolutions with TF "SAME" padding (1 before, 2 after).

    Upsample-then-convolve instead of a transposed convolution avoids checkerboard artefacts; an
    even kernel needs the asymmetric padding to keep the size.

    Shape:
        - x: ``(B, in_channels, H, W)``
        - output: ``(B, out_channels, 2H, 2W)``
    """

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Upsample(scale_factor=2, mode="nearest"),
            nn.ZeroPad2d((1, 2, 1, 2)),
            nn.Conv2d(in_channels, out_channels, 4, bias=False),
            nn.ZeroPad2d((1, 2, 1, 2)),
            nn.Conv2d(out_channels, out_channels, 4, bias=False),
        )

    def forward(self, x: Tensor) -> Tensor:
        return self.body(x)


class Deschaintre2018(nn.Module):
    """U-Net + global-feature track (Deschaintre et al. 2018), photo → our 8-channel maps.

    Args:
        in_channels: photo channels (3).
        width: channels of the first level (64 in the paper); doubled per level up to 8 × width.
        levels: encoder (and decoder) levels; H and W must be multiples of ``2**levels``
            (8 for 256² input: a 1×1 bottleneck, as in the paper).
        normal_head: how the normal's raw channels become a unit normal
            (:func:`~brdfgan.models.heads.maps_from_raw`), so a baseline can share the head of the
            model it is compared with.

    ``Deschaintre2018(**net.config())`` rebuilds the architecture.

    Shape:
        - photo: ``(B, in_channels, H, W)``, linear LDR in [0, 1], encoded to ``2x - 1`` inside
        - output: ``(B, 8, H, W)``, a valid map set (layout of :mod:`brdfgan.core.svbrdf`)
    """

    def __init__(
        self,
        in_channels: int = PHOTO_CHANNELS,
        width: int = 64,
        levels: int = 8,
        normal_head: NormalHead = "softplus_z",
    ) -> None:
        super().__init__()
        self.normal_head: NormalHead = check_normal_head(normal_head)
        if min(in_channels, width, levels) < 1:
            raise ValueError(
                "Deschaintre2018 needs in_channels, width, levels >= 1, "
                f"got {in_channels=}, {width=}, {levels=}"
            )
        self.in_channels = in_channels
        self.width = width
        self.levels = levels
        # channels[k] is the encoder output of level k (1-based); channels[0] is the raw output.
        channels = [NUM_CHANNELS] + [
            width * min(2 ** (k - 1), MAX_WIDTH_FACTOR) for k in range(1, levels + 1)
        ]

        self.encoder = nn.ModuleList(
            nn.Conv2d(
                in_channels if k == 1 else channels[k - 1], channels[k], 4, stride=2, padding=1, bias=False
            )
            for k in range(1, levels + 1)
        )
        self.decoder = nn.ModuleList(
            UpBlock(channels[k] * (1 if k == levels else 2), channels[k - 1]) for k in range(levels, 0, -1)
        )

        # The global track's sites, in forward order: encoder levels 2…L, then decoder levels L…1.
        sites = [channels[k] for k in range(2, levels + 1)] + [channels[k - 1] for k in range(levels, 0, -1)]
        normalised = [2 <= k < levels for k in range(2, levels + 1)] + [k > 1 for k in range(levels, 0, -1)]
        self.norms = nn.ModuleList(
            nn.InstanceNorm2d(c, affine=True) if norm else nn.Identity()
            for c, norm in zip(sites, normalised, strict=True)
        )
        states = [width, *sites[:-1]]  # the state each site reads
        self.global_input = nn.Linear(in_channels, width)
        self.global_to_features = nn.ModuleList(
            nn.Linear(s, c, bias=False) for s, c in zip(states, sites, strict=True)
        )
        # The output site only receives a bias: no state update after it.
        self.global_steps = nn.ModuleList(
            nn.Linear(s + c, c) for s, c in zip(states[:-1], sites[:-1], strict=True)
        )
        init_weights(self)
        self._init_global_track()

    def _init_global_track(self) -> None:
        # LeCun normal keeps SELU activations self-normalising; the released code's init.
        for fc in [self.global_input, *self.global_steps]:
            nn.init.normal_(fc.weight, 0.0, math.sqrt(1.0 / fc.in_features))
            nn.init.normal_(fc.bias, 0.0, GLOBAL_BIAS_STD)
        for fc in self.global_to_features:
            assert isinstance(fc, nn.Linear)
            nn.init.normal_(fc.weight, 0.0, FEATURE_BIAS_INIT_SCALE * math.sqrt(1.0 / fc.in_features))

    def config(self) -> dict[str, Any]:
        """Constructor arguments (plain values), to store next to the weights; ``normal_head`` only
        when it is not the default (a stored config without it means the default)."""
        config: dict[str, Any] = {"in_channels": self.in_channels, "width": self.width, "levels": self.levels}
        if self.normal_head != "softplus_z":
            config["normal_head"] = self.normal_head
        return config

    @property
    def size_multiple(self) -> int:
        """H and W must be multiples of this (the bottleneck is then at least 1×1)."""
        return 2**self.levels

    def check_input(self, photo: Tensor) -> None:
        """Raise ``ValueError`` unless ``photo`` is ``(B, in_channels, H, W)`` of a supported size."""
        check_shape(photo, f"B {self.in_channels} H W", name="Deschaintre2018 photo")
        height, width = photo.shape[-2:]
        multiple = self.size_multiple
        if height % multiple or width % multiple or min(height, width) == 0:
            raise ValueError(
                f"Deschaintre2018 input height and width must be positive multiples of {multiple} "
                f"(2**levels, levels={self.levels}); got {height}×{width}. Pad or crop the photo, "
                f"or use fewer levels."
            )

    def _site(self, index: int, features: Tensor, state: Tensor) -> tuple[Tensor, Tensor]:
        """Normalise, add the global bias, and advance the global state with the feature means."""
        means = features.mean(dim=(-2, -1))
        out = self.norms[index](features) + self.global_to_features[index](state)[:, :, None, None]
        if index < len(self.global_steps):
            state = F.selu(self.global_steps[index](torch.cat([state, means], dim=1)))
        return out, state

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        # ``flash`` (the photo's flash frame) is accepted like the generator's and not read: the
        # baseline is Deschaintre et al.'s network as published.
        self.check_input(photo)
        x = encode_photo(photo)
        state = F.selu(self.global_input(x.mean(dim=(-2, -1))))
        skips = [self.encoder[0](x)]
        site = 0
        for conv in self.encoder[1:]:
            features, state = self._site(site, conv(F.leaky_relu(skips[-1], LEAK)), state)
            skips.append(features)
            site += 1
        out = skips[-1]
        for index, up in enumerate(self.decoder):
            if index > 0:  # every level but the innermost also reads the skip of its size
                out = torch.cat([out, skips[-1 - index]], dim=1)
            out, state = self._site(site, up(F.leaky_relu(out, LEAK)), state)
            site += 1
        return maps_from_raw(out, self.normal_head)
