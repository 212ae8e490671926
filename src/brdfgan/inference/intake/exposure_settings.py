"""How a shot was exposed, from its EXIF: what a flash + no-flash pair's exposure ratio is made of.

A linear pixel value is proportional to the scene's radiance times the shot's exposure
``ExposureTime × ISO / FNumber²`` (the time the shutter was open, the sensor's gain, the light
the aperture lets in). So the room light, which lights both photos of a pair, is ``r`` times
brighter in the flash photo than in the no-flash photo with ``r`` the ratio of their exposures
(:func:`brdfgan.inference.pair.intake.exposure_ratio`).

Phones write the three tags in the Exif sub-IFD (``0x8769``); TIFF-based RAW files (DNG, and the
CR2, NEF, ARW… that Pillow can open) may hold them in IFD0. The ISO is ``ISOSpeedRatings``
(``PhotographicSensitivity`` since EXIF 2.3), else ``RecommendedExposureIndex`` or ``ISOSpeed``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from brdfgan.inference.intake.lens import EXIF_IFD

# EXIF tags (the Exif sub-IFD; TIFF-based RAW files may put them in IFD0).
EXPOSURE_TIME = 0x829A
F_NUMBER = 0x829D
ISO_SPEED_RATINGS = 0x8827  # PhotographicSensitivity (EXIF 2.3)
RECOMMENDED_EXPOSURE_INDEX = 0x8832
ISO_SPEED = 0x8833


@dataclass(frozen=True)
class ExposureSettings:
    """What the EXIF states of a shot's exposure (``None``: not stated, or not a usable number)."""

    exposure_time_s: float | None = None
    iso: float | None = None
    f_number: float | None = None

    @property
    def exposure(self) -> float | None:
        """``ExposureTime × ISO / FNumber²``: a linear value per unit of scene radiance, up to a
        constant of the camera; ``None`` unless all three are stated."""
        if self.exposure_time_s is None or self.iso is None or self.f_number is None:
            return None
        return self.exposure_time_s * self.iso / self.f_number**2

    def to_json(self) -> dict[str, float | None]:
        return {
            "exposure_time_s": self.exposure_time_s,
            "iso": self.iso,
            "f_number": self.f_number,
            "exposure": self.exposure,
        }


def exposure_settings_from_exif(exif: Any) -> ExposureSettings | None:
    """The :class:`ExposureSettings` of a Pillow ``Image.Exif`` (``None`` when it states none of
    them). Each tag is read from the Exif sub-IFD, else from IFD0."""
    try:
        ifd = exif.get_ifd(EXIF_IFD)
    except (KeyError, TypeError, ValueError, SyntaxError):  # malformed sub-IFD: IFD0 alone
        ifd = {}

    def tag(number: int) -> Any:
        value = ifd.get(number)
        return exif.get(number) if value is None else value

    iso = next(
        (
            value
            for value in (
                _positive(tag(number))
                for number in (ISO_SPEED_RATINGS, RECOMMENDED_EXPOSURE_INDEX, ISO_SPEED)
            )
            if value is not None
        ),
        None,
    )
    settings = ExposureSettings(_positive(tag(EXPOSURE_TIME)), iso, _positive(tag(F_NUMBER)))
    if settings == ExposureSettings():
        return None
    return settings


def _positive(value: Any) -> float | None:
    # EXIF values are whatever the file holds (IFDRational, int, a tuple of ISOs, bytes, garbage).
    if isinstance(value, tuple | list):
        value = value[0] if value else None
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) and number > 0.0 else None
