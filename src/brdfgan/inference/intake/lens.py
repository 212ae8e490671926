"""The camera's field of view, from the photo's EXIF, for the refinement's capture model.

Test-time refinement (:mod:`brdfgan.inference.refine`) renders the maps under the capture's own
flash: a camera above the centre of the crop, framing it exactly, with the flash at the lens —
the training captures' geometry (:class:`~brdfgan.core.render.FlashCapture`). What it needs from
the photo is the *horizontal field of view across the crop square*:

- ``FocalLengthIn35mmFilm`` (phones write it): by definition the focal length that gives the
  same diagonal angle of view on a 36 × 24 mm frame, so the photo's diagonal in pixels spans
  43.27 mm at that focal length, and a crop of side ``s`` pixels spans
  ``s · 43.27 / diagonal_px`` mm: ``fov = 2 atan(that / (2 f35))``.
- else ``FocalLength`` with the sensor's pixel pitch from ``FocalPlaneXResolution`` /
  ``FocalPlaneResolutionUnit`` (cameras write these; scaled when the image was resized from the
  ``PixelXDimension`` it states): ``fov = 2 atan(s / pixels_per_mm / (2 f))``.
- else the training default, :data:`DEFAULT_FOV_DEG`.

A photo without EXIF (a screenshot, an exported PNG, a rectified crop) can be given either by the
user instead (``brdfgan predict --fov DEG | --focal-length-35mm MM``, :class:`FieldOfView`): the
photo's horizontal field of view, of which a crop of side ``s`` spans
``2 atan(tan(fov/2) · s / width)``, or the 35 mm equivalent focal length, used as the EXIF one.

The crop is assumed to face the camera (the flash near its centre, as :func:`preprocess
<brdfgan.inference.intake.preprocess.preprocess>` chooses it), so its angle of view is that of a
centred crop of the same size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from brdfgan.core.flash_geometry import DEFAULT_FOV_DEG

FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)

# EXIF tags (the Exif sub-IFD, 0x8769).
EXIF_IFD = 0x8769
FOCAL_LENGTH = 0x920A
FOCAL_LENGTH_35MM = 0xA405
FOCAL_PLANE_X_RESOLUTION = 0xA20E
FOCAL_PLANE_RESOLUTION_UNIT = 0xA210
PIXEL_X_DIMENSION = 0xA002
# FocalPlaneResolutionUnit → millimetres per unit (EXIF 2.32: 2 inch, 3 cm; 4 mm and 5 µm are
# written by some cameras although the standard stops at 3).
_MM_PER_UNIT = {1: 25.4, 2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}

FovSource = Literal[
    "--fov",
    "--focal-length-35mm",
    "exif 35 mm equivalent",
    "exif focal length and sensor",
    "training default",
]


@dataclass(frozen=True)
class FieldOfView:
    """What the user says of the camera, overriding the EXIF: the photo's horizontal field of view
    in degrees (``photo_fov_deg``), or its 35 mm equivalent focal length in mm; at most one."""

    photo_fov_deg: float | None = None
    focal_length_35mm: float | None = None

    def __post_init__(self) -> None:
        if self.photo_fov_deg is not None and self.focal_length_35mm is not None:
            raise ValueError("give the field of view or the 35 mm focal length, not both")
        if self.photo_fov_deg is not None and not 0.0 < self.photo_fov_deg < 180.0:
            raise ValueError(f"field of view must lie in (0, 180) degrees, got {self.photo_fov_deg}")
        if self.focal_length_35mm is not None and not self.focal_length_35mm > 0.0:
            raise ValueError(f"35 mm focal length must be positive, got {self.focal_length_35mm}")


@dataclass(frozen=True)
class Lens:
    """What the EXIF says about the lens (``None``: not stated, or not a usable number).

    ``pixels_per_mm`` is the sensor's resolution in the image's own pixels (already scaled when
    the stored image is smaller than the ``PixelXDimension`` the EXIF states)."""

    focal_length_mm: float | None = None
    focal_length_35mm: float | None = None
    pixels_per_mm: float | None = None

    def to_json(self) -> dict[str, float | None]:
        return {
            "focal_length_mm": self.focal_length_mm,
            "focal_length_35mm": self.focal_length_35mm,
            "pixels_per_mm": self.pixels_per_mm,
        }


def lens_from_exif(exif: Any, stored_width: int) -> Lens | None:
    """The :class:`Lens` of a Pillow ``Image.Exif`` (``None`` when it states no focal length).

    Args:
        exif: ``image.getexif()`` (JPEG) or an ``Image.Exif`` loaded from a PNG ``eXIf`` chunk.
        stored_width: the image's width as stored (before the EXIF orientation is applied).
    """
    try:
        ifd = exif.get_ifd(EXIF_IFD)
    except (KeyError, TypeError, ValueError, SyntaxError):  # malformed sub-IFD: no lens data
        return None
    focal = _positive(ifd.get(FOCAL_LENGTH))
    focal_35 = _positive(ifd.get(FOCAL_LENGTH_35MM))
    pixels_per_mm = None
    resolution = _positive(ifd.get(FOCAL_PLANE_X_RESOLUTION))
    unit = _MM_PER_UNIT.get(_integer(ifd.get(FOCAL_PLANE_RESOLUTION_UNIT, 2)))
    if resolution is not None and unit is not None:
        pixels_per_mm = resolution / unit
        declared_width = _positive(ifd.get(PIXEL_X_DIMENSION))
        if declared_width is not None and stored_width > 0:
            pixels_per_mm *= stored_width / declared_width
    if focal is None and focal_35 is None:
        return None
    return Lens(focal_length_mm=focal, focal_length_35mm=focal_35, pixels_per_mm=pixels_per_mm)


def crop_field_of_view(
    lens: Lens | None, width: int, height: int, crop_size: int, given: FieldOfView = FieldOfView()
) -> tuple[float, FovSource]:
    """Horizontal field of view in degrees across a ``crop_size``² crop of a ``width`` × ``height``
    photo (pixels of the photo as read), and where it came from (module docstring): what the user
    ``given``, else the EXIF ``lens``, else the training default."""
    if width < 1 or height < 1 or not 0 < crop_size <= max(width, height):
        raise ValueError(f"crop of {crop_size} px does not fit a {width}x{height} photo")
    if given.photo_fov_deg is not None:
        half_tangent = math.tan(math.radians(given.photo_fov_deg) / 2.0) * crop_size / width
        return math.degrees(2.0 * math.atan(half_tangent)), "--fov"
    if given.focal_length_35mm is not None:
        span_mm = crop_size * FULL_FRAME_DIAGONAL_MM / math.hypot(width, height)
        return _fov(span_mm, given.focal_length_35mm), "--focal-length-35mm"
    if lens is not None and lens.focal_length_35mm is not None:
        span_mm = crop_size * FULL_FRAME_DIAGONAL_MM / math.hypot(width, height)
        return _fov(span_mm, lens.focal_length_35mm), "exif 35 mm equivalent"
    if lens is not None and lens.focal_length_mm is not None and lens.pixels_per_mm is not None:
        return _fov(crop_size / lens.pixels_per_mm, lens.focal_length_mm), "exif focal length and sensor"
    return DEFAULT_FOV_DEG, "training default"


def _fov(span_mm: float, focal_mm: float) -> float:
    return math.degrees(2.0 * math.atan(span_mm / (2.0 * focal_mm)))


def _positive(value: Any) -> float | None:
    # EXIF values are whatever the file holds (IFDRational, int, bytes, garbage): untyped.
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) and number > 0.0 else None


def _integer(value: Any) -> int:
    try:
        return int(value)
    except (TypeError, ValueError):
        return 0
