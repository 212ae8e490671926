"""`brdfgan predict --views`: several flash photos of one surface → one material (issue 47).

The photos are rendered with the project's renderer (texture-space radiance of each view's own
camera and flash, warped into the view's pixels) from a nadir reference and tilted views, and
saved as 8-bit sRGB PNGs; the shipped weights run at 128².
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image

from brdfgan.cli import PARTIAL_FAILURE_EXIT_CODE, main
from brdfgan.core.homography import pose_homography
from brdfgan.core.render import (
    CameraPose,
    PointLights,
    render_point_lights,
    view_grid,
    warp_to_view,
)
from brdfgan.core.svbrdf import join_maps, linear_to_srgb, normalize_normal
from brdfgan.errors import USER_ERROR_EXIT_CODE
from brdfgan.inference.views.warp import warp_to_reference

PLANE_HALF_SIZE = 2.0  # the textured plane, larger than any view's footprint
TEXELS = 512
WIDTH, HEIGHT = 256, 192
FOV_DEG = 60.0
DISTANCE = 2.0
EXPOSURE = 6.0


def textured_maps(seed: int) -> torch.Tensor:
    """A dielectric with base colour detail at several scales (features to match) and mild bumps."""
    rng = np.random.default_rng(seed)
    detail = sum(
        cv2.GaussianBlur(rng.standard_normal((TEXELS, TEXELS)).astype(np.float32), (0, 0), sigma) * sigma
        for sigma in (1.5, 4.0, 12.0)
    )
    detail = (detail - detail.mean()) / detail.std()
    value = torch.from_numpy(np.clip(0.35 + 0.12 * detail, 0.05, 0.9))
    basecolor = torch.stack([value, 0.9 * value, 0.75 * value])
    noise = rng.standard_normal((TEXELS, TEXELS, 2)).astype(np.float32)
    bumps = torch.from_numpy(cv2.GaussianBlur(noise, (0, 0), 3.0).transpose(2, 0, 1).copy())
    normal = normalize_normal(torch.cat([0.3 * bumps, torch.ones(1, TEXELS, TEXELS)]))
    return join_maps(basecolor, normal, torch.full((1, TEXELS, TEXELS), 0.45), torch.zeros(1, TEXELS, TEXELS))


def tilted_pose(tilt_deg: float, azimuth_deg: float) -> CameraPose:
    """A camera ``DISTANCE`` from the plane's centre, tilted from the vertical toward ``azimuth``."""
    tilt, azimuth = math.radians(tilt_deg), math.radians(azimuth_deg)
    origin = (
        DISTANCE * math.sin(tilt) * math.cos(azimuth),
        DISTANCE * math.sin(tilt) * math.sin(azimuth),
        DISTANCE * math.cos(tilt),
    )
    return CameraPose(origin, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), FOV_DEG)


def flash_photo(maps: torch.Tensor, pose: CameraPose, path: Path) -> Path:
    """The photo of ``pose`` with the flash at its lens, 8-bit sRGB PNG."""
    camera = torch.tensor([[list(pose.origin)]], dtype=torch.float32)
    lights = PointLights(camera[:, :, None], torch.ones(1, 1, 1), torch.ones(1, 1, 1, 3))
    with torch.no_grad():
        radiance = render_point_lights(maps[None], camera, lights, PLANE_HALF_SIZE)[:, 0]
        photo = warp_to_view(radiance, view_grid(pose, HEIGHT, WIDTH, PLANE_HALF_SIZE)[None])[0]
    srgb = linear_to_srgb((EXPOSURE * photo).clamp(0, 1)).permute(1, 2, 0).numpy()
    cv2.imwrite(str(path), np.rint(srgb * 255).astype(np.uint8)[..., ::-1])
    return path


REFERENCE, EAST, NORTH = tilted_pose(0.0, 0.0), tilted_pose(18.0, 0.0), tilted_pose(15.0, 120.0)


def camera_in_reference_world(document: dict[str, Any], pose: CameraPose) -> np.ndarray:
    """Where a view's true camera lies in the reference's world: the crop is the square [-1, 1]²,
    so a true position moves to the crop's centre and scales by the crop's half side on the plane."""
    crop = document["crop"]
    metres_per_px = 2.0 * DISTANCE * math.tan(math.radians(FOV_DEG) / 2.0) / WIDTH  # the nadir reference
    centre = np.array(
        [crop["x"] + crop["size"] / 2 - WIDTH / 2, -(crop["y"] + crop["size"] / 2 - HEIGHT / 2), 0.0]
    )
    return (np.array(pose.origin) - centre * metres_per_px) / (crop["size"] / 2 * metres_per_px)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("views")
    maps, other = textured_maps(0), textured_maps(1)
    photos = {
        "ref": flash_photo(maps, REFERENCE, folder / "ref.png"),
        "east": flash_photo(maps, EAST, folder / "east.png"),
        "north": flash_photo(maps, NORTH, folder / "north.png"),
        "other": flash_photo(other, tilted_pose(0.0, 0.0), folder / "other.png"),
    }
    broken = folder / "broken.jpg"
    broken.write_bytes(b"not a photo")
    photos["broken"] = broken
    return photos


def hidden_entries(folder: Path) -> list[str]:
    return [entry.name for entry in folder.iterdir() if entry.name.startswith(".")]


def test_warp_to_reference_undoes_a_known_homography() -> None:
    """A view of a texture from a known pose, warped back with its true homography, matches the
    texture's central quarter (box-averaged to the reference side)."""
    texture = textured_maps(0)[:3]
    pose = tilted_pose(20.0, 45.0)
    view = warp_to_view(texture[None], view_grid(pose, HEIGHT, WIDTH, PLANE_HALF_SIZE)[None])[0]
    side, crop = 64, TEXELS // 4
    start = (TEXELS - crop) // 2
    truth = F.avg_pool2d(texture[None, :, start : start + crop, start : start + crop], crop // side)[0]
    # Reference texels → plane texels: the central crop, scaled.
    scale = crop / side
    to_plane_texels = np.array([[scale, 0.0, start], [0.0, scale, start], [0.0, 0.0, 1.0]])
    homography = pose_homography(pose, WIDTH, HEIGHT, PLANE_HALF_SIZE, TEXELS) @ to_plane_texels
    image, seen = warp_to_reference(view, homography, side)
    assert seen.shape == (1, side, side) and float(seen.mean()) > 0.9
    error = float(((image - truth).abs() * seen).sum() / (seen.sum() * 3))
    assert error < 0.03 * float(truth.mean())


def test_views_give_one_material_with_each_views_role(
    scene: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    inputs = [scene["ref"], scene["east"], scene["broken"], scene["north"], scene["other"]]
    options = ["--out", str(out), "--resolution", "128", "--fov", str(FOV_DEG), "--no-preview"]
    code = main(["predict", "--views", *map(str, inputs), *options])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert [entry.name for entry in out.iterdir()] == ["ref"]
    assert captured.out.strip() == str(out / "ref")
    document = json.loads((out / "ref" / "material.json").read_text())
    views = document["views"]
    assert [view["file"] for view in views] == list(map(str, inputs))
    assert [view["role"] for view in views] == ["reference", "fitted", "left_out", "fitted", "left_out"]
    for view in (views[1], views[3]):
        assert view["reason"] is None and view["method"] == "sift"
        assert view["reprojection_px"] < 0.5 and view["pose_reprojection_px"] < 1.0
        assert view["camera_position"][2] > 0 and len(view["gain"]) == 3
    for view, pose in ((views[1], EAST), (views[3], NORTH)):
        truth = camera_in_reference_world(document, pose)
        assert np.abs(np.array(view["camera_position"]) - truth).max() < 0.03, (
            view["camera_position"],
            truth,
        )
    assert views[0]["camera_position"][2] == pytest.approx(
        camera_in_reference_world(document, REFERENCE)[2], rel=1e-3
    )
    assert (
        document["view_fit"]["kept"] in ("fit", "prediction") and document["view_fit"]["settings"]["levels"]
    )
    warnings = [line for line in captured.err.splitlines() if line.startswith("warning:")]
    assert any(str(scene["broken"]) in line for line in warnings)
    assert any(str(scene["other"]) in line and "left out" in line for line in warnings)
    assert views[4]["reason"] and views[2]["reason"]
    assert hidden_entries(out) == []


def test_one_readable_view_gives_the_single_photo_output(
    scene: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    options = ["--out", str(out), "--resolution", "128", "--no-preview"]
    code = main(["predict", "--views", str(scene["broken"]), str(scene["ref"]), *options])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert [entry.name for entry in out.iterdir()] == ["broken"]  # OUT/<first stem>/
    document = json.loads((out / "broken" / "material.json").read_text())
    assert "views" not in document and document["refinement"] is None
    warnings = [line for line in captured.err.splitlines() if line.startswith("warning:")]
    assert sum(str(scene["broken"]) in line for line in warnings) == 1
    assert any("single-photo" in line for line in warnings)
    assert hidden_entries(out) == []


def test_refine_with_views_is_a_one_line_usage_error(
    scene: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    photos = [str(scene["ref"]), str(scene["east"])]
    code = main(["predict", "--views", *photos, "--refine", "10", "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert code == USER_ERROR_EXIT_CODE
    assert len(captured.err.strip().splitlines()) == 1 and "--views" in captured.err
    assert not (tmp_path / "o").exists()


def test_more_views_than_the_fit_takes_is_a_one_line_usage_error(
    scene: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    photos = [str(scene["ref"])] * 13
    code = main(["predict", "--views", *photos, "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert code == USER_ERROR_EXIT_CODE
    assert captured.err.strip() == "error: --views takes at most 12 photos of one surface, got 13"
    assert not (tmp_path / "o").exists()


def test_views_stored_rotated_smaller_or_as_jpeg_give_the_same_cameras(
    scene: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # east.jpg is stored turned a quarter (EXIF orientation 6: turn it clockwise to view it), so
    # its width and height swap on disk: misread, its field of view would span the wrong side and
    # its camera's distance would be off by 4:3. north.jpg is 3/4 the size.
    east = np.asarray(Image.open(scene["east"]).convert("RGB"))
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(np.ascontiguousarray(np.rot90(east, 1))).save(
        tmp_path / "east.jpg", quality=95, exif=exif
    )
    north = Image.open(scene["north"]).convert("RGB")
    north.resize((WIDTH * 3 // 4, HEIGHT * 3 // 4), Image.Resampling.LANCZOS).save(
        tmp_path / "north.jpg", quality=95
    )
    out = tmp_path / "out"
    inputs = [scene["ref"], tmp_path / "east.jpg", tmp_path / "north.jpg"]
    options = ["--out", str(out), "--resolution", "128", "--fov", str(FOV_DEG), "--no-preview"]
    assert main(["predict", "--views", *map(str, inputs), *options]) == 0, capsys.readouterr().err
    document = json.loads((out / "ref" / "material.json").read_text())
    views = document["views"]
    assert [view["role"] for view in views] == ["reference", "fitted", "fitted"]
    for view, pose in ((views[1], EAST), (views[2], NORTH)):
        truth = camera_in_reference_world(document, pose)
        assert np.abs(np.array(view["camera_position"]) - truth).max() < 0.05, (
            view["camera_position"],
            truth,
        )


def test_one_photo_is_the_single_photo_output_two_a_warning_and_none_readable_one_line(
    scene: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    options = ["--out", str(out), "--resolution", "128", "--no-preview"]
    assert main(["predict", "--views", str(scene["ref"]), *options]) == 0
    captured = capsys.readouterr()
    assert "views" not in json.loads((out / "ref" / "material.json").read_text())
    assert any("single-photo" in line for line in captured.err.splitlines())
    assert main(["predict", "--views", str(scene["ref"]), str(scene["east"]), *options]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert [line for line in warnings if "only two usable photos" in line] == [
        f"warning: {scene['ref']}: only two usable photos: a fit to two can come out worse than one "
        "photo (glossy surfaces); 3-5 photos are what it needs"
    ]
    code = main(
        ["predict", "--views", str(scene["broken"]), str(scene["broken"]), "--out", str(tmp_path / "o")]
    )
    captured = capsys.readouterr()
    # A capture that fails is one failure of the batch, as a photo is (brdfgan.inference.dispatch).
    assert code == PARTIAL_FAILURE_EXIT_CODE
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: none of the 2 views can be read (")
    assert f"{scene['broken']}: not an image file" in errors[0]
    assert "1 of 1 capture(s) failed:" in captured.err.splitlines()
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
