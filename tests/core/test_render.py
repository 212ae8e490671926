from __future__ import annotations

import pytest
import torch

from brdfgan.core.flash_geometry import centred_flash_frame, crop_flash_frame, field_of_view, hotspot_position
from brdfgan.core.render import (
    FlashCapture,
    PointLightRenderer,
    PointLights,
    capture_camera_height,
    plane_positions,
    render_flash,
    render_point_lights,
)
from brdfgan.core.svbrdf import CHANNELS, flat_maps
from tests.conftest import random_maps


def _lights(position, intensity, color=(1.0, 1.0, 1.0), dtype=torch.float64) -> PointLights:
    pos = torch.tensor(position, dtype=dtype).view(1, 1, -1, 3)
    k = pos.shape[2]
    return PointLights(
        position=pos,
        intensity=torch.full((1, 1, k), float(intensity), dtype=dtype),
        color=torch.tensor(color, dtype=dtype).expand(1, 1, k, 3).clone(),
    )


def test_plane_positions_row_zero_is_plus_y() -> None:
    pos = plane_positions(4, 2, plane_half_size=2.0)
    assert pos.shape == (3, 4, 2)
    torch.testing.assert_close(pos[:, 0, 0], torch.tensor([-1.0, 1.5, 0.0]))
    torch.testing.assert_close(pos[:, 3, 1], torch.tensor([1.0, -1.5, 0.0]))


def test_single_texel_golden_value() -> None:
    # One texel at the origin, light and camera 2 units above: L = f(n, n) · 1 · I / 2².
    maps = flat_maps(1, 1, basecolor=(0.5, 0.5, 0.5), roughness=0.5, batch=(1,), dtype=torch.float64)
    camera = torch.tensor([[[0.0, 0.0, 2.0]]], dtype=torch.float64)
    image = render_point_lights(maps, camera, _lights([0.0, 0.0, 2.0], 4.0))
    assert image.shape == (1, 1, 3, 1, 1)
    torch.testing.assert_close(image.flatten(), torch.full((3,), 0.1190609928549547, dtype=torch.float64))


def test_lights_add_up_and_scale_linearly() -> None:
    maps = random_maps(8, 8, batch=(2,), dtype=torch.float64)
    camera = torch.tensor([0.3, -0.2, 3.0], dtype=torch.float64).expand(2, 1, 3)
    a, b = [1.0, 0.5, 2.0], [-1.5, 0.2, 1.0]

    def render(lights: PointLights) -> torch.Tensor:
        expand = PointLights(
            *(t.expand(2, *t.shape[1:]) for t in (lights.position, lights.intensity, lights.color))
        )
        return render_point_lights(maps, camera, expand)

    both = render(_lights([a, b], 3.0))
    torch.testing.assert_close(both, render(_lights([a], 3.0)) + render(_lights([b], 3.0)))
    torch.testing.assert_close(render(_lights([a], 6.0)), 2 * render(_lights([a], 3.0)))
    tinted = render(_lights([a], 3.0, color=(1.0, 0.5, 0.0)))
    torch.testing.assert_close(tinted[:, :, 1], 0.5 * render(_lights([a], 3.0))[:, :, 1])
    assert torch.count_nonzero(tinted[:, :, 2]) == 0


def test_batch_and_configurations_are_independent() -> None:
    maps = random_maps(6, 5, batch=(3,))
    g = torch.Generator().manual_seed(3)
    camera = torch.rand((3, 4, 3), generator=g) + torch.tensor([0.0, 0.0, 2.0])
    lights = PointLights(
        position=torch.rand((3, 4, 1, 3), generator=g) + torch.tensor([0.0, 0.0, 1.0]),
        intensity=torch.rand((3, 4, 1), generator=g) + 1,
        color=torch.rand((3, 4, 1, 3), generator=g),
    )
    image = render_point_lights(maps, camera, lights)
    assert image.shape == (3, 4, 3, 6, 5)
    single = render_point_lights(
        maps[1:2],
        camera[1:2, 2:3],
        PointLights(*(t[1:2, 2:3] for t in (lights.position, lights.intensity, lights.color))),
    )
    torch.testing.assert_close(image[1:2, 2:3], single)


def test_flash_on_flat_sample_is_mirror_symmetric_and_peaks_in_the_centre() -> None:
    maps = flat_maps(16, 16, roughness=0.3, metallic=1.0, batch=(1,))
    image = render_flash(maps)[0]
    torch.testing.assert_close(image, image.flip(-1))
    torch.testing.assert_close(image, image.flip(-2))
    lum = image.sum(0)
    assert lum[7:9, 7:9].min() == lum.max()


def test_a_flash_beside_the_lens_moves_the_highlight_half_way() -> None:
    # Camera and flash above the centre, the flash 0.4 to +X: the mirror point of a flat sample
    # lies half way between them, at x = 0.2 — column 0.6 · 32 = 19.2 of 32 (columns start at x = −1).
    maps = flat_maps(32, 32, roughness=0.15, metallic=1.0, batch=(1,))
    offset = torch.tensor([[0.4, 0.0]])
    image = render_flash(maps, flash_offset=offset)[0].sum(0)
    assert image.amax(dim=0).argmax().item() == 19
    assert image.amax(dim=1).argmax().item() in (15, 16)
    torch.testing.assert_close(render_flash(maps, flash_offset=torch.zeros(1, 2)), render_flash(maps))


def test_a_moved_camera_renders_an_off_centre_crop_of_the_centred_view() -> None:
    # A 64² sample photographed from above its centre; the 32² window whose top-left texel is
    # (row 8, column 24) is the photo of that window's maps with the camera moved above the
    # window's hotspot — the frame's hotspot, found by hotspot_position — at the same height.
    maps = random_maps(64, 64, seed=11, batch=(1,))
    maps[:, CHANNELS["roughness"]] = maps[:, CHANNELS["roughness"]].clamp(0.2, 1.0)
    wide = FlashCapture(fov_deg=60.0)
    whole = render_flash(maps, wide)
    window = (slice(8, 40), slice(24, 56))
    frame = crop_flash_frame(centred_flash_frame(1, 64, 64, 60.0), 24, 8)
    narrow = FlashCapture(fov_deg=field_of_view(float(frame[0, 2]), 32), plane_half_size=0.5)
    camera_xy = hotspot_position(frame, 32, 32, plane_half_size=0.5)
    torch.testing.assert_close(camera_xy, torch.tensor([[-0.25, -0.25]]))  # window centre at (+0.25, +0.25)
    crop = render_flash(maps[..., window[0], window[1]], narrow, camera_xy=camera_xy)
    torch.testing.assert_close(crop, whole[..., window[0], window[1]], rtol=1e-4, atol=1e-6)
    centred = render_flash(maps[..., window[0], window[1]], narrow)
    assert (centred - whole[..., window[0], window[1]]).abs().max() > 0.1 * whole.max()


def test_normal_tilt_moves_the_highlight() -> None:
    # A normal tilted towards +Y turns the mirror point of the flash towards −Y (lower rows).
    maps = flat_maps(32, 32, roughness=0.2, metallic=1.0, batch=(1,))
    tilt = torch.tensor([0.0, 0.2, 1.0])
    maps[:, CHANNELS["normal"]] = (tilt / tilt.norm()).view(1, 3, 1, 1)
    row_of_peak = render_flash(maps)[0].sum(0).amax(dim=1).argmax().item()
    assert row_of_peak > 20


def test_module_matches_function_and_capture_height() -> None:
    maps = random_maps(4, 4, batch=(1,))
    lights = _lights([0.0, 0.0, 2.0], 1.0, dtype=torch.float32)
    camera = torch.tensor([[[0.0, 0.0, 2.0]]])
    renderer = PointLightRenderer(plane_half_size=0.5)
    torch.testing.assert_close(renderer(maps, camera, lights), render_point_lights(maps, camera, lights, 0.5))
    assert capture_camera_height(90.0) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="fov"):
        capture_camera_height(0.0)


def test_compiled_renderer_matches_eager() -> None:
    maps = random_maps(16, 16, batch=(2,))
    camera = torch.tensor([[[0.3, -0.2, 2.5]], [[-0.4, 0.1, 3.0]]])
    lights = PointLights(camera[:, :, None] + 0.2, torch.full((2, 1, 1), 5.0), torch.ones(2, 1, 1, 3))
    eager = PointLightRenderer()(maps, camera, lights)
    compiled = PointLightRenderer(compile=True)(maps, camera, lights)
    # Inductor fuses and reorders the float32 maths (and picks its vector ISA per machine): up to
    # 1.1e-4 relative was measured on a texel at the edge of a highlight, so 3e-4 is the bound.
    torch.testing.assert_close(compiled, eager, rtol=3e-4, atol=1e-6)


@pytest.mark.parametrize("name", ["basecolor", "normal", "roughness", "metallic"])
def test_gradcheck_float64_wrt_each_map(name: str) -> None:
    maps = random_maps(3, 3, batch=(1,), dtype=torch.float64, seed=5)
    maps[:, CHANNELS["roughness"]] = 0.3 + 0.5 * maps[:, CHANNELS["roughness"]]
    maps[:, CHANNELS["metallic"]] = 0.5
    g = torch.Generator().manual_seed(2)
    camera = torch.tensor([[[0.4, -0.3, 2.0], [-0.5, 0.6, 1.5]]], dtype=torch.float64)
    lights = PointLights(
        position=torch.tensor([[[[0.2, 0.5, 1.8]], [[0.7, -0.4, 1.2]]]], dtype=torch.float64),
        intensity=torch.tensor([[[3.0], [2.0]]], dtype=torch.float64),
        color=torch.rand((1, 2, 1, 3), generator=g, dtype=torch.float64),
    )
    channels = CHANNELS[name]
    part = maps[:, channels].clone().requires_grad_(True)

    def render_with(p: torch.Tensor) -> torch.Tensor:
        full = torch.cat([maps[:, : channels.start], p, maps[:, channels.stop :]], dim=1)
        return render_point_lights(full, camera, lights)

    assert torch.autograd.gradcheck(render_with, (part,), eps=1e-6, atol=1e-6)


@pytest.mark.parametrize(
    ("maps_shape", "camera_shape", "message"),
    [
        ((1, 7, 4, 4), (1, 1, 3), "shape"),
        ((8, 4, 4), (1, 1, 3), r"\(B, 8, H, W\)"),
        ((1, 8, 4, 4), (1, 3), "camera_position"),
        ((2, 8, 4, 4), (1, 1, 3), "camera_position"),
    ],
)
def test_bad_shapes_raise_clear_errors(maps_shape, camera_shape, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        render_point_lights(
            torch.rand(maps_shape), torch.rand(camera_shape), _lights([0, 0, 1], 1, dtype=torch.float32)
        )


def test_bad_light_shapes_raise_clear_errors() -> None:
    maps, camera = random_maps(2, 2, batch=(1,)), torch.rand(1, 1, 3)
    ok = _lights([0, 0, 1], 1, dtype=torch.float32)
    with pytest.raises(ValueError, match="light intensity"):
        render_point_lights(maps, camera, PointLights(ok.position, ok.intensity[..., None], ok.color))
    with pytest.raises(ValueError, match="light color"):
        render_point_lights(maps, camera, PointLights(ok.position, ok.intensity, ok.color[..., :2]))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_cuda_matches_cpu() -> None:
    maps = random_maps(8, 8, batch=(2,))
    camera = torch.tensor([0.0, 0.0, 2.0]).expand(2, 1, 3)
    lights = PointLights(camera[:, :, None], torch.ones(2, 1, 1), torch.ones(2, 1, 1, 3))
    cpu = render_point_lights(maps, camera, lights)
    gpu = render_point_lights(
        maps.cuda(),
        camera.cuda(),
        PointLights(*(t.cuda() for t in (lights.position, lights.intensity, lights.color))),
    )
    torch.testing.assert_close(gpu.cpu(), cpu, rtol=1e-4, atol=1e-6)


def test_supersampling_integrates_the_pixel_footprint() -> None:
    # A uniform rough sample varies slowly: supersampling changes little. A sharp highlight is
    # under-sampled at texel centres: the footprint average moves towards the finer render.
    rough = flat_maps(8, 8, roughness=0.9, batch=(1,), dtype=torch.float64)
    torch.testing.assert_close(render_flash(rough, supersample=4), render_flash(rough), rtol=2e-2, atol=0)
    sharp = flat_maps(8, 8, roughness=0.15, metallic=1.0, batch=(1,), dtype=torch.float64)
    fine = torch.nn.functional.avg_pool2d(
        render_flash(sharp.repeat_interleave(16, -1).repeat_interleave(16, -2)), 16
    )
    coarse_error = (render_flash(sharp) - fine).abs().sum()
    assert (render_flash(sharp, supersample=4) - fine).abs().sum() < 0.5 * coarse_error


def test_flash_capture_geometry() -> None:
    capture = FlashCapture(fov_deg=90.0, intensity=2.0, color=(1.0, 0.5, 0.25), plane_half_size=0.5)
    assert capture.camera_height == pytest.approx(0.5)
    assert capture.radiant_intensity == (2.0, 1.0, 0.5)


@pytest.mark.parametrize("lights_per_config", [1, 3])
def test_factored_renderer_matches_the_direct_evaluation(lights_per_config: int) -> None:
    # The factored renderer against evaluate_brdf on full vector fields: values and gradients of
    # every map, with normals tilted far enough that some texels face away from light or camera
    # (the visibility mask), grazing and close lights, coloured intensities, float64.
    from tests.core.render_reference import render_point_lights_direct

    maps = random_maps(12, 10, batch=(2,), dtype=torch.float64)
    tilt = torch.linspace(-2.5, 2.5, 10, dtype=torch.float64)
    maps[:, 3] = maps[:, 3] + tilt  # some normals lean past 60°
    maps[:, 3:6] = torch.nn.functional.normalize(maps[:, 3:6], dim=1)
    g = torch.Generator().manual_seed(3)
    views = 4
    camera = torch.randn(2, views, 3, generator=g, dtype=torch.float64) * 0.8
    camera[..., 2] = camera[..., 2].abs() + 0.3
    position = torch.randn(2, views, lights_per_config, 3, generator=g, dtype=torch.float64)
    position[..., 2] = position[..., 2].abs() * 0.5 + 0.05  # some nearly grazing
    lights = PointLights(
        position=position,
        intensity=torch.rand(2, views, lights_per_config, generator=g, dtype=torch.float64) + 0.5,
        color=torch.rand(2, views, lights_per_config, 3, generator=g, dtype=torch.float64),
    )
    weights = torch.rand(2, views, 3, 12, 10, generator=g, dtype=torch.float64)
    results = []
    for render in (render_point_lights, render_point_lights_direct):
        pred = maps.clone().requires_grad_(True)
        image = render(pred, camera, lights, 0.7)
        (gradient,) = torch.autograd.grad((image * weights).sum(), pred)
        results.append((image.detach(), gradient))
    (fast, fast_grad), (direct, direct_grad) = results
    assert (direct == 0).any() and (direct > 0).any()  # the visibility mask is exercised
    torch.testing.assert_close(fast, direct, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(fast_grad, direct_grad, rtol=1e-9, atol=1e-11)
