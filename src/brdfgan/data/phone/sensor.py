"""Phone sensor and file effects on a training photo, so training sees what ``brdfgan predict`` sees.

:class:`SensorEffects` turns a rendered linear LDR photo into what predict's intake
(:func:`~brdfgan.inference.intake.photo.read_photo`, then
:func:`~brdfgan.inference.intake.preprocess.preprocess`) gives for a phone's file of it:
vignetting, auto white balance and its residual error, shot and read noise, then either a RAW
capture (16-bit linear) or the phone's look, 8 bits and a real JPEG, linearised and auto-exposed
exactly as predict does (Pillow's libjpeg and :func:`~brdfgan.core.svbrdf.srgb_decoding_table`:
bit-identical to the intake). Every effect has a probability (0 switches it off); ``enabled=False``
(or no ``SensorEffects`` at all) leaves the photo untouched, bit for bit. The order, the ranges and
the reasons for them, and the limits: docs/data.md#photos-as-phones-deliver-them.
"""

from __future__ import annotations

import hashlib
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from PIL import Image
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import LUMINANCE_WEIGHTS, auto_expose
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.sampling import log_uniform
from brdfgan.core.svbrdf import linear_to_srgb, srgb_decoding_table
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range, integer, ordered

__all__ = [
    "SensorEffects",
    "auto_white_balance_gains",
    "decode_srgb8",
    "encode_srgb8",
    "flash_illuminant",
    "jpeg_roundtrip",
    "local_contrast",
    "quantise_linear16",
    "quantise_srgb8",
    "saturation_boost",
    "sensor_noise",
    "sharpening",
    "tone_curve",
    "vignetting",
    "vignetting_falloff",
    "white_balance",
]

CONFIG_KEY = "data.sensor"
LEVELS_8BIT = 255
LEVELS_16BIT = 65535
# Uniform variates drawn per photo, a fixed number whatever is switched on, so turning one
# effect off leaves the values drawn for the others unchanged.
_DRAWS = 10
# The phone processing's variates (RAW, local contrast, tone curve, saturation, sharpening, auto
# white balance; one spare) come from a second stream seeded by a hash of the generator's state on entry: the
# generator itself then draws exactly what it drew before they existed (its 10 uniforms, then the
# noise), so with the phone processing off the output is bit for bit the earlier one.
_PHONE_DRAWS = 12


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


def auto_white_balance_gains(illuminant_rgb: Sequence[float]) -> tuple[float, float, float]:
    """The gains that make a white surface under ``illuminant_rgb`` neutral: ``max(rgb) / rgb``.

    Scaled so the smallest gain is 1, as LibRaw and dcraw scale a camera's multipliers: a pixel
    clipped in every channel stays clipped in every channel (white), and no channel is darkened.

    Shape:
        - illuminant_rgb: 3 positive numbers, linear RGB (any scale)
        - output: 3 gains ≥ 1, the illuminant's strongest channel's gain 1
    """
    rgb = [float(c) for c in illuminant_rgb]
    if len(rgb) != 3 or not all(math.isfinite(c) and c > 0.0 for c in rgb):
        raise ValueError(f"the illuminant must be 3 positive finite numbers, got {illuminant_rgb!r}")
    strongest = max(rgb)
    return (strongest / rgb[0], strongest / rgb[1], strongest / rgb[2])


def sensor_noise(
    photo: Tensor,
    shot: float,
    read: float,
    generator: torch.Generator,
    *,
    gains: tuple[float, float, float] | None = None,
) -> Tensor:
    """Add heteroscedastic Gaussian noise of variance ``shot · x + read`` to every value ``x``.

    The usual Gaussian approximation of Poisson (photon) plus Gaussian (read) noise, with the
    signal in units of the saturation level; negative signal counts as 0 for the variance. With
    per-channel ``gains`` g, ``photo`` is a raw signal already multiplied by them (white balance),
    and the noise is the raw signal's seen through them: variance ``g·shot·x + g²·read``.

    Shape:
        - photo: ``(3, H, W)`` linear RGB
        - output: same (not clipped)
    """
    if gains is None:
        variance = photo.clamp(min=0.0) * shot + read
    else:
        g = torch.tensor(gains, dtype=photo.dtype).view(3, 1, 1)
        variance = photo.clamp(min=0.0) * (shot * g) + read * g**2
    noise = torch.randn(photo.shape, generator=generator, dtype=photo.dtype)
    return photo + variance.sqrt() * noise


def encode_srgb8(linear: Tensor) -> Tensor:
    """Clip to [0, 1], apply the sRGB curve and round to 8-bit codes, as a camera writes a file.

    Shape:
        - linear: ``(3, H, W)`` linear RGB
        - output: ``(3, H, W)`` uint8
    """
    return quantise_srgb8(linear_to_srgb(linear.clamp(0.0, 1.0).to(torch.float32)))


def quantise_srgb8(display: Tensor) -> Tensor:
    """Clip display-referred (sRGB-encoded) values to [0, 1] and round them to 8-bit codes.

    Shape:
        - display: ``(3, H, W)`` float, sRGB-encoded
        - output: ``(3, H, W)`` uint8
    """
    return (display.clamp(0.0, 1.0) * LEVELS_8BIT).round().to(torch.uint8)


def quantise_linear16(linear: Tensor) -> Tensor:
    """Clip to [0, 1] and round to 16-bit linear levels, as ``read_photo`` gets a RAW file from
    LibRaw (``output_bps=16``, ``gamma=(1, 1)``) and divides by 65535.

    Shape:
        - linear: ``(3, H, W)`` linear RGB
        - output: ``(3, H, W)`` float32 in [0, 1]
    """
    levels = (linear.clamp(0.0, 1.0).to(torch.float64) * LEVELS_16BIT).round()
    return (levels / LEVELS_16BIT).to(torch.float32)


def _luma(display: Tensor) -> Tensor:
    # Y' of the encoded values with the Rec. 709 weights, as a phone's YUV stage computes it.
    return (display * torch.tensor(LUMINANCE_WEIGHTS, dtype=display.dtype).view(3, 1, 1)).sum(0, keepdim=True)


def _luma_detail(display: Tensor, sigma: float) -> Tensor:
    # The luma minus its Gaussian blur (mirrored at the border): an unsharp mask's detail layer.
    luma = _luma(display)
    return luma - gaussian_blur(luma[None], sigma, "reflect")[0]


def tone_curve(display: Tensor, strength: float) -> Tensor:
    """An S-shaped contrast curve on display-referred values: ``x + s·(3x² − 2x³ − x)``.

    The identity blended with smoothstep by ``s``: fixed points 0, 0.5 and 1, slope ``1 + s/2``
    at 0.5 (mid-tone contrast) and ``1 − s`` at 0 and 1 (toe and shoulder), monotonic for
    ``s`` in [0, 1]. Values are clipped to [0, 1] first (a curve is a table over the codes).

    Shape:
        - display: ``(3, H, W)`` sRGB-encoded
        - output: same, in [0, 1]
    """
    if not 0.0 <= strength <= 1.0:
        raise ValueError(f"tone curve strength must lie in [0, 1], got {strength}")
    x = display.clamp(0.0, 1.0)
    return x + strength * (x * x * (3.0 - 2.0 * x) - x)


def saturation_boost(display: Tensor, factor: float) -> Tensor:
    """Scale every pixel's chroma by ``factor`` around its luma: ``Y' + factor·(RGB' − Y')``.

    What a phone's YUV stage does to U and V; greys (R' = G' = B') are left as they are and the
    luma is kept. Not clipped.

    Shape:
        - display: ``(3, H, W)`` sRGB-encoded
        - output: same
    """
    luma = _luma(display)
    return luma + factor * (display - luma)


def sharpening(display: Tensor, amount: float, sigma: float = 1.0) -> Tensor:
    """Unsharp mask of the luma, a phone's edge enhancement: ``x + amount·(Y' − blur_σ(Y'))``,
    the same detail added to the three channels (the chroma is not sharpened). Not clipped.

    Shape:
        - display: ``(3, H, W)`` sRGB-encoded
        - output: same
    """
    return display + amount * _luma_detail(display, sigma)


def local_contrast(display: Tensor, amount: float, sigma: float) -> Tensor:
    """The "clarity" of photo editors: :func:`sharpening`'s unsharp mask with a large radius
    ``sigma`` (a sixteenth to an eighth of the image side), the detail boost of a phone's local
    tone mapping. Not clipped.

    Shape:
        - display: ``(3, H, W)`` sRGB-encoded
        - output: same
    """
    return display + amount * _luma_detail(display, sigma)


def jpeg_roundtrip(codes: Tensor, quality: int) -> Tensor:
    """Write the 8-bit image as a JPEG with Pillow at ``quality`` (its default 4:2:0 chroma
    subsampling) and decode it again with Pillow, as ``read_photo`` would.

    Shape:
        - codes: ``(3, H, W)`` uint8
        - output: ``(3, H, W)`` uint8
    """
    check_shape(codes, "3 H W", name="uint8 codes")
    if codes.dtype != torch.uint8:
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


def flash_illuminant(meta: Mapping[str, Any]) -> tuple[float, float, float] | None:
    """The flash colour of a sample (linear RGB, luminance 1) from ``meta["flash"]["temperature_k"]``,
    for :meth:`SensorEffects.apply`; ``None`` when the sample does not record it."""
    flash = meta.get("flash")
    temperature = flash.get("temperature_k") if isinstance(flash, Mapping) else None
    return None if temperature is None else blackbody_rgb(float(temperature))


def _phone_uniforms(generator: torch.Generator) -> list[float]:
    # See _PHONE_DRAWS: a stream of its own, seeded from the generator's state, which stays as is.
    digest = hashlib.blake2b(generator.get_state().numpy().tobytes(), digest_size=8, person=b"brdfgan.phone")
    stream = torch.Generator().manual_seed(int.from_bytes(digest.digest(), "little") >> 1)
    return torch.rand(_PHONE_DRAWS, generator=stream, dtype=torch.float64).tolist()


# ------------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class SensorEffects:
    """Random sensor and file effects (pipeline and ranges: docs/data.md#photos-as-phones-deliver-them).

    Configured as ``data.sensor`` (``_target_: brdfgan.data.phone.sensor.SensorEffects``); every value
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
        auto_white_balance: divide the photo by the flash's colour (the ``illuminant_rgb`` of
            :meth:`apply`) before the white-balance error, as a phone's AWB does.
        auto_white_balance_probability: the chance that it does (with ``auto_white_balance``).
        raw_probability: chance that a photo is a RAW capture: no phone processing and no
            JPEG, a 16-bit linear file (noise and white balance still apply).
        local_contrast_min, local_contrast_max: clarity amount (:func:`local_contrast`), uniform.
        local_contrast_radius_min, local_contrast_radius_max: its Gaussian σ as a fraction of
            the image's shorter side, uniform.
        tone_curve_min, tone_curve_max: S-curve strength in [0, 1] (:func:`tone_curve`), uniform.
        saturation_min, saturation_max: chroma factor (:func:`saturation_boost`), uniform.
        sharpening_min, sharpening_max: unsharp-mask amount (:func:`sharpening`), uniform.
        sharpening_radius: its Gaussian σ in pixels.

    The phone processing (``raw_probability`` and the last four effects) and the auto white
    balance are off by default, so a config written before them trains as it did, bit for bit.
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
    # Phone processing, all off by default (probability 0). The ranges, when switched on, span a
    # neutral rendering to a phone's "vivid" look (judged, not measured on phone files):
    auto_white_balance: bool = False
    # The share of photos it applies to: the rest keep the flash's cast, as a capture that was not
    # white-balanced to the flash (the OOD benchmark's standard variant) does.
    auto_white_balance_probability: float = 1.0
    # Phones that write DNGs (pro modes) are a minority of the photos predict gets.
    raw_probability: float = 0.0
    # Local tone mapping's detail boost: up to +40 % contrast at scales below σ, visible but not
    # the haloed look of a strong HDR mode.
    local_contrast_probability: float = 0.0
    local_contrast_min: float = 0.0
    local_contrast_max: float = 0.4
    local_contrast_radius_min: float = 1.0 / 16.0
    local_contrast_radius_max: float = 1.0 / 8.0
    # Adobe Camera Raw's "Medium Contrast" point curve (codes 64 → 56, 192 → 196) is about
    # strength 0.3; 0.6 (mid-tone slope 1.3) is a punchy phone look.
    tone_curve_probability: float = 0.0
    tone_curve_min: float = 0.0
    tone_curve_max: float = 0.6
    # Chroma ×1–1.3: a phone's default look boosts it moderately, "vivid" modes more.
    saturation_probability: float = 0.0
    saturation_min: float = 1.0
    saturation_max: float = 1.3
    # Edge enhancement on the luma at σ = 1 px, amount 0 (none) to 1 (the pixels next to a sharp
    # edge overshoot by 30 % of its step: the halo phone JPEGs show at 100 %).
    sharpening_probability: float = 0.0
    sharpening_min: float = 0.0
    sharpening_max: float = 1.0
    sharpening_radius: float = 1.0

    def __post_init__(self) -> None:
        key = CONFIG_KEY
        for name in ("enabled", "auto_exposure", "auto_white_balance"):
            if not isinstance(getattr(self, name), bool):
                raise DatasetConfigError(f"{key}.{name}={getattr(self, name)!r}: must be true or false")
        for effect in (
            "vignetting",
            "white_balance",
            "noise",
            "jpeg",
            "raw",
            "local_contrast",
            "tone_curve",
            "saturation",
            "sharpening",
            "auto_white_balance",
        ):
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
        # Upper bounds far beyond any phone's, to catch a slipped decimal point.
        for effect, high in (
            ("local_contrast", 2.0),
            ("tone_curve", 1.0),
            ("saturation", 3.0),
            ("sharpening", 5.0),
        ):
            for bound in ("min", "max"):
                in_range(f"{key}.{effect}_{bound}", getattr(self, f"{effect}_{bound}"), 0.0, high)
            ordered(key, self, f"{effect}_min", f"{effect}_max")
        for name in ("local_contrast_radius_min", "local_contrast_radius_max"):
            in_range(f"{key}.{name}", getattr(self, name), 0.0, 0.5, low_open=True)
        ordered(key, self, "local_contrast_radius_min", "local_contrast_radius_max")
        in_range(f"{key}.sharpening_radius", self.sharpening_radius, 0.0, 10.0, low_open=True)

    @staticmethod
    def flash_illuminant(meta: Mapping[str, Any]) -> tuple[float, float, float] | None:
        """:func:`flash_illuminant`: the ``illuminant_rgb`` of :meth:`apply` for a sample's meta."""
        return flash_illuminant(meta)

    def apply(
        self,
        photo: Tensor,
        generator: torch.Generator,
        *,
        illuminant_rgb: Sequence[float] | None = None,
    ) -> tuple[Tensor, dict[str, Any]]:
        """The photo as ``brdfgan predict`` would see a phone's JPEG (or DNG) of it, and what was
        drawn.

        ``illuminant_rgb`` is the flash's linear RGB colour the photo was rendered under (any
        scale; :func:`flash_illuminant` reads it from a sample's meta), which the auto white
        balance divides out; ``None`` (unknown) leaves the photo's colour as it is.

        The record (JSON-serialisable, for ``meta["sensor"]``) holds the drawn values, ``None``
        for an effect not applied: ``vignetting`` (corner darkening), ``white_balance`` (the
        three gains), ``shot_noise`` and ``read_noise`` (a and b), ``jpeg_quality`` and
        ``exposure_scale`` (the auto exposure's multiplier); then ``raw`` (true for a RAW
        capture), ``illuminant`` (``illuminant_rgb`` as given), ``auto_white_balance`` (the three
        gains applied), ``local_contrast`` (amount and σ in pixels), ``tone_curve`` (strength),
        ``saturation`` (factor) and ``sharpening`` (amount). Disabled: the input itself and ``{}``.

        Shape:
            - photo: ``(3, H, W)`` linear LDR in [0, 1]
            - output: ``(3, H, W)`` float32, linear LDR in [0, 1]
        """
        check_shape(photo, "3 H W", name="photo")
        if not self.enabled:
            return photo, {}
        phone = _phone_uniforms(generator)  # leaves the generator as it is: drawn before u or after
        u = torch.rand(_DRAWS, generator=generator, dtype=torch.float64).tolist()
        record: dict[str, Any] = dict.fromkeys(
            (
                *(
                    "vignetting",
                    "white_balance",
                    "shot_noise",
                    "read_noise",
                    "jpeg_quality",
                    "exposure_scale",
                ),
                *("raw", "illuminant", "auto_white_balance", "local_contrast", "tone_curve", "saturation"),
                "sharpening",
            )
        )
        raw = phone[0] < self.raw_probability
        record["raw"] = raw
        linear = photo.to(torch.float32)
        if u[0] < self.vignetting_probability:
            strength = self.vignetting_min + u[1] * (self.vignetting_max - self.vignetting_min)
            linear = vignetting(linear, strength)
            record["vignetting"] = strength
        awb_gains = None
        if illuminant_rgb is not None:
            record["illuminant"] = [float(c) for c in illuminant_rgb]
            # phone[10]: a spare of the phone stream, so the other draws stay as they were.
            if self.auto_white_balance and phone[10] < self.auto_white_balance_probability:
                awb_gains = auto_white_balance_gains(illuminant_rgb)
                linear = white_balance(linear, awb_gains)
                record["auto_white_balance"] = list(awb_gains)
        if u[2] < self.white_balance_probability:
            limit = 1.0 + self.white_balance_max_error
            gains = (log_uniform(u[3], 1.0 / limit, limit), 1.0, log_uniform(u[4], 1.0 / limit, limit))
            linear = white_balance(linear, gains)
            record["white_balance"] = list(gains)
        if u[5] < self.noise_probability:
            shot = log_uniform(u[6], self.shot_noise_min, self.shot_noise_max)
            read = log_uniform(u[7], self.read_noise_min, self.read_noise_max)
            linear = sensor_noise(linear, shot, read, generator, gains=awb_gains)
            record["shot_noise"], record["read_noise"] = shot, read
        if raw:
            linear = quantise_linear16(linear)
        else:
            linear = decode_srgb8(self._phone_file(linear, u, phone, record))
        if self.auto_exposure:
            # As preprocess does it, on the decoded photo at the network's resolution.
            linear, scale = auto_expose(linear.clamp(min=0.0))
            record["exposure_scale"] = float(scale)
        return linear, record

    def _phone_file(
        self, linear: Tensor, u: list[float], phone: list[float], record: dict[str, Any]
    ) -> Tensor:
        """The 8-bit codes of the phone's JPEG of ``linear``: the processing on the sRGB-encoded
        values, quantisation and the JPEG step (in the order of docs/data.md#photos-as-phones-deliver-them),
        recorded in ``record``."""
        display = linear_to_srgb(linear.clamp(0.0, 1.0).to(torch.float32))
        if phone[1] < self.local_contrast_probability:
            amount = self.local_contrast_min + phone[2] * (self.local_contrast_max - self.local_contrast_min)
            radius = self.local_contrast_radius_min + phone[3] * (
                self.local_contrast_radius_max - self.local_contrast_radius_min
            )
            sigma = radius * min(display.shape[-2:])
            display = local_contrast(display, amount, sigma)
            record["local_contrast"] = [amount, sigma]
        if phone[4] < self.tone_curve_probability:
            strength = self.tone_curve_min + phone[5] * (self.tone_curve_max - self.tone_curve_min)
            display = tone_curve(display, strength)
            record["tone_curve"] = strength
        if phone[6] < self.saturation_probability:
            factor = self.saturation_min + phone[7] * (self.saturation_max - self.saturation_min)
            display = saturation_boost(display, factor)
            record["saturation"] = factor
        if phone[8] < self.sharpening_probability:
            amount = self.sharpening_min + phone[9] * (self.sharpening_max - self.sharpening_min)
            display = sharpening(display, amount, self.sharpening_radius)
            record["sharpening"] = amount
        codes = quantise_srgb8(display)
        if u[8] < self.jpeg_probability:
            span = self.jpeg_quality_max - self.jpeg_quality_min + 1
            quality = self.jpeg_quality_min + min(int(u[9] * span), span - 1)
            codes = jpeg_roundtrip(codes, quality)
            record["jpeg_quality"] = quality
        return codes
