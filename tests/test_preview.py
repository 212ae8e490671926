from __future__ import annotations

import itertools
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image

from brdfgan.core import relight as relight_module
from brdfgan.core.svbrdf import linear_to_srgb, resize_maps
from brdfgan.inference.outputs.preview import (
    LABEL_HEIGHT,
    SEPARATOR,
    SEPARATOR_COLOR,
    animation_frames,
    preview_image,
    preview_lights,
    preview_size,
    write_animation,
    write_preview,
)
from tests.conftest import random_maps, tilted_plane

SIZE = 32


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
    original = relight_module.render_point_lights

    def spy(maps: torch.Tensor, *args: object, **kwargs: object) -> torch.Tensor:
        seen.append(tuple(maps.shape))
        return original(maps, *args, **kwargs)

    monkeypatch.setattr(relight_module, "render_point_lights", spy)
    image = preview_image(torch.rand(3, 48, 80), random_maps(128, 128, seed=7), tile=16, lights=1, samples=4)
    assert image.shape[:2] == preview_size(16, 1)
    assert seen and all(shape[-2:] == (16, 16) for shape in seen)


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
