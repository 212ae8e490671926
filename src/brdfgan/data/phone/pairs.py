"""The second shot of a flash + no-flash pair: the same framing with the flash off, as a phone
takes it a moment after the flash photo (issue 59; docs/data.md#flash--no-flash-pairs).

A phone exposes and white-balances each shot on its own, and a handheld phone moves a little
between them. So the no-flash twin of a photo gets, per pair:

- **its own exposure**: the auto exposure of the room light alone, off by its own drawn error
  (uniform in the spec's ``capture.exposure_ev_min``..``exposure_ev_max``, like the flash shot's);
- **its own white balance** (photos rendered on the fly): every shot, the flash one included, is
  multiplied after its exposure by per-channel gains ``exp(σ·z)``, ``z`` standard normal
  (``white_balance_spread`` σ = 0.03: a shot's channels off by about 3 %, a phone's AWB varying
  between two frames of one scene);
- **a handheld misregistration** (photos rendered on the fly): the twin resampled by a rigid
  motion, a shift uniform in the disc of radius ``shift_max_px`` (2 px) and a rotation about the
  image centre uniform in ±``rotation_max_deg`` (0.5°): what a phone held still for a second
  drifts by at 256²;
- **its own phone** where ``data.sensor`` is on: its own noise, JPEG and phone look, but the lens's
  vignetting and the file type (RAW or JPEG) of the flash shot (:func:`twin_sensor`).

A sample's ``meta["pair"]`` (:func:`pair_meta`) says how to undo all that. With ``r`` =
``exposure_ratio`` and ``g_f``, ``g_n`` = ``white_balance`` (flash shot, no-flash shot):
``flash / g_f − r · no_flash / g_n`` is the flash-only photo (the flash shot's exposure of the flash
alone), wherever neither shot clipped and the twin is registered to the flash photo.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape

# A linear value at or above this in any channel is clipped: the difference of two photos is wrong
# wherever one of them lost its top (issue 59).
from brdfgan.core.clipped_fill import CLIP_LEVEL
from brdfgan.data.phone.conditions import CaptureSampling
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.data.storage.shards import ShardError
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range

__all__ = [
    "CLIP_LEVEL",
    "PAIR_BATCH_KEYS",
    "FlashOnly",
    "PairDraw",
    "PairSampling",
    "draw_exposure_ev",
    "exposure_ratio",
    "flash_only_photos",
    "misregister",
    "pair_batch",
    "pair_meta",
    "pair_record",
    "sensed_pair_meta",
    "twin_sensor",
]

CONFIG_KEY = "data.pairs"
# A pair's tensors in a batch beside the two photos (docs/data.md#flash--no-flash-pairs).
PAIR_BATCH_KEYS = ("exposure_ratio", "white_balance")
# Uniforms per draw (no-flash exposure error, shift radius and angle, rotation) and normals (the
# two shots' log gains): a fixed number whatever the settings.
_UNIFORMS = 4
UNIT_GAINS = (1.0, 1.0, 1.0)


def draw_exposure_ev(sampling: CaptureSampling, u: float) -> float:
    """The no-flash shot's exposure error in stops from a uniform ``u`` in [0, 1): the spec's range
    of the flash shot's (``dataset_spec.capture.exposure_ev_*``; a constant range gives its value)."""
    return sampling.exposure_ev_min + u * (sampling.exposure_ev_max - sampling.exposure_ev_min)


@dataclass(frozen=True)
class PairDraw:
    """One pair's draw: the no-flash shot's exposure error (stops), the two shots' white-balance
    gains (flash, no-flash) and the twin's misregistration (``shift_px`` as ``(x, y)``: columns
    right, rows down; ``rotation_deg`` about the image centre, turning +x towards +y)."""

    exposure_ev: float = 0.0
    white_balance: tuple[tuple[float, float, float], tuple[float, float, float]] = (UNIT_GAINS, UNIT_GAINS)
    shift_px: tuple[float, float] = (0.0, 0.0)
    rotation_deg: float = 0.0

    def misregistration(self) -> tuple[float, float, float]:
        """``(shift x, shift y, rotation)``: a row of :func:`misregister`'s arguments."""
        return (self.shift_px[0], self.shift_px[1], self.rotation_deg)


@dataclass(frozen=True)
class PairSampling:
    """Photos rendered on the fly as flash + no-flash pairs (``data.pairs``; module docstring).
    ``enabled=False`` (the default) renders single flash photos, bit for bit as before pairs.
    Checked on construction, naming the keys under ``data.pairs``."""

    enabled: bool = False
    white_balance_spread: float = 0.03
    shift_max_px: float = 2.0
    rotation_max_deg: float = 0.5

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise DatasetConfigError(f"{CONFIG_KEY}.enabled={self.enabled!r}: must be true or false")
        in_range(f"{CONFIG_KEY}.white_balance_spread", self.white_balance_spread, 0.0, 0.5)
        # Beyond these a pair is no longer "the same spot" (and the fits register larger moves).
        in_range(f"{CONFIG_KEY}.shift_max_px", self.shift_max_px, 0.0, 32.0)
        in_range(f"{CONFIG_KEY}.rotation_max_deg", self.rotation_max_deg, 0.0, 10.0)

    def sample(self, generator: torch.Generator, capture: CaptureSampling) -> PairDraw:
        """One pair's draw (four uniforms and six normals from ``generator``, whatever the
        settings); the no-flash exposure error in ``capture``'s range (:func:`draw_exposure_ev`)."""
        u = torch.rand(_UNIFORMS, generator=generator, dtype=torch.float64).tolist()
        z = torch.randn(2, 3, generator=generator, dtype=torch.float64)
        gains = torch.exp(self.white_balance_spread * z).tolist()
        # sqrt: uniform over the disc's area, not crowded at its centre.
        radius = self.shift_max_px * math.sqrt(u[1])
        angle = 2.0 * math.pi * u[2]
        return PairDraw(
            exposure_ev=draw_exposure_ev(capture, u[0]),
            white_balance=(_triple(gains[0]), _triple(gains[1])),
            shift_px=(radius * math.cos(angle), radius * math.sin(angle)),
            rotation_deg=self.rotation_max_deg * (2.0 * u[3] - 1.0),
        )


def _triple(values: Sequence[float]) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


def misregister(photos: Tensor, motion: Tensor) -> Tensor:
    """Photos resampled (bilinearly) as a handheld camera moved them: the content at pixel ``p``
    (x right, y down, from the image centre) moves to ``R(θ)·p + (dx, dy)``; pixels that come
    from outside the frame repeat its border. ``motion`` rows are ``(dx, dy, θ)`` in pixels and
    degrees (:meth:`PairDraw.misregistration`); a zero row leaves a photo as it is, bit for bit.

    Shape:
        - photos: ``(B, C, H, W)``; motion: ``(B, 3)``
        - output: ``(B, C, H, W)``
    """
    check_shape(photos, "B C H W", name="photos")
    check_shape(motion, f"{photos.shape[0]} 3", name="motion")
    height, width = photos.shape[-2:]
    motion = motion.to(torch.float64)
    angle = torch.deg2rad(motion[:, 2])
    cos, sin = torch.cos(angle), torch.sin(angle)
    # grid_sample's normalised coordinates are pixels over the half size (align_corners=False):
    # output(q) = input(R⁻¹(q − t)) becomes S⁻¹ R⁻¹ S q_n − S⁻¹ R⁻¹ t with S = diag(W/2, H/2).
    half = motion.new_tensor([width / 2.0, height / 2.0])
    inverse = torch.stack([torch.stack([cos, sin], -1), torch.stack([-sin, cos], -1)], -2)  # R⁻¹ = Rᵀ
    linear = inverse * half[None, None, :] / half[None, :, None]
    offset = -(inverse @ motion[:, :2, None])[..., 0] / half
    theta = torch.cat([linear, offset[..., None]], dim=-1).to(photos.dtype)
    grid = F.affine_grid(theta, list(photos.shape), align_corners=False)
    moved = F.grid_sample(photos, grid, mode="bilinear", padding_mode="border", align_corners=False)
    still = (motion == 0).all(dim=1)
    return torch.where(still[:, None, None, None], photos, moved)


def exposure_ratio(flash_scale: float, no_flash_scale: float) -> float:
    """The flash shot's exposure scale over the no-flash shot's; 0 for a black no-flash shot
    (scale 0: it holds no room light to subtract)."""
    return flash_scale / no_flash_scale if no_flash_scale > 0.0 else 0.0


def pair_meta(
    flash_scale: float,
    no_flash: Mapping[str, Any],
    white_balance: Sequence[Sequence[float]] = (UNIT_GAINS, UNIT_GAINS),
) -> dict[str, Any]:
    """A sample's ``meta["pair"]``: ``exposure_ratio`` (:func:`exposure_ratio` of ``flash_scale``,
    the flash shot's exposure scale, and ``no_flash["exposure_scale"]``), ``white_balance`` (the
    gains of the flash shot and of the no-flash shot, applied after exposure) and ``no_flash``, what
    was drawn for the twin (its ``exposure_scale`` and ``exposure_ev`` at least)."""
    return {
        "exposure_ratio": exposure_ratio(flash_scale, float(no_flash["exposure_scale"])),
        "white_balance": [[float(g) for g in gains] for gains in white_balance],
        "no_flash": dict(no_flash),
    }


def twin_sensor(sensor: SensorEffects, flash_record: Mapping[str, Any]) -> SensorEffects:
    """``sensor`` for the no-flash shot of a pair whose flash shot it applied as ``flash_record``
    says (:meth:`SensorEffects.apply`'s record): one camera, so the same vignetting and the same file
    type (RAW or JPEG); every other effect is drawn anew."""
    vignetting = flash_record.get("vignetting")
    strength = 0.0 if vignetting is None else float(vignetting)
    return replace(
        sensor,
        vignetting_probability=0.0 if vignetting is None else 1.0,
        vignetting_min=strength,
        vignetting_max=strength,
        raw_probability=1.0 if flash_record.get("raw") else 0.0,
    )


def _sensor_gains(record: Mapping[str, Any]) -> list[float]:
    gains = [1.0, 1.0, 1.0]
    for name in ("auto_white_balance", "white_balance"):  # both multiply the channels
        applied = record.get(name)
        if applied is not None:
            gains = [g * float(a) for g, a in zip(gains, applied, strict=True)]
    return gains


def _sensor_scale(record: Mapping[str, Any]) -> float:
    scale = record.get("exposure_scale")
    return 1.0 if scale is None else float(scale)


def sensed_pair_meta(
    pair: Mapping[str, Any], flash_record: Mapping[str, Any], twin_record: Mapping[str, Any]
) -> dict[str, Any]:
    """``meta["pair"]`` after the sensor applied ``flash_record`` to the flash shot and
    ``twin_record`` to the twin (:meth:`SensorEffects.apply`'s records): the sensor's white balance
    multiplies each shot's gains, and its auto exposure each shot's exposure scale."""
    flash_scale, twin_scale = _sensor_scale(flash_record), _sensor_scale(twin_record)
    ratio = float(pair["exposure_ratio"]) * flash_scale
    gains = [
        [g * s for g, s in zip(shot, _sensor_gains(record), strict=True)]
        for shot, record in zip(pair["white_balance"], (flash_record, twin_record), strict=True)
    ]
    return {**pair, "exposure_ratio": ratio / twin_scale if twin_scale > 0.0 else 0.0, "white_balance": gains}


def pair_record(meta: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    """The ``meta["pair"]`` of sample ``key``, which has a no-flash twin (:func:`pair_meta`).

    Raises:
        ShardError: naming the sample, when its meta has no such record.
    """
    pair = meta.get("pair")
    if not isinstance(pair, Mapping) or not {"exposure_ratio", "white_balance"} <= pair.keys():
        raise ShardError(f"sample {key!r} has a no-flash photo but no meta['pair'] record")
    return pair


def pair_batch(metas: Sequence[Mapping[str, Any]], keys: Sequence[str]) -> dict[str, Tensor]:
    """The pair tensors of a batch from its samples' :func:`pair_record` (:data:`PAIR_BATCH_KEYS`).

    Shape:
        - output["exposure_ratio"]: ``(B,)`` float32; output["white_balance"]: ``(B, 2, 3)``
          float32 (flash shot, no-flash shot)
    """
    pairs = [pair_record(meta, key) for meta, key in zip(metas, keys, strict=True)]
    return {
        "exposure_ratio": torch.tensor(
            [float(pair["exposure_ratio"]) for pair in pairs], dtype=torch.float32
        ),
        "white_balance": torch.tensor([pair["white_balance"] for pair in pairs], dtype=torch.float32),
    }


@dataclass(frozen=True)
class FlashOnly:
    """Registered pairs undone (:func:`flash_only_photos`), in the flash shot's linear units.

    Attributes:
        flash_only: ``(B, 3, H, W)`` the flash photo less the room light, clamped at 0.
        room: ``(B, 3, H, W)`` the room light's share of the flash photo.
        valid: ``(B, 1, H, W)`` float 0/1: clipped in neither shot.
    """

    flash_only: Tensor
    room: Tensor
    valid: Tensor


def flash_only_photos(
    photo: Tensor, no_flash: Tensor, exposure_ratio: Tensor, white_balance: Tensor, clip: float = CLIP_LEVEL
) -> FlashOnly:
    """The flash-only photos of registered pairs, as the module docstring undoes a pair: with ``r``
    = ``exposure_ratio`` and ``g_f``, ``g_n`` = ``white_balance``, the room light's share is
    ``r · no_flash / g_n`` and the flash alone ``photo / g_f −`` that share.

    Shape:
        - photo, no_flash: ``(B, 3, H, W)`` linear; exposure_ratio: ``(B,)``; white_balance:
          ``(B, 2, 3)`` (flash shot, no-flash shot)
        - output: :class:`FlashOnly`

    Example:
        A pixel lit 0.6 by the flash and 0.2 by the room, the twin exposed 2× brighter:

        >>> photo = torch.full((1, 3, 1, 1), 0.8)
        >>> twin = torch.full((1, 3, 1, 1), 0.4)
        >>> gains = torch.ones(1, 2, 3)
        >>> pair = flash_only_photos(photo, twin, torch.tensor([0.5]), gains)
        >>> round(float(pair.flash_only[0, 0]), 4), round(float(pair.room[0, 0]), 4), float(pair.valid)
        (0.6, 0.2, 1.0)
    """
    dims = check_shape(photo, "B 3 H W", name="photo")
    check_shape(no_flash, "B 3 H W", name="no_flash", dims=dims)
    flash_gain = white_balance[:, 0, :, None, None].to(photo)
    room_gain = white_balance[:, 1, :, None, None].to(photo)
    room = exposure_ratio.to(photo)[:, None, None, None] * no_flash / room_gain
    flash_only = (photo / flash_gain - room).clamp_min(0.0)
    valid = ((photo.amax(1, keepdim=True) < clip) & (no_flash.amax(1, keepdim=True) < clip)).to(photo)
    return FlashOnly(flash_only=flash_only, room=room, valid=valid)
