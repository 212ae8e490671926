"""Synthetic handheld captures (research.synthetic_captures): Mitsuba photos of a known
material from drawn handheld cameras — the cameras frame the sample, the capture folder reads back
as eval-captures reads it and relights as the project's renderer says at the calibration, and
feature registration recovers the true homographies of the photos."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from tests.conftest import random_maps
from tests.inference.views.test_views_fit import FAST, corrupted, map_errors, truth_maps
from tests.inference.views.test_views_register import smooth_texture
from torch import Tensor

from brdfgan.cli import main
from brdfgan.core.exposure import luminance
from brdfgan.core.homography import apply_homography
from brdfgan.core.render import project_to_image
from brdfgan.core.svbrdf import join_maps
from brdfgan.data.phone.sensor import SensorEffects, encode_srgb8
from brdfgan.evaluation.real_captures import (
    CalibratedCapture,
    fit_capture_maps,
    fit_gain,
    read_capture,
    read_views,
    relight,
    score_capture,
    srgb_rmse,
)
from brdfgan.inference.intake.photo import Photo
from brdfgan.inference.views.register import feature_homography, highlight_mask
from brdfgan.io.images import write_image
from brdfgan.io.maps import read_maps
from research.handheld import SURROUND_TILES
from research.synthetic_captures import (
    TRUTH_FILE,
    HandheldSettings,
    handheld_cameras,
    locked_phone,
    render_synthetic_capture,
    sample_corners,
    with_marker_board,
    write_synthetic_capture,
)

pytestmark = [pytest.mark.mitsuba, pytest.mark.integration]
REPO = Path(__file__).resolve().parents[2]


def textured_surface(side: int, seed: int = 0) -> Tensor:
    """A dielectric surface three samples wide: :func:`truth_maps`'s relief and roughness with a
    base colour textured at three scales (features to match everywhere, none repeated).

    Shape: ``(8, 3·side, 3·side)``."""
    big = SURROUND_TILES * side
    maps = truth_maps(big)
    texture = torch.from_numpy(smooth_texture(seed, big))
    detail = (texture / texture.mean()).clamp(0.2, 2.5)
    base = (maps[:3] * detail).clamp(0.02, 1.0)
    return join_maps(base, maps[3:6], maps[6:7], maps[7:8])


def centre_of(surface: Tensor) -> Tensor:
    side = surface.shape[-1] // SURROUND_TILES
    return surface[:, side : 2 * side, side : 2 * side].contiguous()


def eval_sensor() -> SensorEffects:
    """The evaluation photos' phone (conf/sensor/phone_eval.yaml), exposure locked."""
    return locked_phone(REPO / "conf/sensor/phone_eval.yaml")


def test_handheld_cameras_frame_the_sample_and_walk_around_it() -> None:
    settings = HandheldSettings()
    cameras = handheld_cameras(settings, torch.Generator().manual_seed(3))
    assert len(cameras) == 9
    margin = 0.02 * settings.height
    azimuths = []
    for index, camera in enumerate(cameras):
        corners = project_to_image(
            sample_corners(settings.plane_half_size), camera, settings.width, settings.height
        )
        assert (corners >= margin).all() and (corners[:, 0] <= settings.width - margin).all()
        assert (corners[:, 1] <= settings.height - margin).all()
        view = np.subtract(camera.origin, camera.target)
        tilt = math.degrees(math.acos(view[2] / np.linalg.norm(view)))
        if index == 0:
            assert tilt <= settings.reference_tilt_max_deg + 1e-6
        else:
            assert settings.tilt_min_deg - 1e-6 <= tilt <= settings.tilt_max_deg + 1e-6
            azimuths.append(math.atan2(view[1], view[0]))
    # From every side: the eight tilted views' directions spread around the circle.
    assert np.ptp(np.cos(azimuths)) > 1.5 and np.ptp(np.sin(azimuths)) > 1.5
    again = handheld_cameras(settings, torch.Generator().manual_seed(3))
    other = handheld_cameras(settings, torch.Generator().manual_seed(4))
    assert again == cameras and other != cameras


def test_the_capture_relights_as_the_projects_renderer_says_at_its_calibration(tmp_path: Path) -> None:
    # No phone: the photos are the renders at the locked exposure, so the calibrated power holds.
    settings = HandheldSettings(views=3, width=320, height=240, spp=16, side=64)
    maps = truth_maps(64)
    capture = render_synthetic_capture(maps, settings, SensorEffects(enabled=False), seed=1)
    assert capture.seen.min() == 1.0  # every view sees the whole sample
    folder = write_synthetic_capture(capture, maps, tmp_path / "wave")
    read = read_capture(folder)
    photos = read_views(read)
    assert read.side == 64 and len(photos) == 3
    truth = read_maps(folder / "truth")
    assert (truth - maps).abs().max() < 0.01  # 8-bit files (sRGB base colour, encoded normals)
    renders = relight(read, truth)
    gain = fit_gain(renders[0], photos[0].linear)
    assert abs(gain - 1.0) < 0.05, gain  # light_pow carries the flash at the photos' exposure
    for render, photo in zip(renders, photos, strict=True):
        # Mitsuba against the project's renderer, rectified through the true homography: what is
        # left is sampling noise, texel filtering and the 8-bit files.
        assert srgb_rmse(render, photo.linear) < 0.03
        assert srgb_rmse(render * 0.8, photo.linear) > 2 * srgb_rmse(render, photo.linear)


def test_the_capture_folder_holds_photos_truth_and_nothing_half_written(tmp_path: Path) -> None:
    settings = HandheldSettings(views=2, width=160, height=120, spp=4, side=32)
    maps = truth_maps(32)
    capture = render_synthetic_capture(maps, settings, eval_sensor(), seed=2)
    folder = tmp_path / "capture"
    folder.mkdir()
    (folder / "stale.txt").write_text("an older capture", encoding="utf-8")
    write_synthetic_capture(capture, maps, folder)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture"]  # replaced, no staging left
    assert sorted(p.name for p in folder.iterdir()) == [
        "00.png",
        "01.png",
        "handheld",
        "parameters.json",
        "truth",
    ]
    truth = json.loads((folder / "truth" / TRUTH_FILE).read_text(encoding="utf-8"))
    assert [view["file"] for view in truth["views"]] == ["handheld/00.png", "handheld/01.png"]
    parameters = json.loads((folder / "parameters.json").read_text(encoding="utf-8"))
    assert parameters["image_size"] == settings.sample_cm
    for view, camera in zip(truth["views"], capture.cameras, strict=True):
        homography = np.array(view["homography"])
        corners = np.array([[0.0, 0.0], [32.0, 0.0], [32.0, 32.0], [0.0, 32.0]])  # texel edges
        projected = project_to_image(sample_corners(settings.plane_half_size), camera, 160, 120)
        np.testing.assert_allclose(apply_homography(homography, corners), projected, atol=1e-6)
    assert capture.phone["jpeg_quality"] is not None  # through the phone


def test_features_recover_the_photos_true_homographies_within_half_a_pixel() -> None:
    settings = HandheldSettings(views=4, spp=16, side=128)
    surface = textured_surface(128)
    capture = render_synthetic_capture(centre_of(surface), settings, eval_sensor(), seed=5, surround=surface)
    photos = capture.photos
    grey = [luminance(photo)[0].numpy() for photo in photos]
    masks = [highlight_mask(photo) for photo in photos]
    # The reference photo's pixels over the sample (a 21 × 21 grid), where the fit needs them.
    ticks = np.linspace(0.0, settings.side, 21)
    texels = np.stack(np.meshgrid(ticks, ticks), axis=-1).reshape(-1, 2)
    reference = apply_homography(capture.homographies[0], texels)
    for view in range(1, settings.views):
        registration = feature_homography(grey[0], grey[view], masks[0], masks[view])
        assert registration is not None
        truth = capture.homographies[view] @ np.linalg.inv(capture.homographies[0])
        error = np.linalg.norm(
            apply_homography(registration.homography, reference) - apply_homography(truth, reference), axis=1
        )
        assert error.max() < 0.5, (view, error.max(), registration.inliers)


def test_predict_views_registers_by_the_marker_board_where_the_photos_show_it(tmp_path: Path) -> None:
    settings = HandheldSettings(views=2, spp=16, side=256)
    surface = textured_surface(256, seed=2)
    boarded = with_marker_board(surface, settings.sample_cm, board_cm=14.0)
    capture = render_synthetic_capture(centre_of(surface), settings, eval_sensor(), seed=7, surround=boarded)
    folder = write_synthetic_capture(capture, centre_of(surface), tmp_path / "boarded")
    photos = [str(folder / "handheld" / f"{index:02d}.png") for index in range(settings.views)]
    out = tmp_path / "out"
    assert (
        main(
            [
                "predict",
                "--views",
                *photos,
                "--fov",
                "65",
                "--resolution",
                "128",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    views = json.loads((out / "00" / "material.json").read_text(encoding="utf-8"))["views"]
    assert [view["role"] for view in views] == ["reference", "fitted"]
    assert views[1]["method"] == "marker"
    assert views[1]["inliers"] >= 16 * 3  # most of the 16 tags, 4 corners each


def test_a_board_that_would_cover_the_sample_is_refused() -> None:
    with pytest.raises(ValueError, match=r"covers the 10\.0 cm sample"):
        with_marker_board(textured_surface(32), 10.0, board_cm=12.0)


@pytest.fixture(scope="module")
def mitsuba_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Seven views (the first five to fit, two held out) of a textured, bumpy dielectric, through
    the evaluation phone, rectified at 64²."""
    settings = HandheldSettings(views=7, width=320, height=240, spp=16, side=64)
    maps = truth_maps(64)
    capture = render_synthetic_capture(maps, settings, eval_sensor(), seed=11)
    return write_synthetic_capture(capture, maps, tmp_path_factory.mktemp("fit") / "wave")


def held_out_relit(capture: CalibratedCapture, photos: list[Photo], maps: Tensor, fitted: int) -> float:
    scores = score_capture(capture, photos, maps, "m", fit_views=fitted)
    return sum(s.rmse_fitted for s in scores if s.view >= 5) / 2


def test_the_fit_to_mitsuba_photos_recovers_the_material_better_than_one_view(mitsuba_capture: Path) -> None:
    capture = read_capture(mitsuba_capture)
    photos = read_views(capture)
    truth = truth_maps(64)
    prediction = corrupted(truth)
    one = fit_capture_maps(capture, photos, prediction, 1, FAST)  # fitted to the reference alone
    five = fit_capture_maps(capture, photos, prediction, 5, FAST)
    errors = {
        name: map_errors(maps, truth) for name, maps in (("start", prediction), ("one", one), ("five", five))
    }
    relit = {
        name: held_out_relit(capture, photos, maps, 5)
        for name, maps in (("start", prediction), ("one", one), ("five", five))
    }
    assert relit["five"] < 0.6 * relit["start"] and relit["five"] < relit["one"]
    assert errors["five"]["all"] < errors["one"]["all"] < errors["start"]["all"]
    # Several flash positions make the relief observable: one photo cannot place it.
    assert errors["five"]["normal_deg"] < 0.5 * errors["start"]["normal_deg"]
    assert errors["five"]["normal_deg"] < errors["one"]["normal_deg"]


def test_a_photo_of_another_surface_does_not_make_the_fit_worse_than_the_prediction(
    mitsuba_capture: Path, tmp_path: Path
) -> None:
    corrupt = tmp_path / "corrupt"
    shutil.copytree(mitsuba_capture, corrupt)
    other = random_maps(64, 64, seed=5)
    settings = HandheldSettings(views=3, width=320, height=240, spp=16, side=64)
    stranger = render_synthetic_capture(other, settings, eval_sensor(), seed=11)
    write_image(corrupt / "02.png", encode_srgb8(stranger.rectified[2]).permute(1, 2, 0).numpy() / 255.0)
    capture = read_capture(corrupt)
    photos = read_views(capture)
    truth = truth_maps(64)
    prediction = corrupted(truth)
    fitted = fit_capture_maps(capture, photos, prediction, 5, FAST)
    clean = fit_capture_maps(
        read_capture(mitsuba_capture), read_views(read_capture(mitsuba_capture)), prediction, 5, FAST
    )
    start = held_out_relit(capture, photos, prediction, 5)
    assert held_out_relit(capture, photos, fitted, 5) < start
    # The stranger is dropped (an outlier): the fit is that of the other four views.
    four = held_out_relit(capture, photos, fitted, 5)
    assert four < 1.25 * held_out_relit(capture, photos, clean, 5)
