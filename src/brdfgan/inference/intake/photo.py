"""Reading a user's flash photo into linear RGB (docs/conventions.md#photos-are-linear-ldr).

Formats and how their values are interpreted (``colorspace=None`` picks the format's default):

======  ===========================  ============  ===================================================
source  decoder                      default       notes
======  ===========================  ============  ===================================================
jpeg    Pillow                       ``"srgb"``    8-bit; EXIF orientation applied; CMYK rejected
png     OpenCV (pixels), own header  ``"srgb"``    8/16-bit; EXIF (``eXIf`` chunk) orientation applied
heif    pillow-heif (libheif)        ``"srgb"``    8/10/12-bit (``.heic``/``.heif``, phones); turned
                                                   by libheif (the container's ``irot``/``imir``)
tiff    OpenCV (pixels), Pillow      ``"srgb"``    8/16-bit; TIFF/EXIF orientation applied
exr     OpenEXR (``read_image``)     ``"linear"``  half/float; may exceed 1; NaN/Inf rejected,
                                                   negative values clamped to 0 with a warning
raw     rawpy (LibRaw)               ``"linear"``  linear demosaic, camera white balance, sRGB
                                                   primaries, ``/ 65535``; the only colour space
======  ===========================  ============  ===================================================

Why two decoders for JPEG and PNG. Pillow raises "image file is truncated" on a JPEG cut in the
middle, where OpenCV/libjpeg may fill the missing part with grey and only print a warning, so JPEG
pixels come from Pillow. Pillow reduces 16-bit RGB PNGs to 8 bits, so PNG pixels come from OpenCV
(``IMREAD_UNCHANGED``, which, unlike the default ``IMREAD_COLOR``, does *not* apply EXIF
orientation: the orientation is applied exactly once, here, with :func:`apply_orientation`).
Pillow still identifies every file first: its detected format (not the extension) and mode decide
what happens, so a text file renamed ``.jpg``, a CMYK JPEG or a grayscale PNG are reported before
any pixel is decoded.

TIFF is read like PNG, for the same reason (Pillow reduces 16-bit RGB TIFFs to 8 bits): Pillow
identifies it and reads its tags, OpenCV (libtiff) decodes the pixels. OpenCV 5 turns some TIFFs by
their orientation tag even with ``IMREAD_UNCHANGED`` and fails on others, so the bytes it gets have
the tag set to 1 (:func:`_tiff_without_orientation`) and the orientation is applied here, once.

HEIF (``.heic``, what iPhones and many Android phones save) is recognised by its ``ftyp`` brand
before Pillow sees it and decoded with pillow-heif's own API rather than its Pillow plugin: the
plugin reduces 10/12-bit images to 8 bits and registering it would change Pillow for the whole
process. HEIF states its orientation in the container (``irot``/``imir``, which phones write to
match the EXIF tag) and libheif applies it while decoding; :attr:`Photo.orientation` reports the
EXIF tag and nothing is turned a second time.

Colour profiles are not applied, for any format: the stored values are decoded with the sRGB curve
(or taken as linear with ``colorspace="linear"``). An ICC profile (JPEG, PNG, TIFF, HEIF) is
ignored; Display P3, which iPhones embed, has the sRGB curve, so only its wider primaries go
unconverted (colours read slightly less saturated than they are). A HEIF whose ``nclx`` colour
information states an HDR transfer curve (PQ, HLG) gets a warning: its values are not sRGB-encoded.

Alpha: an alpha channel with any transparent pixel is an error (a cut-out, not a photo); a fully
opaque one (many tools always write RGBA) is dropped with a warning. Truncation detection relies on
Pillow's default ``ImageFile.LOAD_TRUNCATED_IMAGES = False``; code that flips that global defeats it.

Every failure is a :class:`PhotoError` whose message is one line starting with the file's path.
Suspicious but usable input gives human-readable strings in :attr:`Photo.warnings` (the CLI prints
them); the colour-space heuristic behind one of them is described at :func:`colorspace_warning`.
"""

from __future__ import annotations

import functools
import io
import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple
from warnings import catch_warnings, filterwarnings

import cv2
import numpy as np
import torch
from PIL import Image, UnidentifiedImageError

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import LUMINANCE_WEIGHTS
from brdfgan.core.svbrdf import srgb_decoding_table, srgb_to_linear
from brdfgan.errors import UserError
from brdfgan.inference.intake.exposure_settings import ExposureSettings, exposure_settings_from_exif
from brdfgan.inference.intake.lens import Lens, lens_from_exif
from brdfgan.io.images import ImageIOError, read_image

__all__ = [
    "EXR_PHOTO_EXTENSIONS",
    "HEIF_PHOTO_EXTENSIONS",
    "JPEG_PHOTO_EXTENSIONS",
    "LOOKS_LINEAR_MAX_MEDIAN",
    "LOOKS_LINEAR_MIN_P99",
    "LOOKS_SRGB_MIN_MEDIAN",
    "MIN_PHOTO_SIZE",
    "PHOTO_EXTENSIONS",
    "PNG_PHOTO_EXTENSIONS",
    "RAW_PHOTO_EXTENSIONS",
    "TIFF_PHOTO_EXTENSIONS",
    "Colorspace",
    "Photo",
    "PhotoError",
    "apply_orientation",
    "colorspace_warning",
    "read_photo",
]

Colorspace = Literal["srgb", "linear"]
Source = Literal["jpeg", "png", "heif", "tiff", "exr", "raw"]

JPEG_PHOTO_EXTENSIONS = frozenset({".jpg", ".jpeg"})
PNG_PHOTO_EXTENSIONS = frozenset({".png"})
HEIF_PHOTO_EXTENSIONS = frozenset({".heic", ".heif"})
TIFF_PHOTO_EXTENSIONS = frozenset({".tif", ".tiff"})
EXR_PHOTO_EXTENSIONS = frozenset({".exr"})
RAW_PHOTO_EXTENSIONS = frozenset(
    {".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".pef", ".srw"}
)
PHOTO_EXTENSIONS = (
    JPEG_PHOTO_EXTENSIONS
    | PNG_PHOTO_EXTENSIONS
    | HEIF_PHOTO_EXTENSIONS
    | TIFF_PHOTO_EXTENSIONS
    | EXR_PHOTO_EXTENSIONS
    | RAW_PHOTO_EXTENSIONS
)
# The extensions expected for each format read by _read_ldr_photo (others get a warning).
_LDR_EXTENSIONS: dict[str, frozenset[str]] = {
    "jpeg": JPEG_PHOTO_EXTENSIONS,
    "png": PNG_PHOTO_EXTENSIONS,
    "heif": HEIF_PHOTO_EXTENSIONS,
    "tiff": TIFF_PHOTO_EXTENSIONS,
}

MIN_PHOTO_SIZE = 32

# Colour-space heuristic thresholds on the *stored* values of an 8/16-bit file, normalised to
# [0, 1] (see colorspace_warning for the reasoning and the limits).
LOOKS_LINEAR_MAX_MEDIAN = 0.1
LOOKS_LINEAR_MIN_P99 = 0.3
LOOKS_SRGB_MIN_MEDIAN = 0.3
# The heuristic and the grayscale check look at a strided subsample of about this many pixels.
_STATISTICS_PIXELS = 250_000

_EXIF_ORIENTATION_TAG = 0x0112
# Pillow modes without colour: a flash photo must be RGB to estimate a base colour.
_GRAYSCALE_MODES = frozenset({"1", "L", "I", "I;16", "I;16B", "I;16L", "I;16N", "F"})
_GRAY_ALPHA_MODES = frozenset({"LA", "La"})
# LibRaw's ``flip`` (applied by postprocess) → the equivalent EXIF orientation tag.
_LIBRAW_FLIP_TO_EXIF = {0: 1, 3: 3, 5: 8, 6: 6}
_EXR_PIXEL_BITS = {0: 32, 1: 16, 2: 32}  # UINT, HALF, FLOAT
# nclx transfer characteristics (ITU-T H.273) whose values are HDR signals, not sRGB-encoded.
_HDR_TRANSFERS = {16: "PQ (SMPTE ST 2084)", 18: "HLG (ARIB STD-B67)"}


class PhotoError(UserError):
    """A photo cannot be used; the message is one line and starts with the file's path."""

    def __init__(self, path: str | os.PathLike[str], problem: str) -> None:
        # Library messages (LibRaw, OpenEXR) can span lines; the CLI prints exactly one.
        super().__init__(" ".join(f"{path}: {problem}".split()))


@dataclass(frozen=True)
class Photo:
    """A decoded photo in linear RGB plus how it was interpreted.

    Attributes:
        path: the file read.
        linear: ``(3, H, W)`` float32 linear RGB, EXIF orientation applied. JPEG/PNG/HEIF/TIFF
            lie in ``[0, 1]``; EXR may exceed 1; RAW is in ``[0, 1]`` relative to the white level.
        source: ``"jpeg"``, ``"png"``, ``"heif"``, ``"tiff"``, ``"exr"`` or ``"raw"`` (from the
            file's content for JPEG/PNG/HEIF/TIFF, not its extension).
        bit_depth: 8/16 for JPEG/PNG/TIFF, 8/10/12 for HEIF, 16/32 for half/float EXR, the
            sensor's bits for RAW when LibRaw reports a white level, else ``None``.
        colorspace: ``"srgb"`` (the stored values were decoded with the sRGB curve) or ``"linear"``.
        orientation: the EXIF orientation tag that was applied (1 = none).
        warnings: human-readable warnings for the user.
        lens: the focal length the EXIF states (JPEG/PNG/HEIF/TIFF), for the refinement's field of view
            (:mod:`brdfgan.inference.intake.lens`); ``None`` when there is none.
        exposure: the exposure time, ISO and f-number the EXIF states (JPEG/PNG/HEIF/TIFF, and
            TIFF-based RAW files Pillow can open), for a flash + no-flash pair's exposure ratio
            (:mod:`brdfgan.inference.intake.exposure_settings`); ``None`` when it states none.
    """

    path: Path
    linear: torch.Tensor
    source: str
    bit_depth: int | None
    colorspace: str
    orientation: int
    warnings: tuple[str, ...]
    lens: Lens | None = None
    exposure: ExposureSettings | None = None

    @property
    def height(self) -> int:
        return int(self.linear.shape[-2])

    @property
    def width(self) -> int:
        return int(self.linear.shape[-1])

    def to_json(self) -> dict[str, Any]:
        """The ``input`` entry of ``material.json``: the file and how it was decoded."""
        return {
            "file": str(self.path),
            "source": self.source,
            "bit_depth": self.bit_depth,
            "colorspace": self.colorspace,
            "exif_orientation": self.orientation,
            "size": [self.width, self.height],
            "lens": None if self.lens is None else self.lens.to_json(),
            "exposure": None if self.exposure is None else self.exposure.to_json(),
        }


def read_photo(path: str | os.PathLike[str], colorspace: Colorspace | None = None) -> Photo:
    """Read a JPEG, PNG, HEIC/HEIF, TIFF, EXR or camera RAW photo into linear RGB.

    Args:
        path: the photo file; its extension must be one of :data:`PHOTO_EXTENSIONS`.
        colorspace: how to interpret the stored values. ``None``: the format's default (sRGB for
            JPEG/PNG/HEIF/TIFF, linear for EXR and RAW). ``"srgb"``: decode with the sRGB curve.
            ``"linear"``: take the values as they are. RAW files are always decoded linearly;
            asking for ``"srgb"`` there is an error.

    Raises:
        PhotoError: the file is missing, unreadable, not an image, truncated, smaller than
            :data:`MIN_PHOTO_SIZE` on a side, grayscale, black (no positive value: all zero, or
            all negative in an EXR), has a (non-opaque) alpha channel, is CMYK, holds NaN/Inf
            (EXR), or has an unsupported extension. One line, naming the file.

    Shape:
        - output ``Photo.linear``: ``(3, H, W)`` float32, H and W after EXIF orientation
    """
    path = Path(path)
    if colorspace not in (None, "srgb", "linear"):
        raise PhotoError(path, f"unknown colour space {colorspace!r}, expected 'srgb' or 'linear'")
    ext = path.suffix.lower()
    if ext not in PHOTO_EXTENSIONS:
        raise PhotoError(
            path,
            f"unsupported file type {path.suffix or '(no extension)'!r}; "
            f"supported: {', '.join(sorted(PHOTO_EXTENSIONS))}",
        )
    _check_file(path)
    if ext in EXR_PHOTO_EXTENSIONS:
        return _read_exr_photo(path, colorspace or "linear")
    if ext in RAW_PHOTO_EXTENSIONS:
        if colorspace == "srgb":
            raise PhotoError(path, "RAW files are demosaiced linearly; colorspace 'srgb' does not apply")
        return _read_raw_photo(path)
    return _read_ldr_photo(path, colorspace)


def apply_orientation(image: np.ndarray, orientation: int) -> np.ndarray:
    """Undo an EXIF orientation like Pillow's ``ImageOps.exif_transpose`` (tags 1–8).

    Returns a view where possible; 1 (or any unknown tag) returns the input.

    Shape:
        - image: ``(H, W, ...)``
        - output: ``(H, W, ...)`` for tags 1–4, ``(W, H, ...)`` for tags 5–8
    """
    if orientation == 2:
        return image[:, ::-1]
    if orientation == 3:
        return image[::-1, ::-1]
    if orientation == 4:
        return image[::-1]
    if orientation == 5:
        return image.swapaxes(0, 1)
    if orientation == 6:
        return np.rot90(image, k=-1)
    if orientation == 7:
        return image[::-1, ::-1].swapaxes(0, 1)
    if orientation == 8:
        return np.rot90(image, k=1)
    return image


def colorspace_warning(stored: np.ndarray, colorspace: Colorspace) -> str | None:
    """A warning when the stored values of an 8/16-bit photo look like the other colour space.

    The statistic is the luma ``Y`` of the *stored* values (normalised to [0, 1], before any
    decoding). It relies on how cameras expose: a meter puts the scene average near middle grey,
    18 % of saturation in linear terms, which the sRGB curve stores as ~0.46.

    - Read as sRGB but looks linear: ``median(Y) < 0.1`` while ``p99(Y) >= 0.3``. Decoded as sRGB
      that median would be ~1 % of saturation, over 7 stops below the highlights: a camera never
      exposes a JPEG like that, but a linear image written without the sRGB curve (a RAW export
      saved as-is, a rendering, our own auto-exposed training inputs with median ~0.05–0.09)
      looks exactly like that.
    - Read as linear but looks sRGB: ``median(Y) > 0.3``. A linear photo exposed by a meter has
      its median near or below 0.18 (flash falloff makes the median smaller than the mean), while
      the sRGB encoding of the same photo has its median near 0.4–0.5.

    Limits (why these are warnings, not errors): the statistic only sees exposure, not the tone
    curve itself. A photo of a very dark material (black leather, slate) with a bright flash
    highlight can trip the first test although it is sRGB; a dark or underexposed sRGB photo
    (median below 0.3) read as linear is not detected, nor is a bright, overexposed linear image
    told apart from sRGB. Images between the thresholds are never flagged. EXR and RAW are not
    checked: their values have no fixed relation to saturation (EXR) or are decoded by us (RAW).

    Shape:
        - stored: ``(H, W, 3)`` floating point in [0, 1] (any subsample of the photo)
    """
    luma = stored.astype(np.float32) @ np.asarray(LUMINANCE_WEIGHTS, dtype=np.float32)
    median, p99 = (float(v) for v in np.quantile(luma, [0.5, 0.99]))
    if colorspace == "srgb" and median < LOOKS_LINEAR_MAX_MEDIAN and p99 >= LOOKS_LINEAR_MIN_P99:
        return (
            f"the photo looks linear, not sRGB-encoded (median stored value {median:.3f}, "
            f"99th percentile {p99:.2f}); if it holds linear data (e.g. a RAW export saved without "
            f"a tone curve), read it as linear (--input-colorspace linear)"
        )
    if colorspace == "linear" and median > LOOKS_SRGB_MIN_MEDIAN:
        return (
            f"the photo looks sRGB-encoded, not linear (median stored value {median:.3f}); "
            f"if it is an ordinary camera JPEG/PNG, read it as sRGB (--input-colorspace srgb)"
        )
    return None


# --------------------------------------------------------------------------------------------- files


def _check_file(path: Path) -> None:
    if not path.exists():
        raise PhotoError(path, "file not found")
    if not path.is_file():
        raise PhotoError(path, "not a regular file")


def _read_bytes(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except OSError as error:
        raise PhotoError(path, f"cannot read file ({error.strerror or error})") from error
    if not data:
        raise PhotoError(path, "file is empty")
    return data


def _check_size(path: Path, width: int, height: int) -> None:
    if min(width, height) < MIN_PHOTO_SIZE:
        raise PhotoError(
            path, f"image is {width}×{height} pixels; at least {MIN_PHOTO_SIZE} pixels per side are needed"
        )


def _subsample(image: np.ndarray) -> np.ndarray:
    """A strided subsample of about ``_STATISTICS_PIXELS`` pixels: statistics stay cheap on 24 MP."""
    stride = max(1, math.ceil(math.sqrt(image.shape[0] * image.shape[1] / _STATISTICS_PIXELS)))
    return image[::stride, ::stride]


def _check_not_black(path: Path, image: np.ndarray, *, clamped: bool = False) -> None:
    """A photo without a single positive value has no light to estimate anything from; the
    auto exposure would multiply it by 0 and the network would see a flat black input."""
    if not (image > 0).any():
        what = "every value is zero or negative" if clamped else "every pixel is 0"
        raise PhotoError(path, f"is black ({what}): nothing to estimate; a lit flash photo is needed")


def _identical_channels_warning(sample: np.ndarray) -> str | None:
    if np.array_equal(sample[..., 0], sample[..., 1]) and np.array_equal(sample[..., 1], sample[..., 2]):
        return (
            "all three colour channels are identical: the photo looks grayscale, "
            "so the base colour cannot be estimated"
        )
    return None


# ------------------------------------------------------------------------------- JPEG/PNG/HEIF/TIFF


def _read_ldr_photo(path: Path, colorspace: Colorspace | None) -> Photo:
    data = _read_bytes(path)
    warnings: list[str] = []
    if _is_heif(data):
        source: Source = "heif"
        stored, bit_depth, orientation, facts = _decode_heif(path, data, warnings)
        pending = 1  # libheif has turned the pixels already
    else:
        source, stored, orientation, facts = _decode_identified(path, data, warnings)
        bit_depth = 16 if stored.dtype == np.uint16 else 8
        pending = orientation
    levels = (1 << bit_depth) - 1
    stored = _drop_opaque_alpha(path, stored, warnings, opaque=levels)
    _check_not_black(path, stored)
    if path.suffix.lower() not in _LDR_EXTENSIONS[source]:
        warnings.append(f"the file holds a {source.upper()} image although its extension is {path.suffix!r}")

    colorspace = colorspace or "srgb"
    sample = _subsample(stored)
    for warning in (
        _identical_channels_warning(sample),
        colorspace_warning(sample.astype(np.float32) / levels, colorspace),
    ):
        if warning:
            warnings.append(warning)

    # A lookup table decodes every code exactly once and avoids the several full-size float
    # temporaries of srgb_to_linear on a 24 MP photo. The sRGB table is the one the training
    # sensor simulation (brdfgan.data.phone.sensor) decodes its JPEGs with: both see the same values.
    if colorspace == "srgb":
        table = srgb_decoding_table(levels)
    else:
        table = (torch.arange(levels + 1, dtype=torch.float64) / levels).to(torch.float32)
    oriented = apply_orientation(stored, pending)
    # Indexing with the (C, H, W) view writes the result directly in channel-first order.
    linear = table.numpy()[oriented.transpose(2, 0, 1)]
    return Photo(
        path=path,
        linear=torch.from_numpy(np.ascontiguousarray(linear)),
        source=source,
        bit_depth=bit_depth,
        colorspace=colorspace,
        orientation=orientation,
        warnings=tuple(warnings),
        lens=facts.lens,
        exposure=facts.exposure,
    )


class _ExifFacts(NamedTuple):
    """What a photo's EXIF states besides its orientation."""

    lens: Lens | None
    exposure: ExposureSettings | None


def _exif_facts(exif: Image.Exif | None, stored_width: int) -> _ExifFacts:
    if exif is None:
        return _ExifFacts(None, None)
    return _ExifFacts(lens_from_exif(exif, stored_width), exposure_settings_from_exif(exif))


def _decode_identified(
    path: Path, data: bytes, warnings: list[str]
) -> tuple[Source, np.ndarray, int, _ExifFacts]:
    """A JPEG, PNG or TIFF, identified by Pillow: its format, stored pixels ``(H, W, C)`` (uint8
    or uint16, not yet turned), the EXIF orientation and the lens and exposure the EXIF states."""
    try:
        # Pillow warns (a UserWarning, printed with a line of its source) about the corrupt or
        # truncated TIFF tags it tolerates; the checks here report what matters, in one line.
        with catch_warnings():
            filterwarnings("ignore", category=UserWarning, module=r"PIL\.TiffImagePlugin")
            with Image.open(io.BytesIO(data)) as image:
                pil_format, mode, (width, height) = image.format, image.mode, image.size
                if pil_format in ("JPEG", "MPO"):  # MPO: multi-picture JPEG written by many cameras
                    source: Source = "jpeg"
                    exif = image.getexif()
                    orientation = _orientation_tag(exif.get(_EXIF_ORIENTATION_TAG, 1), warnings)
                    facts = _exif_facts(exif, width)
                    _check_mode(path, mode)
                    if mode != "RGB":
                        raise PhotoError(path, f"unsupported JPEG mode {mode!r}, expected RGB")
                    _check_size(path, width, height)
                    image.load()  # raises "image file is truncated" instead of decoding grey
                    return source, np.asarray(image), orientation, facts
                if pil_format == "PNG":
                    _check_mode(path, mode)
                    _check_size(path, width, height)
                    png_exif = _png_exif(data)
                    stated = 1 if png_exif is None else png_exif.get(_EXIF_ORIENTATION_TAG, 1)
                    orientation = _orientation_tag(stated, warnings)
                    facts = _exif_facts(png_exif, width)
                    return "png", _decode_opencv(path, data, "PNG"), orientation, facts
                if pil_format == "TIFF":
                    _check_mode(path, mode)  # 16-bit RGB reads as mode "RGB" here
                    _check_size(path, width, height)
                    exif = image.getexif()  # a TIFF's own tags (orientation) and its EXIF IFD
                    orientation = _orientation_tag(exif.get(_EXIF_ORIENTATION_TAG, 1), warnings)
                    facts = _exif_facts(exif, width)
                    stored = _decode_opencv(path, _tiff_without_orientation(data), "TIFF")
                    return "tiff", stored, orientation, facts
                raise PhotoError(
                    path,
                    f"file content is {pil_format or 'an unknown'} image, expected JPEG, PNG, HEIF or TIFF",
                )
    except PhotoError:
        raise
    except UnidentifiedImageError as error:
        if data[:4] in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"):  # a TIFF header, unreadable tags
            raise PhotoError(path, "truncated or corrupt TIFF data") from error
        raise PhotoError(path, "not an image file (or an unsupported or corrupt image format)") from error
    except Image.DecompressionBombError as error:
        raise PhotoError(path, f"image is too large to decode safely ({error})") from error
    except (OSError, SyntaxError, ValueError, EOFError, struct.error) as error:
        raise PhotoError(path, f"truncated or corrupt image data ({error})") from error


def _check_mode(path: Path, mode: str) -> None:
    # Alpha in RGBA/palette images is judged later on the decoded pixels (an opaque one is harmless).
    if mode == "CMYK":
        raise PhotoError(path, "is CMYK; convert it to RGB")
    if mode in _GRAY_ALPHA_MODES:
        raise PhotoError(path, "is grayscale with an alpha channel; a colour RGB photo is needed")
    if mode in _GRAYSCALE_MODES:
        raise PhotoError(path, "is grayscale; a colour photo is needed")


def _orientation_tag(value: Any, warnings: list[str]) -> int:
    # EXIF values are whatever the file holds (int, bytes, a rational, garbage): untyped.
    try:
        tag = int(value)
    except (TypeError, ValueError):
        tag = 0
    if 1 <= tag <= 8:
        return tag
    warnings.append(f"ignored invalid EXIF orientation {value!r}")
    return 1


def _png_exif(data: bytes) -> Image.Exif | None:
    """The EXIF of a PNG's ``eXIf`` chunk (``None`` without one), found by walking the chunk headers.

    Pillow's ``getexif()`` on a PNG decodes the whole image to look for an ``eXIf`` chunk after
    the pixel data; walking the chunks costs nothing.
    """
    offset = 8  # PNG signature
    while offset + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[offset : offset + 8])
        if kind == b"eXIf":
            exif = Image.Exif()
            exif.load(data[offset + 8 : offset + 8 + length])
            return exif
        if kind == b"IEND":
            break
        offset += 12 + length  # length, type, data, CRC
    return None


def _decode_opencv(path: Path, data: bytes, kind: str) -> np.ndarray:
    """The stored pixels of a PNG or TIFF as RGB(A), 8 or 16 bits, not turned by any orientation."""
    # IMREAD_UNCHANGED keeps 16 bits and, unlike IMREAD_COLOR, ignores EXIF orientation.
    # OpenCV logs its own messages ("PNG input buffer is incomplete", libtiff's read errors, over
    # several lines) to stderr; the PhotoError below already says it in one line, so its log is
    # silenced for this call.
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as error:
        raise PhotoError(path, f"truncated or corrupt {kind} data") from error
    finally:
        cv2.utils.logging.setLogLevel(level)
    if image is None:
        raise PhotoError(path, f"truncated or corrupt {kind} data")
    if image.dtype not in (np.uint8, np.uint16):
        raise PhotoError(path, f"unsupported sample type {image.dtype}, expected 8- or 16-bit")
    if image.ndim == 2 or image.shape[2] < 3:
        raise PhotoError(path, "is grayscale; a colour photo is needed")
    if image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)


def _tiff_without_orientation(data: bytes) -> bytes:
    """The TIFF with its first IFD's Orientation tag set to 1 (the input itself when it has none).

    OpenCV 5 turns some TIFFs by that tag even with ``IMREAD_UNCHANGED`` and fails on others
    ("Internal imread issue" on an uncompressed strip image with orientation 6); at 1 it decodes
    the stored pixels, and read_photo applies the orientation once, like for every format. Pillow
    has read the tag already; a header this cannot walk is left to OpenCV to report.
    """
    order = {b"II": "<", b"MM": ">"}.get(data[:2])
    if order is None:
        return data
    try:
        (magic,) = struct.unpack_from(order + "H", data, 2)
        if magic == 42:  # classic TIFF: 4-byte offsets, 12-byte entries
            (ifd,) = struct.unpack_from(order + "I", data, 4)
            (count,) = struct.unpack_from(order + "H", data, ifd)
            first, entry_size, value_at = ifd + 2, 12, 8
        elif magic == 43:  # BigTIFF: 8-byte offsets and counts, 20-byte entries
            (ifd,) = struct.unpack_from(order + "Q", data, 8)
            (count,) = struct.unpack_from(order + "Q", data, ifd)
            first, entry_size, value_at = ifd + 8, 20, 12
        else:
            return data
        for index in range(count):
            entry = first + index * entry_size
            tag, kind = struct.unpack_from(order + "HH", data, entry)
            if tag == _EXIF_ORIENTATION_TAG and kind == 3:  # SHORT: the value sits in the entry
                if struct.unpack_from(order + "H", data, entry + value_at)[0] == 1:
                    return data
                patched = bytearray(data)
                struct.pack_into(order + "H", patched, entry + value_at, 1)
                return bytes(patched)
    except struct.error:
        pass
    return data


def _drop_opaque_alpha(
    path: Path, image: np.ndarray, warnings: list[str], *, opaque: float | None = None
) -> np.ndarray:
    """RGBA → RGB when every pixel is fully opaque (many tools always write alpha), else an error:
    transparent pixels have no meaningful colour and mark a cut-out, not a photo.

    ``opaque`` is the alpha of an opaque pixel: by default the integer type's maximum, or 1.0;
    a 10-bit HEIF's codes sit in uint16 with 1023 as their maximum."""
    if image.shape[-1] != 4:
        return image
    alpha = image[..., 3]
    if opaque is None:
        opaque = np.iinfo(image.dtype).max if np.issubdtype(image.dtype, np.integer) else 1.0
    if not (alpha == opaque).all():
        raise PhotoError(path, "has an alpha channel with transparent pixels; save the photo as RGB")
    warnings.append("the alpha channel is fully opaque and was ignored")
    return image[..., :3]


# ---------------------------------------------------------------------------------------------- HEIF


def _is_heif(data: bytes) -> bool:
    # ISO base media files start with an ``ftyp`` box; MP4/MOV videos do too, so the brand decides
    # (pillow-heif's own check). The import waits until a file looks like one.
    if data[4:8] != b"ftyp":
        return False
    import pillow_heif

    return bool(pillow_heif.is_supported(data[:64]))


def _decode_heif(path: Path, data: bytes, warnings: list[str]) -> tuple[np.ndarray, int, int, _ExifFacts]:
    """A HEIF's primary image: its codes ``(H, W, C)`` as displayed (libheif applied the container's
    rotation and mirroring), their bit depth, the EXIF orientation and the lens and exposure the
    EXIF states."""
    import pillow_heif  # imported lazily: libheif is only needed for HEIF photos

    try:
        # 10/12-bit images (HDR-capable phones) open as 16-bit instead of being reduced to 8 bits.
        heif = pillow_heif.open_heif(data, convert_hdr_to_8bit=False)
        image = heif[heif.primary_index]
        info: dict[str, Any] = image.info  # values of many types (pillow-heif types them as a union)
        mode, (width, height) = image.mode, image.size
        _check_mode(path, mode.split(";")[0])  # "RGB;16" → "RGB", monochrome "L" → rejected
        _check_size(path, width, height)
        bit_depth = int(info.get("bit_depth", 8))
        stored = np.asarray(image)  # decodes; a truncated or damaged file raises here
    except PhotoError:
        raise
    except (OSError, SyntaxError, ValueError, EOFError, RuntimeError) as error:
        raise PhotoError(path, f"truncated or corrupt HEIF data ({str(error).strip()})") from error
    if stored.dtype == np.uint16 and bit_depth < 16:
        # pillow-heif moves 10/12-bit codes to the top of 16 bits with a shift (1023 → 65472, not
        # 65535); dividing by 65535 would be 0.1 % short at white. The file's own codes are exact.
        stored = stored >> (16 - bit_depth)
    else:
        bit_depth = 8 * stored.dtype.itemsize
    exif = _exif_from_bytes(info.get("exif"), warnings)
    orientation = _orientation_tag(exif.get(_EXIF_ORIENTATION_TAG, 1), warnings)
    # The EXIF's pixel dimensions describe the image before it was turned.
    facts = _exif_facts(exif, stored.shape[1] if orientation <= 4 else stored.shape[0])
    transfer = (info.get("nclx_profile") or {}).get("transfer_characteristics")
    if transfer in _HDR_TRANSFERS:
        warnings.append(
            f"the photo states the HDR transfer curve {_HDR_TRANSFERS[transfer]}: its values are not "
            "sRGB-encoded and its tones will be misread; export an SDR (sRGB or Display P3) copy"
        )
    return stored, bit_depth, orientation, facts


def _exif_from_bytes(raw: bytes | None, warnings: list[str]) -> Image.Exif:
    """The EXIF block of a HEIF (an empty one when it has none or it cannot be parsed)."""
    exif = Image.Exif()
    if raw:
        try:
            with catch_warnings():
                filterwarnings("ignore", category=UserWarning, module=r"PIL\.TiffImagePlugin")
                exif.load(raw)
        except (SyntaxError, ValueError, EOFError, struct.error) as error:
            warnings.append(f"ignored unreadable EXIF data ({error})")
            return Image.Exif()
    return exif


# ----------------------------------------------------------------------------------------------- EXR


def _read_exr_photo(path: Path, colorspace: Colorspace) -> Photo:
    names, bit_depth = _exr_channels(path)
    # Luminance-only files (Y, Y+A, one channel); other channel sets are read_image's to report.
    if names is not None and not {"R", "G", "B"} <= set(names) and ("Y" in names or len(names) == 1):
        channels = ", ".join(sorted(names))
        raise PhotoError(path, f"is grayscale (EXR channels {channels}); a colour photo is needed")
    try:
        image = read_image(path)
    except ImageIOError as error:
        raise PhotoError(path, str(error).removeprefix(f"{path}: ")) from error
    if image.shape[2] == 1:
        raise PhotoError(path, "is grayscale; a colour photo is needed")
    _check_size(path, image.shape[1], image.shape[0])
    warnings: list[str] = []
    image = _drop_opaque_alpha(path, image, warnings)
    finite = np.isfinite(image)
    if not finite.all():
        count = int((~finite).sum())
        raise PhotoError(path, f"contains {count} NaN or infinite values")
    _check_not_black(path, image, clamped=True)
    negative = image < 0
    if negative.any():
        # Slightly negative values are common in EXR (out-of-gamut colours after a colour-space
        # conversion, denoiser ringing). They have no physical meaning for a reflectance photo.
        warnings.append(f"{negative.mean():.2%} of the values were negative and were clamped to 0")
        image = np.maximum(image, 0.0)
    warning = _identical_channels_warning(_subsample(image))
    if warning:
        warnings.append(warning)
    linear = torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1)))
    if colorspace == "srgb":
        if float(linear.max()) > 1.0:
            warnings.append("values above 1 were decoded with the sRGB curve, which is defined on [0, 1]")
        linear = srgb_to_linear(linear)
    return Photo(
        path=path,
        linear=linear.to(torch.float32).contiguous(),
        source="exr",
        bit_depth=bit_depth,
        colorspace=colorspace,
        orientation=1,
        warnings=tuple(warnings),
    )


def _exr_channels(path: Path) -> tuple[list[str] | None, int | None]:
    """Channel names and bits per sample from the first EXR header's ``chlist`` attribute.

    The OpenEXR bindings only report a channel's type from its decoded pixels, and read_image
    returns float32 whatever was stored; the header says it without decoding anything.
    Returns ``(None, None)`` when the header cannot be parsed (read_image then reports why).
    """
    try:
        with path.open("rb") as handle:
            header = handle.read(1 << 20)
        if header[:4] != b"\x76\x2f\x31\x01":
            return None, None
        offset = 8
        while offset < len(header) and header[offset] != 0:
            name_end = header.index(b"\0", offset)
            type_end = header.index(b"\0", name_end + 1)
            (size,) = struct.unpack_from("<i", header, type_end + 1)
            value_start = type_end + 5
            if header[offset:name_end] == b"channels" and header[name_end + 1 : type_end] == b"chlist":
                names, types = [], set()
                cursor = value_start
                while header[cursor] != 0:
                    end = header.index(b"\0", cursor)
                    names.append(header[cursor:end].decode("utf-8", "replace"))
                    types.add(struct.unpack_from("<i", header, end + 1)[0])
                    cursor = end + 1 + 16  # pixel type, pLinear + 3 reserved, x/y sampling
                bits = {_EXR_PIXEL_BITS.get(t) for t in types}
                return names, (max(b for b in bits if b) if bits - {None} else None)
            offset = value_start + size
    except (OSError, ValueError, IndexError, struct.error):
        pass
    return None, None


# ----------------------------------------------------------------------------------------------- RAW


def _read_raw_photo(path: Path) -> Photo:
    import rawpy  # imported lazily: LibRaw is only needed for camera RAW files

    try:
        with rawpy.imread(str(path)) as raw:
            white_level = getattr(raw, "white_level", None)
            flip = int(getattr(raw.sizes, "flip", 0) or 0)
            # Linear demosaic like the paper's capture (§6.1, RAW exported linear): gamma (1, 1) is
            # no tone curve, no_auto_bright keeps LibRaw from rescaling, 16 bits keep the shadows.
            rgb = raw.postprocess(
                gamma=(1, 1),
                no_auto_bright=True,
                use_camera_wb=True,
                output_bps=16,
                output_color=rawpy.ColorSpace.sRGB,
            )
    except (rawpy.LibRawError, rawpy.NotSupportedError, OSError, ValueError) as error:
        raise PhotoError(path, f"cannot decode RAW file ({type(error).__name__}: {error})") from error
    rgb = np.asarray(rgb)
    check_shape(rgb, "H W 3", name="RAW decoder output", error=functools.partial(PhotoError, path))
    _check_size(path, rgb.shape[1], rgb.shape[0])
    _check_not_black(path, rgb)
    warnings: list[str] = []
    warning = _identical_channels_warning(_subsample(rgb))
    if warning:
        warnings.append(warning)
    linear = torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1)).astype(np.float32) / 65535.0)
    bit_depth = int(white_level).bit_length() if white_level and int(white_level) > 0 else None
    return Photo(
        path=path,
        linear=linear,
        source="raw",
        bit_depth=bit_depth,
        colorspace="linear",
        orientation=_LIBRAW_FLIP_TO_EXIF.get(flip, 1),
        warnings=tuple(warnings),
        exposure=_raw_exposure_settings(path),
    )


def _raw_exposure_settings(path: Path) -> ExposureSettings | None:
    """The exposure a RAW file's EXIF states where Pillow can read its tags (TIFF-based formats:
    DNG, CR2, NEF, ARW…; opening reads the tags, not the sensor data), else ``None``."""
    try:
        with catch_warnings():
            filterwarnings("ignore", category=UserWarning, module=r"PIL\.TiffImagePlugin")
            with Image.open(path) as image:
                return exposure_settings_from_exif(image.getexif())
    except (OSError, Image.DecompressionBombError, SyntaxError, ValueError, EOFError, struct.error):
        return None  # not TIFF-based (CR3, RAF…) or unreadable tags: no exposure stated
