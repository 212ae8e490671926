"""The flash frame and its offset channels (brdfgan.core.flash_geometry) and the batches that
carry them."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

from brdfgan.core.flash_geometry import (
    DEFAULT_FOV_DEG,
    centred_flash_frame,
    crop_flash_frame,
    field_of_view,
    flash_offset_channels,
    flash_side_channels,
    pixel_scale,
    resize_flash_frame,
)
from brdfgan.core.render import FlashCapture, texel_centres
from brdfgan.data.loading.datamodule import collate_samples, flash_frames, random_crop
from brdfgan.data.storage.shards import Sample
from brdfgan.inference.intake.lens import DEFAULT_FOV_DEG as LENS_DEFAULT_FOV_DEG
from brdfgan.models.generator import Generator
from brdfgan.runs import WeightsError, load_weights, save_weights

TINY = {"width": 4, "downsamplings": 2, "residual_blocks": 1}


def test_golden_values_of_a_2x4_photo() -> None:
    frame = torch.tensor([[2.0, 1.0, 0.5]])
    got = flash_offset_channels(frame, 2, 4)
    assert got.shape == (1, 2, 2, 4)
    assert torch.equal(got[0, 0], torch.tensor([[-0.75, -0.25, 0.25, 0.75]] * 2))
    assert torch.equal(got[0, 1], torch.tensor([[0.25] * 4, [-0.25] * 4]))


def test_side_channels_split_the_offsets_by_sign() -> None:
    frame = torch.tensor([[2.0, 1.0, 0.5]])
    sides = flash_side_channels(frame, 2, 4)
    assert sides.shape == (1, 4, 2, 4)
    assert torch.equal(sides[0, 0], torch.tensor([[0.0, 0.0, 0.25, 0.75]] * 2))
    assert torch.equal(sides[0, 2], torch.tensor([[0.75, 0.25, 0.0, 0.0]] * 2))
    assert torch.equal(sides[0, 1], torch.tensor([[0.25] * 4, [0.0] * 4]))
    assert torch.equal(sides[0, 3], torch.tensor([[0.0] * 4, [0.25] * 4]))
    # What an InstanceNorm keeps: the plain offsets of crops left and right of the flash normalise
    # to the same ramp, the side channels do not.
    left, right = torch.tensor([[40.0, 2.0, 0.01]]), torch.tensor([[-8.0, 2.0, 0.01]])
    norm = torch.nn.InstanceNorm2d(2)
    plain = [norm(flash_offset_channels(f, 4, 8)) for f in (left, right)]
    torch.testing.assert_close(plain[0], plain[1])
    split = [torch.nn.InstanceNorm2d(4)(flash_side_channels(f, 4, 8)) for f in (left, right)]
    assert (split[0] - split[1]).abs().amax() > 1.0


@pytest.mark.parametrize("fov_deg", [40.0, 57.5, 75.0])
def test_centred_frame_is_minus_l_xy_over_l_z_of_the_training_capture(fov_deg: float) -> None:
    """For the nominal capture (camera over the centre framing the square, flash at the lens) the
    channels are exactly (p - f)_xy / f_z at every texel centre."""
    capture = FlashCapture(fov_deg=fov_deg)
    xs, ys = texel_centres(10, 10, dtype=torch.float64)
    got = flash_offset_channels(centred_flash_frame(1, 10, 10, fov_deg, dtype=torch.float64), 10, 10)[0]
    torch.testing.assert_close(got[0], (xs / capture.camera_height).expand(10, 10), rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(
        got[1], (ys / capture.camera_height)[:, None].expand(10, 10), rtol=1e-12, atol=1e-12
    )


def test_crop_and_resize_commute_with_the_channels() -> None:
    frame = torch.tensor(
        [[30.5, 12.0, pixel_scale(60.0, 64)], [3.0, 70.0, pixel_scale(45.0, 64)]], dtype=torch.float64
    )
    whole = flash_offset_channels(frame, 64, 48)
    window = flash_offset_channels(crop_flash_frame(frame, 8, 20), 16, 24)
    torch.testing.assert_close(window, whole[..., 20:36, 8:32], rtol=0, atol=1e-12)
    # The channels are affine in the pixel centre, so area-downscaling them is exact.
    half = flash_offset_channels(resize_flash_frame(frame, 0.5), 32, 24)
    torch.testing.assert_close(half, F.avg_pool2d(whole, 2), rtol=0, atol=1e-12)
    # Per-sample offsets, and padding on the left as a negative offset.
    shifted = crop_flash_frame(frame, torch.tensor([1.0, -2.0]), torch.tensor([0.0, 3.0]))
    assert shifted[:, :2].tolist() == [[29.5, 12.0], [5.0, 67.0]]


def test_bad_frames_are_refused() -> None:
    with pytest.raises(ValueError, match=r"\(B, 3\)"):
        flash_offset_channels(torch.zeros(2, 2), 4, 4)
    with pytest.raises(ValueError, match="positive scale"):
        flash_offset_channels(torch.tensor([[1.0, 1.0, 0.0]]), 4, 4)
    with pytest.raises(ValueError, match="finite"):
        flash_offset_channels(torch.tensor([[math.nan, 1.0, 0.1]]), 4, 4)
    with pytest.raises(ValueError, match="fov_deg"):
        pixel_scale(180.0, 10)
    with pytest.raises(ValueError, match="scale"):
        field_of_view(0.0, 10)


def test_field_of_view_inverts_pixel_scale() -> None:
    assert field_of_view(pixel_scale(57.5, 256), 256) == pytest.approx(57.5, abs=1e-9)
    # A centre crop of half the width sees tan(fov/2) halved.
    assert math.tan(math.radians(field_of_view(pixel_scale(60.0, 200), 100)) / 2) == pytest.approx(
        math.tan(math.radians(30.0)) / 2
    )


def test_one_default_field_of_view() -> None:
    assert LENS_DEFAULT_FOV_DEG == DEFAULT_FOV_DEG


def _sample(key: str, size: int, meta: dict) -> Sample:
    generator = torch.Generator().manual_seed(0)
    photo = torch.rand(3, size, size, generator=generator)
    maps = torch.zeros(8, size, size)
    maps[5] = 1.0
    return Sample(key, photo, maps, meta)


def test_batches_carry_frames_that_follow_the_train_crop() -> None:
    capture = {"hotspot_px": [40.0, 21.5], "fov_deg": 70.0}
    sample = _sample("a", 64, {"capture": capture})
    whole = collate_samples([sample])["flash"]
    torch.testing.assert_close(whole, torch.tensor([[40.0, 21.5, pixel_scale(70.0, 64)]]))
    crop = random_crop(sample, 32, random.Random(3))
    x0, y0, _ = crop.meta["train_crop"]
    cropped = collate_samples([crop])["flash"]
    torch.testing.assert_close(
        flash_offset_channels(cropped, 32, 32),
        flash_offset_channels(whole, 64, 64)[..., y0 : y0 + 32, x0 : x0 + 32],
    )
    # A sample of an older dataset (no capture record): its centre, the nominal capture's 45°.
    old = random_crop(_sample("b", 64, {}), 32, random.Random(4))
    x0, y0, _ = old.meta["train_crop"]
    assert flash_frames([old.meta], 32, 32)[0].tolist() == pytest.approx(
        [32.0 - x0, 32.0 - y0, pixel_scale(45.0, 64)]
    )
    with pytest.raises(ValueError, match="photo_size"):
        flash_frames([{"train_crop": [0, 0, 32]}], 32, 32)


def test_the_paper_generator_ignores_the_frame() -> None:
    torch.manual_seed(0)
    photo = torch.rand(2, 3, 32, 32)
    elsewhere = centred_flash_frame(2, 32, 32)
    elsewhere[:, :2] = torch.tensor([[0.0, 0.0], [40.0, 5.0]])
    plain = Generator(**TINY).eval()
    with torch.no_grad():
        assert torch.equal(plain(photo), plain(photo, elsewhere))


def test_a_stored_config_with_the_retired_flash_option_loads_only_at_its_built_value(tmp_path: Path) -> None:
    # Generator's flash_geometry (tried, not adopted) is gone; configs stored with it off still load.
    g = Generator(**TINY).eval()
    for value in (False, True):
        target, config = "brdfgan.models.generator.Generator", {**g.config(), "flash_geometry": value}
        path = save_weights(tmp_path / f"g{value}.safetensors", g, target=target, config=config, model_id="f")
        if value:
            with pytest.raises(WeightsError, match="flash_geometry=True is a retired option"):
                load_weights(path)
            continue
        loaded, _ = load_weights(path)
        photo = torch.rand(1, 3, 32, 32)
        with torch.no_grad():
            assert torch.equal(loaded(photo), g(photo))
