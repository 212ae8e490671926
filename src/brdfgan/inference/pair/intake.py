"""A flash + no-flash pair at intake: the room light's share of the flash photo, and the flash-only
image left when it is taken out (issue 59; docs/predict.md#flash--no-flash-pair).

The two photos see one surface under the same room light; the flash photo adds the flash. With
``F`` the flash photo and ``N`` the no-flash photo, both linear (read as predict reads any photo),

    flash-only = F − r · G · N(registered)

where

- ``r`` is the exposure ratio (:func:`exposure_ratio`): the flash photo's exposure over the
  no-flash photo's, ``ExposureTime × ISO / FNumber²`` from each one's EXIF, or ``--exposure-ratio``;
- ``G`` are per-channel white-balance gains (:func:`white_balance`): phones set the white balance
  per shot, so the room light's colour differs between the two files. ``G`` is green = 1: a camera
  balances white by scaling red and blue against green, so green follows the exposure alone and
  ``r`` sets the level, ``G`` the colour. On a diffuse surface under one flash and one room light
  (each of one colour, of any strength across the crop), each pixel's flash-only colour is its
  no-flash colour times one constant ``κ`` (``G`` times the flash's colour over the room's), so
  per channel

      F_c / (r N_c) = G_c + κ_c · x,   x = F_g / (r N_g) − 1   (green's flash over room)

  a line in ``x`` whose intercept, at no flash, is ``G_c``: the flash's share is extrapolated
  away, whatever its falloff, rather than assumed small anywhere. An error of ``r`` by a factor
  ``β`` moves ``G_c`` by ``(κ_c − G_c)(1 − 1/β)``: nothing when flash and room are one colour.
  (The intercept against the flat surface's flash falloff, tried first, needs the field of view
  and a diffuse falloff: 5 % off the field of view moved the gains 7–13 % on synthetic pairs.);
- ``N(registered)`` is the no-flash photo warped into the flash photo's crop
  (:func:`register_no_flash`: the views' feature registration, the flash highlight masked on the
  flash photo, only clipped pixels on the no-flash photo, a homography, and the checks of
  :func:`~brdfgan.inference.views.register.check_registration` that both show one surface).

Everything is computed in the flash photo's crop at the output side (:func:`pair_images`), in the
flash photo's linear units. Pixels clipped in either photo (any channel at :data:`CLIP_LEVEL` or
more) or outside the warped no-flash photo are not valid. Each check here returns a one-line
reason (a string) when the pair cannot serve; the caller then warns and takes the single-photo path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.clipped_fill import CLIP_LEVEL
from brdfgan.core.exposure import luminance
from brdfgan.inference.intake.exposure_settings import ExposureSettings
from brdfgan.inference.intake.photo import Photo
from brdfgan.inference.intake.preprocess import Crop, clipped_in_crop, resize_crop
from brdfgan.inference.views.geometry import texture_to_photo
from brdfgan.inference.views.register import (
    Registration,
    check_registration,
    detect_features,
    highlight_mask,
    homography_to_view,
)
from brdfgan.inference.views.warp import warp_to_reference

RatioSource = Literal["exif", "option"]
BalanceMethod = Literal["colour consistency", "assumed equal"]

# The pair cannot serve below these. The flash-only image is a difference: where the flash is
# under ~1/4 of the room light, the noise and the errors of r and G in the room's share swamp it.
MIN_FLASH_TO_ROOM = 0.25
# A no-flash photo whose median linear luminance is below this is mostly noise and quantisation
# (8-bit sRGB codes under ~25).
MIN_NO_FLASH_MEDIAN = 0.01
# Sharpness (the variance of the Laplacian of the log luminance, :func:`sharpness`) of the
# no-flash photo over the flash photo's: a shaken no-flash photo (a slower shutter) falls far
# below 1; different light changes it by much less (tests/inference/pair/test_pair_intake.py).
MIN_SHARPNESS_RATIO = 0.1
# The share of the crop the registered no-flash photo must cover, unclipped.
MIN_VALID_FRACTION = 0.5

# Sharpness is measured on copies this long (px), so that photos of different sizes compare.
SHARPNESS_LONG_SIDE = 1024
# The white balance is fitted on the crop area-averaged to at most this side (JPEG's block noise
# averages out before any ratio is taken: at 256² its gains were 2-5 % further off), in this many bins
# of green's flash-over-room ratio (quantiles), leaving out the flash's highlight (this fraction
# of the crop's side around the hotspot: a glossy surface's specular lobe has the flash's colour,
# not the albedo's) and room-lit values below ROOM_FLOOR (the flash photo's linear units: noise).
STATISTICS_SIDE = 64
BALANCE_BINS = 12
HIGHLIGHT_RADIUS_FRACTION = 0.1
ROOM_FLOOR = 2e-3
# The bins' flash-over-room ratios must span this share of the largest for the line to be
# extrapolated to no flash (a flash equally strong over the whole crop gives no line).
MIN_FLASH_SPAN = 0.2
# The channel a camera's white balance leaves alone (its gains are relative to green).
GREEN = 1
# Gains outside this range are not a white balance but a failed fit: none is applied.
GAIN_RANGE = (1.0 / 3.0, 3.0)
# The flash-to-room ratio is the median over the valid pixels within this fraction of the crop's
# side of the hotspot (where the fit reads the flash's shading).
NEAR_HOTSPOT_FRACTION = 0.25


@dataclass(frozen=True)
class ExposureRatio:
    """``r``: how much brighter the room light is in the flash photo than in the no-flash photo."""

    value: float
    source: RatioSource

    def to_json(self) -> dict[str, Any]:
        return {"value": self.value, "source": self.source}


def exposure_ratio(
    flash: ExposureSettings | None, no_flash: ExposureSettings | None, given: float | None = None
) -> ExposureRatio | str:
    """The flash photo's exposure over the no-flash photo's (``given``: ``--exposure-ratio``, which
    wins), or the one-line reason there is none."""
    if given is not None:
        return ExposureRatio(float(given), "option")
    missing = [
        name
        for name, settings in (("flash", flash), ("no-flash", no_flash))
        if settings is None or settings.exposure is None
    ]
    if missing or flash is None or no_flash is None or flash.exposure is None or no_flash.exposure is None:
        return (
            f"the {' and the '.join(missing)} photo's EXIF does not state its exposure "
            "(ExposureTime, ISO, FNumber): pass --exposure-ratio R"
        )
    return ExposureRatio(flash.exposure / no_flash.exposure, "exif")


def median_luminance(linear: Tensor) -> float:
    """The median linear luminance of a strided subsample (about 250 000 pixels).

    Shape: ``(3, H, W)``."""
    stride = max(1, math.ceil(math.sqrt(linear.shape[-1] * linear.shape[-2] / 250_000)))
    return float(luminance(linear[:, ::stride, ::stride].float()).median())


def sharpness(linear: Tensor) -> float:
    """The variance of the Laplacian of the log luminance of a copy at most
    :data:`SHARPNESS_LONG_SIDE` long (area-averaged). The log makes it independent of the exposure;
    its floor (1 % of the mean) keeps the shadows' noise from counting as detail.

    Shape: ``(3, H, W)``."""
    grey = luminance(linear.float())[0].numpy()
    height, width = grey.shape
    scale = min(1.0, SHARPNESS_LONG_SIDE / max(height, width))
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    small = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
    log = np.log(small + 0.01 * float(small.mean()) + 1e-12)
    return float(cv2.Laplacian(log, cv2.CV_32F).var())


def no_flash_problem(flash: Photo, no_flash: Photo) -> tuple[dict[str, float], str | None]:
    """The no-flash photo's median luminance and sharpness over the flash photo's, and the
    one-line reason it cannot serve (too dark, blurred) or ``None``."""
    median = median_luminance(no_flash.linear)
    flash_sharpness = sharpness(flash.linear)
    ratio = sharpness(no_flash.linear) / flash_sharpness if flash_sharpness > 0 else 1.0
    measures = {"median_luminance": median, "sharpness_ratio": ratio}
    if median < MIN_NO_FLASH_MEDIAN:
        return measures, (
            f"the no-flash photo is too dark (median linear luminance {median:.4f}, at least "
            f"{MIN_NO_FLASH_MEDIAN} needed): expose it longer or light the room"
        )
    if ratio < MIN_SHARPNESS_RATIO:
        return measures, (
            f"the no-flash photo is blurred ({ratio:.2f}× the flash photo's sharpness, at least "
            f"{MIN_SHARPNESS_RATIO} needed): hold the phone still or rest it"
        )
    return measures, None


def feature_exclusion_mask(linear: Tensor) -> np.ndarray:
    """255 on the pixels at :data:`CLIP_LEVEL` or more in any channel, dilated by 0.5 % of the long
    side (at least 3 px), else 0: where no feature is taken on the no-flash photo, which has no
    flash highlight to mask (OpenCV's mask on the full-size photo; the maps' clipped pixels are
    :func:`~brdfgan.core.clipped_fill.clipped_mask`'s).

    Shape: ``(3, H, W)`` → ``(H, W)`` uint8."""
    clipped = (linear >= CLIP_LEVEL).any(dim=0).numpy().astype(np.uint8) * 255
    radius = max(3, round(0.005 * max(clipped.shape)))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    return np.asarray(cv2.dilate(clipped, kernel))


def crop_corners(crop: Crop) -> np.ndarray:
    """The crop square's corners in the photo's pixels, in order. Shape: ``(4, 2)``."""
    x0, y0, x1, y1 = crop.x, crop.y, crop.x + crop.size, crop.y + crop.size
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


def register_no_flash(flash: Photo, no_flash: Photo, crop: Crop) -> Registration | str:
    """The homography from the flash photo's pixels to the no-flash photo's (features away from the
    flash highlight and the clipped pixels), checked by ``check_registration`` on the flash photo's
    ``crop``; or the one-line reason the two do not show one surface."""
    features = detect_features(luminance(flash.linear)[0].numpy(), highlight_mask(flash.linear))
    excluded = feature_exclusion_mask(no_flash.linear)
    found = homography_to_view(features, luminance(no_flash.linear)[0].numpy(), excluded)
    if found is None:
        return "too few features match the flash photo's: a different surface, or the phone moved too much"
    reason = check_registration(
        found, crop_corners(crop), no_flash.width, no_flash.height, reference_size=(flash.width, flash.height)
    )
    if reason is not None:
        return f"{reason}: not one surface, or the phone moved too much"
    return found


def registration_record(registration: Registration) -> dict[str, Any]:
    """``material.json``'s record of the no-flash photo's registration (the homography maps the
    flash photo's pixels to the no-flash photo's, pixel j's centre at j + ½)."""
    return {
        "method": registration.method,
        "inliers": registration.inliers,
        "inlier_ratio": registration.inlier_ratio,
        "reprojection_px": registration.reprojection_px,
        "homography": [[float(v) for v in row] for row in registration.homography],
    }


@dataclass(frozen=True)
class WhiteBalance:
    """Per-channel gains that take the no-flash photo's colour to the flash photo's (module
    docstring), how they were found, and ``flash_colour``: the fitted ``κ`` (the flash-only
    colour over the no-flash photo's, green = 1; ``None`` when no fit)."""

    gains: tuple[float, float, float]
    method: BalanceMethod
    flash_colour: tuple[float, float, float] | None = None

    def to_json(self) -> dict[str, Any]:
        colour = None if self.flash_colour is None else list(self.flash_colour)
        return {"gains": list(self.gains), "method": self.method, "flash_colour": colour}


EQUAL_BALANCE = WhiteBalance((1.0, 1.0, 1.0), "assumed equal")


def _area_shrink(image: Tensor, side: int) -> Tensor:
    return F.adaptive_avg_pool2d(image[None].float(), side)[0] if image.shape[-1] > side else image.float()


def white_balance(flash: Tensor, room: Tensor, valid: Tensor, frame: Tensor) -> WhiteBalance:
    """The gains ``G`` (module docstring) from the flash photo's crop and ``room`` = ``r`` times the
    registered no-flash photo, in its units: per channel, the intercept at ``x = 0`` of a line
    through the middle means (:func:`_middle_mean`) of ``flash / room`` and of ``x`` in
    :data:`BALANCE_BINS` bins of ``x``. With too few pixels, too narrow a spread of ``x`` (less
    than :data:`MIN_FLASH_SPAN` of its largest) or gains out of :data:`GAIN_RANGE`: none
    (:data:`EQUAL_BALANCE`).

    Shape: flash, room ``(3, N, N)``; valid ``(1, N, N)``; frame ``(1, 3)`` of the crop."""
    side = int(flash.shape[-1])
    small = min(side, STATISTICS_SIDE)
    flash_s, room_s = _area_shrink(flash, small), _area_shrink(room, small)
    # A shrunk pixel is valid when every pixel under it is.
    valid_s = _area_shrink(valid, small) >= 1.0 - 1e-6
    hotspot = frame[0, :2].float() * (small / side)
    centre = torch.stack(torch.meshgrid(torch.arange(small) + 0.5, torch.arange(small) + 0.5, indexing="xy"))
    distance = torch.linalg.vector_norm(centre - hotspot[:, None, None], dim=0)[None]
    usable = (
        valid_s
        & (distance > HIGHLIGHT_RADIUS_FRACTION * small)
        & (room_s > ROOM_FLOOR).all(dim=0, keepdim=True)
        & (flash_s > 0).all(dim=0, keepdim=True)
    )[0]
    if int(usable.sum()) < 4 * BALANCE_BINS:
        return EQUAL_BALANCE
    ratio = (flash_s / room_s)[:, usable].double()  # (3, P)
    flash_over_room = ratio[GREEN] - 1.0
    edges = torch.quantile(flash_over_room, torch.linspace(0, 1, BALANCE_BINS + 1, dtype=torch.float64))
    bins = torch.bucketize(flash_over_room, edges[1:-1])
    x, y = [], []
    for index in range(BALANCE_BINS):
        members = bins == index
        if int(members.sum()) >= 3:
            x.append(float(_middle_mean(flash_over_room[members][None])[0]))
            y.append(_middle_mean(ratio[:, members]))
    if len(x) < 2:
        return EQUAL_BALANCE
    xs, ys = torch.tensor(x, dtype=torch.float64), torch.stack(y, dim=1)  # (B,), (3, B)
    if not float(xs.max() - xs.min()) >= MIN_FLASH_SPAN * max(float(xs.abs().max()), 1e-12):
        return EQUAL_BALANCE
    design = torch.stack([torch.ones_like(xs), xs], dim=1)  # (B, 2)
    intercepts, slopes = torch.linalg.lstsq(design, ys.T).solution  # (3,) each
    # Green's line is y = x + 1 by construction; dividing by it removes the rounding.
    if not (float(intercepts[GREEN]) > 0 and float(slopes[GREEN]) > 0):
        return EQUAL_BALANCE
    gains = intercepts / intercepts[GREEN]
    colour = slopes / slopes[GREEN] if bool((slopes > 0).all()) else None
    low, high = GAIN_RANGE
    if not all(low <= float(gain) <= high for gain in gains):
        return EQUAL_BALANCE
    return WhiteBalance(
        (float(gains[0]), float(gains[1]), float(gains[2])),
        "colour consistency",
        None if colour is None else (float(colour[0]), float(colour[1]), float(colour[2])),
    )


def _middle_mean(values: Tensor) -> Tensor:
    """Per row, the mean of the values between the row's quartiles: robust to glints and
    misregistered edges like a median, but a bin whose pixels lie in two groups (the crop's
    corners, under a room light brighter on one side) gets the middle of both, not one of them.

    Shape: ``(C, P)`` → ``(C,)``."""
    low, high = torch.quantile(values, torch.tensor([0.25, 0.75], dtype=values.dtype), dim=1)
    inside = (values >= low[:, None]) & (values <= high[:, None])
    return (values * inside).sum(dim=1) / inside.sum(dim=1).clamp_min(1)


def flash_to_room(flash_only: Tensor, room: Tensor, valid: Tensor, frame: Tensor) -> float:
    """The median of the flash-only luminance over the room's, over the valid pixels within
    :data:`NEAR_HOTSPOT_FRACTION` of the crop's side of the hotspot (all valid pixels when none
    is that near); NaN when no pixel is valid.

    Shape: flash_only, room ``(3, N, N)``; valid ``(1, N, N)``; frame ``(1, 3)``."""
    side = int(flash_only.shape[-1])
    centre = torch.stack(torch.meshgrid(torch.arange(side) + 0.5, torch.arange(side) + 0.5, indexing="xy"))
    distance = torch.linalg.vector_norm(centre - frame[0, :2, None, None].float(), dim=0)
    usable = valid[0] > 0.5
    near = usable & (distance <= NEAR_HOTSPOT_FRACTION * side)
    chosen = near if bool(near.any()) else usable
    if not bool(chosen.any()):
        return math.nan
    ratio = luminance(flash_only.float())[0] / luminance(room.float())[0].clamp_min(1e-6)
    return float(ratio[chosen].median())


@dataclass(frozen=True)
class PairImages:
    """The pair in the flash photo's crop at the output side, in the flash photo's linear units.

    Attributes:
        flash: ``(3, N, N)`` the flash photo's crop.
        room: ``(3, N, N)`` the room light's share of it: ``r · G ·`` the registered no-flash photo
            (0 where unseen).
        flash_only: ``(3, N, N)`` ``flash − room`` (not clamped; unseen pixels are the flash photo's).
        valid: ``(1, N, N)`` float 0/1: seen by the no-flash photo, clipped in neither.
        white_balance: the gains ``G``.
        flash_to_room: :func:`flash_to_room`.
    """

    flash: Tensor
    room: Tensor
    flash_only: Tensor
    valid: Tensor
    white_balance: WhiteBalance
    flash_to_room: float

    @property
    def valid_fraction(self) -> float:
        return float(self.valid.mean())


def pair_images(
    flash: Photo,
    no_flash: Photo,
    registration: Registration,
    crop: Crop,
    side: int,
    ratio: float,
    frame: Tensor,
) -> PairImages:
    """The flash photo's ``crop`` resized to ``side`` as preprocessing resizes it, the no-flash photo
    warped into it through ``registration``, the white balance fitted, and the flash-only image.

    Shape: frame ``(1, 3)`` of the ``side × side`` crop; outputs :class:`PairImages`."""
    flash_crop = resize_crop(crop.slice(flash.linear).float(), side)
    # Any clipped photo pixel under an output pixel makes it clipped.
    flash_clipped = clipped_in_crop(flash.linear, crop, side)
    no_flash_from_crop = registration.homography @ texture_to_photo(crop, side)
    warped, seen = warp_to_reference(no_flash.linear, no_flash_from_crop, side)
    no_flash_clipped = no_flash.linear >= CLIP_LEVEL
    valid = seen * (~flash_clipped).float()
    if bool(no_flash_clipped.any()):  # rare in a no-flash photo: the second warp only when needed
        clipped_warped, _ = warp_to_reference(no_flash_clipped.float(), no_flash_from_crop, side)
        valid = valid * (clipped_warped <= 0).all(dim=0, keepdim=True).float()
    balance = white_balance(flash_crop, ratio * warped, valid, frame)
    gains = torch.tensor(balance.gains, dtype=torch.float32)[:, None, None]
    room = ratio * gains * warped
    # Where the no-flash photo does not see, the flash photo itself (the room light left in).
    flash_only = torch.where(seen > 0, flash_crop - room, flash_crop)
    return PairImages(
        flash=flash_crop,
        room=room,
        flash_only=flash_only,
        valid=valid,
        white_balance=balance,
        flash_to_room=flash_to_room(flash_only, room, valid, frame),
    )


def pair_problem(images: PairImages) -> str | None:
    """The one-line reason the registered pair cannot serve (too little of the crop valid, the
    flash too weak against the room light), or ``None``."""
    if images.valid_fraction < MIN_VALID_FRACTION:
        return (
            f"only {images.valid_fraction:.0%} of the crop is seen unclipped in both photos "
            f"(at least {MIN_VALID_FRACTION:.0%} needed)"
        )
    ratio = images.flash_to_room
    if not ratio >= MIN_FLASH_TO_ROOM:  # NaN too
        return (
            f"the flash is only {ratio:.2f}× the room light near its hotspot (at least "
            f"{MIN_FLASH_TO_ROOM}× needed): get closer or dim the room"
        )
    return None
