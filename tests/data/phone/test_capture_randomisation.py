"""Capture randomisation (brdfgan.data.phone.conditions): sampling, geometry, Mitsuba rendering, metadata."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from omegaconf import OmegaConf

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import (
    FlashCapture,
    PointLights,
    camera_frame,
    capture_camera_height,
    nominal_camera,
    project_to_image,
    render_point_lights,
    view_footprint,
)
from brdfgan.core.svbrdf import flat_maps
from brdfgan.data.generation.generation import material_samples
from brdfgan.data.phone.conditions import (
    CaptureDraw,
    CaptureSampling,
    flash_hotspot_px,
    flash_mirror_point,
    max_distance_factor,
    tilted_camera,
)
from brdfgan.data.phone.environments import build_environment_pools
from brdfgan.data.spec.dataset_spec import spec_from_config
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.errors import UserError
from tests.conftest import ROOT, random_maps, relative_l1
from tests.data.generation.test_generation import TorchPhotographer, tiny_spec

PHONE = CaptureSampling(
    fov_min_deg=40.0,
    fov_max_deg=75.0,
    flash_offset_min=0.01,
    flash_offset_max=0.08,
    tilt_max_deg=5.0,
    distance_min=0.9,
    distance_max=1.0,
    exposure_ev_min=-1.0,
    exposure_ev_max=1.0,
)
FLASH = (8.0, 8.0, 8.0)


def _draws(sampling: CaptureSampling, seed: int, count: int) -> list[CaptureDraw]:
    generator = torch.Generator().manual_seed(seed)
    return [sampling.sample(generator) for _ in range(count)]


# ----------------------------------------------------------------------------- sampling


def test_sampling_is_deterministic_per_seed_and_within_its_ranges() -> None:
    draws = _draws(PHONE, 0, 200)
    assert draws == _draws(PHONE, 0, 200)
    assert draws != _draws(PHONE, 1, 200)
    for draw in draws:
        assert 40.0 <= draw.fov_deg <= 75.0 and 0.0 <= draw.tilt_deg <= 5.0
        assert 0.0 <= draw.tilt_axis_deg < 360.0 and 0.0 <= draw.flash_offset_angle_deg < 360.0
        assert 0.9 <= draw.distance_drawn <= 1.0 and -1.0 <= draw.exposure_ev <= 1.0
        assert 0.01 <= draw.flash_offset <= 0.08
        limit = max_distance_factor(draw.fov_deg, draw.tilt_deg, draw.tilt_axis_deg)
        assert draw.distance_factor == min(draw.distance_drawn, limit)
        # The flash sits in the image plane, flash_offset camera distances from the lens.
        camera = draw.camera
        offset = np.subtract(draw.flash_position, camera.origin)
        _, _, forward = camera_frame(camera)
        assert np.linalg.norm(offset) == pytest.approx(draw.flash_offset * draw.camera_distance, rel=1e-9)
        assert abs(offset @ forward) < 1e-12
        assert np.linalg.norm(camera.origin) == pytest.approx(draw.camera_distance, rel=1e-12)
        # Tilted by tilt_deg from the vertical, about a horizontal axis, aiming at the centre.
        assert math.degrees(math.acos(-forward[2])) == pytest.approx(draw.tilt_deg, abs=1e-6)
    # The ranges are used, not just respected.
    assert max(d.fov_deg for d in draws) > 73 and min(d.fov_deg for d in draws) < 42
    assert max(d.exposure_ev for d in draws) > 0.9 and min(d.exposure_ev for d in draws) < -0.9
    assert any(d.distance_factor < d.distance_drawn for d in draws)  # the footprint limit bites


def test_the_default_sampling_is_todays_capture_exactly() -> None:
    for draw in _draws(CaptureSampling(), 3, 5):
        assert draw.camera == nominal_camera(45.0)  # bit for bit
        assert draw.flash_position == nominal_camera(45.0).origin
        assert (draw.exposure_ev, draw.distance_factor, draw.fov_deg) == (0.0, 1.0, 45.0)
        assert draw.hotspot_px(64) == pytest.approx((32.0, 32.0), abs=1e-12)
    assert CaptureDraw().camera == FlashCapture().camera_pose


def test_one_range_does_not_shift_the_others_draws() -> None:
    base = _draws(PHONE, 5, 20)
    wider = _draws(CaptureSampling(**{**vars(PHONE), "exposure_ev_min": -3.0}), 5, 20)
    for a, b in zip(base, wider, strict=True):
        assert (a.fov_deg, a.tilt_deg, a.flash_offset, a.distance_drawn) == (
            b.fov_deg,
            b.tilt_deg,
            b.flash_offset,
            b.distance_drawn,
        )
        assert a.exposure_ev != b.exposure_ev


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"fov_min_deg": 0.5}, "fov_min_deg"),
        ({"fov_max_deg": 150.0}, "fov_max_deg"),
        ({"fov_min_deg": 60.0, "fov_max_deg": 50.0}, "fov_min_deg"),
        ({"flash_offset_max": 0.6}, "flash_offset_max"),
        ({"flash_offset_min": -0.01}, "flash_offset_min"),
        ({"tilt_max_deg": 25.0}, "tilt_max_deg"),
        ({"tilt_max_deg": "abc"}, "tilt_max_deg"),
        ({"distance_max": 1.1}, "distance_max"),
        ({"distance_min": 0.95, "distance_max": 0.9}, "distance_min"),
        ({"exposure_ev_min": -5.0}, "exposure_ev_min"),
        ({"exposure_ev_max": float("nan")}, "exposure_ev_max"),
    ],
)
def test_bad_ranges_are_one_line_user_errors_naming_the_key(change: dict[str, object], key: str) -> None:
    with pytest.raises(UserError) as error:
        CaptureSampling(**change)  # type: ignore[arg-type]
    message = str(error.value)
    assert message.startswith(f"dataset_spec.capture.{key}=") and "\n" not in message


def test_the_config_node_builds_the_spec_and_reports_bad_values_by_key() -> None:
    config = OmegaConf.load(ROOT / "conf" / "dataset_spec" / "default.yaml")
    assert spec_from_config(config).capture == CaptureSampling()  # the default is off
    config.capture.tilt_max_deg = 30.0
    with pytest.raises(
        DatasetConfigError, match=r"^dataset_spec\.capture\.tilt_max_deg=30: must be in \[0, 20\]$"
    ):
        spec_from_config(config)


# ----------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("fov", [1.0, 40.0, 75.0, 120.0])
@pytest.mark.parametrize("tilt_axis", [0.0, 45.0, 100.0, 225.0])
def test_the_footprint_stays_inside_the_square_for_extreme_draws(fov: float, tilt_axis: float) -> None:
    for tilt in (0.0, 0.5, 5.0, 20.0):
        limit = max_distance_factor(fov, tilt, tilt_axis)
        corners = view_footprint(tilted_camera(fov, tilt, tilt_axis, limit), 8, 8)
        assert np.abs(corners[:, :2]).max() <= 1.0 + 1e-9
        # Tight: the largest factor that fits, so a corner touches the edge.
        assert np.abs(corners[:, :2]).max() == pytest.approx(1.0, abs=1e-9)
        assert (limit == 1.0) if tilt == 0.0 else (limit < 1.0)
    # The sampled factor is never above the limit, whatever was drawn.
    for draw in _draws(CaptureSampling(fov, fov, 0.0, 0.0, 20.0, 1.0, 1.0), int(fov), 20):
        corners = view_footprint(draw.camera, 8, 8)
        assert np.abs(corners[:, :2]).max() <= 1.0 + 1e-9


def test_the_nominal_footprint_is_the_sample_square_and_projects_to_the_image_corners() -> None:
    corners = view_footprint(nominal_camera(45.0), 64, 64)
    np.testing.assert_allclose(corners, [[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]], atol=1e-12)
    # Any camera: the footprint corners land on the image corners (x right, y down).
    camera = tilted_camera(60.0, 12.0, 33.0, 0.8)
    pixels = project_to_image(view_footprint(camera, 48, 32), camera, 48, 32)
    np.testing.assert_allclose(pixels, [[0, 0], [48, 0], [48, 32], [0, 32]], atol=1e-9)
    # Texel centres of the nominal camera project onto pixel centres (row 0 = +Y, column 0 = −X).
    pixel = project_to_image(np.array([[-1 + 0.5 / 32, 1 - 2.5 / 32, 0.0]]), nominal_camera(45.0), 64, 64)
    np.testing.assert_allclose(pixel, [[0.5, 2.5]], atol=1e-9)


def test_the_hotspot_is_the_mirror_point_of_the_flash() -> None:
    # Golden: flash at the lens height, shifted by (dx, dy): the mirror point is halfway, so the
    # hotspot moves half the offset's projection.
    h = capture_camera_height(45.0)
    hotspot = flash_hotspot_px(nominal_camera(45.0), (0.2, -0.1, h), 64, 64)
    assert hotspot == pytest.approx((32 + 0.1 * 32, 32 + 0.05 * 32), abs=1e-9)
    # Any draw: the half vector of the directions to camera and flash at the point is +Z.
    for draw in _draws(CaptureSampling(30, 90, 0.1, 0.5, 20, 0.5, 1.0), 2, 50):
        point = np.array(flash_mirror_point(draw.camera.origin, draw.flash_position))
        to_camera = np.subtract(draw.camera.origin, point)
        to_flash = np.subtract(draw.flash_position, point)
        half = to_camera / np.linalg.norm(to_camera) + to_flash / np.linalg.norm(to_flash)
        np.testing.assert_allclose(half / np.linalg.norm(half), [0, 0, 1], atol=1e-12)
        assert draw.to_json(64)["hotspot_px"] == list(project_to_image(point[None], draw.camera, 64, 64)[0])


def test_to_json_records_every_value_as_plain_json() -> None:
    draw = _draws(PHONE, 4, 1)[0]
    record = draw.to_json(256)
    assert list(record) == [
        "fov_deg",
        "tilt_deg",
        "tilt_axis_deg",
        "distance_drawn",
        "distance_factor",
        "camera_distance",
        "flash_offset",
        "flash_offset_angle_deg",
        "exposure_ev",
        "camera_origin",
        "camera_target",
        "camera_up",
        "flash_position",
        "hotspot_px",
    ]
    assert all(type(v) is float or all(type(c) is float for c in v) for v in record.values())
    assert record["camera_origin"] == list(draw.camera.origin)
    assert record["hotspot_px"] == list(draw.hotspot_px(256))


def test_the_exposure_error_scales_the_auto_exposure_by_stops() -> None:
    # A dim sample with a flash hotspot ramping from 1 to 8: how much of it clips is up to the error.
    hdr = torch.full((3, 8, 8), 0.1)
    hdr[:, 4] = torch.linspace(1.0, 8.0, 8)
    exact, scale = auto_expose(hdr)
    same, same_scale = auto_expose(hdr, 0.0)
    assert torch.equal(exact, same) and torch.equal(scale, same_scale)
    clipped = []
    for ev in (-2.0, -1.0, 0.0, 1.0, 2.0):
        ldr, ev_scale = auto_expose(hdr, ev)
        assert float(ev_scale) == pytest.approx(float(scale) * 2**ev, rel=1e-6)
        torch.testing.assert_close(ldr, (hdr * ev_scale).clamp(0, 1))
        clipped.append(int((ldr[0] == 1).sum()))
    assert clipped == sorted(clipped) and clipped[0] == 0 < clipped[2] < clipped[-1]


# ----------------------------------------------------------------------------- generation


def test_material_samples_record_the_draw_and_shift_no_other_draw() -> None:
    spec = tiny_spec(capture=PHONE)
    plain = tiny_spec()
    pools = build_environment_pools(spec.lighting, 0)
    photographer = TorchPhotographer(spec)
    randomised = list(material_samples(spec, "train", 0, pools, photographer))
    default = list(material_samples(plain, "train", 0, pools, TorchPhotographer(plain)))
    for a, b in zip(randomised, default, strict=True):
        for key in ("lighting", "flash", "render", "crop"):  # drawn as before: nothing shifted
            assert a.meta[key] == b.meta[key]
        nominal = CaptureDraw().to_json(spec.resolution)
        pose = ("camera_origin", "camera_up", "flash_position", "hotspot_px", "exposure_ev", "fov_deg")
        assert [b.meta["capture"][k] for k in pose] == [nominal[k] for k in pose]
        assert a.meta["capture"]["fov_deg"] != 45.0
        assert a.meta["capture"]["hotspot_px"] != [16.0, 16.0]
    assert len({s.meta["capture"]["fov_deg"] for s in randomised}) == len(randomised)  # one per photo
    # The photographer got the draw: the stand-in renders at its field of view and exposure.
    first = randomised[0].meta["capture"]
    assert randomised[0].meta["exposure_scale"] != default[0].meta["exposure_scale"]
    assert next(material_samples(spec, "train", 0, pools, photographer)).meta["capture"] == first


# ----------------------------------------------------------------------------- Mitsuba

RES = 32


def _old_capture_photo(maps: torch.Tensor, spp: int, seed: int) -> torch.Tensor:
    """Today's (pre-randomisation) capture scene, its camera and flash written out literally."""
    from brdfgan.mitsuba_render.photos import capture_scene_dict
    from brdfgan.mitsuba_render.variant import mitsuba

    mi = mitsuba()
    scene = capture_scene_dict(maps, None, FLASH, capture=FlashCapture(), resolution=RES, spp=spp, seed=0)
    camera_z = capture_camera_height(45.0, 1.0)
    scene["sensor"]["fov"] = 45.0
    scene["sensor"]["to_world"] = mi.ScalarTransform4f().look_at(
        origin=[0.0, 0.0, camera_z], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0]
    )
    scene["point_light_0"]["position"] = [0.0, 0.0, camera_z]
    image = mi.render(mi.load_dict(scene), spp=spp, seed=seed)
    return torch.from_numpy(np.array(image, dtype=np.float32)).permute(2, 0, 1)[:3].contiguous()


@pytest.mark.integration
@pytest.mark.mitsuba
def test_the_default_draw_renders_todays_photo_bit_for_bit() -> None:
    from brdfgan.mitsuba_render.photos import CaptureRenderer, render_capture

    maps = random_maps(RES, RES, seed=3)
    old = _old_capture_photo(maps, 16, seed=5)
    draw = CaptureSampling().sample(torch.Generator().manual_seed(9))
    for reuse in (False, True):
        renderer = CaptureRenderer(RES, 16, FlashCapture(), 16, reuse_scene=reuse)
        if reuse:  # the reused scene must come back to the nominal pose from another one
            other = _draws(PHONE, 0, 1)[0]
            renderer.render(
                maps, None, FLASH, seed=5, camera=other.camera, flash_position=other.flash_position
            )
        result = render_capture(
            renderer,
            maps,
            None,
            FLASH,
            seed=5,
            camera=draw.camera,
            flash_position=draw.flash_position,
            exposure_ev=draw.exposure_ev,
        )
        assert torch.equal(result.hdr, old), reuse
        ldr, scale = auto_expose(old)
        assert torch.equal(result.ldr, ldr) and result.exposure_scale == float(scale)


def _torch_photo(maps: torch.Tensor, draw: CaptureDraw, supersample: int = 4) -> torch.Tensor:
    # Texture space is the photo when the camera is untilted at the framing distance; 4×4
    # shading points per pixel stand in for Mitsuba's box-filtered footprint.
    camera = torch.tensor(draw.camera.origin).view(1, 1, 3)
    lights = PointLights(
        torch.tensor(draw.flash_position).view(1, 1, 1, 3),
        torch.full((1, 1, 1), FLASH[0]),
        torch.ones(1, 1, 1, 3),
    )
    fine = maps[None].repeat_interleave(supersample, -1).repeat_interleave(supersample, -2)
    return F.avg_pool2d(render_point_lights(fine, camera, lights)[:, 0], supersample)[0]


@pytest.fixture(scope="module")
def renderer():  # type: ignore[no-untyped-def]
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    return CaptureRenderer(RES, 64, FlashCapture(), 16)


@pytest.mark.integration
@pytest.mark.mitsuba
@pytest.mark.parametrize(
    "draw",
    [
        CaptureDraw(fov_deg=60.0, flash_offset=0.08, flash_offset_angle_deg=30.0),
        CaptureDraw(fov_deg=40.0, flash_offset=0.3, flash_offset_angle_deg=250.0),
    ],
    ids=["fov60-offset0.08", "fov40-offset0.3"],
)
def test_an_offset_flash_agrees_with_render_point_lights(renderer, draw: CaptureDraw) -> None:  # type: ignore[no-untyped-def]
    cases = {
        "glossy-metal": flat_maps(RES, RES, basecolor=(0.8, 0.45, 0.2), roughness=0.3, metallic=1.0),
        "rough-dielectric": flat_maps(RES, RES, basecolor=(0.8, 0.45, 0.2), roughness=0.8),
        "bumpy": random_maps(RES, RES, seed=11),
    }
    for name, maps in cases.items():
        photo = renderer.render(
            maps, None, FLASH, seed=1, camera=draw.camera, flash_position=draw.flash_position
        )
        reference = _torch_photo(maps, draw)
        assert relative_l1(photo, reference) < 0.02, name
        if name == "glossy-metal":  # sharp: the flash left at the lens misses by far more
            at_lens = _torch_photo(maps, CaptureDraw(fov_deg=draw.fov_deg))
            assert relative_l1(at_lens, reference) > 0.1


def _highlight_centroid(image: torch.Tensor) -> tuple[float, float]:
    """``(x, y)`` in continuous pixels (pixel centres at +½) of the pixels above half the peak."""
    luminance = image.sum(0).numpy()
    weights = np.where(luminance >= 0.5 * luminance.max(), luminance, 0.0)
    rows, cols = np.indices(luminance.shape)
    return float(((cols + 0.5) * weights).sum() / weights.sum()), float(
        ((rows + 0.5) * weights).sum() / weights.sum()
    )


@pytest.mark.integration
@pytest.mark.mitsuba
def test_the_highlight_lands_on_hotspot_px() -> None:
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    res = 64
    renderer = CaptureRenderer(res, 16, FlashCapture(), 16)
    maps = flat_maps(res, res, basecolor=(0.9, 0.9, 0.9), roughness=0.15, metallic=1.0)
    draws = [
        CaptureDraw(flash_offset=0.3, flash_offset_angle_deg=30.0),
        CaptureDraw(fov_deg=70.0, flash_offset=0.25, flash_offset_angle_deg=200.0),
        CaptureDraw(
            tilt_deg=10.0, tilt_axis_deg=120.0, distance_factor=max_distance_factor(45.0, 10.0, 120.0)
        ),
        CaptureDraw(
            fov_deg=60.0,
            tilt_deg=8.0,
            tilt_axis_deg=30.0,
            flash_offset=0.2,
            flash_offset_angle_deg=300.0,
            distance_factor=max_distance_factor(60.0, 8.0, 30.0),
        ),
    ]
    for draw in draws:
        image = renderer.render(
            maps, None, FLASH, seed=2, camera=draw.camera, flash_position=draw.flash_position
        )
        x, y = draw.hotspot_px(res)
        assert math.hypot(x - res / 2, y - res / 2) > 5.0  # it moved: the check can tell
        cx, cy = _highlight_centroid(image)
        assert math.hypot(cx - x, cy - y) < 1.0, (draw, (cx, cy), (x, y))
