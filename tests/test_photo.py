"""Reading user photos: colour-space round trips, orientation, EXR/RAW, every bad input."""

from __future__ import annotations

import os
import sys
import types
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest
import torch
from PIL import Image, ImageOps

from brdfgan.core.exposure import auto_expose
from brdfgan.core.svbrdf import linear_to_srgb, srgb_to_linear
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
from brdfgan.io.images import write_image

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
    image.save(path, **options)
    return path


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
    [("black.jpg", 0.0), ("black.png", 0.0), ("black.exr", 0.0), ("negative.exr", -0.25)],
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


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
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


@pytest.mark.parametrize(("name", "mode"), [("gray.jpg", "L"), ("gray.png", "L"), ("gray16.png", "I;16")])
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


@pytest.mark.parametrize("name", ["photo.tif", "photo.bmp", "photo"])
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
