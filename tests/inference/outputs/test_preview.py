from __future__ import annotations

import itertools
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image

from brdfgan.core.relight import relight, render_sky
from brdfgan.core.render import ShadingInputs
from brdfgan.core.sky import ProceduralSky
from brdfgan.core.svbrdf import join_maps, linear_to_srgb, normalize_normal, resize_maps
from brdfgan.inference.outputs import preview as preview_module
from brdfgan.inference.outputs.preview import (
    LABEL_HEIGHT,
    PREVIEW_SKY_SAMPLES,
    SEPARATOR,
    SEPARATOR_COLOR,
    animation_frames,
    preview_image,
    preview_lights,
    preview_size,
    render_preview_tiles,
    write_animation,
    write_preview,
)
from tests.conftest import random_maps, tilted_plane

SIZE = 32


def quality_maps(kind: str, size: int) -> torch.Tensor:
    """Map sets on which the environment tile's sampling noise differs (also used by
    benchmarks/bench_preview.py): ``glossy_metal`` (gold, roughness 0.15–0.2, gentle bumps),
    ``rough_dielectric`` (roughness 0.85–0.95, fine bumps), ``bumpy_glossy`` (roughness 0.25, strong
    normal map), ``mixed`` (:func:`tests.conftest.random_maps`: random roughness, half metal)."""
    if kind == "mixed":
        return random_maps(size, size, seed=1)
    g = torch.Generator().manual_seed(3)

    def noise(channels: int = 1) -> torch.Tensor:
        return torch.rand(channels, size, size, generator=g)

    def bumps(amplitude: float, frequency: float) -> torch.Tensor:
        y, x = torch.meshgrid(torch.linspace(0, 1, size), torch.linspace(0, 1, size), indexing="ij")
        phase = 2 * math.pi * torch.rand(4, generator=g)
        w = 2 * math.pi * frequency
        dx = amplitude * torch.sin(w * x + phase[0]) * torch.cos(0.7 * w * y + phase[1])
        dy = amplitude * torch.cos(1.3 * w * x + phase[2]) * torch.sin(w * y + phase[3])
        return normalize_normal(torch.stack([dx, dy, torch.ones_like(dx)]))

    one = torch.ones(1, size, size)
    if kind == "glossy_metal":
        gold = torch.tensor([1.0, 0.78, 0.34]).view(3, 1, 1) * (0.8 + 0.2 * noise())
        return join_maps(gold, bumps(0.08, 3), 0.15 + 0.05 * noise(), one)
    if kind == "rough_dielectric":
        return join_maps(0.2 + 0.6 * noise(3), bumps(0.3, 12), 0.85 + 0.1 * noise(), 0 * one)
    if kind == "bumpy_glossy":
        return join_maps(0.1 + 0.3 * noise(3), bumps(0.5, 8), 0.25 * one, 0 * one)
    raise ValueError(f"unknown map set {kind!r}")


# ------------------------------------------------------------------------------------------- lights


def test_preview_lights_are_novel_and_spread() -> None:
    lights = preview_lights(4)
    assert lights.shape == (4, 3)
    distance = lights.norm(dim=-1)
    torch.testing.assert_close(distance, torch.full((4,), 3.0))
    elevation = torch.rad2deg(torch.asin(lights[:, 2] / distance))
    torch.testing.assert_close(elevation, torch.tensor([45.0, 45.0, 45.0, 12.0]), atol=1e-4, rtol=0)
    assert (lights[:, :2].norm(dim=-1) > 1.0).all()  # none of them on the flash/camera axis
    azimuth = torch.rad2deg(torch.atan2(lights[:, 1], lights[:, 0])) % 360
    torch.testing.assert_close(azimuth, torch.tensor([45.0, 165.0, 285.0, 105.0]), atol=1e-3, rtol=0)
    assert preview_lights(1).shape == (1, 3)
    with pytest.raises(ValueError, match="count"):
        preview_lights(0)


# ------------------------------------------------------------------------------------------- resize


def test_resize_maps_averages_and_keeps_normals_unit() -> None:
    maps = random_maps(64, 64, seed=5)
    small = resize_maps(maps, 16)
    assert small.shape == (8, 16, 16)
    torch.testing.assert_close(small[3:6].norm(dim=0), torch.ones(16, 16))
    torch.testing.assert_close(small[6:], F.avg_pool2d(maps[6:], 4))
    torch.testing.assert_close(resize_maps(tilted_plane(64), 16), tilted_plane(16))
    assert resize_maps(maps, 64) is maps
    big = resize_maps(small, (24, 40))
    assert big.shape == (8, 24, 40)
    torch.testing.assert_close(big[3:6].norm(dim=0), torch.ones(24, 40))


# ------------------------------------------------------------------------------------------ preview


def test_preview_image_layout_and_input_tile() -> None:
    photo = torch.rand(3, 64, 64, generator=torch.Generator().manual_seed(0))
    maps = random_maps(64, 64, seed=6)
    tile, lights = 32, 2
    image = preview_image(photo, maps, tile=tile, lights=lights, samples=8)
    tiles = 1 + lights + 1
    assert image.dtype == np.uint8
    assert image.shape == (tile + LABEL_HEIGHT, tiles * tile + (tiles - 1) * SEPARATOR, 3)
    assert image.shape[:2] == preview_size(tile, lights)
    expected = linear_to_srgb(F.avg_pool2d(photo[None], 2)[0]).mul(255).round().to(torch.uint8)
    np.testing.assert_array_equal(image[LABEL_HEIGHT:, :tile], expected.permute(1, 2, 0).numpy())
    np.testing.assert_array_equal(
        image[:, tile : tile + SEPARATOR],
        np.broadcast_to(SEPARATOR_COLOR, (tile + LABEL_HEIGHT, SEPARATOR, 3)),
    )
    renders = [
        image[LABEL_HEIGHT:, k * (tile + SEPARATOR) : k * (tile + SEPARATOR) + tile] for k in range(1, tiles)
    ]
    assert all(r.std() > 0 for r in renders)  # every rendering shows something
    assert not np.array_equal(renders[0], renders[1])

    bare = preview_image(photo, maps, tile=tile, lights=lights, samples=8, labels=False)
    assert bare.shape[:2] == preview_size(tile, lights, labels=False) == (tile, image.shape[1])
    np.testing.assert_array_equal(bare, image[LABEL_HEIGHT:])


def test_preview_image_renders_big_maps_at_tile_size(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[int, ...]] = []
    original = preview_module.shade_point_lights

    def spy(inputs: ShadingInputs, *args: object, **kwargs: object) -> torch.Tensor:
        seen.append(inputs.shape)
        return original(inputs, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(preview_module, "shade_point_lights", spy)
    image = preview_image(torch.rand(3, 48, 80), random_maps(128, 128, seed=7), tile=16, lights=1, samples=4)
    assert image.shape[:2] == preview_size(16, 1)
    assert seen and all(shape[-2:] == (16, 16) for shape in seen)


@pytest.mark.parametrize("chunk", [1, 3, 100])
def test_render_preview_tiles_renders_the_lights_of_relight_and_render_sky(chunk: int) -> None:
    # The batched renderer is a speed-up only: the same lights, the same images as the core
    # functions it replaces in the preview, whatever the chunking (chunk 3 mixes point and sky
    # lights in one call).
    maps, sky = random_maps(24, 24, seed=9), ProceduralSky()
    positions = preview_lights(3)
    tiles = render_preview_tiles(maps, positions, sky, samples=7, chunk=chunk)
    expected = torch.cat([relight(maps, positions), render_sky(maps, sky, samples=7)[None]])
    assert tiles.shape == (4, 3, 24, 24)
    torch.testing.assert_close(tiles, expected, rtol=1e-5, atol=1e-7)
    sky_only = render_preview_tiles(maps, torch.zeros(0, 3), sky, samples=5, seed=2, chunk=chunk)
    torch.testing.assert_close(sky_only[0], render_sky(maps, sky, samples=5, seed=2), rtol=1e-5, atol=1e-7)
    dark = render_preview_tiles(
        maps, torch.zeros(0, 3), ProceduralSky(zenith=(0, 0, 0), horizon=(0, 0, 0), sun_irradiance=0)
    )
    assert dark.shape == (1, 3, 24, 24) and not dark.any()
    with pytest.raises(ValueError, match="chunk"):
        render_preview_tiles(maps, positions, sky, chunk=0)


def _environment_tile(maps: torch.Tensor, samples: int) -> np.ndarray:
    tile = maps.shape[-1]
    image = preview_image(
        torch.zeros(3, tile, tile), maps, tile=tile, lights=0, samples=samples, labels=False
    )
    return image[:, tile + SEPARATOR :].astype(np.float64)


# RMSE (8-bit sRGB levels) of the default environment tile against a 4×-sample reference at 64²,
# as measured (deterministic: seed 0) plus ~10 %: bumpy_glossy 8.5, rough_dielectric 1.27. A quarter
# of the lights measured 18.9 and 2.54, which is why the default stays at 64 lights
# (benchmarks/bench_preview.py measures the same at 256²).
ENVIRONMENT_TOLERANCE = {"bumpy_glossy": 9.4, "rough_dielectric": 1.4}


@pytest.mark.parametrize("kind", sorted(ENVIRONMENT_TOLERANCE))
def test_preview_environment_tile_stays_within_measured_error_of_a_reference(kind: str) -> None:
    maps = quality_maps(kind, 64)
    reference = _environment_tile(maps, 4 * PREVIEW_SKY_SAMPLES)
    error = math.sqrt(((_environment_tile(maps, PREVIEW_SKY_SAMPLES) - reference) ** 2).mean())
    fewer = math.sqrt(((_environment_tile(maps, PREVIEW_SKY_SAMPLES // 4) - reference) ** 2).mean())
    assert error <= ENVIRONMENT_TOLERANCE[kind]
    assert fewer > 1.5 * error  # a quarter of the lights is measurably noisier


def test_preview_image_rejects_bad_input() -> None:
    maps = random_maps(16, 16)
    with pytest.raises(ValueError, match="photo"):
        preview_image(torch.rand(16, 16), maps, tile=16)
    with pytest.raises(ValueError, match="tile"):
        preview_image(torch.rand(3, 16, 16), maps, tile=0)


def test_write_preview_png_reads_back_identical(tmp_path: Path) -> None:
    photo, maps = torch.rand(3, 32, 32), random_maps(32, 32, seed=8)
    path = write_preview(tmp_path / "preview.png", photo, maps, tile=32, lights=1, samples=4)
    assert path == tmp_path / "preview.png"
    back = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(back, preview_image(photo, maps, tile=32, lights=1, samples=4))
    assert [p.name for p in tmp_path.iterdir()] == ["preview.png"]
    with pytest.raises(ValueError, match=r"\.png"):
        write_preview(tmp_path / "preview.jpg", photo, maps, tile=32)


# ---------------------------------------------------------------------------------------- animation


def test_animation_frames_move_the_light_with_a_fixed_exposure() -> None:
    frames = list(animation_frames(tilted_plane(normal=(0.4, 0.0, 1.0)), frames=12, size=SIZE))
    assert len(frames) == 12
    assert all(f.shape == (SIZE, SIZE, 3) and f.dtype == np.uint8 for f in frames)
    assert all(not np.array_equal(a, b) for a, b in itertools.pairwise(frames))
    means = np.array([f.astype(np.float64).mean() for f in frames])
    # Frame 0 has the light at +X, where the normals lean; frame 6 at −X. Per-frame auto exposure
    # would level them; one exposure for all keeps the material's own brightness change.
    assert means[0] > 1.3 * means[6]
    steps = np.abs(np.diff(np.append(means, means[0])))
    assert steps.max() < 0.4 * (means.max() - means.min())  # a smooth cycle, no exposure jumps


def test_animation_frames_check_arguments_on_call() -> None:
    with pytest.raises(ValueError, match="frames"):
        animation_frames(tilted_plane(), frames=0)
    with pytest.raises(ValueError, match="elevation"):
        animation_frames(tilted_plane(), elevation_deg=0.0)


def test_write_animation_gif(tmp_path: Path) -> None:
    maps = tilted_plane(normal=(0.3, 0.1, 1.0))
    path = write_animation(tmp_path / "turn.gif", maps, frames=8, size=SIZE, fps=10)
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert gif.n_frames == 8
        assert gif.size == (SIZE, SIZE)
        assert gif.info["loop"] == 0
        assert gif.info["duration"] == 100
    assert [p.name for p in tmp_path.iterdir()] == ["turn.gif"]


def test_write_animation_mp4(tmp_path: Path) -> None:
    maps = tilted_plane(normal=(0.3, 0.1, 1.0))
    path = write_animation(tmp_path / "turn.mp4", maps, frames=9, size=SIZE, fps=12)
    capture = cv2.VideoCapture(str(path))
    try:
        assert capture.isOpened()
        frames = []
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            frames.append(frame)
    finally:
        capture.release()
    assert len(frames) == 9
    assert all(f.shape == (SIZE, SIZE, 3) for f in frames)
    assert [p.name for p in tmp_path.iterdir()] == ["turn.mp4"]


def test_write_animation_rejects_bad_suffix_and_unwritable_video(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in ("turn.avi", "turn.png", "turn"):
        with pytest.raises(ValueError, match="animation must be one of"):
            write_animation(tmp_path / name, tilted_plane(8), frames=2, size=8)

    # No encoder to run: a one-line error naming the file, nothing left behind.
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(tmp_path / "no-such-ffmpeg"))
    with pytest.raises(ValueError, match=r"turn\.mp4: cannot start ffmpeg"):
        write_animation(tmp_path / "turn.mp4", tilted_plane(8), frames=2, size=8)
    assert list(tmp_path.iterdir()) == []
