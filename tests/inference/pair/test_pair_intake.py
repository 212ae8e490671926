"""A flash + no-flash pair at intake (issue 59, item 1): the exposure ratio from EXIF, the no-flash
photo registered to the flash photo, the white balance between the shots, the flash-only image and
the checks that send a pair to the single-photo path. Synthetic pairs: tests/inference/pair/scene.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from brdfgan.core.exposure import LUMINANCE_WEIGHTS
from brdfgan.core.homography import apply_homography
from brdfgan.inference.intake.exposure_settings import ExposureSettings, exposure_settings_from_exif
from brdfgan.inference.intake.photo import Photo, read_photo
from brdfgan.inference.intake.preprocess import Crop, resize_crop
from brdfgan.inference.pair.intake import (
    MIN_FLASH_TO_ROOM,
    ExposureRatio,
    crop_corners,
    exposure_ratio,
    no_flash_problem,
    pair_images,
    pair_problem,
    register_no_flash,
)
from brdfgan.inference.views.register import Registration
from tests.inference.pair import scene

# The flash photo's crop (the largest square centred on the flash), resized to SIDE.
CROP = Crop(60, 0, 360)
SIDE = 180


def photos(pair: scene.Pair) -> tuple[Photo, Photo]:
    return (
        scene.as_photo(pair.flash, Path("flash.jpg"), scene.FLASH_SETTINGS),
        scene.as_photo(pair.no_flash, Path("flash_noflash.jpg"), scene.NO_FLASH_SETTINGS),
    )


def truth(image: np.ndarray) -> torch.Tensor:
    """A linear image of the flash photo in the crop at SIDE, as the intake resizes it."""
    return resize_crop(CROP.slice(torch.from_numpy(image).permute(2, 0, 1).float()), SIDE)


def exact(pair: scene.Pair) -> Registration:
    return Registration(pair.homography, "sift", 1000, 1.0, 0.0, np.zeros((0, 2)), np.zeros((0, 2)))


def test_the_exposure_ratio_is_read_from_the_jpegs_exif(tmp_path: Path) -> None:
    pair = scene.make_pair()
    flash = read_photo(scene.save_jpeg(pair.flash, tmp_path / "wood.jpg", scene.FLASH_SETTINGS))
    no_flash = read_photo(
        scene.save_jpeg(pair.no_flash, tmp_path / "wood_noflash.jpg", scene.NO_FLASH_SETTINGS)
    )
    assert flash.exposure is not None and no_flash.exposure is not None
    assert flash.exposure.exposure_time_s == pytest.approx(1 / 60)
    assert (flash.exposure.iso, no_flash.exposure.iso, flash.exposure.f_number) == (100.0, 320.0, 1.8)
    ratio = exposure_ratio(flash.exposure, no_flash.exposure)
    assert isinstance(ratio, ExposureRatio) and ratio.source == "exif"
    assert ratio.value == pytest.approx(scene.RATIO, rel=1e-6)
    # material.json's input records them.
    assert flash.to_json()["exposure"] == {
        "exposure_time_s": pytest.approx(1 / 60),
        "iso": 100.0,
        "f_number": 1.8,
        "exposure": pytest.approx(100 / 60 / 1.8**2),
    }


def test_the_exposure_ratio_from_the_option_or_a_one_line_reason(tmp_path: Path) -> None:
    bare = read_photo(scene.save_jpeg(scene.make_pair().flash, tmp_path / "bare.jpg", None))
    assert bare.exposure is None and bare.to_json()["exposure"] is None
    reason = exposure_ratio(scene.FLASH_SETTINGS, bare.exposure)
    assert reason == (
        "the no-flash photo's EXIF does not state its exposure (ExposureTime, ISO, FNumber): "
        "pass --exposure-ratio R"
    )
    partial = ExposureSettings(1 / 30, None, 2.0)
    assert isinstance(exposure_ratio(partial, partial), str) and "flash and the no-flash" in str(
        exposure_ratio(partial, partial)
    )
    assert exposure_ratio(None, None, 0.25) == ExposureRatio(0.25, "option")
    assert exposure_ratio(scene.FLASH_SETTINGS, scene.NO_FLASH_SETTINGS, 0.5) == ExposureRatio(0.5, "option")


def test_the_iso_of_older_and_newer_exif_and_ifd0_are_read() -> None:
    from PIL import Image

    exif = Image.Exif()
    exif[0x829A] = 0.01  # IFD0, as some DNGs write it
    exif[0x829D] = 2.0
    exif.get_ifd(0x8769)[0x8827] = (200, 0)  # a tuple of ratings: the first
    settings = exposure_settings_from_exif(exif)
    assert settings == ExposureSettings(0.01, 200.0, 2.0) and settings.exposure == pytest.approx(0.5)
    assert exposure_settings_from_exif(Image.Exif()) is None


@pytest.mark.parametrize(
    ("degrees", "shift", "scale"),
    [(2.0, (7.3, -4.1), 1.02), (-4.0, (-12.6, 9.4), 0.96), (0.3, (0.4, 0.7), 1.0)],
)
def test_a_moved_no_flash_photo_is_registered_within_half_a_pixel(
    degrees: float, shift: tuple[float, float], scale: float
) -> None:
    pair = scene.make_pair(no_flash_to_world=scene.moved(degrees, shift, scale))
    flash, no_flash = photos(pair)
    registration = register_no_flash(flash, no_flash, CROP)
    assert isinstance(registration, Registration), registration
    corners = crop_corners(CROP)
    found = apply_homography(registration.homography, corners)
    error = np.linalg.norm(found - apply_homography(pair.homography, corners), axis=1)
    assert error.max() < 0.5, error
    assert registration.inliers >= 40 and registration.reprojection_px < 0.5


def test_two_different_surfaces_are_refused_with_one_line() -> None:
    flash, _ = photos(scene.make_pair())
    _, other = photos(scene.make_pair(no_flash_seed=1))
    reason = register_no_flash(flash, other, CROP)
    assert isinstance(reason, str) and "\n" not in reason
    assert reason.endswith("not one surface, or the phone moved too much")


def test_a_white_balance_shift_between_the_shots_is_recovered() -> None:
    """The no-flash shot balanced for the warm room (blue ×1.45, red ×0.75 against the flash
    shot): the gains that take its colour to the flash photo's come out within 1 %, although the
    flash outshines the room light over the whole crop; an exposure ratio 10 % off moves them by
    ``(κ − G)(1 − 1/β)``, a few per cent (the module docstring)."""
    pair = scene.make_pair()
    flash, no_flash = photos(pair)
    registration = register_no_flash(flash, no_flash, CROP)
    assert isinstance(registration, Registration)
    frame = scene.flash_frame(SIDE, (60, 0, 360))
    balance = pair_images(flash, no_flash, registration, CROP, SIDE, scene.RATIO, frame).white_balance
    assert balance.method == "colour consistency"
    np.testing.assert_allclose(balance.gains, scene.true_gains(), rtol=0.01)
    # κ: the flash-only colour over the no-flash photo's, G times the white flash over the room.
    kappa = scene.true_gains() * scene.ROOM_COLOUR[1] / scene.ROOM_COLOUR
    assert balance.flash_colour == pytest.approx(tuple(kappa), rel=0.02)
    off = pair_images(flash, no_flash, registration, CROP, SIDE, 1.1 * scene.RATIO, frame).white_balance
    np.testing.assert_allclose(off.gains, scene.true_gains(), rtol=0.04)


def test_the_flash_only_image_is_the_flash_share_with_clipped_and_unseen_pixels_masked() -> None:
    pair = scene.make_pair()
    clipped = pair.flash.copy()
    clipped[150:170, 200:230] = 1.0  # a clipped glint in the flash photo
    flash, no_flash = photos(scene.Pair(clipped, pair.no_flash, pair.flash_only, pair.homography))
    frame = scene.flash_frame(SIDE, (60, 0, 360))
    images = pair_images(flash, no_flash, exact(pair), CROP, SIDE, scene.RATIO, frame)
    valid = images.valid[0] > 0
    # The glint (photo rows 150-170, columns 200-230 → crop pixels 75-85, 70-85) is not valid;
    # neither is the strip the moved no-flash photo does not see.
    assert not valid[75:85, 70:85].any()
    assert 0.9 < images.valid_fraction < 0.995
    expected = truth(pair.flash_only)
    error = (images.flash_only - expected).abs()[:, valid].mean() / expected[:, valid].mean()
    assert float(error) < 0.02
    # flash-only + room is the flash photo wherever the no-flash photo sees.
    np.testing.assert_allclose((images.flash_only + images.room)[:, valid], images.flash[:, valid], atol=1e-5)
    # The white flash over the warm room light's luminance, near the hotspot (falloff ~0.95).
    room_luminance = float(scene.ROOM_COLOUR @ np.array(LUMINANCE_WEIGHTS))
    assert images.flash_to_room == pytest.approx(0.95 * scene.FLASH_STRENGTH / room_luminance, rel=0.1)
    assert pair_problem(images) is None


def test_a_flash_under_a_quarter_of_the_room_light_is_refused() -> None:
    pair = scene.make_pair(flash_strength=0.15)
    flash, no_flash = photos(pair)
    frame = scene.flash_frame(SIDE, (60, 0, 360))
    images = pair_images(flash, no_flash, exact(pair), CROP, SIDE, scene.RATIO, frame)
    assert images.flash_to_room < MIN_FLASH_TO_ROOM
    reason = pair_problem(images)
    assert reason is not None and reason.startswith("the flash is only 0.1")


def test_a_dark_or_blurred_no_flash_photo_is_refused_and_a_sharp_one_kept() -> None:
    pair = scene.make_pair()
    flash, no_flash = photos(pair)
    measures, problem = no_flash_problem(flash, no_flash)
    assert problem is None and measures["sharpness_ratio"] > 0.5
    _, dark = photos(scene.Pair(pair.flash, pair.no_flash * 0.03, pair.flash_only, pair.homography))
    assert str(no_flash_problem(flash, dark)[1]).startswith("the no-flash photo is too dark (median linear")
    _, shaken = photos(scene.make_pair(blur=2.5))
    assert str(no_flash_problem(flash, shaken)[1]).startswith("the no-flash photo is blurred (0.0")
