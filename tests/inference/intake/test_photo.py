"""Reading user photos: colour-space round trips, orientation, HEIF/TIFF/EXR/RAW, every bad input."""

from __future__ import annotations

import io
import json
import os
import struct
import sys
import types
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pillow_heif
import pytest
import torch
from PIL import Image, ImageCms, ImageOps

from brdfgan.cli import PARTIAL_FAILURE_EXIT_CODE, main
from brdfgan.core.exposure import auto_expose
from brdfgan.core.svbrdf import linear_to_srgb, srgb_to_linear
from brdfgan.inference.intake.lens import EXIF_IFD, FOCAL_LENGTH, FOCAL_LENGTH_35MM, crop_field_of_view
from brdfgan.inference.intake.photo import (
    LOOKS_LINEAR_MAX_MEDIAN,
    LOOKS_SRGB_MIN_MEDIAN,
    MIN_PHOTO_SIZE,
    PHOTO_EXTENSIONS,
    Photo,
    PhotoError,
    apply_orientation,
    read_photo,
)
from brdfgan.inference.pipeline import collect_photos
from brdfgan.io.images import write_image
from brdfgan.models.generator import Generator
from brdfgan.runs import save_weights

ORIENTATION_TAG = 0x0112


# ------------------------------------------------------------------------------------------- helpers


def known_linear(height: int = 48, width: int = 64) -> np.ndarray:
    """A smooth, asymmetric linear RGB image in [0, 1] (float64) covering dark and bright values."""
    y = np.linspace(0.0, 1.0, height)[:, None]
    x = np.linspace(0.0, 1.0, width)[None, :]
    return np.stack([0.002 + 0.95 * x * y, 0.6 * x + 0.35 * y * y, 0.8 * (1 - x) * y + 0.01], axis=-1)


def srgb_codes(linear: np.ndarray, levels: int) -> np.ndarray:
    encoded = linear_to_srgb(torch.from_numpy(linear)).numpy()
    return np.rint(encoded * levels).astype(np.uint8 if levels == 255 else np.uint16)


def srgb_decode_slope(stored: np.ndarray) -> np.ndarray:
    """d srgb_to_linear / d v at ``stored`` (the curve is convex: the slope grows with v)."""
    v = np.clip(stored, 0.0, 1.0)
    return np.where(v <= 0.04045, 1.0 / 12.92, 2.4 / 1.055 * ((v + 0.055) / 1.055) ** 1.4)


def quantisation_bound(linear: np.ndarray, codes: float) -> np.ndarray:
    """|Δlinear| allowed for an sRGB-encoded value off by ``codes`` steps of 1/255: the largest
    slope of the decoding curve within that distance times the distance (convexity)."""
    encoded = linear_to_srgb(torch.from_numpy(linear)).numpy()
    step = codes / 255.0
    return srgb_decode_slope(encoded + step) * step + 1e-6


def chw(array: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(array.transpose(2, 0, 1)))


def save_pil(path: Path, array: np.ndarray, mode: str | None = None, **options: object) -> Path:
    image = Image.fromarray(array) if mode is None else Image.fromarray(array).convert(mode)
    if path.suffix.lower() in (".heic", ".heif"):
        # pillow-heif's own writer: registering its Pillow plugin would change Pillow for the whole
        # test session (read_photo does not need it).
        pillow_heif.from_pillow(image).save(path, **options)
    else:
        image.save(path, **options)
    return path


# HEIF saved without loss: all chroma planes, and RGB coded as GBR (matrix 0) instead of YCbCr,
# whose rounding would change the codes.
HEIF_LOSSLESS: dict[str, object] = {"quality": -1, "chroma": 444, "matrix_coefficients": 0}


def save_heif16(path: Path, codes: np.ndarray, bits: int, **options: object) -> Path:
    """A HEIF of ``(H, W, 3)`` integer codes below ``2**bits``; pillow-heif takes them at the top of
    16 bits and writes 10 bits, or 12 with ``pillow_heif.options.SAVE_HDR_TO_12_BIT``."""
    height, width = codes.shape[:2]
    shifted = (codes.astype(np.uint16) << (16 - bits)).astype("<u2")
    heif = pillow_heif.from_bytes(mode="RGB;16", size=(width, height), data=shifted.tobytes())
    heif.save(path, **options)
    return path


def write_tiff(
    path: Path, image: np.ndarray, orientation: int | None = None, focal_length_35mm: int | None = None
) -> Path:
    """An uncompressed baseline TIFF of ``(H, W, C)`` uint8/uint16, written byte by byte: Pillow
    cannot write 16-bit RGB, and OpenCV neither writes an orientation nor an EXIF IFD.

    Layout: header, IFD0, BitsPerSample (one SHORT per channel), the EXIF IFD, the pixels."""
    height, width, channels = image.shape
    bits = 8 * image.dtype.itemsize
    pixels = np.ascontiguousarray(image, dtype=image.dtype.newbyteorder("<")).tobytes()
    count = 10 + (orientation is not None) + (focal_length_35mm is not None)
    bits_at = 8 + 2 + 12 * count + 4
    exif_at = bits_at + 2 * channels
    pixels_at = exif_at + (18 if focal_length_35mm is not None else 0)
    # tag: (type, count, value); type 3 is SHORT, 4 is LONG.
    entries = {
        256: (4, 1, width),  # ImageWidth
        257: (4, 1, height),  # ImageLength
        258: (3, channels, bits_at),  # BitsPerSample
        259: (3, 1, 1),  # Compression: none
        262: (3, 1, 2),  # PhotometricInterpretation: RGB
        273: (4, 1, pixels_at),  # StripOffsets
        277: (3, 1, channels),  # SamplesPerPixel
        278: (4, 1, height),  # RowsPerStrip: a single strip
        279: (4, 1, len(pixels)),  # StripByteCounts
        284: (3, 1, 1),  # PlanarConfiguration: chunky
    }
    if orientation is not None:
        entries[ORIENTATION_TAG] = (3, 1, orientation)
    if focal_length_35mm is not None:
        entries[EXIF_IFD] = (4, 1, exif_at)
    data = b"II*\0" + struct.pack("<IH", 8, count)
    for tag, (kind, number, value) in sorted(entries.items()):
        value_field = struct.pack("<HH", value, 0) if kind == 3 else struct.pack("<I", value)
        data += struct.pack("<HHI", tag, kind, number) + value_field
    data += struct.pack("<I", 0) + struct.pack(f"<{channels}H", *[bits] * channels)
    if focal_length_35mm is not None:  # one entry, no next IFD
        data += struct.pack("<HHHIHHI", 1, FOCAL_LENGTH_35MM, 3, 1, focal_length_35mm, 0, 0)
    path.write_bytes(data + pixels)
    return path


def display_p3_icc() -> bytes:
    """A minimal ICC v2 display profile with Display P3's primaries (D50-adapted) and a 2.2 curve:
    a non-sRGB profile like the one iPhones embed (ImageCms can only make sRGB, Lab, XYZ)."""

    def tag(kind: bytes, body: bytes) -> bytes:
        data = kind + b"\0" * 4 + body
        return data + b"\0" * (-len(data) % 4)

    def xyz(x: float, y: float, z: float) -> bytes:
        return tag(b"XYZ ", struct.pack(">3i", *(round(v * 65536) for v in (x, y, z))))

    name = b"Display P3"
    tags = [
        (b"desc", tag(b"desc", struct.pack(">I", len(name) + 1) + name + b"\0" + b"\0" * 78)),
        (b"wtpt", xyz(0.9642, 1.0, 0.8249)),
        (b"rXYZ", xyz(0.5151, 0.2412, -0.0011)),
        (b"gXYZ", xyz(0.2920, 0.6922, 0.0419)),
        (b"bXYZ", xyz(0.1571, 0.0666, 0.7841)),
    ] + [(channel, tag(b"curv", struct.pack(">IH", 1, 0x0233))) for channel in (b"rTRC", b"gTRC", b"bTRC")]
    offset = 128 + 4 + 12 * len(tags)
    table, bodies = struct.pack(">I", len(tags)), b""
    for signature, body in tags:
        table += signature + struct.pack(">II", offset + len(bodies), len(body))
        bodies += body
    size = offset + len(bodies)
    header = struct.pack(">I4sI4s4s4s12s4s24sI", size, b"lcms", 0x02100000, b"mntr", b"RGB ", b"XYZ ",
                         b"\0" * 12, b"acsp", b"\0" * 24, 0)  # fmt: skip
    header += struct.pack(">3i", *(round(v * 65536) for v in (0.9642, 1.0, 0.8249)))
    header += b"\0" * (128 - len(header))
    return header + table + bodies


def exif_with_orientation(tag: int) -> Image.Exif:
    exif = Image.Exif()
    exif[ORIENTATION_TAG] = tag
    return exif


def blocks(height: int = 40, width: int = 64) -> np.ndarray:
    """Large flat colour blocks (JPEG reproduces them well) that are asymmetric in X and Y."""
    image = np.zeros((height, width, 3), dtype=np.uint8)
    image[: height // 2, : width // 4] = (220, 30, 30)
    image[: height // 2, width // 4 :] = (30, 200, 40)
    image[height // 2 :, : width // 2] = (20, 40, 210)
    image[height // 2 :, width // 2 :] = (240, 230, 60)
    return image


def assert_photo_error(error: pytest.ExceptionInfo[PhotoError], path: Path, *phrases: str) -> None:
    message = str(error.value)
    assert message.startswith(f"{path}: "), message
    assert "\n" not in message
    for phrase in phrases:
        assert phrase in message, message


def flash_scene_linear(height: int = 96, width: int = 128, seed: int = 0) -> np.ndarray:
    """A rendered-looking flash photo: textured albedo under a falloff plus a specular highlight,
    auto-exposed like the training inputs (linear LDR, median well below 0.1)."""
    g = torch.Generator().manual_seed(seed)
    ys = torch.linspace(-1.0, 1.0, height).view(height, 1)
    xs = torch.linspace(-1.3, 1.3, width).view(1, width)
    r2 = xs**2 + ys**2
    albedo = 0.15 + 0.6 * torch.rand(3, height, width, generator=g)
    diffuse = albedo / (1.0 + 2.0 * r2) ** 2
    specular = 6.0 * torch.exp(-r2 / 0.01)
    ldr, _ = auto_expose(diffuse + specular)
    return ldr.permute(1, 2, 0).double().numpy()


# -------------------------------------------------------------------------------- colour-space trips


def test_png8_srgb_round_trip_within_quantisation(tmp_path: Path) -> None:
    linear = known_linear()
    codes = srgb_codes(linear, 255)
    path = save_pil(tmp_path / "photo.png", codes)

    photo = read_photo(path)

    assert (photo.source, photo.bit_depth, photo.colorspace, photo.orientation) == ("png", 8, "srgb", 1)
    assert photo.linear.dtype == torch.float32 and photo.linear.shape == (3, 48, 64)
    # Decoding is exactly the project's sRGB curve applied to the stored codes ...
    expected = srgb_to_linear(torch.from_numpy(codes / 255.0)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)
    # ... and gets the known linear image back within half an 8-bit step through the curve.
    error = np.abs(photo.linear.double().numpy().transpose(1, 2, 0) - linear)
    bound = quantisation_bound(linear, 0.5)
    assert (error <= bound).all(), float((error - bound).max())
    assert bound.max() < 0.005  # the bound is tight enough to mean something


def test_jpeg_srgb_round_trip_within_jpeg_error(tmp_path: Path) -> None:
    linear = known_linear()
    path = save_pil(tmp_path / "photo.jpg", srgb_codes(linear, 255), quality=100, subsampling=0)

    photo = read_photo(path)

    assert (photo.source, photo.bit_depth, photo.colorspace) == ("jpeg", 8, "srgb")
    error = np.abs(photo.linear.double().numpy().transpose(1, 2, 0) - linear)
    # Quality 100 without chroma subsampling stays within a few codes of the stored values
    # (measured ≤ 4, mean ~0.5): half a step of quantisation plus 4 steps of JPEG slack.
    assert (error <= quantisation_bound(linear, 4.5)).all()
    assert error.mean() < np.mean(quantisation_bound(linear, 1.0))


def test_png16_round_trip_srgb_and_linear(tmp_path: Path) -> None:
    linear = known_linear()
    srgb_path = tmp_path / "srgb16.png"
    cv2.imwrite(str(srgb_path), srgb_codes(linear, 65535)[..., ::-1].copy())
    linear_path = tmp_path / "linear16.png"
    write_image(linear_path, linear.astype(np.float32), bit_depth=16)

    srgb_photo = read_photo(srgb_path)
    linear_photo = read_photo(linear_path, colorspace="linear")

    assert srgb_photo.bit_depth == 16 and srgb_photo.colorspace == "srgb"
    error = np.abs(srgb_photo.linear.double().numpy().transpose(1, 2, 0) - linear)
    step = 0.5 / 65535.0
    encoded = linear_to_srgb(torch.from_numpy(linear)).numpy()
    assert (error <= srgb_decode_slope(encoded + step) * step + 1e-6).all()
    assert error.max() < 5e-5  # 256 times finer than 8 bits
    assert linear_photo.bit_depth == 16 and linear_photo.colorspace == "linear"
    np.testing.assert_allclose(
        linear_photo.linear.numpy().transpose(1, 2, 0), linear, atol=0.5 / 65535 + 1e-7
    )


def test_linear_colorspace_takes_stored_values(tmp_path: Path) -> None:
    codes = srgb_codes(known_linear(), 255)
    path = save_pil(tmp_path / "photo.png", codes)

    photo = read_photo(path, colorspace="linear")

    assert photo.colorspace == "linear"
    torch.testing.assert_close(photo.linear, chw(codes.astype(np.float32) / 255.0), atol=1e-7, rtol=0)


def test_palette_png_is_converted_to_rgb(tmp_path: Path) -> None:
    codes = blocks()
    path = tmp_path / "palette.png"
    Image.fromarray(codes).convert("P", palette=Image.Palette.ADAPTIVE, colors=8).save(path)

    photo = read_photo(path)

    expected = srgb_to_linear(torch.from_numpy(codes / 255.0)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)


# --------------------------------------------------------------------------------------- orientation


@pytest.mark.parametrize("tag", range(1, 9))
def test_apply_orientation_matches_pillow_exif_transpose(tag: int) -> None:
    array = np.arange(5 * 7 * 3, dtype=np.uint8).reshape(5, 7, 3)
    image = Image.fromarray(array)
    image.info["exif"] = exif_with_orientation(tag).tobytes()

    expected = np.asarray(ImageOps.exif_transpose(image))

    np.testing.assert_array_equal(apply_orientation(array, tag), expected)


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
@pytest.mark.parametrize("tag", [3, 6])
def test_exif_orientation_is_applied_once(tmp_path: Path, suffix: str, tag: int) -> None:
    codes = blocks()
    options: dict[str, object] = {"quality": 95} if suffix == ".jpg" else {}
    plain = save_pil(tmp_path / f"plain{suffix}", codes, **options)
    rotated = save_pil(tmp_path / f"rotated{suffix}", codes, exif=exif_with_orientation(tag), **options)

    reference = read_photo(plain)
    photo = read_photo(rotated)

    assert reference.orientation == 1
    assert photo.orientation == tag
    # The same compressed pixels, turned exactly once: 6 = 90° clockwise (H and W swap), 3 = 180°.
    turned = torch.rot90(reference.linear, k=-1, dims=(1, 2)) if tag == 6 else reference.linear.flip(1, 2)
    assert photo.linear.shape == turned.shape
    torch.testing.assert_close(photo.linear, turned, atol=0, rtol=0)
    with Image.open(rotated) as image:
        pillow = np.asarray(ImageOps.exif_transpose(image).convert("RGB"))
    expected = srgb_to_linear(torch.from_numpy(pillow / 255.0)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)


# ----------------------------------------------------------------------------------------------- EXR


def test_exr_float_and_half_are_linear(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    hdr = (rng.random((40, 48, 3)) * 20.0).astype(np.float32)  # values well above 1 stay
    full = write_image(tmp_path / "float.exr", hdr, exr_precision="float")
    half = write_image(tmp_path / "half.exr", hdr, exr_precision="half")

    photo = read_photo(full)
    half_photo = read_photo(half)

    assert (photo.source, photo.bit_depth, photo.colorspace, photo.warnings) == ("exr", 32, "linear", ())
    torch.testing.assert_close(photo.linear, chw(hdr), atol=0, rtol=0)
    assert half_photo.bit_depth == 16
    torch.testing.assert_close(half_photo.linear, chw(hdr), atol=0, rtol=1e-3)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_exr_with_nan_or_inf_is_rejected(tmp_path: Path, bad: float) -> None:
    hdr = np.ones((40, 40, 3), dtype=np.float32)
    hdr[3, 5, 1] = bad
    path = tmp_path / "bad.exr"
    # write_image refuses NaN (rightly), so the bad file is written with OpenEXR directly.
    channels = {name: np.ascontiguousarray(hdr[:, :, i]) for i, name in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as exr:
        exr.write(str(path))

    with pytest.raises(PhotoError) as error:
        read_photo(path)

    assert_photo_error(error, path, "NaN or infinite")


def test_exr_negative_values_are_clamped_with_warning(tmp_path: Path) -> None:
    hdr = np.full((40, 40, 3), 0.5, dtype=np.float32)
    hdr[:4, :, 2] = -0.01
    path = write_image(tmp_path / "neg.exr", hdr, exr_precision="float")

    photo = read_photo(path)

    assert float(photo.linear.min()) == 0.0
    assert float(photo.linear[2, :4].max()) == 0.0 and float(photo.linear[2, 4:].min()) == 0.5
    assert any("negative" in warning and "clamped" in warning for warning in photo.warnings)


@pytest.mark.parametrize(
    ("name", "values"),
    [
        ("black.jpg", 0.0),
        ("black.png", 0.0),
        ("black.heic", 0.0),
        ("black.tif", 0.0),
        ("black.exr", 0.0),
        ("negative.exr", -0.25),
    ],
)
def test_black_or_negative_photo_is_rejected(tmp_path: Path, name: str, values: float) -> None:
    # Auto exposure multiplies a photo without light by 0: the network would see a flat black
    # input and the batch would write a made-up material; like grayscale, it is an error.
    path = tmp_path / name
    if path.suffix == ".exr":
        write_image(path, np.full((40, 40, 3), values, dtype=np.float32), exr_precision="float")
    else:
        save_pil(path, np.zeros((40, 40, 3), dtype=np.uint8))

    with pytest.raises(PhotoError) as error:
        read_photo(path)

    assert_photo_error(error, path, "is black", "nothing to estimate")
    # One lit pixel is a (very dark) photo, not an error.
    if path.suffix == ".exr":
        image = np.full((40, 40, 3), values, dtype=np.float32)
        image[20, 20] = 0.5
        write_image(path, image, exr_precision="float")
        assert float(read_photo(path).linear.max()) == 0.5


@pytest.mark.parametrize("channels", ["Y", "YA"])
def test_grayscale_exr_is_rejected(tmp_path: Path, channels: str) -> None:
    # read_image replicates Y+A to RGBA: the header's channel names tell it is grayscale.
    path = tmp_path / "gray.exr"
    planes = {name: np.full((40, 40), 0.5, dtype=np.float32) for name in channels}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, planes) as exr:
        exr.write(str(path))

    with pytest.raises(PhotoError) as error:
        read_photo(path)

    assert_photo_error(error, path, "is grayscale")


# ----------------------------------------------------------------------------------------------- RAW


def test_fake_raw_file_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "photo.dng"
    path.write_text("not a raw file\n" * 20)

    with pytest.raises(PhotoError) as error:
        read_photo(path)

    assert_photo_error(error, path, "cannot decode RAW file")


def test_raw_is_demosaiced_linearly(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import rawpy

    rng = np.random.default_rng(1)
    sensor = rng.integers(0, 65536, size=(36, 50, 3), dtype=np.uint16)
    calls: list[dict[str, object]] = []

    class FakeRaw:
        white_level = 16383
        sizes = types.SimpleNamespace(flip=6)

        def __enter__(self) -> FakeRaw:
            return self

        def __exit__(self, *exc: object) -> None:
            return None

        def postprocess(self, **kwargs: object) -> np.ndarray:
            calls.append(kwargs)
            return sensor

    opened: list[str] = []
    monkeypatch.setattr(rawpy, "imread", lambda name: opened.append(name) or FakeRaw())
    path = tmp_path / "IMG_0001.CR2"
    path.write_bytes(b"\0" * 64)

    photo = read_photo(path)

    assert opened == [str(path)]
    assert calls == [
        {
            "gamma": (1, 1),
            "no_auto_bright": True,
            "use_camera_wb": True,
            "output_bps": 16,
            "output_color": rawpy.ColorSpace.sRGB,
        }
    ]
    assert (photo.source, photo.colorspace, photo.bit_depth, photo.orientation) == ("raw", "linear", 14, 6)
    torch.testing.assert_close(photo.linear, chw(sensor.astype(np.float32) / 65535.0), atol=0, rtol=0)
    with pytest.raises(PhotoError) as error:
        read_photo(path, colorspace="srgb")
    assert_photo_error(error, path, "linearly")


# ---------------------------------------------------------------------------------------- HEIF/TIFF


def srgb_codes_bits(linear: np.ndarray, bits: int) -> np.ndarray:
    return np.rint(linear_to_srgb(torch.from_numpy(linear)).numpy() * ((1 << bits) - 1)).astype(np.uint16)


def test_heic_8bit_decodes_like_jpeg(tmp_path: Path) -> None:
    linear = known_linear()
    codes = srgb_codes(linear, 255)
    path = save_pil(tmp_path / "IMG_0001.HEIC", codes, **HEIF_LOSSLESS)

    photo = read_photo(path)

    assert (photo.source, photo.bit_depth, photo.colorspace, photo.orientation) == ("heif", 8, "srgb", 1)
    assert photo.linear.dtype == torch.float32 and photo.warnings == ()
    expected = srgb_to_linear(torch.from_numpy(codes / 255.0)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)
    as_linear = read_photo(path, colorspace="linear")  # --input-colorspace linear: codes as they are
    torch.testing.assert_close(as_linear.linear, chw(codes.astype(np.float32) / 255.0), atol=1e-7, rtol=0)


@pytest.mark.parametrize("bits", [10, 12])
def test_high_bit_depth_heic_keeps_its_precision(
    tmp_path: Path, bits: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(pillow_heif.options, "SAVE_HDR_TO_12_BIT", bits == 12)
    linear = known_linear()
    linear[0, 0] = 1.0  # white must read as exactly 1
    codes = srgb_codes_bits(linear, bits)
    path = save_heif16(tmp_path / "hdr.heic", codes, bits, **HEIF_LOSSLESS)

    photo = read_photo(path)
    as_linear = read_photo(path, colorspace="linear")

    assert (photo.source, photo.bit_depth) == ("heif", bits)
    levels = (1 << bits) - 1
    expected = srgb_to_linear(torch.from_numpy(codes / levels)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)
    torch.testing.assert_close(as_linear.linear, chw((codes / levels).astype(np.float32)), atol=1e-7, rtol=0)
    assert float(as_linear.linear.max()) == 1.0
    # Finer than 8 bits could hold: within half a step of the file's own bit depth.
    error = np.abs(photo.linear.double().numpy().transpose(1, 2, 0) - linear)
    encoded = linear_to_srgb(torch.from_numpy(linear)).numpy()
    step = 0.5 / levels
    assert (error <= srgb_decode_slope(encoded + step) * step + 1e-6).all()
    assert error.max() < quantisation_bound(linear, 0.5).max() / 3


@pytest.mark.parametrize("tag", [3, 6, 8])
def test_heic_exif_orientation_and_lens(tmp_path: Path, tag: int) -> None:
    # Like an iPhone photo: lossy, 4:2:0, turned by the container (irot/imir, which pillow-heif
    # writes from the EXIF tag) with the EXIF saying the same, and the lens in the EXIF IFD.
    codes = blocks()
    exif = exif_with_orientation(tag)
    exif.get_ifd(EXIF_IFD).update({FOCAL_LENGTH_35MM: 26, FOCAL_LENGTH: 4.2})
    plain = save_pil(tmp_path / "plain.heic", codes, quality=90)
    turned_file = save_pil(tmp_path / "turned.heic", codes, quality=90, exif=exif.tobytes())

    reference = read_photo(plain)
    photo = read_photo(turned_file)

    assert (reference.orientation, reference.lens) == (1, None)
    assert photo.orientation == tag
    # The same compressed pixels, turned exactly once (6: 90° clockwise, 8: counter-clockwise).
    turned = {3: reference.linear.flip(1, 2), 6: torch.rot90(reference.linear, k=-1, dims=(1, 2)),
              8: torch.rot90(reference.linear, k=1, dims=(1, 2))}[tag]  # fmt: skip
    assert photo.linear.shape == turned.shape
    torch.testing.assert_close(photo.linear, turned, atol=0, rtol=0)
    # Lossy: close to the source blocks away from their edges (chroma is subsampled).
    source = chw(apply_orientation(srgb_to_linear(torch.from_numpy(codes / 255.0)).float().numpy(), tag))
    assert float((photo.linear - source).abs().median()) < 0.01
    assert photo.lens is not None
    assert (photo.lens.focal_length_35mm, photo.lens.focal_length_mm) == (26.0, pytest.approx(4.2))
    _, fov_source = crop_field_of_view(photo.lens, photo.width, photo.height, 32)
    assert fov_source == "exif 35 mm equivalent"
    assert photo.to_json()["lens"]["focal_length_35mm"] == 26.0


def test_embedded_display_p3_profile_is_not_applied_like_jpeg(tmp_path: Path) -> None:
    # Colour profiles are not applied for any format: an iPhone's Display P3 values are decoded with
    # the sRGB curve (P3's own curve) and their primaries are not converted, in HEIF as in JPEG.
    icc = display_p3_icc()
    assert ImageCms.getProfileDescription(ImageCms.ImageCmsProfile(io.BytesIO(icc))).strip() == "Display P3"
    codes = srgb_codes(known_linear(), 255)
    heic = save_pil(tmp_path / "p3.heic", codes, icc_profile=icc, **HEIF_LOSSLESS)
    jpeg = save_pil(tmp_path / "p3.jpg", codes, icc_profile=icc, quality=100, subsampling=0)
    assert pillow_heif.open_heif(heic).info["icc_profile"] == icc

    heic_photo, jpeg_photo = read_photo(heic), read_photo(jpeg)

    expected = chw(srgb_to_linear(torch.from_numpy(codes / 255.0)).float().numpy())
    torch.testing.assert_close(heic_photo.linear, expected, atol=1e-6, rtol=0)
    assert heic_photo.warnings == () and jpeg_photo.warnings == ()
    without = read_photo(save_pil(tmp_path / "plain.jpg", codes, quality=100, subsampling=0))
    torch.testing.assert_close(jpeg_photo.linear, without.linear, atol=0, rtol=0)


def test_heic_with_an_hdr_transfer_curve_warns(tmp_path: Path) -> None:
    codes = srgb_codes_bits(known_linear(), 10)
    pq = save_heif16(tmp_path / "pq.heic", codes, 10, transfer_characteristics=16, **HEIF_LOSSLESS)

    photo = read_photo(pq)

    assert any("HDR transfer curve PQ" in warning for warning in photo.warnings)
    assert read_photo(save_heif16(tmp_path / "sdr.heic", codes, 10, **HEIF_LOSSLESS)).warnings == ()


@pytest.mark.parametrize("bits", [8, 16])
def test_tiff_values_are_exact(tmp_path: Path, bits: int) -> None:
    linear = known_linear()
    codes = srgb_codes(linear, (1 << bits) - 1)
    baseline = write_tiff(tmp_path / "baseline.tif", codes)
    # LZW with a predictor, as Photoshop and most tools compress, through libtiff.
    lzw = tmp_path / "lzw.tiff"
    cv2.imwrite(str(lzw), codes[..., ::-1].copy(), [cv2.IMWRITE_TIFF_COMPRESSION, 5])

    for path in (baseline, lzw):
        photo = read_photo(path)
        as_linear = read_photo(path, colorspace="linear")

        assert (photo.source, photo.bit_depth, photo.colorspace) == ("tiff", bits, "srgb")
        levels = (1 << bits) - 1
        expected = srgb_to_linear(torch.from_numpy(codes / levels)).float()
        torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)
        stored = np.rint(as_linear.linear.double().numpy().transpose(1, 2, 0) * levels)
        np.testing.assert_array_equal(stored, codes)
    if bits == 16:  # 256 times finer than 8 bits survives
        error = np.abs(read_photo(baseline).linear.double().numpy().transpose(1, 2, 0) - linear)
        assert error.max() < 5e-5


@pytest.mark.parametrize("tag", [3, 6])
def test_tiff_orientation_is_applied_once_and_lens_read(tmp_path: Path, tag: int) -> None:
    rng = np.random.default_rng(4)
    codes = rng.integers(1, 65536, size=(40, 64, 3), dtype=np.uint16)
    reference = read_photo(write_tiff(tmp_path / "plain.tif", codes), colorspace="linear")
    photo = read_photo(
        write_tiff(tmp_path / "turned.tif", codes, orientation=tag, focal_length_35mm=28), colorspace="linear"
    )

    assert (reference.orientation, photo.orientation) == (1, tag)
    turned = torch.rot90(reference.linear, k=-1, dims=(1, 2)) if tag == 6 else reference.linear.flip(1, 2)
    torch.testing.assert_close(photo.linear, turned, atol=0, rtol=0)
    assert photo.lens is not None and photo.lens.focal_length_35mm == 28.0
    # Pillow's own reading of the same tags and pixels agrees (8-bit: Pillow's 16-bit RGB is 8-bit).
    small = (codes >> 8).astype(np.uint8)
    eight = save_pil(tmp_path / "pillow.tif", small, exif=exif_with_orientation(tag))
    with Image.open(eight) as image:
        pillow = np.asarray(ImageOps.exif_transpose(image))
    np.testing.assert_array_equal(
        np.rint(read_photo(eight, colorspace="linear").linear.numpy().transpose(1, 2, 0) * 255), pillow
    )


@pytest.mark.parametrize("suffix", [".heic", ".tif"])
def test_corrupt_heic_and_tiff_are_one_line_errors(
    tmp_path: Path, suffix: str, capfd: pytest.CaptureFixture[str]
) -> None:
    header = b"\0\0\0\x18ftypheic\0\0\0\0mif1heic" if suffix == ".heic" else b"II*\0\x08\0\0\0"
    path = tmp_path / f"garbage{suffix}"
    path.write_bytes(header + bytes(range(256)) * 8)

    with pytest.raises(PhotoError, match=r"garbage\.(heic|tif): truncated or corrupt") as error:
        read_photo(path)

    assert_photo_error(error, path, "HEIF" if suffix == ".heic" else "TIFF")
    assert capfd.readouterr().err == ""  # neither libheif, libtiff nor Pillow prints anything


def test_heic_named_jpg_is_read_with_a_warning(tmp_path: Path) -> None:
    codes = blocks()
    path = save_pil(tmp_path / "heic.heic", codes, **HEIF_LOSSLESS).rename(tmp_path / "actually_heic.jpg")

    photo = read_photo(path)

    assert photo.source == "heif"
    assert any("HEIF image although its extension is '.jpg'" in warning for warning in photo.warnings)


def test_collect_photos_finds_heic_and_tiff(tmp_path: Path) -> None:
    names = ["a.heic", "b.HEIC", "c.heif", "d.tif", "e.TIFF", "f.jpg", "notes.txt", "g.gif"]
    for name in names:
        (tmp_path / name).write_bytes(b"x")

    found = [path.name for path in collect_photos([tmp_path])]

    assert found == ["a.heic", "b.HEIC", "c.heif", "d.tif", "e.TIFF", "f.jpg"]
    assert {".heic", ".heif", ".tif", ".tiff"} <= PHOTO_EXTENSIONS


def test_predict_reads_heic_and_tiff_and_reports_bad_ones_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    torch.manual_seed(0)
    generator = Generator(width=4, residual_blocks=1)
    weights = tmp_path / "tiny.safetensors"
    save_weights(weights, generator, target="brdfgan.models.generator.Generator", config=generator.config(),
                 model_id="tiny-test", extra={"resolution": 64})  # fmt: skip
    scene = np.clip(flash_scene_linear() * 4.0, 0.0, 1.0)  # exposed like a camera's sRGB photo
    photos = tmp_path / "photos"
    photos.mkdir()
    save_pil(
        photos / "phone.heic", srgb_codes(scene, 255), quality=90, exif=exif_with_orientation(6).tobytes()
    )
    write_tiff(photos / "scan.tif", srgb_codes(scene, 65535))
    full = (photos / "phone.heic").read_bytes()
    (photos / "cut.heic").write_bytes(full[: len(full) // 2])
    (photos / "cut.tif").write_bytes((photos / "scan.tif").read_bytes()[:3000])
    out = tmp_path / "out"

    code = main(["predict", str(photos), "--out", str(out), "--weights", str(weights), "--quiet"])

    captured = capsys.readouterr()
    assert code == PARTIAL_FAILURE_EXIT_CODE
    assert sorted(p.name for p in out.iterdir()) == ["phone", "scan"]
    phone = json.loads((out / "phone" / "material.json").read_text())["input"]
    scan = json.loads((out / "scan" / "material.json").read_text())["input"]
    assert (phone["source"], phone["exif_orientation"], phone["size"]) == ("heif", 6, [96, 128])
    assert (scan["source"], scan["bit_depth"], scan["size"]) == ("tiff", 16, [128, 96])
    summary = captured.err.split("photo(s) failed:")[1].strip().splitlines()
    assert sorted(Path(line.strip().split(": ")[0]).name for line in summary) == ["cut.heic", "cut.tif"]
    assert all("truncated or corrupt" in line for line in summary)
    assert "Traceback" not in captured.err


# ---------------------------------------------------------------------------------------- bad inputs


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "missing.jpg"
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "not found")


def test_directory(tmp_path: Path) -> None:
    path = tmp_path / "folder.png"
    path.mkdir()
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "not a regular file")


def test_unreadable_file_reported(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = save_pil(tmp_path / "photo.png", blocks())

    def deny(self: Path) -> bytes:
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_bytes", deny)
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "cannot read file", "Permission denied")


@pytest.mark.skipif(sys.platform == "win32" or os.geteuid() == 0, reason="root ignores file permissions")
def test_unreadable_file_permissions(tmp_path: Path) -> None:
    path = save_pil(tmp_path / "photo.jpg", blocks())
    path.chmod(0)
    try:
        with pytest.raises(PhotoError) as error:
            read_photo(path)
    finally:
        path.chmod(0o644)
    assert_photo_error(error, path, "cannot read file")


def test_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.jpg"
    path.touch()
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "empty")


def test_text_file_renamed_jpg(tmp_path: Path) -> None:
    path = tmp_path / "notes.jpg"
    path.write_text("these are my notes, not a photo\n" * 10)
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "not an image")


@pytest.mark.parametrize("suffix", [".jpg", ".png", ".heic", ".tif"])
def test_truncated_file_does_not_decode_silently(tmp_path: Path, suffix: str) -> None:
    rng = np.random.default_rng(2)
    noisy = rng.integers(0, 256, size=(128, 128, 3), dtype=np.uint8)  # incompressible: data is large
    full = save_pil(tmp_path / f"full{suffix}", noisy)
    path = tmp_path / f"truncated{suffix}"
    data = full.read_bytes()
    path.write_bytes(data[: len(data) // 2])

    with pytest.raises(PhotoError) as error:
        read_photo(path)

    assert_photo_error(error, path, "truncated or corrupt")


def test_tiny_image(tmp_path: Path) -> None:
    path = save_pil(tmp_path / "tiny.png", blocks(8, 8))
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "8×8", f"at least {MIN_PHOTO_SIZE}")


def test_tiny_exr(tmp_path: Path) -> None:
    path = write_image(tmp_path / "tiny.exr", np.ones((64, 16, 3), dtype=np.float32))
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "16×64")


@pytest.mark.parametrize(
    ("name", "mode"),
    [
        ("gray.jpg", "L"),
        ("gray.png", "L"),
        ("gray16.png", "I;16"),
        ("gray.heic", "L"),
        ("gray.tif", "L"),
        ("gray16.tif", "I;16"),
    ],
)
def test_grayscale_is_rejected(tmp_path: Path, name: str, mode: str) -> None:
    path = tmp_path / name
    if mode == "I;16":
        cv2.imwrite(str(path), np.full((40, 40), 30000, dtype=np.uint16))
    else:
        save_pil(path, blocks(), mode=mode)
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "is grayscale; a colour photo is needed")


def test_rgba_with_transparency_is_rejected(tmp_path: Path) -> None:
    rgba = np.dstack([blocks(), np.full((40, 64), 255, dtype=np.uint8)])
    rgba[:10, :10, 3] = 0
    path = save_pil(tmp_path / "cutout.png", rgba)
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "alpha channel")


def test_gray_alpha_is_rejected(tmp_path: Path) -> None:
    path = save_pil(tmp_path / "la.png", blocks(), mode="LA")
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "alpha channel")


def test_opaque_alpha_is_dropped_with_warning(tmp_path: Path) -> None:
    codes = blocks()
    path = save_pil(tmp_path / "opaque.png", np.dstack([codes, np.full((40, 64), 255, dtype=np.uint8)]))

    photo = read_photo(path)

    assert photo.linear.shape == (3, 40, 64)
    expected = srgb_to_linear(torch.from_numpy(codes / 255.0)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)
    assert any("alpha" in warning for warning in photo.warnings)


def test_cmyk_jpeg_is_rejected(tmp_path: Path) -> None:
    path = save_pil(tmp_path / "print.jpg", blocks(), mode="CMYK")
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "is CMYK; convert it to RGB")


@pytest.mark.parametrize("name", ["photo.gif", "photo.bmp", "photo"])
def test_unsupported_extension_lists_supported(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(b"whatever")
    with pytest.raises(PhotoError) as error:
        read_photo(path)
    assert_photo_error(error, path, "unsupported file type", *sorted(PHOTO_EXTENSIONS))


def test_unknown_colorspace_argument(tmp_path: Path) -> None:
    path = save_pil(tmp_path / "photo.png", blocks())
    with pytest.raises(PhotoError) as error:
        read_photo(path, colorspace="rec709")  # type: ignore[arg-type]
    assert_photo_error(error, path, "unknown colour space")


def test_extension_mismatch_warns_and_reads_content(tmp_path: Path) -> None:
    codes = blocks()
    path = tmp_path / "actually_png.jpg"
    Image.fromarray(codes).save(path, format="PNG")

    photo = read_photo(path)

    assert photo.source == "png"
    expected = srgb_to_linear(torch.from_numpy(codes / 255.0)).float()
    torch.testing.assert_close(photo.linear, chw(expected.numpy()), atol=1e-6, rtol=0)
    assert any("extension" in warning for warning in photo.warnings)


def test_rgb_file_with_identical_channels_warns(tmp_path: Path) -> None:
    gray = np.repeat(blocks()[..., :1], 3, axis=2)
    photo = read_photo(save_pil(tmp_path / "gray_rgb.png", gray))
    assert any("grayscale" in warning for warning in photo.warnings)
    assert not any(
        "grayscale" in warning for warning in read_photo(save_pil(tmp_path / "c.png", blocks())).warnings
    )


# --------------------------------------------------------------------------- colour-space heuristic


def colorspace_warnings(photo: Photo) -> list[str]:
    return [w for w in photo.warnings if "looks linear" in w or "looks sRGB" in w]


def test_linear_file_read_as_srgb_is_flagged(tmp_path: Path) -> None:
    # A training-like auto-exposed linear image saved without the sRGB curve.
    linear = flash_scene_linear()
    assert np.median(linear) < LOOKS_LINEAR_MAX_MEDIAN
    as_is = tmp_path / "linear_as_is.png"
    write_image(as_is, linear.astype(np.float32))
    encoded = save_pil(tmp_path / "encoded.png", srgb_codes(np.clip(linear, 0, 1), 255))

    flagged = colorspace_warnings(read_photo(as_is))
    fine = colorspace_warnings(read_photo(encoded))
    read_right = colorspace_warnings(read_photo(as_is, colorspace="linear"))

    assert len(flagged) == 1 and "looks linear" in flagged[0]
    assert fine == [] and read_right == []


def test_srgb_file_read_as_linear_is_flagged(tmp_path: Path) -> None:
    # A camera-metered exposure: the median sits near middle grey (18 % linear).
    scene = flash_scene_linear(seed=3)
    linear = np.clip(scene * (0.18 / np.median(scene)), 0.0, 1.0)
    encoded = save_pil(tmp_path / "camera.jpg", srgb_codes(linear, 255), quality=95)
    stored_linear = tmp_path / "raw_export.png"
    write_image(stored_linear, linear.astype(np.float32), bit_depth=16)

    flagged = colorspace_warnings(read_photo(encoded, colorspace="linear"))
    fine = colorspace_warnings(read_photo(encoded))
    read_right = colorspace_warnings(read_photo(stored_linear, colorspace="linear"))

    assert len(flagged) == 1 and "looks sRGB" in flagged[0]
    assert fine == [] and read_right == []
    assert np.median(srgb_codes(linear, 255) / 255.0) > LOOKS_SRGB_MIN_MEDIAN
