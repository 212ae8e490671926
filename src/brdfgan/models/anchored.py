"""The photo-anchored two-decoder U-Net: the CPU default's generator (``brdfgan-default-v4``;
the paper's :class:`~brdfgan.models.generator.Generator` stays for GPUs). ``AnchoredUNet()``
with no arguments is the shipped architecture. Design, measurements and ablations:
``docs/default_model.md`` ("Design").

- **Anchored on the de-lit photo.** The base colour is a correction of
  :func:`~brdfgan.core.delit.delit_photo` times a learnt exposure gain, binomially blurred
  (:func:`compose_basecolor`): per pixel and channel a log-gain and a bounded residual, blended
  toward a free metal colour by the metallic map. The output layers start at zero, so an untrained
  network returns the blurred, gained de-lit photo: the photo's hue and detail.
- **A U-Net with resize-convolution upsampling** (no transposed convolutions: no checkerboard),
  and **two decoders**, (base colour, metallic) and (normal, roughness).
- **The shading image** (``shading``): the surface decoder may read ``log(photo) − log(flat
  render)`` of the material decoder's maps (:func:`~brdfgan.core.delit.flat_flash_render`).
- **A global track** (``global_features``, ``highlight_profile``): per-image moments of every
  encoder level and the flash highlight's profile, through a small MLP added to every head but the
  normal's (:mod:`brdfgan.models.image_statistics`, frozen in tiles like the norms' statistics).

Inputs per pixel: ``log`` of the photo and of the anchor, and the four flash side channels
(:func:`~brdfgan.core.flash_geometry.flash_side_channels`). Normalisation is affine-free
``InstanceNorm2d``, so whole-photo inference tiles with frozen statistics
(:mod:`brdfgan.inference.model.tiling`). The normal head is ``normalize(s_x, s_y, 1)`` of two
slopes, or of a height's differences (``normal_head``).

Ablation-only switches (no shipped recipe sets them; each one's run is in
``research/notes/2026-12-default-model-v4.md``): ``anchored=False``, ``shading`` other than
``"detached"``, ``global_features=False``, ``highlight_profile=False``. ``normal_head="height"``
is ``experiment=anchored_rendered``'s (the v5 candidate).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar, Literal, cast

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.delit import clip_hotspot, delit_photo, flat_flash_render
from brdfgan.core.filtering import binomial_blur
from brdfgan.core.flash_geometry import (
    DEFAULT_FOV_DEG,
    FLASH_CHANNELS,
    centred_flash_frame,
    check_flash_frame,
    flash_side_channels,
)
from brdfgan.core.height import height_slope_channels
from brdfgan.core.svbrdf import join_maps, linear_to_srgb, normalize_normal
from brdfgan.models.image_statistics import PROFILE_RINGS, HighlightProfile, HotspotCap, ImageMoments

Shading = Literal["detached", "gradient", "none"]
SHADINGS: tuple[str, ...] = ("detached", "gradient", "none")
NormalHead = Literal["slopes", "height"]
NORMAL_HEADS: tuple[str, ...] = ("slopes", "height")
# The de-lit photo's exposure gain fitted on the procedural_and_scans train split (the de_lit
# reference, src/brdfgan/weights/references/de_lit.safetensors): the anchor's starting level.
DEFAULT_ANCHOR_GAIN = 2.13
LOG_EPS = 1e-3  # log(x + eps) of linear values: 1e-3 is below an 8-bit sRGB code's step near black
RESIDUAL_SCALE = 0.25  # the base colour's additive correction is bounded by ±this (linear)
LOG_GAIN_LIMIT = 4.0  # the per-pixel log-gain is clamped to ±this (×0.018 … ×55)
# An untrained network's metallic: sigmoid(−5) ≈ 0.007, so its base colour is the de-lit photo's
# within 0.7 % of the way to the metal colour's start (0.5). Metallic is learnt through a
# cross-entropy on its logit, which does not saturate there.
METALLIC_BIAS = -5.0
# log-gain 3, residual 3, metallic logit 1, provisional roughness logit 1, metal colour logits 3
MATERIAL_OUTPUTS = 11
INPUT_CHANNELS = 3 + 3 + FLASH_CHANNELS
GLOBAL_HIDDEN = 64  # the global track's hidden width
# The global track feeds every material output and the roughness logit, not the normal slopes: a
# surface's mean tilt is not an image-wide level (docs/default_model.md, "Design").
GLOBAL_OUTPUTS = MATERIAL_OUTPUTS + 1
# The base colour's corrections as applied (compose_basecolor): log-gain 3, residual 3 (after its
# tanh bound), metal colour 3 (after its sigmoid), metallic 1.
CORRECTION_CHANNELS = 10


def compose_basecolor(anchor: Tensor, corrections: Tensor) -> Tensor:
    """The anchored base colour: ``b = lerp(clamp(a · exp(γ) + r, 0, 1), c, m)`` from the anchor
    ``a`` and the corrections (:data:`CORRECTION_CHANNELS`): log-gain ``γ``, residual ``r``, metal
    colour ``c`` and metallic ``m``, each clamped to its range (``±LOG_GAIN_LIMIT``,
    ``±RESIDUAL_SCALE``, [0, 1]) — the network's own are within it, corrections carried to another
    resolution may overshoot. A metal's base colour is its specular colour, which the de-lit photo
    does not hold (dark away from the highlight): a free colour, blended in by the metallic map.

    Shape:
        - anchor: ``(B, 3, H, W)`` linear
        - corrections: ``(B, 10, H, W)``
        - output: ``(B, 3, H, W)`` linear in [0, 1]

    Example:
        No log-gain, residual or metal: the anchor itself (clamped to [0, 1]); all metal: the
        metal colour:

        >>> anchor = torch.tensor([0.2, 0.5, 1.5]).view(1, 3, 1, 1)
        >>> dielectric = torch.zeros(1, CORRECTION_CHANNELS, 1, 1)
        >>> [round(v, 4) for v in compose_basecolor(anchor, dielectric).flatten().tolist()]
        [0.2, 0.5, 1.0]
        >>> metal = dielectric.clone()
        >>> metal[:, 6:9], metal[:, 9] = 0.9, 1.0
        >>> [round(v, 4) for v in compose_basecolor(anchor, metal).flatten().tolist()]
        [0.9, 0.9, 0.9]
    """
    check_shape(corrections, f"B {CORRECTION_CHANNELS} H W", name="corrections")
    check_shape(anchor, "B 3 H W", name="anchor")
    if anchor.shape[0] != corrections.shape[0] or anchor.shape[-2:] != corrections.shape[-2:]:
        raise ValueError(
            f"anchor {tuple(anchor.shape)} and corrections {tuple(corrections.shape)} differ in batch or size"
        )
    log_gain, residual, metal_colour, metallic = corrections.split([3, 3, 3, 1], dim=1)
    log_gain = log_gain.clamp(-LOG_GAIN_LIMIT, LOG_GAIN_LIMIT)
    residual = residual.clamp(-RESIDUAL_SCALE, RESIDUAL_SCALE)
    dielectric = (anchor * log_gain.exp() + residual).clamp(0.0, 1.0)
    return torch.lerp(dielectric, metal_colour.clamp(0.0, 1.0), metallic.clamp(0.0, 1.0))


def _conv_block(in_channels: int, out_channels: int) -> nn.Sequential:
    """Two 3×3 convolutions (reflection padding), each followed by InstanceNorm and LeakyReLU(0.2).
    No conv bias: the InstanceNorm after it would cancel it."""
    layers: list[nn.Module] = []
    for channels_in in (in_channels, out_channels):
        layers += [
            nn.Conv2d(channels_in, out_channels, 3, padding=1, padding_mode="reflect", bias=False),
            nn.InstanceNorm2d(out_channels, affine=False),
            nn.LeakyReLU(0.2, inplace=True),
        ]
    return nn.Sequential(*layers)


class _Decoder(nn.Module):
    """Resize-convolution decoder over the encoder's features ``skips[0]`` (full size) …
    ``skips[-1]`` (the bottleneck); ``extra`` channels (e.g. the shading image, pooled) join the
    skip at every level. A zero-initialised 1×1 head gives ``out_channels``."""

    def __init__(self, widths: list[int], extra: int, out_channels: int) -> None:
        super().__init__()
        self.blocks = nn.ModuleList(
            _conv_block(widths[level + 1] + widths[level] + extra, widths[level])
            for level in range(len(widths) - 1)
        )
        self.head = nn.Conv2d(widths[0], out_channels, 1)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head_bias)

    @property
    def head_bias(self) -> Tensor:
        """The output layer's bias (its start values: a network's outputs before any training)."""
        assert self.head.bias is not None  # built with bias=True
        return self.head.bias

    def forward(self, skips: list[Tensor], extras: list[Tensor] | None = None) -> Tensor:
        x = skips[-1]
        for level in reversed(range(len(self.blocks))):
            x = F.interpolate(x, size=skips[level].shape[-2:], mode="bilinear", align_corners=False)
            parts = [x, skips[level]] + ([extras[level]] if extras is not None else [])
            x = self.blocks[level](torch.cat(parts, dim=1))
        return self.head(x)


# The constructor's defaults before they became the shipped model's (issue 48).
_DEFAULTS_BEFORE_SHIPPED: dict[str, Any] = {
    "head_gain": 1.0,
    "anchor_blur": False,
    "correction_blur": False,
    "global_features": False,
    "highlight_profile": False,
}


class AnchoredUNet(nn.Module):
    """The photo-anchored two-decoder U-Net (module docstring).

    Args:
        width: channels at full resolution; each level doubles them, up to 8 × width.
        depth: downsamplings (2×2 average pooling); H and W must be multiples of ``2**depth``.
        shading: how the surface decoder reads the shading image: ``"detached"``, ``"gradient"``
            or ``"none"``.
        anchored: predict the base colour as a correction of the de-lit photo (``False``: the
            de-lit photo is an input only, the base colour a sigmoid).
        anchor_gain: the de-lit photo's starting exposure gain (a learnt scalar from there).
        head_gain: both decoders' outputs are this times their zero-initialised 1×1 heads (the
            start is unchanged): Adam moves every weight by about its learning rate per step, so
            outputs that start at zero and must travel far would crawl.
        global_features: a global track: the per-image mean and log standard deviation of every
            encoder level's first convolution (before its InstanceNorm removes them;
            :class:`~brdfgan.models.image_statistics.ImageMoments`, frozen in tiles like the norms)
            go through a small MLP whose zero-initialised output is added to the heads' outputs
            (all but the normal slopes: :data:`GLOBAL_OUTPUTS`): a per-image level for roughness,
            metal share, exposure and colour, which a network of
            affine-free instance norms cannot otherwise see but through spatial patterns
            (Deschaintre et al. 2018's reason for their track).
        highlight_profile: the global track also reads the flash highlight's profile around the
            hotspot (:class:`~brdfgan.models.image_statistics.HighlightProfile`: the de-lit
            photo's relative log luminance and clipped share per ring of angle from the hotspot),
            the width and height of the specular lobe from which roughness and specular level are
            read; needs ``global_features``.
        normal_head: ``"slopes"``: the surface decoder's first two outputs are the normal's
            slopes; ``"height"``: its first output is a height field (pixel units) whose central
            differences are the slopes (:func:`~brdfgan.core.height.height_slope_channels`), so
            the normals are integrable and a groove's two walls come from one dark line.

    Shape:
        - photo: ``(B, 3, H, W)`` linear LDR in [0, 1]
        - flash: ``(B, 3)`` flash frames (optional: the photo centred on its hotspot, 57.5°)
        - output: ``(B, 8, H, W)`` maps
    """

    # Options since removed, with the one value the network is now built with: a stored config
    # that names one (the shipped weights' does) loads when it asks for that value
    # (brdfgan.runs.build_network).
    RETIRED_OPTIONS: ClassVar[dict[str, Any]] = {"anchor_blur": True, "correction_blur": True}

    @classmethod
    def upgrade_stored_config(cls, config: Mapping[str, Any]) -> dict[str, Any]:
        """A stored config as today's constructor reads it. Configs written before the defaults
        became the shipped model's (they have no ``normal_head``) left out what they did not set,
        and a missing key then meant the old default: those are filled in, so an old network is
        built as it was, or refused by name when it needs a retired option
        (brdfgan.runs.build_network)."""
        if "normal_head" in config:
            return dict(config)
        return {**_DEFAULTS_BEFORE_SHIPPED, **config}

    def __init__(
        self,
        width: int = 16,
        depth: int = 4,
        shading: Shading = "detached",
        anchored: bool = True,
        anchor_gain: float = DEFAULT_ANCHOR_GAIN,
        head_gain: float = 10.0,
        global_features: bool = True,
        highlight_profile: bool = True,
        normal_head: NormalHead = "slopes",
    ) -> None:
        super().__init__()
        if width < 1 or depth < 1:
            raise ValueError(f"width and depth must be positive, got {width=}, {depth=}")
        if shading not in SHADINGS:
            raise ValueError(f"shading={shading!r}: must be one of {', '.join(SHADINGS)}")
        if not anchor_gain > 0:
            raise ValueError(f"anchor_gain must be positive, got {anchor_gain}")
        if not head_gain > 0:
            raise ValueError(f"head_gain must be positive, got {head_gain}")
        if normal_head not in NORMAL_HEADS:
            raise ValueError(f"normal_head={normal_head!r}: must be one of {', '.join(NORMAL_HEADS)}")
        if highlight_profile and not global_features:
            raise ValueError("highlight_profile feeds the global track: it needs global_features=True")
        self.width, self.depth = int(width), int(depth)
        self.shading: Shading = shading
        self.anchored = bool(anchored)
        self.anchor_gain = float(anchor_gain)
        self.head_gain = float(head_gain)
        self.global_features = bool(global_features)
        self.highlight_profile = bool(highlight_profile)
        self.normal_head: NormalHead = normal_head
        self.relief_channels = 2 if normal_head == "slopes" else 1
        widths = [width * 2 ** min(level, 3) for level in range(depth + 1)]
        self.encoder = nn.ModuleList(
            _conv_block(INPUT_CHANNELS if level == 0 else widths[level - 1], widths[level])
            for level in range(depth + 1)
        )
        self.material = _Decoder(widths, 0, MATERIAL_OUTPUTS)
        self.surface = _Decoder(widths, 3 if shading != "none" else 0, self.relief_channels + 1)
        with torch.no_grad():
            self.material.head_bias[6] = METALLIC_BIAS / self.head_gain
        self.log_anchor_gain = nn.Parameter(torch.tensor(math.log(anchor_gain)))
        self.hotspot_cap = HotspotCap()  # a module, so that tiles share the whole photo's cap
        self.moments = nn.ModuleList(ImageMoments() for _ in widths) if global_features else None
        self.profile = HighlightProfile() if highlight_profile else None
        self.global_track: nn.Sequential | None = None
        if global_features:
            output = nn.Linear(GLOBAL_HIDDEN, GLOBAL_OUTPUTS)
            nn.init.zeros_(output.weight)
            nn.init.zeros_(output.bias)
            self.global_track = nn.Sequential(
                nn.Linear(2 * sum(widths) + (3 * PROFILE_RINGS if highlight_profile else 0), GLOBAL_HIDDEN),
                nn.LeakyReLU(0.2, inplace=True),
                output,
            )

    def config(self) -> dict[str, Any]:
        """The constructor arguments (stored with the weights)."""
        return {
            "width": self.width,
            "depth": self.depth,
            "shading": self.shading,
            "anchored": self.anchored,
            "anchor_gain": self.anchor_gain,
            "head_gain": self.head_gain,
            "global_features": self.global_features,
            "highlight_profile": self.highlight_profile,
            "normal_head": self.normal_head,
        }

    @property
    def size_multiple(self) -> int:
        """H and W must be multiples of this (and at least twice it)."""
        return 2**self.depth

    def check_input(self, photo: Tensor) -> None:
        """Raise ``ValueError`` unless ``photo`` is ``(B, 3, H, W)`` of a supported size."""
        check_shape(photo, "B 3 H W", name="AnchoredUNet photo")
        height, width = photo.shape[-2:]
        multiple = self.size_multiple
        if height % multiple or width % multiple or min(height, width) < 2 * multiple:
            raise ValueError(
                f"AnchoredUNet input height and width must be multiples of {multiple} (2**depth, "
                f"depth={self.depth}) and at least {2 * multiple}; got {height}×{width}"
            )

    def anchor(self, photo: Tensor, flash: Tensor, cap: Tensor | None = None) -> Tensor:
        """The anchor ``g · d`` the base colour corrects: the de-lit photo, its hotspot clipped at
        ``cap`` (default: measured on this photo, as the forward pass does), times the learnt
        exposure gain, blurred. Any size: the guided fast path of
        ``brdfgan predict`` composes a full-resolution base colour on it
        (:func:`compose_basecolor`) with the cap of the photo the network read.

        Shape:
            - photo: ``(B, 3, H, W)`` linear LDR; flash: ``(B, 3)``; cap: ``(B, 1)``
            - output: ``(B, 3, H, W)`` linear
        """
        check_shape(photo, "B 3 H W", name="AnchoredUNet photo")
        check_flash_frame(flash, photo.shape[0])
        frame = flash.to(device=photo.device, dtype=photo.dtype)
        return self._anchor(delit_photo(photo.clamp(0.0, 1.0), frame, clip=False), cap)

    def _anchor(self, delit: Tensor, cap: Tensor | None = None) -> Tensor:
        cap = self.hotspot_cap(delit) if cap is None else cap  # the module: tiles replay the photo's
        anchor = self.log_anchor_gain.exp().to(delit.dtype) * clip_hotspot(delit, cap=cap)
        return binomial_blur(anchor)

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        return self.maps_and_corrections(photo, flash)[0]

    def maps_and_corrections(
        self, photo: Tensor, flash: Tensor | None = None
    ) -> tuple[Tensor, Tensor | None]:
        """The maps (what ``forward`` returns) and, for an anchored network, the corrections its
        base colour was composed from (:func:`compose_basecolor`; ``None`` when not anchored).

        Shape:
            - photo: ``(B, 3, H, W)``; flash: ``(B, 3)``
            - output: ``(B, 8, H, W)`` maps, ``(B, CORRECTION_CHANNELS, H, W)`` corrections
        """
        self.check_input(photo)
        batch, _, height, width = photo.shape
        if flash is None:
            flash = centred_flash_frame(batch, height, width, DEFAULT_FOV_DEG, device=photo.device)
        check_flash_frame(flash, batch)
        frame = flash.to(device=photo.device, dtype=photo.dtype)
        photo = photo.clamp(0.0, 1.0)
        delit = delit_photo(photo, frame, clip=False)
        anchor = self._anchor(delit)
        log_photo = (photo + LOG_EPS).log()  # an input, and the shading image's numerator
        x = torch.cat([log_photo, (anchor + LOG_EPS).log(), flash_side_channels(frame, height, width)], dim=1)
        skips, moments = self._encode(x)
        levels = None  # per image and output channel: the global track's addition to the heads
        if self.global_track is not None:
            if self.profile is not None:
                moments.append(self.profile(delit, photo, frame))
            levels = self.global_track(torch.cat(moments, dim=1))[:, :, None, None]
        basecolor, metallic, provisional, corrections = self._material_maps(skips, levels, anchor)
        extras = None
        if self.shading != "none":
            # Detached: rendered without a graph (the same values; no autograd bookkeeping).
            with torch.set_grad_enabled(torch.is_grad_enabled() and self.shading == "gradient"):
                flat = flat_flash_render(basecolor, torch.sigmoid(provisional), metallic, frame)
                shading = log_photo - (flat + LOG_EPS).log()
            extras = [
                shading if level == 0 else F.avg_pool2d(shading, 2**level) for level in range(self.depth)
            ]
        normal, roughness = self._surface_maps(skips, extras, levels)
        return join_maps(linear_to_srgb(basecolor), normal, roughness, metallic), corrections

    def _encode(self, x: Tensor) -> tuple[list[Tensor], list[Tensor]]:
        """The encoder's features at every level and, with the global track, the moments of each
        level's first convolution (before its norm removes them)."""
        skips, moments = [], []
        for level, block in enumerate(self.encoder):
            x = x if level == 0 else F.avg_pool2d(x, 2)
            if self.moments is not None:
                layers = cast(nn.Sequential, block)  # built by _conv_block
                x = layers[0](x)
                moments.append(self.moments[level](x))
                x = layers[1:](x)
            else:
                x = block(x)
            skips.append(x)
        return skips, moments

    def _material_maps(
        self, skips: list[Tensor], levels: Tensor | None, anchor: Tensor
    ) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
        """The material decoder's linear base colour, metallic, provisional roughness logit (what
        the shading image renders with) and, when anchored, the base colour's corrections."""
        material = self.material(skips)
        if levels is not None:
            material = material + levels[:, :MATERIAL_OUTPUTS]
        material = self.head_gain * material
        metallic = torch.sigmoid(material[:, 6:7])
        if not self.anchored:
            return torch.sigmoid(material[:, 0:3] + material[:, 3:6]), metallic, material[:, 7:8], None
        # The corrections only are blurred: metallic and the provisional roughness stay sharp.
        blurred = binomial_blur(torch.cat([material[:, 0:6], material[:, 8:11]], dim=1))
        corrections = torch.cat(
            [
                blurred[:, 0:3].clamp(-LOG_GAIN_LIMIT, LOG_GAIN_LIMIT),
                RESIDUAL_SCALE * torch.tanh(blurred[:, 3:6]),
                torch.sigmoid(blurred[:, 6:9]),
                metallic,
            ],
            dim=1,
        )
        return compose_basecolor(anchor, corrections), metallic, material[:, 7:8], corrections

    def _surface_maps(
        self, skips: list[Tensor], extras: list[Tensor] | None, levels: Tensor | None
    ) -> tuple[Tensor, Tensor]:
        """The surface decoder's unit normals and roughness."""
        surface = self.surface(skips, extras)
        relief, roughness_logit = surface[:, : self.relief_channels], surface[:, self.relief_channels :]
        if levels is not None:  # the roughness logit only (GLOBAL_OUTPUTS)
            roughness_logit = roughness_logit + levels[:, MATERIAL_OUTPUTS:]
        relief, roughness_logit = self.head_gain * relief, self.head_gain * roughness_logit
        slopes = relief if self.normal_head == "slopes" else height_slope_channels(relief)
        normal = normalize_normal(torch.cat([slopes, torch.ones_like(roughness_logit)], dim=1))
        return normal, torch.sigmoid(roughness_logit)


__all__ = [
    "CORRECTION_CHANNELS",
    "DEFAULT_ANCHOR_GAIN",
    "METALLIC_BIAS",
    "NORMAL_HEADS",
    "SHADINGS",
    "AnchoredUNet",
    "NormalHead",
    "Shading",
    "compose_basecolor",
]
