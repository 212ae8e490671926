"""Phone sensor and file effects on a training photo, so training sees what ``brdfgan predict`` sees.

Training photos are perfect linear LDR renders; a real input is a phone JPEG that
:func:`~brdfgan.inference.intake.photo.read_photo` linearises and
:func:`~brdfgan.inference.intake.preprocess.preprocess` auto-exposes. :class:`SensorEffects`
turns a rendered photo into what that path would give for a phone's file of it, in this order::

    linear LDR photo
      ─ vignetting            radial cos⁴-like falloff, random corner darkening     (optics)
      ─ white-balance error   random gains on red and blue, green fixed             (ISP)
      ─ shot and read noise   Gaussian with variance a·x + b, a and b log-uniform   (sensor)
      ─ clip to [0, 1], sRGB encoding, 8-bit quantisation                           (the file)
      ─ JPEG at a random quality, decoded to 8 bits again (Pillow's libjpeg)
      ─ linearisation with predict's table (srgb_decoding_table)                    (read_photo)
      ─ auto exposure, as preprocess applies it                                     (preprocess)

Every effect has a probability (0 switches it off); the file steps (clip, sRGB, 8 bits,
linearisation) always run, and the final auto exposure has its own flag. ``enabled=False`` (or
no ``SensorEffects`` at all) leaves the photo untouched, bit for bit.

Why Pillow and not kornia for the JPEG step: ``kornia.enhance.jpeg_codec_differentiable`` (and
``kornia.augmentation.RandomJPEG``, built on it) approximates the codec differentiably; on a
256² image it differs from libjpeg by ~7 codes on average (noise image, quality 80) and took
~22 ms against Pillow's ~3 ms on this CPU. No gradient flows through the data pipeline, and
Pillow is what ``read_photo`` decodes JPEGs with, so the simulated file is a real JPEG and its
decoding is bit-identical to predict's. The sRGB curve has one home too
(:mod:`brdfgan.core.svbrdf`), so ``kornia.color`` is not used either.

Ranges (defaults). Noise: the "unprocessing" model of Brooks et al. 2019 (shot variance per unit
signal a ∈ [1e-4, 1.2e-2], log-uniform; their read variance b follows log b ≈ 2.18 log a + 1.2,
which spans ≈ [1e-8, 2e-4] over that range; here b is drawn log-uniform over that span,
independently of a). JPEG: quality 70–95, what phone cameras and apps write. Vignetting: up to
30 % darker corners (what remains after a phone's lens-shading correction). White balance: red and
blue gains log-uniform within ±10 %.

Limits. Everything happens at the network's resolution, as if the phone's file were the network
input. A real photo is cropped and downscaled by ``preprocess`` first (a 12 MP photo's central
square to 256² averages ~140 pixels into one), which removes most of its noise, JPEG blocks and
quantisation; these effects are therefore stronger here than on a large phone photo, and match a
photo taken or saved at about the network's size. Phone denoising, sharpening and tone curves are
not modelled.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from PIL import Image
from torch import Tensor

from brdfgan.core.exposure import auto_expose
from brdfgan.core.sampling import log_uniform
from brdfgan.core.svbrdf import linear_to_srgb, srgb_decoding_table
from brdfgan.data.spec_checks import DatasetConfigError, in_range, integer, ordered

__all__ = [
    "SensorEffects",
    "decode_srgb8",
    "encode_srgb8",
    "jpeg_roundtrip",
    "sensor_noise",
    "vignetting",
    "vignetting_falloff",
    "white_balance",
]

CONFIG_KEY = "data.sensor"
LEVELS_8BIT = 255
# Uniform variates drawn per photo, a fixed number whatever is switched on, so turning one
# effect off leaves the values drawn for the others unchanged.
_DRAWS = 10


# ------------------------------------------------------------------------------- pure functions


def vignetting_falloff(height: int, width: int, strength: float) -> Tensor:
    """The cos⁴-law falloff ``1 / (1 + (k r)²)²`` with ``r`` the distance from the image centre
    over the half-diagonal, and ``k`` such that the corners keep ``1 - strength`` of their light.

    A thin lens sees a point at field angle θ darkened by cos⁴ θ; ``k`` is tan θ at the corner.

    Shape:
        - output: ``(1, height, width)`` float32, 1 at the centre, ``1 - strength`` at r = 1
    """
    if not 0.0 <= strength < 1.0:
        raise ValueError(f"vignetting strength must lie in [0, 1), got {strength}")
    k_squared = (1.0 - strength) ** -0.5 - 1.0
    ys = torch.arange(height, dtype=torch.float64) - (height - 1) / 2.0
    xs = torch.arange(width, dtype=torch.float64) - (width - 1) / 2.0
    half_diagonal = 0.5 * math.hypot(height, width)
    r_squared = (ys[:, None] ** 2 + xs[None, :] ** 2) / half_diagonal**2
    return ((1.0 + k_squared * r_squared) ** -2).to(torch.float32)[None]


def vignetting(photo: Tensor, strength: float) -> Tensor:
    """Darken ``photo`` radially with :func:`vignetting_falloff` (centred on the image: the
    flash, and so the training photo's hotspot, sits next to the lens).

    Shape:
        - photo: ``(3, H, W)`` linear RGB
        - output: same
    """
    return photo * vignetting_falloff(photo.shape[-2], photo.shape[-1], strength).to(photo.dtype)


def white_balance(photo: Tensor, gains: tuple[float, float, float]) -> Tensor:
    """Multiply each channel by its gain: a camera's white-balance error.

    Shape:
        - photo: ``(3, H, W)`` linear RGB
        - output: same
    """
    return photo * torch.tensor(gains, dtype=photo.dtype).view(3, 1, 1)


def sensor_noise(photo: Tensor, shot: float, read: float, generator: torch.Generator) -> Tensor:
    """Add heteroscedastic Gaussian noise of variance ``shot · x + read`` to every value ``x``.

    The usual Gaussian approximation of Poisson (photon) plus Gaussian (read) noise, with the
    signal in units of the saturation level; negative signal counts as 0 for the variance.

    Shape:
        - photo: ``(3, H, W)`` linear RGB
        - output: same (not clipped)
    """
    variance = photo.clamp(min=0.0) * shot + read
    noise = torch.randn(photo.shape, generator=generator, dtype=photo.dtype)
    return photo + variance.sqrt() * noise


def encode_srgb8(linear: Tensor) -> Tensor:
    """Clip to [0, 1], apply the sRGB curve and round to 8-bit codes, as a camera writes a file.

    Shape:
        - linear: ``(3, H, W)`` linear RGB
        - output: ``(3, H, W)`` uint8
    """
    encoded = linear_to_srgb(linear.clamp(0.0, 1.0).to(torch.float32))
    return (encoded * LEVELS_8BIT).round().to(torch.uint8)


def jpeg_roundtrip(codes: Tensor, quality: int) -> Tensor:
    """Write the 8-bit image as a JPEG with Pillow at ``quality`` (its default 4:2:0 chroma
    subsampling) and decode it again with Pillow, as ``read_photo`` would.

    Shape:
        - codes: ``(3, H, W)`` uint8
        - output: ``(3, H, W)`` uint8
    """
    if codes.dtype != torch.uint8 or codes.ndim != 3 or codes.shape[0] != 3:
        raise ValueError(f"expected (3, H, W) uint8 codes, got {tuple(codes.shape)} {codes.dtype}")
    buffer = io.BytesIO()
    Image.fromarray(codes.permute(1, 2, 0).contiguous().numpy(), mode="RGB").save(
        buffer, format="JPEG", quality=int(quality)
    )
    buffer.seek(0)
    with Image.open(buffer) as image:
        decoded = np.asarray(image.convert("RGB"))
    return torch.from_numpy(np.ascontiguousarray(decoded.transpose(2, 0, 1)))


def decode_srgb8(codes: Tensor) -> Tensor:
    """8-bit sRGB codes → linear, with the table ``brdfgan predict`` decodes photos with.

    Shape:
        - codes: ``(3, H, W)`` uint8
        - output: ``(3, H, W)`` float32 in [0, 1]
    """
    return srgb_decoding_table(LEVELS_8BIT)[codes.long()]


# ------------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class SensorEffects:
    """Random sensor and file effects; see the module docstring for the pipeline and the ranges.

    Configured as ``data.sensor`` (``_target_: brdfgan.data.sensor.SensorEffects``); every value
    is checked on construction and a bad one raises a one-line error naming
    ``data.sensor.<key>``. Each ``*_probability`` is the chance that the effect is applied to a
    photo (0: never, 1: always). Ranges are ``[min, max]``; equal bounds make a constant.

    Attributes:
        enabled: ``False`` switches the whole simulation off (the photo is returned untouched).
        vignetting_min, vignetting_max: fraction of light lost in the image corners, uniform.
        white_balance_max_error: red and blue gains are log-uniform in
            ``[1 / (1 + e), 1 + e]``; green stays 1.
        shot_noise_min, shot_noise_max: ``a`` of the noise variance ``a·x + b``, log-uniform.
        read_noise_min, read_noise_max: ``b`` of the noise variance, log-uniform.
        jpeg_quality_min, jpeg_quality_max: JPEG quality, a uniform integer.
        auto_exposure: end with the auto exposure ``preprocess`` applies before the network.
    """

    enabled: bool = True
    vignetting_probability: float = 1.0
    vignetting_min: float = 0.0
    vignetting_max: float = 0.3
    white_balance_probability: float = 1.0
    white_balance_max_error: float = 0.1
    noise_probability: float = 1.0
    shot_noise_min: float = 1e-4
    shot_noise_max: float = 1.2e-2
    read_noise_min: float = 1e-8
    read_noise_max: float = 2e-4
    jpeg_probability: float = 1.0
    jpeg_quality_min: int = 70
    jpeg_quality_max: int = 95
    auto_exposure: bool = True

    def __post_init__(self) -> None:
        key = CONFIG_KEY
        for name in ("enabled", "auto_exposure"):
            if not isinstance(getattr(self, name), bool):
                raise DatasetConfigError(f"{key}.{name}={getattr(self, name)!r}: must be true or false")
        for effect in ("vignetting", "white_balance", "noise", "jpeg"):
            in_range(f"{key}.{effect}_probability", getattr(self, f"{effect}_probability"), 0.0, 1.0)
        for name in ("vignetting_min", "vignetting_max"):  # 1 would make the corners black
            in_range(f"{key}.{name}", getattr(self, name), 0.0, 1.0, high_open=True)
        ordered(key, self, "vignetting_min", "vignetting_max")
        in_range(f"{key}.white_balance_max_error", self.white_balance_max_error, 0.0, 1.0)
        for noise in ("shot_noise", "read_noise"):
            for bound in ("min", "max"):  # log-uniform: strictly positive
                in_range(f"{key}.{noise}_{bound}", getattr(self, f"{noise}_{bound}"), 0.0, 1.0, low_open=True)
            ordered(key, self, f"{noise}_min", f"{noise}_max")
        for name in ("jpeg_quality_min", "jpeg_quality_max"):
            integer(f"{key}.{name}", getattr(self, name), minimum=1)
            in_range(f"{key}.{name}", getattr(self, name), 1, 100)
        ordered(key, self, "jpeg_quality_min", "jpeg_quality_max")

    def apply(self, photo: Tensor, generator: torch.Generator) -> tuple[Tensor, dict[str, Any]]:
        """The photo as ``brdfgan predict`` would see a phone's JPEG of it, and what was drawn.

        The record (JSON-serialisable, for ``meta["sensor"]``) holds the drawn values, ``None``
        for an effect not applied: ``vignetting`` (corner darkening), ``white_balance`` (the
        three gains), ``shot_noise`` and ``read_noise`` (a and b), ``jpeg_quality`` and
        ``exposure_scale`` (the auto exposure's multiplier). Disabled: the input itself and ``{}``.

        Shape:
            - photo: ``(3, H, W)`` linear LDR in [0, 1]
            - output: ``(3, H, W)`` float32, linear LDR in [0, 1]
        """
        if photo.ndim != 3 or photo.shape[0] != 3:
            raise ValueError(f"expected a (3, H, W) photo, got shape {tuple(photo.shape)}")
        if not self.enabled:
            return photo, {}
        u = torch.rand(_DRAWS, generator=generator, dtype=torch.float64).tolist()
        record: dict[str, Any] = dict.fromkeys(
            ("vignetting", "white_balance", "shot_noise", "read_noise", "jpeg_quality", "exposure_scale")
        )
        linear = photo.to(torch.float32)
        if u[0] < self.vignetting_probability:
            strength = self.vignetting_min + u[1] * (self.vignetting_max - self.vignetting_min)
            linear = vignetting(linear, strength)
            record["vignetting"] = strength
        if u[2] < self.white_balance_probability:
            limit = 1.0 + self.white_balance_max_error
            gains = (log_uniform(u[3], 1.0 / limit, limit), 1.0, log_uniform(u[4], 1.0 / limit, limit))
            linear = white_balance(linear, gains)
            record["white_balance"] = list(gains)
        if u[5] < self.noise_probability:
            shot = log_uniform(u[6], self.shot_noise_min, self.shot_noise_max)
            read = log_uniform(u[7], self.read_noise_min, self.read_noise_max)
            linear = sensor_noise(linear, shot, read, generator)
            record["shot_noise"], record["read_noise"] = shot, read
        codes = encode_srgb8(linear)
        if u[8] < self.jpeg_probability:
            span = self.jpeg_quality_max - self.jpeg_quality_min + 1
            quality = self.jpeg_quality_min + min(int(u[9] * span), span - 1)
            codes = jpeg_roundtrip(codes, quality)
            record["jpeg_quality"] = quality
        linear = decode_srgb8(codes)
        if self.auto_exposure:
            # As preprocess does it, on the decoded photo at the network's resolution.
            linear, scale = auto_expose(linear.clamp(min=0.0))
            record["exposure_scale"] = float(scale)
        return linear, record
