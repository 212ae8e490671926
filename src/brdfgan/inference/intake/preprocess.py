"""From a decoded photo to the generator's input, like the paper's capture and training data.

The paper (§6.1) exported RAW photos linearly and cropped them 1:1 with the camera flash roughly
at the centre; the training inputs were rendered HDR images auto-exposed to linear LDR (appendix,
docs/conventions.md#auto-exposure). :func:`preprocess` does the same to a
:class:`~brdfgan.inference.intake.photo.Photo`:

1. **Crop.** Either the user's ``x,y,size`` square (validated against the photo), or the square
   chosen by :func:`hotspot_crop` around the flash highlight found by :func:`find_hotspot`.
2. **Resize** the crop to ``resolution`` in *linear* space (averaging sRGB-encoded values would
   darken edges and textures): an exact box average for integer factors, an antialiased
   (triangle-filter) bilinear downscale otherwise, bicubic upscaling with a warning when the crop
   is smaller than the network's input.
3. **Expose** with the training's :func:`~brdfgan.core.exposure.auto_expose`, which is
   scale-invariant, so the camera's own exposure does not matter; it also clips to [0, 1].
   Exposure comes *after* resizing because that is what training did: the renderer produced an
   HDR image at the network's resolution (pixel filtering happens on unclipped radiance) and
   only then was it exposed and clipped. For LDR sources already clipped at 1 it is applied all
   the same. The image mean, which sets the exposure, is preserved by the box average.

Warnings: a clipped flash hotspot (LDR sources only: for EXR there is no saturation level), a
hotspot far from the crop centre, upscaling. An all-black crop is an error (nothing to estimate).

Memory stays bounded on 24 MP photos: the hotspot search runs on a copy downscaled to at most
:data:`HOTSPOT_WORKING_SIZE` pixels, statistics on a strided subsample, and only the cropped region
is resized.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.clipped_fill import CLIP_LEVEL
from brdfgan.core.exposure import SATURATION_LEVEL, auto_expose, luminance
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.flash_geometry import pixel_scale
from brdfgan.inference.intake.photo import Photo, PhotoError

__all__ = [
    "CLIPPED_WARNING_FRACTION",
    "CLIP_DISC_FRACTION",
    "HOTSPOT_SIGMA_FRACTION",
    "HOTSPOT_WORKING_SIZE",
    "OFF_CENTRE_WARNING_FRACTION",
    "Crop",
    "Preprocessed",
    "clipped_fraction",
    "find_hotspot",
    "hotspot_crop",
    "preprocess",
    "resize_crop",
]

# Hotspot search: long side of the downscaled working copy, blur sigma as a fraction of its long
# side, the luminance quantile that caps tiny bright specks, and the top share of the blurred
# range whose centroid refines the argmax.
HOTSPOT_WORKING_SIZE = 512
HOTSPOT_SIGMA_FRACTION = 0.025
HOTSPOT_CLAMP_QUANTILE = 0.99
HOTSPOT_PEAK_FRACTION = 0.9

# Clipping check: a value at or above core.exposure.SATURATION_LEVEL counts as clipped; the disc
# around the hotspot has this radius as a fraction of the crop side; warn when more than this
# fraction of the disc is clipped.
CLIP_DISC_FRACTION = 0.05
CLIP_DISC_MIN_RADIUS = 2.0
CLIPPED_WARNING_FRACTION = 0.01

# Warn when the hotspot lies farther than this fraction of the crop side from the crop centre.
OFF_CENTRE_WARNING_FRACTION = 0.1
# A detected highlight must be this much brighter (mean luminance in the clipping disc) than the
# image centre to move the crop; otherwise it is texture or environment light, not the flash.
MIN_HOTSPOT_OVER_CENTRE = 2.0
# A square centred on the hotspot at least this fraction of the short side counts as "the flash
# roughly at the centre" (paper §6.1): the whole central square is used, nothing is upscaled.
CENTRED_SNAP_FRACTION = 0.9
_STATISTICS_PIXELS = 1_000_000


@dataclass(frozen=True)
class Crop:
    """A square region of the (oriented) photo: top-left corner ``(x, y)`` and side ``size``."""

    x: int
    y: int
    size: int

    def __post_init__(self) -> None:
        for name in ("x", "y", "size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"crop {name} must be an integer, got {value!r}")
        if self.x < 0 or self.y < 0:
            raise ValueError(f"crop corner must not be negative, got x={self.x}, y={self.y}")
        if self.size < 1:
            raise ValueError(f"crop size must be positive, got {self.size}")

    @classmethod
    def parse(cls, text: str) -> Crop:
        """``"x,y,size"`` (integers, spaces allowed) → :class:`Crop`; one-line ``ValueError`` otherwise."""
        parts = [part.strip() for part in str(text).split(",")]
        try:
            if len(parts) != 3:
                raise ValueError
            x, y, size = (int(part) for part in parts)
            return cls(x, y, size)
        except ValueError as error:
            detail = f" ({error})" if str(error) else ""
            raise ValueError(
                f"invalid crop {text!r}: expected 'x,y,size' with integers x, y >= 0 and size > 0{detail}"
            ) from None

    def check(self, height: int, width: int) -> None:
        """Raise a one-line ``ValueError`` when the square does not lie inside a ``width × height`` image."""
        if self.x + self.size > width or self.y + self.size > height:
            raise ValueError(
                f"crop {self.x},{self.y},{self.size} (x,y,size) does not fit in the {width}×{height} photo: "
                f"it reaches x={self.x + self.size}, y={self.y + self.size}"
            )

    def slice(self, image: Tensor) -> Tensor:
        """The cropped view. Shape: ``(*, H, W)`` → ``(*, size, size)``."""
        return image[..., self.y : self.y + self.size, self.x : self.x + self.size]


@dataclass(frozen=True)
class CropSized:
    """An output side that follows the crop: its side in photo pixels (no detail is invented or
    thrown away), clamped to ``[minimum, maximum]`` — ``brdfgan predict``'s default resolution."""

    minimum: int
    maximum: int

    def __post_init__(self) -> None:
        if not 1 <= self.minimum <= self.maximum:
            raise ValueError(f"CropSized needs 1 <= minimum <= maximum, got {self.minimum}, {self.maximum}")

    def side(self, crop_size: int) -> int:
        return min(max(crop_size, self.minimum), self.maximum)


@dataclass(frozen=True)
class Preprocessed:
    """The generator's input and how it was made.

    Attributes:
        photo: ``(3, N, N)`` float32 linear LDR in [0, 1].
        crop: the square taken from the oriented photo.
        hotspot: the detected flash highlight ``(x, y)`` in photo pixels; ``None`` when the user
            gave the crop (the highlight found inside it is still in ``stats``).
        exposure_scale: the auto-exposure multiplier applied to the resized crop.
        resized_from: the crop side before resizing.
        stats: input statistics for ``material.json``, all floats: ``mean_luminance``,
            ``median_luminance``, ``p99_luminance``, ``max_luminance`` (of the crop, linear,
            before exposure), ``hotspot_x``, ``hotspot_y``, ``hotspot_offset`` (distance from the
            crop centre / crop side), ``exposure_scale``, ``output_clipped_fraction`` (share of
            output pixels the exposure clipped at 1), and ``clipped_fraction`` only when the
            source has a saturation level (not for EXR).
        warnings: human-readable warnings for the user.
        chosen: how the crop was placed: ``"user"`` (``--crop``), ``"flash hotspot"``, or
            ``"image centre"`` when no highlight stood out from the centre.
    """

    photo: Tensor
    crop: Crop
    hotspot: tuple[float, float] | None
    exposure_scale: float
    resized_from: int
    stats: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    chosen: str = "flash hotspot"

    def flash_frame(self, fov_deg: float) -> Tensor:
        """The :mod:`flash frame <brdfgan.core.flash_geometry>` of :attr:`photo`: the detected
        highlight (``stats``; the image centre when none stood out) moved into the crop and scaled
        to the network's resolution, with the horizontal field of view ``fov_deg`` across the crop.

        Shape: output ``(1, 3)``.
        """
        size = int(self.photo.shape[-1])
        factor = size / self.crop.size
        # find_hotspot puts pixel i at i; the frame puts its centre at i + 0.5.
        x = (self.stats["hotspot_x"] + 0.5 - self.crop.x) * factor
        y = (self.stats["hotspot_y"] + 0.5 - self.crop.y) * factor
        return torch.tensor([[x, y, pixel_scale(fov_deg, size)]], dtype=torch.float32)

    def to_json(self) -> dict[str, Any]:
        """The ``crop``, ``resolution``, ``resized_from`` and ``exposure_scale`` entries of
        ``material.json`` (``input_statistics`` is :attr:`stats`)."""
        return {
            "crop": {
                "x": self.crop.x,
                "y": self.crop.y,
                "size": self.crop.size,
                "chosen": self.chosen,
                "hotspot": list(self.hotspot) if self.hotspot is not None else None,
            },
            "resolution": int(self.photo.shape[-1]),
            "resized_from": self.resized_from,
            "exposure_scale": self.exposure_scale,
        }


def find_hotspot(linear: Tensor) -> tuple[float, float]:
    """The centre ``(x, y)`` of the flash highlight, in pixel coordinates (pixel ``i`` is at ``i``).

    Robust to texture, noise and small bright specks: the image is area-downscaled to at most
    :data:`HOTSPOT_WORKING_SIZE` pixels, its luminance capped at the 99th percentile (a speck of
    any brightness then weighs no more than the brightest 1 % of the image), blurred with a
    Gaussian of sigma 2.5 % of the long side (normalised convolution, so borders are not
    darkened and a hotspot near an edge is not pulled inwards), and the argmax refined by the
    weighted centroid of the blurred values in the top 10 % of their range near it. An image
    without any variation gives its centre.

    Shape:
        - linear: ``(3, H, W)`` linear RGB, any non-negative scale
        - output: ``(x, y)`` floats
    """
    _check_image(linear)
    height, width = linear.shape[-2:]
    factor = max(1, math.ceil(max(height, width) / HOTSPOT_WORKING_SIZE))
    small = linear[None].float()
    if factor > 1:
        # Adaptive average pooling reads the full image once and allocates only the small copy.
        small = F.adaptive_avg_pool2d(small, (math.ceil(height / factor), math.ceil(width / factor)))
    small_h, small_w = small.shape[-2:]
    lum = luminance(small)[0, 0].clamp(min=0.0)
    cap = torch.quantile(lum.flatten(), HOTSPOT_CLAMP_QUANTILE)
    lum = torch.minimum(lum, cap)

    sigma = max(1.0, HOTSPOT_SIGMA_FRACTION * max(small_h, small_w))
    blurred = gaussian_blur(lum[None, None], sigma) / gaussian_blur(torch.ones_like(lum)[None, None], sigma)
    blurred = blurred[0, 0]
    top, bottom = float(blurred.max()), float(blurred.min())
    # Relative test: the normalised blur of a flat image differs from flat by rounding only.
    if not top - bottom > 1e-5 * abs(top):
        return ((width - 1) / 2.0, (height - 1) / 2.0)

    index = int(torch.argmax(blurred))
    iy, ix = divmod(index, small_w)
    # Centroid of the peak's neighbourhood (2 sigma) above 90 % of the blurred range: sub-pixel
    # precision on the working copy, and a second bright region elsewhere cannot shift it.
    radius = math.ceil(2.0 * sigma)
    y0, y1 = max(0, iy - radius), min(small_h, iy + radius + 1)
    x0, x1 = max(0, ix - radius), min(small_w, ix + radius + 1)
    window = blurred[y0:y1, x0:x1]
    weights = (window - (bottom + HOTSPOT_PEAK_FRACTION * (top - bottom))).clamp(min=0.0)
    ys = torch.arange(y0, y1, dtype=weights.dtype)[:, None]
    xs = torch.arange(x0, x1, dtype=weights.dtype)[None, :]
    total = weights.sum()
    if not total > 0:  # a one-pixel plateau: the argmax itself is the best estimate
        cx, cy = float(ix), float(iy)
    else:
        cy = float((weights * ys).sum() / total)
        cx = float((weights * xs).sum() / total)
    # Back to full-resolution pixel coordinates: pixel centres sit at (i + 0.5) · scale − 0.5.
    return ((cx + 0.5) * width / small_w - 0.5, (cy + 0.5) * height / small_h - 0.5)


def hotspot_crop(height: int, width: int, hotspot: tuple[float, float]) -> Crop:
    """The square crop around the flash highlight.

    Policy: the largest square centred on the hotspot that fits in the image (the paper's capture
    has the flash roughly at the centre of a 1:1 crop). When the hotspot is so close to an edge
    that this square would be smaller than half of ``min(height, width)``, the square keeps that
    minimum side and is shifted into the image instead (the hotspot is then off-centre; a tiny
    crop of a corner is worse than an off-centre highlight). A centred square of at least
    :data:`CENTRED_SNAP_FRACTION` of the short side becomes the whole central square (the flash
    is "roughly at the centre"; nothing is thrown away or upscaled for a pixel or two). The side
    never exceeds ``min(height, width)``.
    """
    if height < 1 or width < 1:
        raise ValueError(f"image size must be positive, got {width}×{height}")
    hx, hy = (float(v) for v in hotspot)
    if not (math.isfinite(hx) and math.isfinite(hy)):
        raise ValueError(f"hotspot must be finite, got {hotspot}")
    # Edge coordinates: pixel i spans [i, i + 1), so the hotspot pixel centre is at i + 0.5.
    cx, cy = hx + 0.5, hy + 0.5
    shortest = min(height, width)
    largest_centred = math.floor(2.0 * min(cx, width - cx, cy, height - cy))
    if largest_centred >= CENTRED_SNAP_FRACTION * shortest:
        largest_centred = shortest
    size = min(shortest, max(largest_centred, math.ceil(shortest / 2)))
    x = min(max(math.floor(cx - size / 2 + 0.5), 0), width - size)
    y = min(max(math.floor(cy - size / 2 + 0.5), 0), height - size)
    return Crop(x, y, size)


def disc_luminance(linear: Tensor, centre: tuple[float, float]) -> float:
    """Mean luminance in the clipping-check disc around ``centre``.

    Shape:
        - linear: ``(3, H, W)``
    """
    height, width = linear.shape[-2:]
    radius = max(CLIP_DISC_MIN_RADIUS, CLIP_DISC_FRACTION * min(height, width))
    x0, x1 = max(0, math.floor(centre[0] - radius)), min(width, math.ceil(centre[0] + radius) + 1)
    y0, y1 = max(0, math.floor(centre[1] - radius)), min(height, math.ceil(centre[1] + radius) + 1)
    window = luminance(linear[:, y0:y1, x0:x1].float())[0]
    ys = torch.arange(y0, y1, dtype=torch.float32)[:, None]
    xs = torch.arange(x0, x1, dtype=torch.float32)[None, :]
    inside = (xs - centre[0]) ** 2 + (ys - centre[1]) ** 2 <= radius * radius
    return float(window[inside].mean())


def flash_centre(linear: Tensor, detected: tuple[float, float]) -> tuple[tuple[float, float], float]:
    """Where to centre the crop: the detected highlight, or the image centre when the highlight
    is not clearly brighter than the centre (a phone's flash sits beside the lens, so without a
    distinct highlight — rough or dark materials, bright environment light — the flash is at
    the centre). Returns the point and the highlight's brightness over the centre's.

    Shape:
        - linear: ``(3, H, W)``
    """
    height, width = linear.shape[-2:]
    centre = ((width - 1) / 2.0, (height - 1) / 2.0)
    if math.hypot(detected[0] - centre[0], detected[1] - centre[1]) <= CLIP_DISC_FRACTION * min(
        height, width
    ):
        return detected, 1.0  # the highlight is at the centre already: nothing to decide
    at_centre, at_detected = disc_luminance(linear, centre), disc_luminance(linear, detected)
    # Never 0/0 (NaN, which would also print as "nan×"): a dark detected spot is no highlight, a
    # lit spot over a black centre is one however bright it is.
    if not at_detected > 0:
        ratio = 0.0
    elif not at_centre > 0:
        ratio = math.inf
    else:
        ratio = at_detected / at_centre
    return (detected if ratio >= MIN_HOTSPOT_OVER_CENTRE else centre), ratio


def clipped_fraction(linear: Tensor, crop: Crop, hotspot: tuple[float, float]) -> float:
    """Share of pixels with any channel at or above :data:`SATURATION_LEVEL` in a disc around the hotspot.

    The disc's radius is :data:`CLIP_DISC_FRACTION` of the crop side (at least
    ``CLIP_DISC_MIN_RADIUS`` pixels), so it covers the highlight whatever the photo's resolution;
    it is cut to the image. Meaningful for sources where 1.0 is saturation (JPEG/PNG/RAW).

    Shape:
        - linear: ``(3, H, W)`` source values (before exposure)
    """
    _check_image(linear)
    height, width = linear.shape[-2:]
    radius = max(CLIP_DISC_MIN_RADIUS, CLIP_DISC_FRACTION * crop.size)
    hx, hy = (float(v) for v in hotspot)
    x0, x1 = max(0, math.floor(hx - radius)), min(width, math.ceil(hx + radius) + 1)
    y0, y1 = max(0, math.floor(hy - radius)), min(height, math.ceil(hy + radius) + 1)
    if x0 >= x1 or y0 >= y1:
        return 0.0
    ys = torch.arange(y0, y1, dtype=torch.float32)[:, None]
    xs = torch.arange(x0, x1, dtype=torch.float32)[None, :]
    disc = (xs - hx) ** 2 + (ys - hy) ** 2 <= radius**2
    if not disc.any():
        return 0.0
    saturated = (linear[:, y0:y1, x0:x1] >= SATURATION_LEVEL).any(dim=0)
    return float(saturated[disc].float().mean())


def preprocess(
    photo: Photo, resolution: int | CropSized, crop: Crop | None = None, *, clipped_is_saturated: bool = True
) -> Preprocessed:
    """Crop, resize (linear) and auto-expose a photo into the generator's input.

    Args:
        photo: the decoded photo (:func:`~brdfgan.inference.intake.photo.read_photo`).
        resolution: the side N of the network input, or a rule that sets it from the crop's side.
        crop: a user-given square (validated against the photo); ``None`` chooses one around the
            flash highlight with :func:`hotspot_crop`.
        clipped_is_saturated: whether source values at 1.0 mean sensor saturation, which enables
            the clipped-hotspot check. It is never run for EXR photos (HDR has no saturation).

    Raises:
        PhotoError: the crop does not fit in the photo, or it is black (one line, naming the file).
        ValueError: ``resolution`` is not a positive integer.

    Shape:
        - ``photo.linear``: ``(3, H, W)``
        - output ``Preprocessed.photo``: ``(3, N, N)`` float32 in [0, 1]
    """
    if not isinstance(resolution, CropSized) and (
        isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 1
    ):
        raise ValueError(f"resolution must be a positive integer, got {resolution!r}")
    _check_image(photo.linear)
    warnings: list[str] = []
    placement = _place_crop(photo, crop, warnings)
    crop = placement.crop
    region = crop.slice(photo.linear)
    if isinstance(resolution, CropSized):
        resolution = resolution.side(crop.size)
    stats = _hotspot_stats(photo, region, placement, warnings, clipped_is_saturated=clipped_is_saturated)

    resized = resize_crop(region.float(), resolution)
    if crop.size < resolution:
        warnings.append(
            f"upscaled from {crop.size}×{crop.size} to {resolution}×{resolution} pixels: "
            f"the crop has fewer pixels than the network input, so fine detail is missing"
        )
    # Bicubic overshoot can go below 0; the exposure meter must not see negative light.
    ldr, scale = auto_expose(resized.clamp(min=0.0))
    exposure_scale = float(scale)
    if exposure_scale == 0.0:
        # read_photo refuses black photos; a black region of a lit one (a user crop) gets here.
        where = "the given crop" if placement.hotspot is None else "the automatic crop"
        raise PhotoError(
            photo.path,
            f"{where} ({crop.x},{crop.y},{crop.size}) is black: nothing to estimate; pass another --crop",
        )
    stats["exposure_scale"] = exposure_scale
    stats["output_clipped_fraction"] = float((ldr >= 1.0).any(dim=0).float().mean())
    return Preprocessed(
        photo=ldr.to(torch.float32).contiguous(),
        crop=crop,
        hotspot=placement.hotspot,
        exposure_scale=exposure_scale,
        resized_from=crop.size,
        stats=stats,
        warnings=tuple(warnings),
        chosen=placement.chosen,
    )


@dataclass(frozen=True)
class _Placement:
    """Where :func:`preprocess` crops, and why."""

    crop: Crop
    detected: tuple[float, float]  # the flash highlight (x, y) in the photo's pixels
    over_centre: float | None  # the highlight's brightness over the image centre's; None: a user crop
    chosen: str  # Preprocessed.chosen

    @property
    def hotspot(self) -> tuple[float, float] | None:
        """Preprocessed.hotspot: the point the automatic crop is centred on; ``None``: a user crop."""
        return None if self.chosen == "user" else self.detected


def _place_crop(photo: Photo, crop: Crop | None, warnings: list[str]) -> _Placement:
    """The user's ``crop`` checked against the photo, or a crop around the flash highlight (around
    the image centre, with a warning, when no highlight stands out)."""
    linear = photo.linear
    height, width = linear.shape[-2:]
    if crop is not None:
        try:
            crop.check(height, width)
        except ValueError as error:
            raise PhotoError(photo.path, str(error)) from None
        # The highlight inside the user's crop still drives the clipping check and the stats.
        hx, hy = find_hotspot(crop.slice(linear))
        return _Placement(crop, (crop.x + hx, crop.y + hy), None, "user")
    found = find_hotspot(linear)
    detected, over_centre = flash_centre(linear, found)
    if detected != found:
        warnings.append(
            f"no distinct flash highlight (the brightest spot, at ({found[0]:.0f}, {found[1]:.0f}), "
            f"is only {over_centre:.2f}× as bright as the centre): cropped around the image centre; "
            "pass --crop to choose"
        )
    chosen = "flash hotspot" if detected == found else "image centre"
    return _Placement(hotspot_crop(height, width, detected), detected, over_centre, chosen)


def _hotspot_stats(
    photo: Photo, region: Tensor, placement: _Placement, warnings: list[str], *, clipped_is_saturated: bool
) -> dict[str, float]:
    """The crop ``region``'s luminance statistics with where its hotspot lies and (where 1.0 means
    saturation) how much of it is clipped; a warning when it is far off-centre or clipped."""
    crop, detected = placement.crop, placement.detected
    centre = (crop.x + (crop.size - 1) / 2.0, crop.y + (crop.size - 1) / 2.0)
    offset = math.hypot(detected[0] - centre[0], detected[1] - centre[1]) / crop.size
    if offset > OFF_CENTRE_WARNING_FRACTION:
        warnings.append(
            f"the flash hotspot at ({detected[0]:.0f}, {detected[1]:.0f}) is {offset:.0%} of the crop side "
            f"away from the crop centre; the network expects the flash near the centre"
        )

    stats = _luminance_stats(region)
    stats.update(hotspot_x=float(detected[0]), hotspot_y=float(detected[1]), hotspot_offset=float(offset))
    if placement.over_centre is not None and math.isfinite(placement.over_centre):
        stats["hotspot_over_centre"] = float(placement.over_centre)
    if clipped_is_saturated and photo.source != "exr":
        fraction = clipped_fraction(photo.linear, crop, detected)
        stats["clipped_fraction"] = fraction
        if fraction > CLIPPED_WARNING_FRACTION:
            warnings.append(
                f"flash hotspot is clipped ({fraction:.1%} of the pixels within {CLIP_DISC_FRACTION:.0%} "
                f"of the crop's side of it saturated): the highlight's shape and the roughness "
                f"estimate suffer; lower the exposure"
            )
    return stats


def _check_image(linear: Tensor) -> None:
    if not isinstance(linear, Tensor):
        raise ValueError(f"expected a linear RGB tensor of shape (3, H, W), got {type(linear).__name__}")
    check_shape(linear, "3 H W", name="linear RGB image")
    if linear.shape[1] < 1 or linear.shape[2] < 1:
        raise ValueError(f"expected a non-empty image, got shape {tuple(linear.shape)}")


def resize_crop(region: Tensor, resolution: int) -> Tensor:
    """Linear-space resize of a square crop, as :func:`preprocess` resizes the photo's (other
    images of the crop, e.g. a pair's registered no-flash photo, follow it exactly).

    Shape: ``(C, S, S)`` → ``(C, N, N)``."""
    size = region.shape[-1]
    if size == resolution:
        return region.clone()
    batch = region[None]
    if size % resolution == 0:
        # Exact box average: each output pixel is the mean of its (size / N)² source pixels.
        out = F.avg_pool2d(batch, size // resolution)
    elif size > resolution:
        out = F.interpolate(batch, size=(resolution, resolution), mode="bilinear", antialias=True)
    else:
        out = F.interpolate(batch, size=(resolution, resolution), mode="bicubic", align_corners=False)
    return out[0]


def clipped_in_crop(linear: Tensor, crop: Crop, side: int) -> Tensor:
    """The output pixels of ``crop`` resized to ``side`` (as :func:`resize_crop` resizes it) with a
    clipped source pixel under them: any channel at :data:`~brdfgan.core.clipped_fill.CLIP_LEVEL`
    or more. Meaningful for sources where 1.0 is saturation (not EXR).

    Shape: ``(3, H, W)`` source values → ``(1, N, N)`` bool."""
    clipped = crop.slice((linear >= CLIP_LEVEL).any(dim=0, keepdim=True)).float()
    return resize_crop(clipped, side) > 0


def _subsampled(image: Tensor) -> Tensor:
    """A strided view of at most about a million pixels (bounded cost on huge photos)."""
    size = image.shape[-1] * image.shape[-2]
    stride = max(1, math.ceil(math.sqrt(size / _STATISTICS_PIXELS)))
    return image[:, ::stride, ::stride].float()


def _luminance_stats(region: Tensor) -> dict[str, float]:
    """Mean/median/p99/max luminance of a strided subsample (bounded cost on huge crops)."""
    lum = luminance(_subsampled(region)).flatten()
    median, p99 = (float(v) for v in torch.quantile(lum, torch.tensor([0.5, 0.99])))
    return {
        "mean_luminance": float(lum.mean()),
        "median_luminance": median,
        "p99_luminance": p99,
        "max_luminance": float(lum.max()),
    }
