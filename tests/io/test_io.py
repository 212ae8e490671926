"""Image and map-set IO: round trips per format, on-disk conventions, atomicity, error messages."""

from __future__ import annotations

import errno
import math
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from torch import Tensor

from brdfgan.core.svbrdf import (
    InvalidMapsError,
    join_maps,
    normalize_normal,
    split_maps,
    srgb_to_linear,
    validate_maps,
)
from brdfgan.errors import DiskFullError
from brdfgan.io.images import ImageIOError, read_image, write_image
from brdfgan.io.maps import MapIOError, map_paths, read_maps, write_maps

H, W = 24, 40  # non-square so that a transposed read cannot pass


def random_maps(seed: int = 0, height: int = H, width: int = W) -> Tensor:
    """A valid (8, H, W) map set with independent random content in every channel."""
    gen = torch.Generator().manual_seed(seed)
    basecolor = torch.rand(3, height, width, generator=gen)
    xy = torch.rand(2, height, width, generator=gen) - 0.5
    normal = normalize_normal(torch.cat([xy, torch.ones(1, height, width)]))
    roughness = torch.rand(1, height, width, generator=gen)
    metallic = torch.rand(1, height, width, generator=gen)
    maps = join_maps(basecolor, normal, roughness, metallic)
    validate_maps(maps)
    return maps


def max_angle_deg(a: Tensor, b: Tensor) -> float:
    # atan2 of |a×b| and a·b stays accurate for tiny angles, where acos of a float32 cosine does not.
    a, b = a.double(), b.double()
    sin = torch.linalg.vector_norm(torch.cross(a, b, dim=0), dim=0)
    return math.degrees(torch.atan2(sin, (a * b).sum(dim=0)).max().item())


def files_in(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


# --- map-set round trips ------------------------------------------------------------------------


def test_png8_round_trip(tmp_path: Path) -> None:
    maps = random_maps(1)
    paths = write_maps(tmp_path, maps, format="png", bit_depth=8)
    assert set(paths) == {"basecolor", "normal", "roughness", "metallic"}
    assert files_in(tmp_path) == ["basecolor.png", "metallic.png", "normal.png", "roughness.png"]
    back = read_maps(tmp_path)
    assert back.shape == (8, H, W) and back.dtype == torch.float32
    validate_maps(back)
    a, b = split_maps(maps), split_maps(back)
    for name in ("basecolor", "roughness", "metallic"):
        assert (getattr(a, name) - getattr(b, name)).abs().max() <= 0.5 / 255 + 1e-6, name
    assert max_angle_deg(a.normal, b.normal) < 1.0


def test_png16_round_trip(tmp_path: Path) -> None:
    maps = random_maps(2)
    write_maps(tmp_path, maps, format="png", bit_depth=16)
    back = read_maps(tmp_path, format="png")
    a, b = split_maps(maps), split_maps(back)
    for name in ("basecolor", "roughness", "metallic"):
        assert (getattr(a, name) - getattr(b, name)).abs().max() <= 0.5 / 65535 + 1e-7, name
    assert max_angle_deg(a.normal, b.normal) < 0.01


def test_png16_is_uint16_on_disk(tmp_path: Path) -> None:
    paths = write_maps(tmp_path, random_maps(3), format="png", bit_depth=16)
    raw = cv2.imread(str(paths["basecolor"]), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16 and raw.shape == (H, W, 3)
    gray = cv2.imread(str(paths["roughness"]), cv2.IMREAD_UNCHANGED)
    assert gray.dtype == np.uint16 and gray.shape == (H, W)


def test_exr_half_round_trip(tmp_path: Path) -> None:
    maps = random_maps(4)
    write_maps(tmp_path, maps, format="exr", exr_precision="half")
    back = read_maps(tmp_path)
    validate_maps(back)
    a, b = split_maps(maps), split_maps(back)
    for name in ("basecolor", "roughness", "metallic"):
        torch.testing.assert_close(getattr(b, name), getattr(a, name), rtol=1e-3, atol=1e-4, msg=name)
    assert max_angle_deg(a.normal, b.normal) < 0.1
    raw = read_image(tmp_path / "roughness.exr")
    assert raw.shape == (H, W, 1)


def test_exr_float_round_trip_is_exact_to_float32(tmp_path: Path) -> None:
    maps = random_maps(5)
    write_maps(tmp_path, maps, format="exr", exr_precision="float")
    back = read_maps(tmp_path, format="exr")
    a, b = split_maps(maps), split_maps(back)
    # Roughness and metallic are stored raw: bit-exact.
    assert torch.equal(a.roughness, b.roughness) and torch.equal(a.metallic, b.metallic)
    # Base color goes through the sRGB curve and normals through renormalisation: float32 rounding only.
    torch.testing.assert_close(b.basecolor, a.basecolor, rtol=0, atol=1e-6)
    torch.testing.assert_close(b.normal, a.normal, rtol=0, atol=1e-6)


def test_exr_basecolor_is_stored_linear(tmp_path: Path) -> None:
    maps = random_maps(6)
    write_maps(tmp_path, maps, format="exr", exr_precision="float")
    raw = torch.from_numpy(read_image(tmp_path / "basecolor.exr")).permute(2, 0, 1)
    expected = srgb_to_linear(split_maps(maps).basecolor.double()).float()
    torch.testing.assert_close(raw, expected, rtol=0, atol=1e-7)
    # The difference from sRGB storage is large, so this cannot pass by accident.
    assert (raw - split_maps(maps).basecolor).abs().max() > 0.1
    normal_raw = torch.from_numpy(read_image(tmp_path / "normal.exr")).permute(2, 0, 1)
    torch.testing.assert_close(normal_raw, (split_maps(maps).normal + 1) / 2, rtol=0, atol=1e-7)


def test_png_basecolor_is_stored_srgb(tmp_path: Path) -> None:
    maps = random_maps(7)
    write_maps(tmp_path, maps, format="png", bit_depth=16)
    raw = torch.from_numpy(read_image(tmp_path / "basecolor.png")).permute(2, 0, 1)
    assert (raw - split_maps(maps).basecolor).abs().max() <= 0.5 / 65535 + 1e-7
    normal_raw = torch.from_numpy(read_image(tmp_path / "normal.png")).permute(2, 0, 1)
    assert (normal_raw - (split_maps(maps).normal + 1) / 2).abs().max() <= 0.5 / 65535 + 1e-7


def test_write_other_format_replaces_stale_set(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(8), format="png")
    maps = random_maps(9)
    write_maps(tmp_path, maps, format="exr", exr_precision="float")
    assert files_in(tmp_path) == ["basecolor.exr", "metallic.exr", "normal.exr", "roughness.exr"]
    torch.testing.assert_close(read_maps(tmp_path), maps, rtol=0, atol=1e-6)


def test_write_maps_rejects_invalid_maps_before_writing(tmp_path: Path) -> None:
    maps = random_maps(10)
    maps[6, 0, 0] = 1.5
    with pytest.raises(InvalidMapsError, match="roughness"):
        write_maps(tmp_path / "set", maps)
    assert not (tmp_path / "set").exists()
    with pytest.raises(InvalidMapsError, match=r"\(8, H, W\)"):
        write_maps(tmp_path / "set", random_maps(10)[None])


# --- lenient reading of real texture packs ------------------------------------------------------


def test_grayscale_maps_stored_as_rgb_are_accepted(tmp_path: Path) -> None:
    maps = random_maps(11)
    write_maps(tmp_path, maps, format="png", bit_depth=16)
    for name, channel in (("roughness", 6), ("metallic", 7)):
        gray = maps[channel].numpy()[:, :, None]
        write_image(tmp_path / f"{name}.png", np.repeat(gray, 3, axis=2), bit_depth=16)
        assert read_image(tmp_path / f"{name}.png").shape == (H, W, 3)
    back = read_maps(tmp_path)
    torch.testing.assert_close(back[6:], maps[6:], rtol=0, atol=1e-5)


def test_packed_rgb_texture_rejected_as_grayscale(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(12))
    orm = np.random.default_rng(0).random((H, W, 3))
    write_image(tmp_path / "roughness.png", orm)
    with pytest.raises(MapIOError, match=r"roughness\.png.*grayscale"):
        read_maps(tmp_path)


def test_exr_tiny_excursions_clipped_large_rejected(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(13), format="exr", exr_precision="float")
    rough = read_image(tmp_path / "roughness.exr")
    rough[0, 0, 0], rough[1, 1, 0] = -2e-4, 1.0 + 2e-4
    write_image(tmp_path / "roughness.exr", rough, exr_precision="float")
    back = read_maps(tmp_path)
    assert back[6, 0, 0] == 0.0 and back[6, 1, 1] == 1.0
    rough[0, 0, 0] = 3.0
    write_image(tmp_path / "roughness.exr", rough, exr_precision="float")
    with pytest.raises(MapIOError, match=r"roughness\.exr.*\[0, 1\]"):
        read_maps(tmp_path)


def test_normal_pointing_into_surface_rejected(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(14))
    normal = read_image(tmp_path / "normal.png")
    normal[..., 2] = 0.1  # z = -0.8 after decoding
    write_image(tmp_path / "normal.png", normal)
    with pytest.raises(MapIOError, match=r"normal\.png.*into the surface"):
        read_maps(tmp_path)


# --- map-set errors -----------------------------------------------------------------------------


def test_missing_map_file_named(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(15))
    (tmp_path / "metallic.png").unlink()
    with pytest.raises(MapIOError, match=r"metallic\.png: map file missing"):
        read_maps(tmp_path)


def test_size_mismatch_named(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(16))
    write_image(tmp_path / "normal.png", np.full((H, W + 1, 3), 0.5))
    with pytest.raises(MapIOError, match=r"normal\.png: size 41x24"):
        read_maps(tmp_path)


def test_format_detection_errors(tmp_path: Path) -> None:
    with pytest.raises(MapIOError, match="not found"):
        read_maps(tmp_path / "nowhere")
    with pytest.raises(MapIOError, match="no map files"):
        read_maps(tmp_path)
    paths = write_maps(tmp_path, random_maps(17), format="png")
    write_image(tmp_path / "basecolor.exr", np.zeros((H, W, 3)))
    with pytest.raises(MapIOError, match="both PNG"):
        read_maps(tmp_path)
    assert read_maps(tmp_path, format="png").shape == (8, H, W)
    with pytest.raises(MapIOError, match="unsupported map format"):
        read_maps(tmp_path, format="jpg")  # type: ignore[arg-type]
    assert map_paths(tmp_path, "png") == paths


def test_corrupt_map_file_is_map_error(tmp_path: Path) -> None:
    write_maps(tmp_path, random_maps(18))
    (tmp_path / "roughness.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(MapIOError, match=r"roughness\.png"):
        read_maps(tmp_path)


# --- low-level images ---------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize(("ext", "kwargs", "atol"), [
    (".png", {"bit_depth": 8}, 0.5 / 255 + 1e-6),
    (".png", {"bit_depth": 16}, 0.5 / 65535 + 1e-7),
    (".exr", {"exr_precision": "half"}, 2.5e-4),
    (".exr", {"exr_precision": "float"}, 0.0),
])  # fmt: skip
def test_image_round_trip_channel_order(
    tmp_path: Path, channels: int, ext: str, kwargs: dict[str, object], atol: float
) -> None:
    image = np.random.default_rng(channels).random((7, 9, channels)).astype(np.float32)
    image[0, 0, :] = np.linspace(0.0, 1.0, channels)  # distinct per channel: catches BGR swaps
    path = write_image(tmp_path / f"img{ext}", image, **kwargs)  # type: ignore[arg-type]
    back = read_image(path)
    assert back.dtype == np.float32 and back.shape == (7, 9, channels)
    np.testing.assert_allclose(back, image, rtol=0, atol=atol)


def test_png_channel_order_matches_cv2_bgr(tmp_path: Path) -> None:
    image = np.zeros((2, 3, 3), dtype=np.float32)
    image[..., 0] = 1.0  # pure red
    write_image(tmp_path / "red.png", image)
    raw = cv2.imread(str(tmp_path / "red.png"), cv2.IMREAD_UNCHANGED)
    assert (raw[..., 2] == 255).all() and (raw[..., :2] == 0).all()


def test_png_write_clips_and_exr_keeps_raw(tmp_path: Path) -> None:
    image = np.array([[[-0.5], [2.0]]])
    np.testing.assert_array_equal(read_image(write_image(tmp_path / "a.png", image))[..., 0], [[0.0, 1.0]])
    exr = read_image(write_image(tmp_path / "a.exr", image, exr_precision="float"))
    np.testing.assert_array_equal(exr[..., 0], [[-0.5, 2.0]])


def test_atomic_write_leaves_no_temp_files(tmp_path: Path) -> None:
    image = np.random.default_rng(0).random((5, 6, 3))
    for name, kwargs in (("a.png", {}), ("a.exr", {}), ("b.png", {"bit_depth": 16})):
        write_image(tmp_path / name, image, **kwargs)  # type: ignore[arg-type]
        write_image(tmp_path / name, image, **kwargs)  # overwrite goes through os.replace too
    assert files_in(tmp_path) == ["a.exr", "a.png", "b.png"]


@pytest.mark.parametrize("ext", [".png", ".exr"])
def test_failed_write_keeps_existing_file(tmp_path: Path, ext: str) -> None:
    path = tmp_path / f"good{ext}"
    good = np.full((4, 4, 3), 0.25)
    write_image(path, good)
    before = path.read_bytes()
    bad = good.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ImageIOError, match=rf"good\{ext}: .*NaN"):
        write_image(path, bad)
    assert path.read_bytes() == before
    assert files_in(tmp_path) == [path.name]


@pytest.mark.parametrize("ext", [".png", ".exr"])
@pytest.mark.parametrize("code", [errno.EIO, errno.ENOSPC])
def test_failure_after_temp_file_written_cleans_up(
    tmp_path: Path, ext: str, code: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / f"good{ext}"
    write_image(path, np.full((4, 4, 1), 0.25))
    before = path.read_bytes()

    def failing_replace(src: object, dst: object) -> None:
        assert Path(str(src)).exists()  # the temp file really was written before the failure
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr("brdfgan.io.images.os.replace", failing_replace)
    with pytest.raises(ImageIOError if code == errno.EIO else DiskFullError) as error:
        write_image(path, np.full((4, 4, 1), 0.75))
    if code == errno.EIO:
        assert f"good{ext}: cannot write file (Input/output error)" in str(error.value)
    else:  # a full disk is reported as such, naming the file and not its hidden temporary
        assert str(error.value) == f"{path}: no space left on device"
    assert path.read_bytes() == before
    assert files_in(tmp_path) == [path.name]


def test_half_overflow_rejected(tmp_path: Path) -> None:
    with pytest.raises(ImageIOError, match="range"):
        write_image(tmp_path / "big.exr", np.full((2, 2, 1), 1e6))
    assert files_in(tmp_path) == []
    write_image(tmp_path / "big.exr", np.full((2, 2, 1), 1e6), exr_precision="float")


def test_write_argument_errors(tmp_path: Path) -> None:
    image = np.zeros((2, 2, 3))
    with pytest.raises(ImageIOError, match=r"x\.tif: unsupported extension '\.tif'"):
        write_image(tmp_path / "x.tif", image)
    with pytest.raises(ImageIOError, match=r"x\.png: unsupported bit depth 12"):
        write_image(tmp_path / "x.png", image, bit_depth=12)  # type: ignore[arg-type]
    with pytest.raises(ImageIOError, match="unsupported EXR precision"):
        write_image(tmp_path / "x.exr", image, exr_precision="double")  # type: ignore[arg-type]
    with pytest.raises(ImageIOError, match="floating-point"):
        write_image(tmp_path / "x.png", np.zeros((2, 2, 3), dtype=np.uint8))
    with pytest.raises(ImageIOError, match="shape"):
        write_image(tmp_path / "x.png", np.zeros((2, 2, 2)))
    with pytest.raises(ImageIOError, match="parent directory"):
        write_image(tmp_path / "missing" / "x.png", image)
    assert files_in(tmp_path) == []


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(ImageIOError, match=r"nope\.png: file not found"):
        read_image(tmp_path / "nope.png")
    (tmp_path / "x.bmp").write_bytes(b"BM")
    with pytest.raises(ImageIOError, match=r"x\.bmp: unsupported extension"):
        read_image(tmp_path / "x.bmp")
    for name in ("garbage.png", "garbage.jpg", "garbage.exr", "empty.png"):
        (tmp_path / name).write_bytes(b"" if name.startswith("empty") else b"this is not an image" * 8)
        with pytest.raises(ImageIOError, match=rf"{name}: corrupt or unreadable"):
            read_image(tmp_path / name)


def test_read_jpeg_and_gray16(tmp_path: Path) -> None:
    bgr = np.zeros((8, 8, 3), dtype=np.uint8)
    bgr[..., 2] = 255  # red in OpenCV's order
    cv2.imwrite(str(tmp_path / "red.jpg"), bgr)
    rgb = read_image(tmp_path / "red.jpg")
    assert rgb.shape == (8, 8, 3) and rgb[..., 0].min() > 0.9 and rgb[..., 2].max() < 0.1
    gray = np.arange(16, dtype=np.uint16).reshape(4, 4) * 4000
    cv2.imwrite(str(tmp_path / "gray16.png"), gray)
    np.testing.assert_allclose(read_image(tmp_path / "gray16.png")[..., 0], gray / 65535, atol=1e-7)


def test_truncated_exr_library_messages_stay_off_stdout(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    # OpenEXR's C++ code prints "Warning: Exception raised reading pixel data ..." to stdout (fd 1)
    # on a file cut in the pixel data; `brdfgan predict`'s stdout is the list of output folders.
    rng = np.random.default_rng(0)
    full = write_image(
        tmp_path / "full.exr", rng.random((64, 64, 3)).astype(np.float32), exr_precision="float"
    )
    data = full.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: len(data) * 2 // 3])
    capfd.readouterr()
    with pytest.raises(ImageIOError) as error:
        read_image(cut)
    captured = capfd.readouterr()
    assert captured.out == "" and captured.err == ""
    message = str(error.value)
    # The library's own diagnosis is folded into the one-line error instead.
    assert message.startswith(f"{cut}: corrupt or unreadable EXR file: ") and "\n" not in message
    assert "EXR_ERR" in message or "scanline" in message, message
    assert read_image(full).shape == (64, 64, 3)  # descriptors are restored: later reads still work
    print("after")
    assert capfd.readouterr().out == "after\n"
