"""Tiled high-resolution inference: frozen InstanceNorm statistics, blending windows, padding.

The models are tiny and randomly initialised (CPU-cheap); ``TINY`` still has a receptive field of
about 28 px, so a 96 px tile has a real border zone that the blending has to discard.

Measurements behind the tolerances (192×256 photo, ``TINY``, tile 96, margin 24, ramp 16; the
error is ``max`` over the 8 channels of ``|tiled - untiled|``):

- padding influence of a frozen-statistics tile: > 1e-2 up to 20 px, > 1e-3 up to 26 px from the
  tile edge, < 1e-5 beyond 32 px;
- tiled vs untiled, statistics at full resolution: max 1.7e-4, mean 1.0e-6 (blend bands 1.8e-6,
  elsewhere 1.8e-7);
- statistics measured at half resolution (``stats_resolution=128``): mean 5.2e-2 (blend bands
  5.7e-2, elsewhere 4.7e-2): a uniform approximation, not seams;
- every tile with its own statistics (``freeze_statistics=False``): mean 2.3e-1, max 1.2, i.e.
  10⁵ times the frozen error in the blend bands; neighbouring tiles disagree by ~0.1 where they are
  blended, which no window can hide.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.svbrdf import NORMAL, validate_maps
from brdfgan.inference.model.tiling import (
    TILED_BUFFER_CHANNELS,
    TilingConfig,
    TilingError,
    activation_bytes_per_pixel,
    blend_window,
    frozen_instance_norm,
    norm_statistics,
    padded_size,
    predict_direct,
    predict_maps,
    predict_memory,
    predict_tiled,
    reflect_pad,
    stats_photo,
    tile_starts,
)
from brdfgan.models.anchored import AnchoredUNet
from brdfgan.models.deschaintre2018 import Deschaintre2018
from brdfgan.models.generator import Generator

TINY = {"width": 8, "downsamplings": 2, "residual_blocks": 2}  # size multiple 4
HEIGHT, WIDTH = 192, 256
TILED = TilingConfig(tile=96, overlap=64, margin=24, max_direct_pixels=0)  # ramp 16


def make_photo(height: int, width: int, seed: int = 1) -> Tensor:
    """Pink noise (detail at every scale) under a flash-like falloff, in [0, 1]."""
    gen = torch.Generator().manual_seed(seed)
    texture = torch.zeros(1, 3, height, width)
    scale = 2
    while scale <= max(height, width):
        noise = torch.rand(1, 3, max(2, height // scale), max(2, width // scale), generator=gen) - 0.5
        texture += math.sqrt(scale) * F.interpolate(noise, size=(height, width), mode="bicubic")
        scale *= 2
    texture = texture / texture.std() * 0.15 + 0.45
    y, x = torch.meshgrid(torch.linspace(-1, 1, height), torch.linspace(-1, 1, width), indexing="ij")
    return (texture / (1.0 + 1.5 * (x**2 + y**2))).clamp(0.0, 1.0)


def tiny_generator(seed: int = 0, **overrides: int | bool) -> Generator:
    torch.manual_seed(seed)
    return Generator(**{**TINY, **overrides}).eval()


@pytest.fixture(scope="module")
def generator() -> Generator:
    return tiny_generator()


@pytest.fixture(scope="module")
def photo() -> Tensor:
    return make_photo(HEIGHT, WIDTH)


@pytest.fixture(scope="module")
def untiled(generator: Generator, photo: Tensor) -> Tensor:
    return predict_direct(generator, photo)


def pixel_error(a: Tensor, b: Tensor) -> Tensor:
    """``(H, W)``: the largest absolute difference over the 8 channels."""
    return (a - b).abs().amax(dim=(0, 1))


def blend_bands(length: int, config: TilingConfig, multiple: int = 4) -> Tensor:
    """``(length,)`` bool: positions where more than one tile has a non-zero weight (the seams)."""
    tile = min(config.tile, length)
    covered = torch.zeros(length)
    for start in tile_starts(length, tile, config.overlap, multiple):
        window = blend_window(
            tile, config.ramp, config.margin, taper_start=start > 0, taper_end=start + tile < length
        )
        covered[start : start + tile] += window > 0
    return covered > 1


def seam_mask(height: int, width: int, config: TilingConfig) -> Tensor:
    return blend_bands(height, config)[:, None] | blend_bands(width, config)[None, :]


# --- geometry --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("length", "tile", "overlap", "multiple"),
    [(256, 96, 64, 4), (192, 96, 64, 4), (1000, 96, 40, 8), (104, 96, 64, 8), (4096, 1024, 256, 8)],
)
def test_tile_starts_cover_the_length_exactly_with_enough_overlap(
    length: int, tile: int, overlap: int, multiple: int
) -> None:
    starts = tile_starts(length, tile, overlap, multiple)
    assert starts[0] == 0 and starts[-1] == length - tile  # the last tile is flush with the border
    assert all(s % multiple == 0 for s in starts)
    gaps = np.diff(starts)
    assert (gaps > 0).all() and (gaps <= tile - overlap).all()  # neighbours overlap by >= overlap
    assert gaps.max() - gaps.min() <= multiple  # spread evenly
    # As few tiles as the overlap allows: one fewer could not cover the length.
    assert (len(starts) - 2) * (tile - overlap) + tile < length


def test_tile_starts_single_tile_and_bad_arguments() -> None:
    assert tile_starts(96, 96, 64, 4) == [0]
    assert tile_starts(64, 96, 64, 4) == [0]
    with pytest.raises(ValueError, match="multiples"):
        tile_starts(100, 96, 64, 8)
    with pytest.raises(ValueError, match="at least the size multiple"):
        tile_starts(256, 96, 92, 8)


def test_blend_window_is_zero_in_the_margin_symmetric_and_one_in_the_middle() -> None:
    window = blend_window(96, 16, 24, taper_start=True, taper_end=True)
    assert window.shape == (96,) and window.dtype == torch.float32
    assert (window[:24] == 0).all() and (window[-24:] == 0).all()
    assert (window[40:56] == 1).all()
    assert torch.equal(window, window.flip(0))
    ramp = window[24:40]
    assert (ramp > 0).all() and (ramp < 1).all() and (ramp.diff() > 0).all()
    # An image border has no neighbour: no taper there.
    one_sided = blend_window(96, 16, 24, taper_start=False, taper_end=True)
    assert (one_sided[:56] == 1).all() and (one_sided[-24:] == 0).all()
    assert (blend_window(96, 16, 24, taper_start=False, taper_end=False) == 1).all()
    hard = blend_window(32, 0, 8, taper_start=True, taper_end=False)
    assert (hard[:8] == 0).all() and (hard[8:] == 1).all()


@pytest.mark.parametrize(("margin", "ramp"), [(24, 16), (8, 32), (0, 20), (96, 64)])
def test_neighbouring_windows_are_a_partition_of_unity_across_an_exact_overlap(
    margin: int, ramp: int
) -> None:
    tile, overlap = 2 * (2 * margin + ramp) + 8, 2 * margin + ramp
    first = blend_window(tile, ramp, margin, taper_start=False, taper_end=True)
    second = blend_window(tile, ramp, margin, taper_start=True, taper_end=False)
    total = torch.zeros(2 * tile - overlap)
    total[:tile] += first
    total[tile - overlap :] += second
    torch.testing.assert_close(total, torch.ones_like(total), atol=1e-6, rtol=0)


@pytest.mark.parametrize("length", [96, 100 // 4 * 4, 256, 1000, 1004])
def test_windows_of_all_tiles_sum_to_at_least_one(length: int) -> None:
    # Starts spread over the length make most overlaps larger than 2 * margin + ramp: the sum then
    # exceeds 1 inside (normalised away) but never drops below 1.
    config = TilingConfig(tile=96, overlap=64, margin=24)
    bands = blend_bands(length, config)
    tile = min(96, length)
    total = torch.zeros(length)
    for start in tile_starts(length, tile, config.overlap, 4):
        total[start : start + tile] += blend_window(
            tile, config.ramp, config.margin, taper_start=start > 0, taper_end=start + tile < length
        )
    assert total.min() >= 1 - 1e-6 and total.max() <= 2
    assert bands.any() == (length > tile)


def test_config_validation() -> None:
    assert TilingConfig().ramp == 64
    with pytest.raises(ValueError, match="2 \\* margin <= overlap < tile"):
        TilingConfig(tile=96, overlap=96, margin=16)
    with pytest.raises(ValueError, match="2 \\* margin <= overlap"):
        TilingConfig(tile=96, overlap=40, margin=24)
    with pytest.raises(ValueError, match="stats_resolution"):
        TilingConfig(stats_resolution=0)


# --- padding ---------------------------------------------------------------------------------------


def test_reflect_pad_repeats_reflection_like_numpy() -> None:
    image = torch.arange(12.0).view(1, 1, 3, 4)
    padded = reflect_pad(image, 16, 17)
    expected = np.pad(image[0, 0].numpy(), ((0, 13), (0, 13)), mode="reflect")
    assert np.array_equal(padded[0, 0].numpy(), expected)
    assert torch.equal(padded[..., :3, :4], image)


def test_padded_size_follows_the_model() -> None:
    generator = tiny_generator(downsamplings=3)
    assert padded_size(generator, 101, 150) == (104, 152)
    assert padded_size(generator, 10, 40) == (16, 40)  # the Generator needs >= 2 × its multiple
    baseline = Deschaintre2018(width=4, levels=4)
    assert padded_size(baseline, 10, 40) == (16, 48)  # its bottleneck only needs 1 × 1


@pytest.mark.parametrize("tiled", [False, True])
def test_odd_sizes_are_padded_and_cropped_back(generator: Generator, tiled: bool) -> None:
    photo = make_photo(101, 150, seed=3)
    config = TILED if tiled else TilingConfig()
    maps = predict_maps(generator, photo, config)  # 101 × 150 > TILED.max_direct_pixels = 0
    assert maps.shape == (1, 8, 101, 150)
    validate_maps(maps)
    with torch.no_grad():
        expected = generator(reflect_pad(photo, 104, 152))[..., :101, :150]
    if tiled:
        # 104 × 152 padded photo in 2 × 3 tiles, the padding tiled like the rest: measured max 5.5e-5.
        assert pixel_error(maps, expected).max() < 1e-3
    else:
        torch.testing.assert_close(maps, expected, atol=1e-6, rtol=0)


# --- statistics ------------------------------------------------------------------------------------


def test_norm_statistics_record_every_instance_norm_input(generator: Generator, photo: Tensor) -> None:
    stats = norm_statistics(generator, photo)
    norms = [name for name, m in generator.named_modules() if isinstance(m, nn.InstanceNorm2d)]
    assert sorted(stats) == sorted(norms) and all(len(entries) == 1 for entries in stats.values())
    first = generator.down[1]  # after the 7×7 conv of the encoded photo
    with torch.no_grad():
        features = generator.down[0](photo * 2 - 1)
    mean, var = stats[norms[0]][0]
    assert generator.get_submodule(norms[0]) is first
    torch.testing.assert_close(mean, features.mean(dim=(0, 2, 3)))
    torch.testing.assert_close(var, features.var(dim=(0, 2, 3), unbiased=False))
    assert not any(m._forward_pre_hooks for m in generator.modules())  # hooks removed


def test_frozen_statistics_reproduce_the_forward_and_are_restored(
    generator: Generator, photo: Tensor
) -> None:
    other = make_photo(HEIGHT, WIDTH, seed=7)
    stats = norm_statistics(generator, photo)
    with torch.no_grad():
        plain, plain_other = generator(photo), generator(other)
        with frozen_instance_norm(generator, stats):
            frozen = generator(photo)
            frozen_other = generator(other)  # normalised with the first photo's statistics
        after = generator(other)
        # Restored also when the forward inside fails.
        with pytest.raises(RuntimeError, match="inside"), frozen_instance_norm(generator, stats):
            raise RuntimeError("inside")
        after_error = generator(other)
    torch.testing.assert_close(frozen, plain, atol=1e-5, rtol=0)
    assert (frozen_other - plain_other).abs().max() > 1e-2
    assert torch.equal(after, plain_other) and torch.equal(after_error, plain_other)
    assert not any("forward" in m.__dict__ for m in generator.modules())


def test_frozen_statistics_apply_the_affine_of_the_baseline() -> None:
    torch.manual_seed(0)
    baseline = Deschaintre2018(width=4, levels=4).eval()
    with torch.no_grad():
        for module in baseline.modules():
            if isinstance(module, nn.InstanceNorm2d):
                module.weight.uniform_(0.5, 2.0)
                module.bias.uniform_(-1.0, 1.0)
    photo = make_photo(64, 96)
    stats = norm_statistics(baseline, photo)
    assert stats and all(name.startswith("norms.") for name in stats)
    with torch.no_grad(), frozen_instance_norm(baseline, stats):
        frozen = baseline(photo)
    torch.testing.assert_close(frozen, baseline(photo).detach(), atol=1e-5, rtol=0)


def test_padding_influence_is_local(generator: Generator, photo: Tensor, untiled: Tensor) -> None:
    """The method behind the margins: a frozen-statistics tile against the untiled output."""
    y, x, size = 48, 64, 96
    with torch.no_grad(), frozen_instance_norm(generator, norm_statistics(generator, photo)):
        tile = generator(photo[..., y : y + size, x : x + size])
    error = pixel_error(tile, untiled[..., y : y + size, x : x + size])
    edge = torch.minimum(torch.arange(size), torch.arange(size).flip(0))
    distance = torch.minimum(edge[:, None], edge[None, :])  # to the nearest tile edge
    assert error[distance < 4].max() > 0.1  # the tile's own padding corrupts its border ...
    assert error[distance >= 26].max() < 1e-3  # ... up to ~26 px for this receptive field
    assert error[distance >= 32].max() < 1e-5


# --- tiled prediction ------------------------------------------------------------------------------


def test_tiled_matches_untiled(generator: Generator, photo: Tensor, untiled: Tensor) -> None:
    tiled = predict_tiled(generator, photo, TILED)
    assert tiled.shape == untiled.shape
    validate_maps(tiled)
    torch.testing.assert_close(tiled[:, NORMAL].norm(dim=1), torch.ones(1, HEIGHT, WIDTH))
    error = pixel_error(tiled, untiled)
    assert error.max() < 1e-3  # measured 1.7e-4
    assert error.mean() < 1e-5  # measured 1.0e-6


@pytest.mark.parametrize("frame", [None, torch.tensor([[40.0, 150.0, 0.006]])])
def test_flash_aware_tiles_see_the_whole_photo_geometry(photo: Tensor, frame: Tensor | None) -> None:
    """Each tile gets the whole photo's flash frame moved to its corner, so tiled and untiled agree
    as for a plain generator; the default frame is the whole photo's centre, not each tile's."""
    torch.manual_seed(0)
    aware = AnchoredUNet(width=4, depth=2).eval()  # reads the flash frame (its anchor, its side channels)
    untiled = predict_direct(aware, photo, frame)
    tiled = predict_tiled(aware, photo, TILED, flash=frame)
    error = pixel_error(tiled, untiled)
    assert error.max() < 1e-3
    assert error.mean() < 1e-5
    with torch.no_grad():  # the geometry matters: another frame gives other maps
        elsewhere = predict_direct(aware, photo, torch.tensor([[0.0, 0.0, 0.02]]))
    assert pixel_error(elsewhere, untiled).mean() > 1e-3


def test_seams_are_no_worse_than_the_interior(generator: Generator, photo: Tensor, untiled: Tensor) -> None:
    seams = seam_mask(HEIGHT, WIDTH, TILED)
    assert 0.3 < seams.float().mean() < 0.7  # both regions are large and interleaved
    # Statistics at full resolution: only padding effects remain, all but removed by the margins.
    exact = pixel_error(predict_tiled(generator, photo, TILED), untiled)
    assert exact[seams].mean() <= 1.5 * exact[~seams].mean() + 1e-5  # measured 1.8e-6 vs 1.8e-7
    # Statistics at half resolution: a global approximation, spread evenly, not concentrated at seams.
    approx = pixel_error(
        predict_tiled(generator, photo, dataclasses.replace(TILED, stats_resolution=128)), untiled
    )
    assert approx.mean() > 100 * exact.mean()  # the statistics, not the tiling, dominate
    assert approx[seams].mean() <= 1.5 * approx[~seams].mean()  # measured 5.7e-2 vs 4.7e-2


def test_per_tile_statistics_give_much_larger_errors(
    generator: Generator, photo: Tensor, untiled: Tensor
) -> None:
    seams = seam_mask(HEIGHT, WIDTH, TILED)
    frozen = pixel_error(predict_tiled(generator, photo, TILED), untiled)
    independent = pixel_error(
        predict_tiled(generator, photo, dataclasses.replace(TILED, freeze_statistics=False)), untiled
    )
    # Measured: 2.3e-1 vs 1.8e-6 in the blend bands; every tile is normalised differently.
    assert independent[seams].mean() > 1e-2
    assert independent[seams].mean() > 1000 * frozen[seams].mean()


@pytest.mark.parametrize(("freeze", "bound"), [(True, 1e-3), (False, None)])
def test_neighbouring_tiles_agree_only_with_frozen_statistics(
    generator: Generator, photo: Tensor, freeze: bool, bound: float | None
) -> None:
    """Two horizontal neighbours compared where they are blended: a seam no window can hide."""
    tile, margin, ramp = TILED.tile, TILED.margin, TILED.ramp
    left_x, right_x = 0, tile - TILED.overlap
    stats = norm_statistics(generator, photo) if freeze else {}
    with torch.no_grad(), frozen_instance_norm(generator, stats):
        left = generator(photo[..., :tile, left_x : left_x + tile])
        right = generator(photo[..., :tile, right_x : right_x + tile])
    # The ramp: columns [right_x + margin, right_x + margin + ramp) of the photo.
    band = slice(right_x + margin, right_x + margin + ramp)
    disagreement = pixel_error(left[..., band], right[..., band.start - right_x : band.stop - right_x])
    if bound is not None:
        assert disagreement.max() < bound
    else:
        assert disagreement.mean() > 5e-2


def test_tiles_never_exceed_the_tile_size_and_statistics_run_at_stats_resolution(
    generator: Generator, photo: Tensor
) -> None:
    shapes: list[tuple[int, ...]] = []
    handle = generator.register_forward_pre_hook(lambda _m, args: shapes.append(tuple(args[0].shape)))
    calls: list[tuple[int, int]] = []
    try:
        config = dataclasses.replace(TILED, stats_resolution=128)
        predict_maps(generator, photo, config, progress=lambda done, total: calls.append((done, total)))
    finally:
        handle.remove()
    tiles = len(tile_starts(HEIGHT, 96, 64, 4)) * len(tile_starts(WIDTH, 96, 64, 4))
    assert len(shapes) == 1 + tiles and tiles == 4 * 6
    assert shapes[0] == (1, 3, 96, 128)  # the statistics pass: longer side = stats_resolution
    assert all(shape == (1, 3, 96, 96) for shape in shapes[1:])
    assert calls == [(k, tiles) for k in range(1, tiles + 1)]


def test_statistics_pass_runs_at_the_photo_size_when_it_is_small_enough(generator: Generator) -> None:
    padded = make_photo(104, 152)
    assert stats_photo(generator, padded, 152) is padded
    small = stats_photo(generator, padded, 64)
    assert small.shape == (1, 3, 44, 64)  # 104 × 152 scaled to 43.8 × 64, padded to the multiple 4


def test_predict_maps_runs_small_photos_directly_and_restores_the_mode(
    generator: Generator, photo: Tensor, untiled: Tensor
) -> None:
    shapes: list[tuple[int, ...]] = []
    handle = generator.register_forward_pre_hook(lambda _m, args: shapes.append(tuple(args[0].shape)))
    generator.train()
    try:
        calls: list[tuple[int, int]] = []
        maps = predict_maps(
            generator,
            photo,
            TilingConfig(max_direct_pixels=HEIGHT * WIDTH),
            progress=lambda *a: calls.append(a),
        )
        assert generator.training  # the caller's mode is back ...
    finally:
        generator.eval()
        handle.remove()
    assert shapes == [(1, 3, HEIGHT, WIDTH)] and calls == [(1, 1)]
    assert torch.equal(maps, untiled)  # ... and the pass ran in eval mode
    assert not maps.requires_grad


def test_bad_inputs_are_refused(generator: Generator, photo: Tensor) -> None:
    # --tile is the user's choice: a UserError, reported as one line per photo.
    with pytest.raises(TilingError, match="multiple of the model's size multiple 4"):
        predict_tiled(generator, photo, TilingConfig(tile=98, overlap=32, margin=8))
    with pytest.raises(ValueError, match=r"\(1, 3, H, W\)"):
        predict_maps(generator, photo.expand(2, -1, -1, -1))
    with pytest.raises(ValueError, match=r"\(1, 3, H, W\)"):
        predict_maps(generator, photo[:, :1])


def test_baseline_with_global_track_runs_tiled() -> None:
    # Its global track sees each tile's own feature means (a documented limitation); the instance
    # norms are frozen, and the result is a valid map set of the photo's size.
    torch.manual_seed(0)
    baseline = Deschaintre2018(width=4, levels=4)
    photo = make_photo(100, 150)
    config = TilingConfig(tile=64, overlap=32, margin=8, max_direct_pixels=0)
    maps = predict_maps(baseline, photo, config)
    assert maps.shape == (1, 8, 100, 150)
    validate_maps(maps)
    # Measured mean |tiled - untiled| 1.5e-2 (2.6e-2 with per-tile instance norms too): the global
    # track's per-tile means differ from the whole photo's, so unlike the Generator it is not exact.
    direct = predict_maps(baseline, photo)
    assert pixel_error(maps, direct).mean() < 5e-2


def test_memory_estimate_follows_the_widest_layer_and_tiles_bound_the_network() -> None:
    # Width 16: the first InstanceNorm reads and writes 16 float32 channels at full resolution,
    # 128 B/px, doubled for what stays alive beside it; twice the width, twice the bytes.
    narrow, wide = Generator(width=16, residual_blocks=1), Generator(width=32, residual_blocks=1)
    assert activation_bytes_per_pixel(narrow) == 256.0
    assert activation_bytes_per_pixel(wide) == 512.0
    config = TilingConfig()  # photos above 1024² run as 1024² tiles
    direct = predict_memory(narrow, 1024, 1024, config, 256.0)
    assert direct == 256 * 1024 * 1024
    tiled = [predict_memory(narrow, side, side, config, 256.0) for side in (2048, 4096)]
    # Tiled, the network costs one tile whatever the size; only the full-size buffers grow.
    assert tiled[1] - tiled[0] == TILED_BUFFER_CHANNELS * 4 * (4096**2 - 2048**2)
    assert tiled[0] - TILED_BUFFER_CHANNELS * 4 * 2048**2 == direct


def test_tile_option_policy_keeps_the_config_valid_and_tiles_above_one_tile() -> None:
    assert TilingConfig.for_tile(None) == TilingConfig()
    small = TilingConfig.for_tile(128)  # overlap and margin shrink with the tile
    assert (small.tile, small.overlap, small.margin, small.max_direct_pixels) == (128, 64, 24, 128 * 128)
    assert not small.runs_tiled(128, 128) and small.runs_tiled(129, 128)
    assert TilingConfig.for_tile(1).overlap == 0  # the smallest tile is still a valid config
    assert small.to_json(True) == {"tiled": True, "tile": 128, "overlap": 64}
    assert small.to_json(False) == {"tiled": False, "tile": None, "overlap": None}


def test_image_statistics_are_frozen_in_tiles_like_the_norms() -> None:
    # The anchored network reads per-image values (ImageStatistic: the de-lit anchor's hotspot cap,
    # the global track's feature moments and highlight profile): tiling records them in the
    # statistics pass and every tile replays the whole photo's, so tiled inference reproduces the
    # untiled network.

    torch.manual_seed(0)
    # depth 2: a small field; the highlight profile reads the photo and its flash frame.
    model = AnchoredUNet(width=4, depth=2)  # the shipped options: global track, highlight profile
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    photo = make_photo(256, 320)
    config = TilingConfig(tile=128, overlap=64, margin=24, max_direct_pixels=0)
    direct, tiled = predict_maps(model, photo), predict_maps(model, photo, config)
    error = pixel_error(tiled, direct)
    assert error.max() < 2e-3 and error.mean() < 1e-5  # measured 3.1e-4, 9.5e-7
    # The global track matters to the output: without its moments the maps are far away.
    assert model.global_track is not None
    with torch.no_grad():
        model.global_track[-1].weight.zero_()
        model.global_track[-1].bias.zero_()
    assert pixel_error(predict_maps(model, photo), direct).mean() > 100 * error.mean()


def test_image_moments_golden_values() -> None:
    from brdfgan.models.image_statistics import MOMENTS_EPS, ImageMoments

    x = torch.tensor([[1.0, 3.0], [1.0, 3.0]]).view(1, 1, 2, 2).expand(2, 2, 2, 2)
    moments = ImageMoments()(x)
    expected = torch.tensor([2.0, 2.0, 0.5 * math.log(1.0 + MOMENTS_EPS), 0.5 * math.log(1.0 + MOMENTS_EPS)])
    torch.testing.assert_close(moments, expected.expand(2, 4))
