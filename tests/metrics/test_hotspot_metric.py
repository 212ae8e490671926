"""Hotspot error ratio: the disk and its position convention, golden ratios, statistics of an
even error, batch-split exactness, NaN cases, the collection's keyword routing and the evaluator's
table."""

from __future__ import annotations

import json
import math
import random
from functools import partial
from pathlib import Path
from typing import Any

import pytest
import torch
from torch import Tensor, nn

from brdfgan.config_check import ConfigValueError
from brdfgan.core.flash_geometry import hotspot_disk
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, NORMAL, ROUGHNESS, flat_maps
from brdfgan.data.loading.datamodule import random_crop
from brdfgan.data.storage.shards import Sample
from brdfgan.errors import UserError
from brdfgan.evaluation.evaluator import evaluate_models, markdown_table, write_results
from brdfgan.metrics import (
    HOTSPOT_RADIUS_FRACTION,
    RMSE_MAPS,
    HotspotError,
    SVBRDFMetrics,
    compared_maps,
    hotspot_centres,
)
from tests.conftest import random_maps

STORED_MAPS = ("basecolor", "roughness", "metallic")


def mid_maps(height: int, width: int, batch: int = 1) -> Tensor:
    """Flat maps with every stored value at 0.5 (room for ± errors), normal straight up."""
    return flat_maps(
        height,
        width,
        basecolor=(0.5, 0.5, 0.5),
        roughness=0.5,
        metallic=0.5,
        batch=(batch,),
        dtype=torch.float64,
    )


def disk_by_loops(height: int, width: int, x: float, y: float, radius: float) -> Tensor:
    """The disk written out pixel by pixel (pixel (i, j) has its centre at (j + ½, i + ½))."""
    mask = torch.zeros(height, width, dtype=torch.bool)
    for i in range(height):
        for j in range(width):
            mask[i, j] = (j + 0.5 - x) ** 2 + (i + 0.5 - y) ** 2 <= radius**2
    return mask


def sign_pattern_prediction(
    true: Tensor,
    inside: Tensor,
    error_in: float,
    error_out: float,
    tilt_in: float,
    tilt_out: float,
    seed: int,
) -> Tensor:
    """``true`` plus errors of constant magnitude and random sign: ``error_in`` on the stored maps
    inside the disk, ``error_out`` outside; normals tilted by ``tilt_in`` / ``tilt_out`` radians
    in random directions. Every squared error of a part is then the same number, so the ratio is
    exact.

    Shape: true ``(B, 8, H, W)``, inside ``(B, H, W)`` or ``(H, W)``
    """
    g = torch.Generator().manual_seed(seed)
    inside = inside.expand(true.shape[0], *true.shape[-2:]).unsqueeze(1)
    signs = torch.randint(0, 2, true.shape, generator=g).to(true.dtype) * 2.0 - 1.0

    def part(value_in: float, value_out: float) -> Tensor:
        return torch.where(
            inside, torch.tensor(value_in, dtype=true.dtype), torch.tensor(value_out, dtype=true.dtype)
        )

    magnitude = part(error_in, error_out)
    pred = true + signs * magnitude
    tilt = part(tilt_in, tilt_out)[:, 0]
    azimuth = torch.rand(tilt.shape, generator=g, dtype=true.dtype) * 2.0 * math.pi
    pred[:, 3] = torch.sin(tilt) * torch.cos(azimuth)
    pred[:, 4] = torch.sin(tilt) * torch.sin(azimuth)
    pred[:, 5] = torch.cos(tilt)
    return pred


def normal_ratio(tilt_in: float, tilt_out: float) -> float:
    """|p − t|² = 2 − 2 cos θ for unit normals θ apart."""
    return math.sqrt((1.0 - math.cos(tilt_in)) / (1.0 - math.cos(tilt_out)))


# ---------------------------------------------------------------- positions and the disk


def test_hotspot_centres_follow_the_metadata_convention() -> None:
    meta: list[dict[str, Any]] = [
        {},  # an older dataset: the image centre
        {"capture": {"hotspot_px": [10.5, 20]}},
        {"capture": {"exposure": 1.0}},  # a capture record without the position: the centre
        {"capture": {"hotspot_px": [40, 30]}, "train_crop": [8, 4, 32]},  # shifted by (−8, −4)
    ]
    centres = hotspot_centres(meta, height=48, width=64)
    expected = torch.tensor([[32.0, 24.0], [10.5, 20.0], [32.0, 24.0], [32.0, 26.0]], dtype=torch.float64)
    assert torch.equal(centres, expected)
    assert hotspot_centres([], 8, 8).shape == (0, 2)
    with pytest.raises(ValueError, match="train crop without"):
        hotspot_centres([{"train_crop": [0, 0, 16]}], 16, 16)
    with pytest.raises(ValueError, match=r"sample 1: meta\['capture'\]\['hotspot_px'\] must be \[x, y\]"):
        hotspot_centres([{}, {"capture": {"hotspot_px": [1.0]}}], 16, 16)
    with pytest.raises(ValueError, match="two finite numbers"):
        hotspot_centres([{"capture": {"hotspot_px": [1.0, float("nan")]}}], 16, 16)


def test_disk_pixels_by_hand() -> None:
    # 16² with the hotspot at the centre (8, 8) and radius 0.125·16 = 2 px: the pixel centres
    # (7.5 ± k, 7.5 ± l) at squared distance 0.5 (4 pixels) and 2.5 (8 pixels) are inside;
    # the next ones, at 4.5 and 6.5, are not.
    disk = hotspot_disk(torch.tensor([[8.0, 8.0]]), 16, 16, radius=2.0)[0]
    rows, cols = torch.nonzero(disk, as_tuple=True)
    assert sorted(zip(rows.tolist(), cols.tolist(), strict=True)) == sorted(
        [(r, c) for r in (7, 8) for c in (6, 7, 8, 9)] + [(r, c) for r in (6, 9) for c in (7, 8)]
    )
    # A hotspot on the corner between pixels (4, 2), (4, 3), (5, 2), (5, 3): x = 3 is the
    # column index boundary, y = 5 the row boundary.
    corner = hotspot_disk(torch.tensor([[3.0, 5.0]]), 10, 12, radius=1.0)[0]
    assert torch.nonzero(corner).tolist() == [[4, 2], [4, 3], [5, 2], [5, 3]]
    assert torch.equal(
        hotspot_disk(torch.tensor([[20.5, 44.0]]), 64, 64, 8.0)[0], disk_by_loops(64, 64, 20.5, 44.0, 8.0)
    )


# ---------------------------------------------------------------- golden ratios


@pytest.mark.parametrize(
    ("error_in", "error_out", "tilt_in", "tilt_out"),
    [
        (0.2, 0.05, 0.3, 0.1),  # the highlight leaks into the maps: > 1
        (0.05, 0.2, 0.1, 0.4),  # worse away from it: < 1
        (0.0, 0.1, 0.0, 0.2),  # exact inside: 0
    ],
)
def test_error_placed_in_the_disk_gives_the_golden_ratio(
    error_in: float, error_out: float, tilt_in: float, tilt_out: float
) -> None:
    size = 64
    true = mid_maps(size, size, batch=2)
    inside = disk_by_loops(size, size, size / 2, size / 2, HOTSPOT_RADIUS_FRACTION * size)
    pred = sign_pattern_prediction(true, inside, error_in, error_out, tilt_in, tilt_out, seed=3)
    metric = HotspotError(rmse=True)
    metric.update(pred, true)  # hotspot None: the image centre
    out = metric.compute()
    for name in STORED_MAPS:
        assert out[name].item() == pytest.approx(error_in / error_out, rel=1e-9), name
        assert out[f"{name}/outside"].item() == pytest.approx(error_out, rel=1e-9), name
    assert out["normal"].item() == pytest.approx(normal_ratio(tilt_in, tilt_out), rel=1e-9)
    # The derived albedos mix base colour and metallic errors non-linearly: direction only.
    for name in ("diffuse", "specular"):
        value = out[name].item()
        assert value > 1.5 if error_in > error_out else (value < 0.7 if error_in > 0 else value == 0.0), name
    assert int(metric.pixels_in) == 2 * int(inside.sum())
    assert int(metric.pixels_in + metric.pixels_out) == 2 * size * size


def test_uniform_noise_gives_a_ratio_of_one_within_the_sampling_error() -> None:
    # Noise U(−a, a) on every channel, i.i.d. over pixels: the expected ratio is 1. Per pixel let
    # q = Σ_channels e²; MSE_in is the mean of q over N_in pixels, so with v = Var(q) / E[q]²
    # its relative standard deviation is sqrt(v / N_in), and by the delta method the ratio
    # sqrt(MSE_in / MSE_out) has standard deviation ½ sqrt(v (1/N_in + 1/N_out)). The test
    # allows 4 of those (v measured on the sample itself, so it also covers the renormalised
    # normals and the derived albedos).
    size, batch, a = 64, 4, 0.1
    true = mid_maps(size, size, batch=batch)
    g = torch.Generator().manual_seed(11)
    pred = true + (torch.rand(true.shape, generator=g, dtype=torch.float64) * 2.0 - 1.0) * a
    metric = HotspotError()
    metric.update(pred, true)
    out = metric.compute()
    n_in, n_out = int(metric.pixels_in), int(metric.pixels_out)
    assert n_in == batch * int(disk_by_loops(size, size, 32.0, 32.0, 8.0).sum())
    pred_images, true_images = compared_maps(pred), compared_maps(true)
    for name in RMSE_MAPS:
        q = (pred_images[name] - true_images[name]).square().sum(dim=1).flatten()
        v = (q.var() / q.mean().square()).item()
        if name == "basecolor":  # three uniform components: Var(q)/E[q]² = 3·(4a⁴/45) / a⁴
            assert v == pytest.approx(12 / 45, rel=0.05)
        tolerance = 4.0 * 0.5 * math.sqrt(v * (1.0 / n_in + 1.0 / n_out))
        assert tolerance < 0.1  # the test can tell a leak of 10 % from none
        assert out[name].item() == pytest.approx(1.0, abs=tolerance), name


def test_the_disk_follows_hotspot_px() -> None:
    size, hotspot = 64, (16.5, 44.0)
    true = mid_maps(size, size)
    inside = disk_by_loops(size, size, *hotspot, HOTSPOT_RADIUS_FRACTION * size)
    pred = sign_pattern_prediction(true, inside, 0.2, 0.05, 0.3, 0.1, seed=5)
    pointed = HotspotError()
    pointed.update(
        pred, true, hotspot=hotspot_centres([{"capture": {"hotspot_px": list(hotspot)}}], size, size)
    )
    assert pointed.compute()["basecolor"].item() == pytest.approx(4.0, rel=1e-9)
    # Metadata without the position: the centre disk (22.6 px away, disjoint) sees only the
    # small error, and the large one counts outside.
    unpointed = HotspotError()
    unpointed.update(pred, true, hotspot=hotspot_centres([{}], size, size))
    assert unpointed.compute()["basecolor"].item() < 1.0
    default = HotspotError()
    default.update(pred, true)
    assert torch.equal(default.compute()["basecolor"], unpointed.compute()["basecolor"])


def test_train_crop_shift_through_random_crop() -> None:
    # The error sits around the hotspot of the stored 64² sample; the datamodule's random_crop
    # cuts 40² windows and records them; the centres of the cropped metadata find the disk again.
    stored, crop, hotspot = 64, 40, (40.0, 30.0)
    radius = HOTSPOT_RADIUS_FRACTION * crop  # the metric's radius on the crop: 5 px
    true = mid_maps(stored, stored)
    pred = sign_pattern_prediction(
        true, disk_by_loops(stored, stored, *hotspot, radius), 0.2, 0.05, 0.3, 0.1, 7
    )
    sample = Sample(
        "s", torch.full((3, stored, stored), 0.5), true[0].float(), {"capture": {"hotspot_px": list(hotspot)}}
    )
    checked = 0
    for seed in range(8):
        cropped = random_crop(sample, crop, random.Random(seed))
        x0, y0, _ = cropped.meta["train_crop"]
        if not (
            x0 + radius <= hotspot[0] <= x0 + crop - radius
            and y0 + radius <= hotspot[1] <= y0 + crop - radius
        ):
            continue  # the disk is cut by the window's edge
        window = (..., slice(y0, y0 + crop), slice(x0, x0 + crop))
        metric = HotspotError()
        metric.update(pred[window], cropped.maps[None].double(), hotspot_centres([cropped.meta], crop, crop))
        assert metric.compute()["basecolor"].item() == pytest.approx(4.0, rel=1e-9), seed
        checked += 1
    assert checked >= 3


# ---------------------------------------------------------------- accumulation and edge cases


def test_sums_are_exact_whatever_the_batch_split() -> None:
    pred, true = random_maps(24, 32, seed=1, batch=(5,)), random_maps(24, 32, seed=2, batch=(5,))
    centres = torch.tensor([[16.0, 12.0], [3.5, 20.0], [30.0, 2.0], [-4.0, 12.0], [16.0, 30.0]])
    whole, split = HotspotError(rmse=True), HotspotError(rmse=True)
    whole.update(pred, true, centres)
    split.update(pred[:1], true[:1], centres[:1])
    split.update(pred[1:], true[1:], centres[1:])
    assert int(split.pixels_in) == int(whole.pixels_in) and int(split.pixels_out) == int(whole.pixels_out)
    for name in whole._reductions:
        torch.testing.assert_close(getattr(split, name), getattr(whole, name), rtol=1e-12, atol=0.0)
    for key, value in whole.compute().items():
        torch.testing.assert_close(split.compute()[key], value, rtol=1e-12, atol=0.0)
    # Averaging per-batch ratios instead would differ.
    first = HotspotError()
    first.update(pred[:1], true[:1], centres[:1])
    assert not torch.isclose(first.compute()["roughness"], whole.compute()["roughness"])


def test_nan_when_the_outside_error_is_zero_or_a_part_is_empty() -> None:
    size = 32
    true = mid_maps(size, size)
    inside = disk_by_loops(size, size, 16.0, 16.0, 4.0)
    metric = HotspotError(rmse=True)
    with pytest.warns(UserWarning, match="before the ``update``"):
        assert all(math.isnan(v.item()) for v in metric.compute().values())  # nothing accumulated
    metric.update(true, true)
    assert all(math.isnan(metric.compute()[name].item()) for name in RMSE_MAPS)
    only_inside = sign_pattern_prediction(true, inside, 0.1, 0.0, 0.2, 0.0, seed=1)
    metric.reset()
    metric.update(only_inside, true)
    out = metric.compute()
    assert out["roughness/inside"].item() == pytest.approx(0.1) and out["roughness/outside"].item() == 0.0
    assert all(math.isnan(out[name].item()) for name in RMSE_MAPS)  # NaN, not inf
    far = HotspotError()  # a crop that missed the highlight: nothing inside
    far.update(
        random_maps(8, 8, seed=1, batch=(1,)),
        random_maps(8, 8, seed=2, batch=(1,)),
        torch.tensor([[100.0, 100.0]]),
    )
    assert int(far.pixels_in) == 0 and all(math.isnan(v.item()) for v in far.compute().values())


def test_bad_arguments() -> None:
    for bad in (0.0, -0.1, 0.6, True, "0.1"):
        with pytest.raises(
            ConfigValueError, match=r"^metrics\.hotspot_radius_fraction=.*: must be in \(0, 0\.5\]$"
        ):
            SVBRDFMetrics(hotspot=True, hotspot_radius_fraction=bad)  # type: ignore[arg-type]
    assert issubclass(ConfigValueError, UserError)
    metric = HotspotError()
    maps = random_maps(8, 8, seed=1, batch=(2,))
    with pytest.raises(ValueError, match=r"hotspot must have shape \(2, 2\)"):
        metric.update(maps, maps, torch.zeros(1, 2))
    metric.update(maps[0], maps[0], torch.tensor([4.0, 4.0]))  # unbatched maps, one position
    assert int(metric.pixels_in + metric.pixels_out) == 64


def test_the_collection_routes_hotspot_to_the_hotspot_metric_only() -> None:
    # MetricCollection passes a keyword only to children whose update() names it
    # (Metric._filter_kwargs): MapRMSE & co. never see `hotspot`.
    pred, true = random_maps(16, 16, seed=3, batch=(2,)), random_maps(16, 16, seed=4, batch=(2,))
    centres = torch.tensor([[2.0, 3.0], [12.0, 9.5]])
    collection = SVBRDFMetrics(
        downscale_to=None, rerender_configs=2, hotspot=True, hotspot_rmse=True, prefix="val/"
    )
    collection.update(pred, true, hotspot=centres)
    alone = HotspotError(rmse=True)
    alone.update(pred, true, centres)
    out = collection.compute()
    for key, value in alone.compute().items():
        assert torch.equal(out[f"val/hotspot/{key}"], value), key
    assert len([k for k in out if k.startswith("val/hotspot/")]) == 3 * len(RMSE_MAPS)
    without = SVBRDFMetrics(downscale_to=None, rerender_configs=2)
    without.update(pred, true, hotspot=centres)  # accepted and unused
    assert not any("hotspot" in key for key in without.compute())


# ---------------------------------------------------------------- evaluator


class OffsetModel(nn.Module):
    """Predicts the maps of :func:`mid_maps` plus the error written in the photo's red channel
    (its value − 0.5) on base colour, roughness and metallic, with the normal tilted by it."""

    def __init__(self) -> None:
        super().__init__()
        self.anchor = nn.Parameter(torch.zeros(()))  # so .to(device) has something to move

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        error = photo[:, :1].double() - 0.5
        height, width = photo.shape[-2:]
        maps = mid_maps(height, width, batch=photo.shape[0]).to(photo.device)
        for channels in (BASECOLOR, ROUGHNESS, METALLIC):
            maps[:, channels] += error
        maps[:, NORMAL.start] = error[:, 0]  # normal tilted by atan(|error|) along x
        return maps


def synthetic_batches(leak: float, size: int = 32) -> list[dict]:
    """Two batches (3 + 1 samples, off-centre hotspots in the metadata): the red channel holds an
    error ±0.05 outside each sample's disk and ±0.05·leak inside."""
    batches = []
    positions = [[(8.0, 10.0), (20.5, 16.0), (16.0, 24.0)], [(24.0, 8.0)]]
    g = torch.Generator().manual_seed(0)
    for hotspots in positions:
        photos, metas = [], []
        for x, y in hotspots:
            inside = disk_by_loops(size, size, x, y, HOTSPOT_RADIUS_FRACTION * size)
            signs = torch.randint(0, 2, (size, size), generator=g) * 2.0 - 1.0
            red = 0.5 + signs * torch.where(inside, 0.05 * leak, 0.05)
            photos.append(torch.stack([red, torch.full_like(red, 0.5), torch.full_like(red, 0.5)]))
            metas.append({"capture": {"hotspot_px": [x, y]}})
        truth = mid_maps(size, size, batch=len(hotspots)).float()
        batches.append({"photo": torch.stack(photos).float(), "maps": truth, "meta": metas})
    return batches


def test_evaluator_reports_hotspot_ratios(tmp_path: Path) -> None:
    make_metrics = partial(
        SVBRDFMetrics, downscale_to=None, rerender_configs=2, hotspot=True, hotspot_rmse=True
    )
    results: dict[str, dict[str, float]] = {}
    for name, leak in (("leaky", 3.0), ("even", 1.0)):
        results |= evaluate_models({name: OffsetModel()}, synthetic_batches(leak), make_metrics)
    for name in ("basecolor", "roughness", "metallic"):
        assert results["leaky"][f"hotspot/{name}"] == pytest.approx(3.0, rel=1e-5), name
        assert results["even"][f"hotspot/{name}"] == pytest.approx(1.0, rel=1e-5), name
    assert results["leaky"]["hotspot/normal"] > 2.5
    table = markdown_table(results)
    header, _, leaky, even = table.splitlines()
    columns = [cell.strip() for cell in header.strip("|").split("|")]
    assert columns[-4:] == ["hot basecolor", "hot normal", "hot rough", "hot metal"]
    assert leaky.split("|")[-5].strip() == "3.0000" and even.split("|")[-5].strip() == "1.0000"
    write_results(results, tmp_path)
    stored = json.loads((tmp_path / "metrics.json").read_text())
    assert stored["leaky"]["hotspot/basecolor"] == pytest.approx(3.0, rel=1e-5)
    assert {f"hotspot/{name}/inside" for name in RMSE_MAPS} <= set(stored["even"])
