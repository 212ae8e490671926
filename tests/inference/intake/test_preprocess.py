"""Photo preprocessing: hotspot detection, crop policy, linear resize, auto exposure, warnings."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image

from brdfgan.core.exposure import auto_expose
from brdfgan.core.svbrdf import linear_to_srgb
from brdfgan.inference.intake.photo import Photo, PhotoError, read_photo
from brdfgan.inference.intake.preprocess import (
    CENTRED_SNAP_FRACTION,
    CLIPPED_WARNING_FRACTION,
    Crop,
    Preprocessed,
    clipped_fraction,
    find_hotspot,
    hotspot_crop,
    preprocess,
)
from brdfgan.io.images import write_image

# ------------------------------------------------------------------------------------------- helpers


def flash_photo(
    height: int,
    width: int,
    hotspot: tuple[float, float],
    *,
    seed: int = 0,
    scale: float = 1.0,
    speck_value: float = 1.0,
    clip_radius: float = 0.0,
) -> torch.Tensor:
    """A synthetic flash photo: tiled, noisy albedo under a broad falloff and a specular blob at
    ``hotspot``, plus a few bright specks elsewhere; ``clip_radius`` > 0 saturates a disc at 1.

    Shape: output ``(3, height, width)`` float32.
    """
    g = torch.Generator().manual_seed(seed)
    hx, hy = hotspot
    ys = torch.arange(height, dtype=torch.float32).view(height, 1)
    xs = torch.arange(width, dtype=torch.float32).view(1, width)
    r2 = (xs - hx) ** 2 + (ys - hy) ** 2
    size = min(height, width)
    tiles = 0.25 + 0.45 * (((xs // 7) + (ys // 5)) % 2)  # strong texture: dark/light tiles
    albedo = tiles * (0.8 + 0.4 * torch.rand(3, height, width, generator=g))
    falloff = 1.0 / (1.0 + r2 / (0.6 * size) ** 2) ** 2
    specular = 0.3 * torch.exp(-r2 / (2 * (0.06 * size) ** 2))
    image = 0.6 * albedo * falloff + specular
    image = image + 0.02 * torch.randn(3, height, width, generator=g)  # sensor noise
    for _ in range(6):  # specks: single bright pixels far from the hotspot
        while True:
            sy = int(torch.randint(0, height, (1,), generator=g))
            sx = int(torch.randint(0, width, (1,), generator=g))
            if math.hypot(sx - hx, sy - hy) > 0.3 * size:
                break
        image[:, sy, sx] = speck_value
    if clip_radius > 0:
        image = torch.where(r2 <= clip_radius**2, torch.ones_like(image), image)
    return (image.clamp(min=0.0) * scale).float()


def make_photo(linear: torch.Tensor, source: str = "png", path: str = "photo.png") -> Photo:
    return Photo(
        path=Path(path),
        linear=linear,
        source=source,
        bit_depth=8 if source in ("png", "jpeg") else 32,
        colorspace="srgb" if source in ("png", "jpeg") else "linear",
        orientation=1,
        warnings=(),
    )


def distance(a: tuple[float, float], b: tuple[float, float]) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


# ---------------------------------------------------------------------------------------------- Crop


@pytest.mark.parametrize(
    ("text", "expected"), [("10,20,300", Crop(10, 20, 300)), (" 0 , 7,  64 ", Crop(0, 7, 64))]
)
def test_crop_parse(text: str, expected: Crop) -> None:
    assert Crop.parse(text) == expected


@pytest.mark.parametrize("text", ["10,20", "1,2,3,4", "a,b,c", "1.5,2,30", "-1,0,5", "0,0,0", "", "10;20;30"])
def test_crop_parse_rejects_bad_text(text: str) -> None:
    with pytest.raises(ValueError, match="invalid crop") as error:
        Crop.parse(text)
    assert "\n" not in str(error.value)


def test_crop_check_bounds() -> None:
    Crop(10, 20, 80).check(height=100, width=90)  # touches the right and bottom edges exactly
    with pytest.raises(ValueError, match=r"does not fit in the 90×100 photo") as error:
        Crop(11, 20, 80).check(height=100, width=90)
    assert "\n" not in str(error.value)


# ------------------------------------------------------------------------------------------- hotspot


@pytest.mark.parametrize(
    ("height", "width", "hotspot"), [(120, 200, (142.0, 41.0)), (160, 96, (30.5, 101.0))]
)
def test_find_hotspot_off_centre_with_texture_and_specks(
    height: int, width: int, hotspot: tuple[float, float]
) -> None:
    image = flash_photo(height, width, hotspot)
    assert float(image.amax(dim=0).max()) >= 1.0  # the specks are as bright as anything else

    found = find_hotspot(image)

    assert distance(found, hotspot) < 2.0, found


def test_find_hotspot_ignores_very_bright_hdr_specks() -> None:
    hotspot = (60.0, 85.0)
    # HDR: the highlight peaks near 30, the specks are 100 times brighter still.
    image = flash_photo(110, 150, hotspot, seed=4, scale=30.0, speck_value=100.0)

    assert distance(find_hotspot(image), hotspot) < 2.0


def test_find_hotspot_on_a_large_photo_is_fast_and_accurate() -> None:
    height, width, hotspot = 4000, 6000, (3900.0, 1700.0)
    gy = torch.exp(-((torch.arange(height) - hotspot[1]) ** 2) / (2 * 250.0**2))
    gx = torch.exp(-((torch.arange(width) - hotspot[0]) ** 2) / (2 * 250.0**2))
    image = (0.1 + 0.8 * gy[:, None] * gx[None, :]).expand(3, height, width)

    start = time.perf_counter()
    found = find_hotspot(image)
    elapsed = time.perf_counter() - start

    # The search runs on a ~12× smaller copy; its centroid is still far better than one cell.
    assert distance(found, hotspot) < 6.0, found
    assert elapsed < 20.0  # ~0.5 s here; generous for a shared CPU


def test_find_hotspot_of_flat_image_is_centre() -> None:
    assert find_hotspot(torch.full((3, 40, 60), 0.3)) == (29.5, 19.5)


def test_find_hotspot_rejects_bad_shape() -> None:
    with pytest.raises(ValueError, match=r"\(3, H, W\)"):
        find_hotspot(torch.zeros(1, 3, 40, 40))


# ------------------------------------------------------------------------------------ crop policy


@pytest.mark.parametrize(
    ("height", "width", "hotspot", "expected"),
    [
        # Centred flash: the largest centred square is the full height.
        (200, 300, (149.5, 99.5), Crop(50, 0, 200)),
        # Off-centre but far enough from the edges: a smaller square, still centred on the flash.
        (400, 400, (150.0, 120.0), Crop(30, 0, 241)),
        # Near a corner: the minimum side (half of 400) is kept and shifted into the image.
        (400, 600, (10.0, 10.0), Crop(0, 0, 200)),
        (400, 600, (590.0, 200.0), Crop(400, 101, 200)),
        # Outside the image (bad detection): still a valid crop.
        (100, 80, (-50.0, 500.0), Crop(0, 60, 40)),
    ],
)
def test_hotspot_crop_cases(height: int, width: int, hotspot: tuple[float, float], expected: Crop) -> None:
    assert hotspot_crop(height, width, hotspot) == expected


def test_hotspot_crop_policy_properties() -> None:
    rng = np.random.default_rng(0)
    for _ in range(300):
        height, width = (int(v) for v in rng.integers(32, 400, size=2))
        hotspot = (float(rng.uniform(-0.5, width - 0.5)), float(rng.uniform(-0.5, height - 0.5)))
        crop = hotspot_crop(height, width, hotspot)
        shortest = min(height, width)
        assert crop.x + crop.size <= width and crop.y + crop.size <= height
        assert math.ceil(shortest / 2) <= crop.size <= shortest
        cx, cy = hotspot[0] + 0.5, hotspot[1] + 0.5
        largest_centred = math.floor(2 * min(cx, width - cx, cy, height - cy))
        centre = (crop.x + (crop.size - 1) / 2, crop.y + (crop.size - 1) / 2)
        if largest_centred >= CENTRED_SNAP_FRACTION * shortest:
            # Roughly centred: the whole central square, the hotspot within 5 % of its centre.
            assert crop.size == shortest
            assert max(abs(centre[0] - hotspot[0]), abs(centre[1] - hotspot[1])) <= 0.05 * shortest + 1
        elif largest_centred >= math.ceil(shortest / 2):
            assert crop.size == min(largest_centred, shortest)
            assert abs(centre[0] - hotspot[0]) <= 1.0 and abs(centre[1] - hotspot[1]) <= 1.0


# ------------------------------------------------------------------------------------------ clipping


def test_clipped_fraction_counts_saturated_disc() -> None:
    hotspot = (100.0, 80.0)
    clipped = flash_photo(160, 200, hotspot, clip_radius=5.0)
    clean = flash_photo(160, 200, hotspot)
    crop = Crop(20, 0, 160)  # disc radius 5 % of 160 = 8 px

    fraction = clipped_fraction(clipped, crop, hotspot)

    assert fraction == pytest.approx(25 / 64, abs=0.05)  # (5 / 8)² of the disc
    assert clipped_fraction(clean, crop, hotspot) == 0.0
    assert clipped_fraction(clipped, crop, (-100.0, -100.0)) == 0.0


# ----------------------------------------------------------------------------------------- preprocess


def test_preprocess_auto_crop_output() -> None:
    hotspot = (142.0, 41.0)
    image = flash_photo(120, 200, hotspot)

    result = preprocess(make_photo(image), 32)

    assert isinstance(result, Preprocessed)
    assert result.photo.shape == (3, 32, 32) and result.photo.dtype == torch.float32
    assert float(result.photo.min()) >= 0.0 and float(result.photo.max()) <= 1.0
    assert result.hotspot is not None and distance(result.hotspot, hotspot) < 2.0
    assert result.crop == hotspot_crop(120, 200, result.hotspot)
    # Largest square centred on (142, 41) in 200×120: 2 · (41 + 0.5) = 83 pixels.
    assert 81 <= result.crop.size <= 85 and result.resized_from == result.crop.size
    assert result.exposure_scale > 0 and result.stats["exposure_scale"] == result.exposure_scale
    for key in ("mean_luminance", "median_luminance", "p99_luminance", "max_luminance", "clipped_fraction"):
        assert math.isfinite(result.stats[key])
    assert result.stats["median_luminance"] < result.stats["mean_luminance"] < result.stats["p99_luminance"]
    assert result.warnings == ()


def test_preprocess_exposure_is_scale_invariant(tmp_path: Path) -> None:
    image = flash_photo(96, 140, (80.0, 50.0), scale=3.0).permute(1, 2, 0).numpy()
    dim = read_photo(write_image(tmp_path / "dim.exr", image, exr_precision="float"))
    bright = read_photo(write_image(tmp_path / "bright.exr", image * 7.0, exr_precision="float"))

    a = preprocess(dim, 48)
    b = preprocess(bright, 48)

    assert a.crop == b.crop
    assert a.exposure_scale == pytest.approx(7.0 * b.exposure_scale, rel=1e-5)
    torch.testing.assert_close(a.photo, b.photo, atol=1e-5, rtol=0)
    assert 0.05 < float(a.photo.mean()) < 0.5  # exposed, not black or white


def test_preprocess_box_averages_in_linear_space_then_exposes() -> None:
    g = torch.Generator().manual_seed(1)
    hdr = torch.rand(3, 80, 90, generator=g) ** 3 * 5.0
    crop = Crop(4, 6, 64)

    result = preprocess(make_photo(hdr, source="exr"), 16, crop)

    expected, scale = auto_expose(F.avg_pool2d(hdr[None, :, 6:70, 4:68], 4)[0])
    torch.testing.assert_close(result.photo, expected, atol=1e-6, rtol=1e-5)
    assert result.exposure_scale == pytest.approx(float(scale), rel=1e-6)
    assert (result.crop, result.hotspot, result.resized_from) == (crop, None, 64)
    assert "clipped_fraction" not in result.stats  # EXR has no saturation level


def test_preprocess_averages_linear_not_srgb(tmp_path: Path) -> None:
    # Left half: a 1-pixel checkerboard of sRGB codes 0 and 255 (linear mean 0.5). Right half: the
    # flat sRGB code whose linear value is 0.5. Averaged in linear space both halves are equal;
    # averaged in sRGB space the checkerboard would come out less than half as bright.
    flat = round(float(linear_to_srgb(torch.tensor(0.5))) * 255)
    codes = np.full((64, 64, 3), flat, dtype=np.uint8)
    checker = ((np.arange(64)[:, None] + np.arange(32)[None, :]) % 2 * 255).astype(np.uint8)
    codes[:, :32] = checker[..., None]
    path = tmp_path / "checker.png"
    Image.fromarray(codes).save(path)

    result = preprocess(read_photo(path), 16, Crop(0, 0, 64))

    left, right = result.photo[:, :, :7].mean(), result.photo[:, :, 9:].mean()
    assert float(left) == pytest.approx(float(right), rel=0.01)


def test_preprocess_non_integer_downscale_and_upscale_warning() -> None:
    image = flash_photo(100, 100, (50.0, 50.0))

    down = preprocess(make_photo(image), 48, Crop(0, 0, 100))
    up = preprocess(make_photo(image), 64, Crop(30, 30, 40))

    assert down.photo.shape == (3, 48, 48) and not any("upscaled" in w for w in down.warnings)
    assert up.photo.shape == (3, 64, 64)
    assert float(up.photo.min()) >= 0.0 and float(up.photo.max()) <= 1.0
    assert any(w.startswith("upscaled from 40×40 to 64×64") for w in up.warnings)
    # The box-filtered downscale keeps the mean, which sets the exposure.
    plain, _ = auto_expose(image)
    assert float(down.photo.mean()) == pytest.approx(float(plain.mean()), rel=0.02)


def test_preprocess_user_crop_out_of_bounds_names_file() -> None:
    photo = make_photo(flash_photo(100, 120, (60.0, 50.0)), path="/photos/sample.jpg")

    with pytest.raises(PhotoError) as error:
        preprocess(photo, 32, Crop(50, 10, 80))

    message = str(error.value)
    assert message.startswith("/photos/sample.jpg: crop 50,10,80") and "does not fit" in message
    assert "\n" not in message


def test_preprocess_warns_on_clipped_hotspot_for_ldr_only() -> None:
    hotspot = (70.0, 60.0)
    clipped = flash_photo(120, 140, hotspot, clip_radius=4.0)
    clean = flash_photo(120, 140, hotspot)

    warned = preprocess(make_photo(clipped, source="jpeg"), 32)
    hdr = preprocess(make_photo(clipped, source="exr"), 32)
    disabled = preprocess(make_photo(clipped, source="jpeg"), 32, clipped_is_saturated=False)
    fine = preprocess(make_photo(clean, source="jpeg"), 32)

    assert warned.stats["clipped_fraction"] > CLIPPED_WARNING_FRACTION
    clip_warnings = [w for w in warned.warnings if w.startswith("flash hotspot is clipped")]
    assert len(clip_warnings) == 1 and "lower the exposure" in clip_warnings[0]
    for result in (hdr, disabled, fine):
        assert not any("clipped" in w for w in result.warnings)
    assert fine.stats["clipped_fraction"] == 0.0


def test_preprocess_warns_when_hotspot_is_off_centre() -> None:
    corner = preprocess(make_photo(flash_photo(100, 160, (8.0, 10.0))), 32)
    user_crop = preprocess(make_photo(flash_photo(100, 160, (80.0, 50.0))), 32, Crop(60, 0, 100))
    centred = preprocess(make_photo(flash_photo(100, 160, (80.0, 50.0))), 32, Crop(30, 0, 100))

    assert corner.crop == Crop(0, 0, 50)
    assert any("away from the crop centre" in w for w in corner.warnings)
    assert any("away from the crop centre" in w for w in user_crop.warnings)
    assert user_crop.hotspot is None and user_crop.stats["hotspot_x"] == pytest.approx(80.0, abs=2.0)
    assert not any("away from the crop centre" in w for w in centred.warnings)


def test_preprocess_black_crop_is_an_error() -> None:
    # read_photo refuses black photos; a black region of a lit one reaches preprocess.
    image = torch.zeros(3, 40, 80)
    image[:, :, 40:] = 0.5
    photo = make_photo(image)
    with pytest.raises(
        PhotoError, match=r"photo\.png: the given crop \(0,0,32\) is black: nothing to estimate"
    ):
        preprocess(photo, 16, Crop(0, 0, 32))
    with pytest.raises(PhotoError, match=r"the automatic crop .* is black"):
        preprocess(make_photo(torch.zeros(3, 40, 40)), 16)
    assert preprocess(photo, 16, Crop(40, 0, 32)).exposure_scale > 0


def test_no_nan_in_the_highlight_message_of_a_mostly_black_photo() -> None:
    # Median luminance 0 (a lit spot on black): both brightness measures used to divide by the
    # median, giving inf / inf and "only nan× as bright as the centre".
    yy, xx = torch.meshgrid(torch.arange(128.0), torch.arange(160.0), indexing="ij")
    spot = 0.8 * torch.exp(-((xx - 20) ** 2 + (yy - 20) ** 2) / (2 * 6.0**2))
    image = torch.where(spot < 0.05, 0.0, spot).expand(3, -1, -1).clone()
    result = preprocess(make_photo(image), 64)
    assert not any("nan" in w.lower() for w in result.warnings), result.warnings
    # The only light there is counts as the flash: the crop follows it, not the black centre.
    assert not any("no distinct flash highlight" in w for w in result.warnings)
    assert result.crop == Crop(0, 0, 64) and result.to_json()["crop"]["chosen"] == "flash hotspot"
    # A lit centre with a dark spot elsewhere gives a finite ratio in the message, never NaN.
    dim = torch.full((3, 120, 160), 0.2)
    dim[:, 5:25, 120:150] = 0.3
    result = preprocess(make_photo(dim), 64)
    message = next(w for w in result.warnings if "no distinct flash highlight" in w)
    assert "1.50× as bright" in message and "nan" not in message
    # material.json says where the crop really came from: the centre, not the hotspot.
    assert result.to_json()["crop"]["chosen"] == "image centre"


@pytest.mark.parametrize("resolution", [0, -4, 2.5, True])
def test_preprocess_rejects_bad_resolution(resolution: object) -> None:
    with pytest.raises(ValueError, match="resolution"):
        preprocess(make_photo(torch.rand(3, 40, 40)), resolution)  # type: ignore[arg-type]


def test_jpeg_end_to_end(tmp_path: Path) -> None:
    hotspot = (100.0, 45.0)
    linear = flash_photo(96, 160, hotspot).clamp(0.0, 1.0)
    codes = np.rint(linear_to_srgb(linear).permute(1, 2, 0).numpy() * 255).astype(np.uint8)
    path = tmp_path / "flash.jpg"
    Image.fromarray(codes).save(path, quality=92)

    result = preprocess(read_photo(path), 64)

    assert result.hotspot is not None and distance(result.hotspot, hotspot) < 3.0
    assert result.photo.shape == (3, 64, 64)
    assert float(result.photo.min()) >= 0.0 and float(result.photo.max()) <= 1.0


def test_crop_falls_back_to_the_centre_without_a_distinct_flash_highlight() -> None:
    # A photo lit evenly (no flash highlight) with a bright patch near an edge, like paint on
    # rusted metal under a bright sky: the patch is texture, the crop stays centred.
    rng = np.random.default_rng(3)
    image = 0.2 + 0.02 * rng.random((3, 120, 160))
    image[:, 5:25, 120:150] = 0.34  # 1.7× the surroundings
    photo = Photo(Path("patch.png"), torch.tensor(image, dtype=torch.float32), "png", 8, "linear", 1, ())
    result = preprocess(photo, 64)
    assert result.crop == Crop(20, 0, 120)
    assert any("no distinct flash highlight" in w for w in result.warnings)
    assert result.stats["hotspot_over_centre"] < 2.0
    # A real flash highlight off-centre is followed (ratio far above the threshold).
    flashed = flash_photo(120, 160, (100.0, 60.0))
    photo = Photo(Path("flash.png"), flashed, "png", 8, "linear", 1, ())
    result = preprocess(photo, 64)
    assert not any("no distinct" in w for w in result.warnings)
    assert abs(result.crop.x + (result.crop.size - 1) / 2 - 100) <= 1
    # A highlight found at the centre is kept without a warning, however faint.
    flat = Photo(Path("flat.png"), torch.full((3, 64, 64), 0.3), "png", 8, "linear", 1, ())
    assert not any("no distinct" in w for w in preprocess(flat, 32).warnings)
