"""The guided fast path of `brdfgan predict` (issue 46): `guided_upsample`'s invariants, the anchored
model's composition from its corrections, and the pipeline's choice of path."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
import torch.nn.functional as F

from brdfgan.core.delit import delit_photo, flat_flash_falloff
from brdfgan.core.exposure import luminance
from brdfgan.core.filtering import guided_upsample
from brdfgan.core.flash_geometry import centred_flash_frame
from brdfgan.core.svbrdf import resize_maps, srgb_to_linear
from brdfgan.inference.model.guided import OUTPUT_CHANNELS, MapsAndCorrections, band_detail, carry_up
from brdfgan.inference.model.tiling import TilingConfig, predict_direct
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pipeline import PredictOptions, Predictor
from brdfgan.models.anchored import CORRECTION_CHANNELS, AnchoredUNet, compose_basecolor
from brdfgan.models.generator import Generator


def enlarge(image: torch.Tensor, size: int) -> torch.Tensor:
    return F.interpolate(image, size=(size, size), mode="bilinear", align_corners=False)


# --- guided_upsample -------------------------------------------------------------------------------


def test_a_constant_guide_gives_bilinear_enlargement() -> None:
    source = torch.rand(2, 4, 8, 8, generator=torch.Generator().manual_seed(0))
    out = guided_upsample(source, torch.full((2, 3, 24, 24), 0.3))
    torch.testing.assert_close(out, enlarge(source, 24), atol=1e-6, rtol=0)


def test_equal_sizes_give_the_source_itself() -> None:
    source = torch.rand(1, 5, 16, 16)
    assert guided_upsample(source, torch.rand(1, 1, 16, 16)) is source


def test_a_step_in_the_guide_stays_sharp_where_bilinear_blurs_it() -> None:
    # A vertical step between two pixels of the guide that falls inside a source pixel.
    guide = torch.zeros(1, 1, 32, 32)
    guide[..., 13:] = 1.0
    source = 0.5 * F.interpolate(guide, size=(8, 8), mode="area") + 0.2  # follows the guide linearly
    out = guided_upsample(source, guide, eps=1e-4)
    want = 0.5 * guide + 0.2
    assert (out - want).abs().max() < 1e-3
    assert (enlarge(source, 32) - want).abs().max() > 0.1  # what the guide adds: bilinear blurs it


def test_a_colour_guide_carries_an_edge_its_luminance_does_not_show() -> None:
    # Red | green of equal luminance: the step is in the guide's chroma only.
    red, green = torch.tensor([0.7152, 0.0, 0.0]), torch.tensor([0.0, 0.2126, 0.0])
    guide = torch.where(torch.arange(32).view(1, 1, 1, 32) < 13, red.view(1, 3, 1, 1), green.view(1, 3, 1, 1))
    guide = guide.expand(1, 3, 32, 32).contiguous()
    assert luminance(guide).std() < 1e-6
    source = F.interpolate(guide[:, :1], size=(8, 8), mode="area")  # the red channel, small
    colour = guided_upsample(source, guide, eps=1e-5)
    grey = guided_upsample(source, luminance(guide), eps=1e-5)
    assert (colour - guide[:, :1]).abs().max() < 1e-3
    torch.testing.assert_close(grey, enlarge(source, 32), atol=1e-5, rtol=0)  # no edge to follow


def test_a_guide_without_relation_to_the_source_adds_nothing() -> None:
    # Noise in the guide where the source is flat: zero slopes, so no detail is invented.
    guide = torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(1))
    source = torch.full((1, 2, 8, 8), 0.4)
    torch.testing.assert_close(
        guided_upsample(source, guide), torch.full((1, 2, 32, 32), 0.4), atol=1e-5, rtol=0
    )


@pytest.mark.parametrize(
    ("source", "guide", "kwargs", "message"),
    [
        ((1, 2, 8, 8), (1, 2, 16, 16), {}, "1 or 3 channels"),
        ((2, 2, 8, 8), (1, 3, 16, 16), {}, "batch"),
        ((1, 2, 8, 8), (1, 3, 4, 16), {}, "smaller than the source"),
        ((1, 2, 8, 8), (1, 3, 16, 16), {"eps": 0.0}, "eps > 0"),
        ((1, 2, 8, 8), (1, 3, 16, 16), {"radius": 0}, "radius >= 1"),
        ((2, 8, 8), (1, 3, 16, 16), {}, "source"),
    ],
)
def test_guided_upsample_checks_its_inputs(
    source: tuple[int, ...], guide: tuple[int, ...], kwargs: dict[str, float], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        guided_upsample(torch.rand(source), torch.rand(guide), **kwargs)  # type: ignore[arg-type]


# --- the anchored composition ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def shipped() -> AnchoredUNet:
    generator = load_model().generator
    assert isinstance(generator, AnchoredUNet) and generator.anchored
    return generator


def photo_with_stripes(side: int, period: int) -> torch.Tensor:
    """A flash photo (centred, default field of view) of a brown surface with thin vertical
    stripes of ``period`` pixels and a smooth light patch: ``(1, 3, side, side)``."""
    x = torch.arange(side, dtype=torch.float32)
    stripes = 0.5 + 0.5 * torch.cos(2 * torch.pi * x / period)
    patch = torch.exp(-((x - side / 3) ** 2) / (2 * (side / 8) ** 2))
    albedo = (
        torch.tensor([0.35, 0.22, 0.12]).view(1, 3, 1, 1) * (0.7 + 0.3 * stripes) * (1 + patch.view(-1, 1))
    )
    frame = centred_flash_frame(1, side, side)
    return (albedo * flat_flash_falloff(frame, side, side)).clamp(0, 1)


def test_the_maps_are_composed_from_the_corrections_the_network_returns(shipped: AnchoredUNet) -> None:
    photo = photo_with_stripes(64, 4)
    frame = centred_flash_frame(1, 64, 64)
    with torch.inference_mode():
        maps, corrections = shipped.maps_and_corrections(photo, frame)
        assert corrections is not None and corrections.shape == (1, CORRECTION_CHANNELS, 64, 64)
        torch.testing.assert_close(shipped(photo, frame), maps, atol=0, rtol=0)
        basecolor = compose_basecolor(shipped.anchor(photo, frame), corrections)
    torch.testing.assert_close(srgb_to_linear(maps[:, :3]), basecolor, atol=1e-5, rtol=0)


def test_carrying_up_to_the_same_size_gives_the_network_maps(shipped: AnchoredUNet) -> None:
    photo = photo_with_stripes(64, 4)
    frame = centred_flash_frame(1, 64, 64)
    with torch.inference_mode():
        outputs = MapsAndCorrections(shipped)(photo, frame)
        maps = shipped(photo, frame)
        cap = shipped.hotspot_cap(delit_photo(photo, frame, clip=False))
        carried = carry_up(shipped, outputs, photo, frame)
    torch.testing.assert_close(outputs[:, :8], maps, atol=0, rtol=0)
    assert (outputs[:, -1] == cap[0, 0]).all()  # the anchor's hotspot cap, one channel
    torch.testing.assert_close(carried, maps, atol=1e-5, rtol=0)


# --- the pipeline's paths --------------------------------------------------------------------------


def test_the_fast_path_runs_the_network_at_the_cap_and_keeps_the_photos_detail(shipped: AnchoredUNet) -> None:
    # Stripes of 4 px at 256²: at the network's 128² they are the period-2 frequency, which the
    # anchor's blur removes there, so only the full-resolution photo can bring them back.
    model = load_model()
    photo = photo_with_stripes(256, 4)[0]
    fast = Predictor.create(model, PredictOptions(network_cap=128))
    assert fast.network_side(256) == 128 and fast.network_side(100) == 100
    outputs = fast.network(photo)
    assert outputs.shape == (OUTPUT_CHANNELS, 128, 128)
    maps = fast.upsample(outputs, photo)
    assert maps.shape == (8, 256, 256) and torch.isfinite(maps).all()
    frame = centred_flash_frame(1, 256, 256)
    with torch.inference_mode():
        anchor = shipped.anchor(photo[None], frame)
    kept = band_detail(srgb_to_linear(maps[None, :3]), anchor, 128)
    enlarged = band_detail(srgb_to_linear(resize_maps(outputs[:8].clone(), 256)[None, :3]), anchor, 128)
    assert kept.correlation > 0.95 and 0.8 < kept.energy_ratio < 1.25, kept  # measured 0.998, 1.09
    assert enlarged.energy_ratio < 0.01, enlarged  # measured 8e-5
    # Against the network run at 256² itself (the exact path): close, not the same (measured 0.043,
    # mostly the base colour: a network trained at 256² reads this photo differently at 128²).
    exact = Predictor(model, PredictOptions(network_cap=128), 256).maps(photo)
    assert 0 < (maps - exact).abs().mean() < 0.1


def test_an_explicit_resolution_takes_the_exact_path(tmp_path: Path) -> None:
    from brdfgan.inference.pipeline import predict_photo
    from tests.inference.test_predict import flash_photo

    model = load_model()
    path = flash_photo(tmp_path / "p.png", size=(320, 320), centre=(160, 160))
    exact = Predictor.create(model, PredictOptions(resolution=320, network_cap=128, preview=False))
    assert exact.network_side(320) == 320
    record = json.loads((predict_photo(path, tmp_path / "e", exact).output / "material.json").read_text())
    assert record["inference"]["network_resolution"] == 320 and record["inference"]["upsampling"] is None
    fast = Predictor.create(model, PredictOptions(network_cap=128, preview=False))
    record = json.loads((predict_photo(path, tmp_path / "f", fast).output / "material.json").read_text())
    inference = record["inference"]
    sides = (inference["network_resolution"], inference["output_resolution"], record["resolution"])
    assert sides == (128, 320, 320)
    assert inference["upsampling"]["method"].startswith("guided_upsample")
    photo = torch.rand(3, 320, 320)
    torch.testing.assert_close(
        exact.maps(photo), predict_direct(model.generator, photo[None])[0], atol=0, rtol=0
    )


def test_a_tiled_capped_network_matches_the_untiled_one() -> None:
    model = load_model()
    photo = photo_with_stripes(256, 4)[0]
    direct = Predictor.create(model, PredictOptions(network_cap=192)).maps(photo)
    tiled_options = PredictOptions(network_cap=192, tiling=TilingConfig.for_tile(128))
    tiled = Predictor.create(model, tiled_options)
    assert tiled.tiled(256) and not Predictor.create(model, PredictOptions(network_cap=192)).tiled(256)
    assert (tiled.maps(photo) - direct).abs().mean() < 5e-3


def test_networks_that_are_not_anchored_keep_the_exact_path(tmp_path: Path) -> None:
    from brdfgan.inference.model.weights import Model

    generator = Generator(width=4, residual_blocks=1).eval()
    model = Model(generator, "tiny", "brdfgan.models.generator.Generator", {}, {"resolution": 64}, tmp_path)
    predictor = Predictor.create(model, PredictOptions(network_cap=64))
    assert predictor.network_side(256) == 256
    assert predictor.inference_record(256)["upsampling"] is None
