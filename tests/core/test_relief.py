"""Height, ambient occlusion, normal strength and tileable maps (the artist's outputs)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from brdfgan.core.height import ambient_occlusion, height_from_normals
from brdfgan.core.seamless import wrap_ratios
from brdfgan.core.svbrdf import scale_normal_strength, split_maps
from brdfgan.data.materials.base import height_to_normal
from tests.conftest import SHARED, random_maps


def _grid(size: int) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.meshgrid(torch.arange(size, dtype=torch.float64), torch.arange(size, dtype=torch.float64),
                          indexing="ij")  # fmt: skip


def test_a_sum_of_sines_comes_back_from_its_normals() -> None:
    size = 128
    y, x = _grid(size)
    # Texel units (height_to_normal's); periodic on the map, so it is the --tileable case.
    height = 3.0 * torch.sin(4 * math.pi * x / size) + 2.0 * torch.cos(2 * math.pi * (3 * y + x) / size)
    normals = height_to_normal(height[None]).float()
    recovered = height_from_normals(normals, periodic=True).double() * size  # sample sides → texels
    expected = height - height.mean()
    assert (recovered - expected).abs().max() < 0.01 * expected.abs().max()
    # Not periodic: mirrored before integration; the borders (where height_to_normal wrapped the
    # slopes of a non-periodic field) aside, the shape is the same up to a constant.
    bowl = 5.0 * torch.sin(2 * math.pi * 0.7 * x / size + 0.3) + 0.002 * (y - 64) ** 2
    recovered = height_from_normals(height_to_normal(bowl[None]).float()).double() * size
    error = (recovered - bowl)[4:-4, 4:-4]
    assert (error - error.mean()).abs().max() < 0.03 * (bowl.max() - bowl.min())


def test_height_is_in_units_of_the_sample_side_and_ignores_a_global_tilt() -> None:
    size = 64
    _, x = _grid(size)
    amplitude = 0.02  # of the sample side; two periods across the map
    slope = amplitude * 4 * math.pi * torch.cos(4 * math.pi * x / size)  # dh/dx, both in sample sides
    normals = torch.stack([-slope, torch.zeros_like(slope), torch.ones_like(slope)])
    normals = (normals / normals.norm(dim=0)).float()
    height = height_from_normals(normals, periodic=True).double()
    expected = amplitude * torch.sin(4 * math.pi * x / size)
    assert (height - expected).abs().max() < 0.02 * amplitude
    # A constant tilt on top (a biased normal map) adds no ramp: a sample is a flat surface.
    tilted = normals.clone()
    tilted[0] -= 0.1
    tilted = tilted / tilted.norm(dim=0)
    assert (height_from_normals(tilted, periodic=True).double() - expected).abs().max() < 0.1 * amplitude


def test_ambient_occlusion_is_one_on_a_flat_surface_and_darkens_a_pit() -> None:
    flat = torch.zeros(64, 64)
    assert torch.equal(ambient_occlusion(flat), torch.ones(64, 64))
    y, x = _grid(64)
    pit = (-0.05 * torch.exp(-((x - 32) ** 2 + (y - 32) ** 2) / 50.0)).float()
    ao = ambient_occlusion(pit)
    assert ao.min() >= 0 and ao.max() <= 1
    assert ao[32, 32] == ao.min() and ao[32, 32] < 0.97 and ao[2, 2] > 0.999
    deeper = ambient_occlusion(4 * pit)
    assert deeper[32, 32] < ao[32, 32]  # a deeper pit sees less sky
    bump = ambient_occlusion(-pit)
    assert bump[32, 32] == pytest.approx(1.0)  # the top of a bump is open


def test_normal_strength_scales_the_tilt_and_keeps_unit_length() -> None:
    maps = random_maps(16, 16)
    normal = split_maps(maps).normal
    stronger = scale_normal_strength(normal, 2.0)
    assert torch.allclose(stronger.norm(dim=0), torch.ones(16, 16), atol=1e-5)
    tilt = torch.atan2(normal[:2].norm(dim=0), normal[2])
    tilt_after = torch.atan2(stronger[:2].norm(dim=0), stronger[2])
    moved = tilt > 0.01
    assert torch.allclose(torch.tan(tilt_after[moved]), 2.0 * torch.tan(tilt[moved]), rtol=1e-4)
    assert torch.allclose(scale_normal_strength(normal, 1.0), normal, atol=1e-6)
    flat = scale_normal_strength(normal, 0.0)
    assert torch.allclose(flat, torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand_as(flat))
    with pytest.raises(ValueError, match="normal strength"):
        scale_normal_strength(normal, -1.0)


SCANS = SHARED / "ood" / "ambientcg"


@pytest.mark.skipif(not SCANS.is_dir(), reason="the scanned OOD materials (../shared/ood) are not here")
@pytest.mark.parametrize(("material", "least"), [("rock", 0.95), ("mossyrock", 0.95), ("rustymetal", 0.8)])
def test_height_of_a_scanned_normal_map_matches_its_scanned_displacement(material: str, least: float) -> None:
    # Real photogrammetry: the normal map and the displacement map were made from the same scan.
    from brdfgan.core.svbrdf import decode_normal
    from brdfgan.io.images import read_image

    def load(name: str) -> torch.Tensor:
        image = cv2.resize(read_image(SCANS / material / name), (256, 256), interpolation=cv2.INTER_AREA)
        return torch.from_numpy(image.reshape(256, 256, -1)).permute(2, 0, 1)

    normals = decode_normal(load("normal.jpg"))
    displacement = load("displacement.jpg")[0]
    for periodic in (True, False):  # the scans tile; integrated as a photo crop would be too
        height = height_from_normals(normals, periodic=periodic)
        correlation = np.corrcoef(height.ravel().numpy(), displacement.ravel().numpy())[0, 1]
        assert correlation > least, (periodic, correlation)


def test_tileable_predictions_of_the_shipped_samples_wrap_and_plain_ones_are_unchanged(
    tmp_path: Path,
) -> None:
    from importlib import resources

    from brdfgan.core.clipped_fill import remove_flash
    from brdfgan.core.flash_geometry import DEFAULT_FOV_DEG
    from brdfgan.inference.intake.photo import read_photo
    from brdfgan.inference.intake.preprocess import preprocess
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.outputs.export import ExportOptions, texture_set
    from brdfgan.inference.pipeline import PredictOptions, Predictor, input_clipped, predict_photo
    from brdfgan.io.images import read_image

    model = load_model(None)
    samples = sorted(Path(str(resources.files("brdfgan") / "samples")).glob("*.jpg"))
    assert len(samples) == 4
    # 16-bit files: the metric is about the maps, not about 8-bit steps (a near-zero metallic map
    # moves by less than one 8-bit level between neighbours).
    tileable = Predictor.create(
        model, PredictOptions(tileable=True, preview=False, export=ExportOptions(bit_depth=16))
    )
    for photo in samples:
        out = predict_photo(photo, tmp_path / photo.stem, tileable).output
        # The bar: at least 85 % of every map's pixels copied from one copy (a cut, not a blend).
        tiling = json.loads((out / "material.json").read_text())["tileable"]
        assert min(tiling["copied_fraction"].values()) >= 0.85, (photo.name, tiling["copied_fraction"])
        for name in ("basecolor", "normal", "roughness", "metallic", "height", "ao"):
            image = torch.from_numpy(read_image(out / f"{name}.png")).permute(2, 0, 1).double()
            columns, rows = wrap_ratios(image)
            assert columns < 1.2 and rows < 1.2, (photo.name, name, columns, rows)
    # Without --tileable the maps are the network's with the flash taken out, as before (only
    # height and ao are new files).
    plain = Predictor.create(model, PredictOptions(preview=False))
    out = predict_photo(samples[0], tmp_path / "plain", plain).output
    photo = read_photo(samples[0])
    prepared = preprocess(photo, plain.resolution, None)
    frame = prepared.flash_frame(DEFAULT_FOV_DEG)
    maps, _ = remove_flash(
        plain.maps(prepared.photo, frame), prepared.photo, frame, clipped=input_clipped(photo, prepared)
    )
    expected = texture_set(maps, ExportOptions())
    for name in ("basecolor", "normal", "roughness", "metallic"):
        stored = read_image(out / f"{name}.png")
        assert np.abs(stored - expected[name].values).max() <= 0.5 / 255 + 1e-6, name
