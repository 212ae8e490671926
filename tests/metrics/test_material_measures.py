"""False metal, relief leak and the observable normal angle: golden values, invariants, batch-split
exactness, the evaluator."""

from __future__ import annotations

import json
import math
from functools import partial
from pathlib import Path

import pytest
import torch
from torch import Tensor, nn

from brdfgan.core.brdf import evaluate_brdf
from brdfgan.core.delit import flash_render, flat_flash_falloff
from brdfgan.core.flash_geometry import centred_flash_frame, crop_flash_frame, flash_offset_channels
from brdfgan.core.svbrdf import (
    flat_maps,
    join_maps,
    linear_to_srgb,
    normalize_normal,
    split_maps,
    srgb_to_linear,
)
from brdfgan.data.materials.base import height_to_normal
from brdfgan.data.materials.noise import fbm
from brdfgan.evaluation.evaluator import evaluate_models, markdown_table, write_results
from brdfgan.metrics import (
    DIELECTRIC_THRESHOLD,
    FalseMetal,
    ObservableNormalAngle,
    ReliefLeak,
    SlopeAgreement,
    SVBRDFMetrics,
    false_metal,
    observable_mask,
    relief_leak,
    relief_shading,
    slope_agreement,
    srgb8_rounding_log,
)

SIZE = 32


def with_metallic(maps: Tensor, metallic: Tensor | float) -> Tensor:
    out = maps.clone()
    out[:, 7:8] = metallic
    return out


def half_metal_truth(batch: int = 2, size: int = 8) -> Tensor:
    """Grey maps, dielectric (metallic 0) in the left half, metal (1) in the right half."""
    maps = flat_maps(size, size, batch=(batch,), dtype=torch.float64)
    maps[:, 7, :, size // 2 :] = 1.0
    return maps


# ---------------------------------------------------------------- slope agreement


def fbm_relief(scale: float, batch: int = 1) -> Tensor:
    """Flat grey maps with the normals of ``scale`` times an fbm height (negative: inside out)."""
    maps = flat_maps(32, 32, batch=(batch,))
    for i in range(batch):
        height = fbm(32, 4, torch.Generator().manual_seed(i), octaves=3)[None]
        maps[i, 3:6] = height_to_normal(scale * height)
    return maps


def test_slope_agreement_right_way_round_one_inside_out_minus_one_half_as_steep_half() -> None:
    truth = fbm_relief(2.0)
    for pred, cosine, ratio in (
        (truth, 1.0, 1.0),
        (fbm_relief(-2.0), -1.0, 1.0),
        (fbm_relief(1.0), 1.0, 0.5),
    ):
        scores = slope_agreement(pred, truth)
        assert scores["normal_slope_cosine"].item() == pytest.approx(cosine, abs=1e-6)
        # slopes of a halved height, renormalised: half as steep up to the normalisation's rounding
        assert scores["normal_slope_ratio"].item() == pytest.approx(ratio, rel=2e-2)
    flat = slope_agreement(flat_maps(32, 32, batch=(1,)), truth)
    assert flat["normal_slope_cosine"].item() == 0.0 and flat["normal_slope_ratio"].item() == 0.0
    on_flat = slope_agreement(truth, flat_maps(32, 32, batch=(1,)))  # no true relief to agree with
    assert all(math.isnan(value.item()) for value in on_flat.values())
    # Unrelated relief: near 0.
    other = fbm_relief(2.0, batch=2)[1:]
    assert abs(slope_agreement(other, truth)["normal_slope_cosine"].item()) < 0.2


def test_slope_agreement_pools_texels_exactly_over_batch_splits() -> None:
    truth, pred = fbm_relief(2.0, batch=3), fbm_relief(1.0, batch=3).flip(0)
    split, whole = SlopeAgreement(), SlopeAgreement()
    split.update(pred[:1], truth[:1])
    split.update(pred[1:], truth[1:])
    whole.update(pred, truth)
    a, b = split.compute(), whole.compute()
    for key in ("normal_slope_cosine", "normal_slope_ratio"):
        torch.testing.assert_close(a[key], b[key], rtol=1e-12, atol=0.0)
        torch.testing.assert_close(b[key], slope_agreement(pred, truth)[key])
    # Pooled, not a mean of per-sample cosines.
    per_sample = torch.stack([slope_agreement(pred[i], truth[i])["normal_slope_cosine"] for i in range(3)])
    assert not torch.isclose(per_sample.mean(), b["normal_slope_cosine"])


# ---------------------------------------------------------------- false metal


def test_false_metal_is_the_mean_predicted_metallic_on_dielectric_truth() -> None:
    truth = half_metal_truth()
    pred = with_metallic(truth, 0.3)
    pred[:, 7, :, 4:] = 0.9  # metal texels: whatever is predicted there is ignored
    assert false_metal(pred, truth).item() == pytest.approx(0.3, abs=1e-12)
    metric = FalseMetal()
    metric.update(pred, truth)
    assert metric.compute().item() == pytest.approx(0.3, abs=1e-12)
    assert false_metal(truth, truth).item() == 0.0
    # Only dielectric texels count: 0.1 on half of them, 0.5 on the other half.
    pred[:, 7, :4, :4], pred[:, 7, 4:, :4] = 0.1, 0.5
    assert false_metal(pred, truth).item() == pytest.approx(0.3, abs=1e-12)
    # A soft truth between the classes (a rust edge) is neither: ignored too.
    truth[:, 7, 0, 0], pred[:, 7, 0, 0] = 0.3, 1.0
    assert false_metal(pred, truth).item() == pytest.approx((15 * 0.1 + 16 * 0.5) / 31, abs=1e-12)


def test_false_metal_threshold_and_empty_cases() -> None:
    below = with_metallic(flat_maps(4, 4, batch=(1,), dtype=torch.float64), DIELECTRIC_THRESHOLD - 0.01)
    at = with_metallic(below, DIELECTRIC_THRESHOLD)
    pred = with_metallic(below, 0.2)
    assert false_metal(pred, below).item() == pytest.approx(0.2)  # a soft dielectric counts
    assert math.isnan(false_metal(pred, at).item())  # no dielectric texel: NaN, not 0/0 = inf
    metric = FalseMetal()
    with pytest.warns(UserWarning, match="before the ``update``"):
        assert math.isnan(metric.compute().item())  # before any update
    metric.update(pred, at)
    assert math.isnan(metric.compute().item()) and int(metric.texels) == 0
    metric.update(pred[0], below[0])  # unbatched maps
    assert metric.compute().item() == pytest.approx(0.2) and int(metric.texels) == 16


def test_false_metal_is_exact_over_uneven_batch_splits() -> None:
    g = torch.Generator().manual_seed(0)
    truth = (torch.rand(5, 1, 6, 6, generator=g, dtype=torch.float64) > 0.3).double()  # ~30 % dielectric
    truth_maps = with_metallic(flat_maps(6, 6, batch=(5,), dtype=torch.float64), truth)
    pred_maps = with_metallic(truth_maps, torch.rand(5, 1, 6, 6, generator=g, dtype=torch.float64))
    whole, split = FalseMetal(), FalseMetal()
    whole.update(pred_maps, truth_maps)
    split.update(pred_maps[:1], truth_maps[:1])
    split.update(pred_maps[1:], truth_maps[1:])
    dielectric = truth_maps[:, 7] < DIELECTRIC_THRESHOLD
    expected = pred_maps[:, 7][dielectric].mean()
    torch.testing.assert_close(whole.compute(), expected, rtol=1e-14, atol=0.0)
    torch.testing.assert_close(split.compute(), whole.compute(), rtol=1e-14, atol=0.0)


# ---------------------------------------------------------------- relief shading


def frames(batch: int = 4, size: int = SIZE) -> Tensor:
    """Flash frames of 60° photos whose hotspots lie off centre, differently per sample."""
    shifts_x = torch.tensor([3.0, -6.0, 8.0, 0.0, -2.0, 5.0])[:batch]
    shifts_y = torch.tensor([0.0, 4.0, -5.0, 7.0, -3.0, 2.0])[:batch]
    return crop_flash_frame(
        centred_flash_frame(batch, size, size, 60.0, dtype=torch.float64), shifts_x, shifts_y
    )


def bumpy_truth(batch: int = 4, size: int = SIZE, seed: int = 0) -> Tensor:
    """Textured dielectric maps with smooth relief (normals of a height field of random waves),
    base colour sRGB in [0.35, 0.7] and roughness in [0.6, 0.9]: matte enough that the truth times
    its relief shading stays a valid base colour."""
    g = torch.Generator().manual_seed(seed)
    coords = torch.arange(size, dtype=torch.float64) * 2 * math.pi / size
    rows, cols = torch.meshgrid(coords, coords, indexing="ij")
    normals = []
    for _ in range(batch):
        slope_x, slope_y = (
            torch.zeros(size, size, dtype=torch.float64),
            torch.zeros(size, size, dtype=torch.float64),
        )
        for _ in range(3):
            kx, ky = (int(k) for k in torch.randint(1, 4, (2,), generator=g))
            amplitude, phase = 0.08 * torch.rand(2, generator=g, dtype=torch.float64)
            wave = torch.cos(kx * cols + ky * rows + 2 * math.pi * phase)
            slope_x, slope_y = slope_x + amplitude * kx * wave, slope_y + amplitude * ky * wave
        normals.append(torch.stack([-slope_x, -slope_y, torch.ones_like(slope_x)]))
    shape = (batch, 1, size, size)
    return join_maps(
        0.35 + 0.35 * torch.rand((batch, 3, size, size), generator=g, dtype=torch.float64),
        normalize_normal(torch.stack(normals)),
        0.6 + 0.3 * torch.rand(shape, generator=g, dtype=torch.float64),
        torch.zeros(shape, dtype=torch.float64),
    )


def shaded_basecolor(truth: Tensor, factor: Tensor) -> Tensor:
    """The truth with its linear base colour multiplied by ``factor`` ``(B, 1, H, W)``."""
    pred = truth.clone()
    pred[:, 0:3] = linear_to_srgb(srgb_to_linear(split_maps(truth).basecolor) * factor)
    return pred


def test_flash_render_with_flat_normals_is_the_brdf_times_the_flat_falloff() -> None:
    truth = bumpy_truth(batch=2)
    parts = split_maps(truth)
    linear = srgb_to_linear(parts.basecolor)
    flat = torch.zeros_like(parts.normal)
    flat[:, 2] = 1.0
    frame = frames(2)
    offsets = flash_offset_channels(frame, SIZE, SIZE)
    towards = torch.cat([-offsets, torch.ones_like(offsets[:, :1])], dim=1)
    towards = towards / towards.norm(dim=1, keepdim=True)
    brdf = evaluate_brdf(linear, flat, parts.roughness, parts.metallic, towards, towards)
    torch.testing.assert_close(
        flash_render(linear, flat, parts.roughness, parts.metallic, frame),
        math.pi * brdf * flat_flash_falloff(frame, SIZE, SIZE),
        rtol=1e-12,
        atol=0.0,
    )
    flat_truth = truth.clone()
    flat_truth[:, 3:6] = flat
    assert torch.equal(relief_shading(flat_truth, frame), torch.zeros(2, 1, SIZE, SIZE, dtype=torch.float64))


def test_relief_shading_golden_value_at_the_hotspot() -> None:
    # One texel at the hotspot (l = v = +Z), white dielectric, roughness 1 (α = 1), normal tilted
    # 60°: n·l = 1/2. Burley: Fd90 = 0.5 + 2·1·1 = 2.5, factor (1 + 1.5·(1/2)^5)² tilted, 1 flat.
    # GGX with α = 1: D = 1/π, F = F0 = 0.04 (h = l), G1 = 2c/(c + 1): 2/3 tilted, 1 flat.
    # π f · cos: tilted (1.046875² + 0.04·(4/9)/(4·¼)) · ½, flat (1 + 0.04/4) · 1.
    maps = flat_maps(
        1, 1, basecolor=(1.0, 1.0, 1.0), roughness=1.0, metallic=0.0, batch=(1,), dtype=torch.float64
    )
    maps[:, 3:6] = torch.tensor([math.sin(math.pi / 3), 0.0, 0.5], dtype=torch.float64).view(1, 3, 1, 1)
    frame = torch.tensor([[0.5, 0.5, 1.0]], dtype=torch.float64)
    tilted = (1.046875**2 + 0.04 * (4 / 9)) * 0.5
    flat = 1.0 + 0.04 / 4
    assert relief_shading(maps, frame).item() == pytest.approx(math.log(tilted / flat), rel=1e-12)


def test_relief_shading_follows_the_flash_side() -> None:
    # A texel right of the hotspot is lit from its left: tilted towards the flash (−x) it is
    # brighter than flat, tilted away darker; mirrored, the hotspot right of it, the other way round.
    maps = flat_maps(1, 3, roughness=0.8, batch=(2,), dtype=torch.float64)
    maps[0, 3:6] = normalize_normal(torch.tensor([-0.3, 0.0, 1.0], dtype=torch.float64), dim=0).view(3, 1, 1)
    maps[1, 3:6] = normalize_normal(torch.tensor([0.3, 0.0, 1.0], dtype=torch.float64), dim=0).view(3, 1, 1)
    left_flash = torch.tensor([[0.5, 0.5, 0.3], [0.5, 0.5, 0.3]], dtype=torch.float64)
    shading = relief_shading(maps, left_flash)[:, 0, 0, 2]
    assert shading[0] > 0.05 and shading[1] < -0.05
    right_flash = torch.tensor([[2.5, 0.5, 0.3], [2.5, 0.5, 0.3]], dtype=torch.float64)
    shading = relief_shading(maps, right_flash)[:, 0, 0, 0]
    assert shading[0] < -0.05 and shading[1] > 0.05


# ---------------------------------------------------------------- relief leak


def test_relief_leak_golden_values() -> None:
    truth, frame = bumpy_truth(), frames()
    shading = relief_shading(truth, frame).exp()
    assert (shading.std(dim=(1, 2, 3)) > 0.03).all()  # real relief, several % of brightness

    def leak(pred: Tensor) -> tuple[float, float]:
        values = relief_leak(pred, truth, frame)
        return values["relief_leak"].item(), values["relief_leak/slope"].item()

    copied = shaded_basecolor(truth, shading)
    assert leak(copied) == pytest.approx((1.0, 1.0), abs=1e-9)
    # Darker overall and only part of the shading: still all of the error is relief, slope 0.3.
    assert leak(shaded_basecolor(truth, 0.5 * shading**0.3)) == pytest.approx((1.0, 0.3), abs=1e-9)
    assert leak(shaded_basecolor(truth, 1 / shading)) == pytest.approx((-1.0, -1.0), abs=1e-9)
    assert leak(truth) == (0.0, 0.0)
    assert leak(shaded_basecolor(truth, torch.full_like(shading, 0.5))) == pytest.approx((0.0, 0.0), abs=1e-9)
    g = torch.Generator().manual_seed(1)
    noise = (0.1 * torch.randn(shading.shape, generator=g, dtype=torch.float64)).exp()
    independent = leak(shaded_basecolor(truth, noise))
    assert abs(independent[0]) < 0.05 and abs(independent[1]) < 0.1
    # The relief plus an independent error of about the same size: a partial correlation.
    mixed = leak(shaded_basecolor(truth, shading * noise))
    assert 0.3 < mixed[0] < 0.95 and mixed[1] == pytest.approx(1.0, abs=0.1)


def test_relief_leak_skips_samples_without_relief() -> None:
    truth, frame = bumpy_truth(batch=3), frames(3)
    copied = shaded_basecolor(truth, relief_shading(truth, frame).exp())
    truth[1, 3:6] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).view(3, 1, 1)  # flat
    copied[1] = truth[1]
    copied[1, 0:3] = 0.9 * truth[1, 0:3] + 0.05 * torch.rand(3, SIZE, SIZE, dtype=torch.float64)  # any error
    metric = ReliefLeak()
    metric.update(copied, truth, frame)
    assert int(metric.samples) == 2
    assert metric.compute()["relief_leak"].item() == pytest.approx(1.0, abs=1e-9)
    nothing = ReliefLeak()
    with pytest.warns(UserWarning, match="before the ``update``"):
        assert all(math.isnan(v.item()) for v in nothing.compute().values())  # before any update
    nothing.update(copied[1:2], truth[1:2], frame[1:2])
    assert all(math.isnan(v.item()) for v in nothing.compute().values())  # flat truth only


def test_relief_leak_is_exact_over_batch_splits() -> None:
    truth, frame = bumpy_truth(batch=4, seed=2), frames(4)
    g = torch.Generator().manual_seed(3)
    noise = (0.1 * torch.randn(4, 1, SIZE, SIZE, generator=g, dtype=torch.float64)).exp()
    pred = shaded_basecolor(truth, relief_shading(truth, frame).exp() ** 0.5 * noise).float()
    whole = ReliefLeak()
    whole.update(pred, truth.float(), frame.float())
    for cut in (1, 2):
        split = ReliefLeak()
        split.update(pred[:cut], truth[:cut].float(), frame[:cut].float())
        split.update(pred[cut:], truth[cut:].float(), frame[cut:].float())
        for key, value in whole.compute().items():
            torch.testing.assert_close(split.compute()[key], value, rtol=1e-13, atol=1e-15)
    assert 0.2 < whole.compute()["relief_leak"].item() < 1.0


def test_relief_leak_uses_the_flash_frame() -> None:
    truth, frame = bumpy_truth(batch=2), frames(2)
    copied = shaded_basecolor(truth, relief_shading(truth, frame).exp())
    right, wrong = ReliefLeak(), ReliefLeak()
    right.update(copied, truth, frame)
    wrong.update(copied, truth, crop_flash_frame(frame, 12.0, -12.0))  # the hotspot elsewhere
    assert right.compute()["relief_leak"].item() == pytest.approx(1.0, abs=1e-9)
    assert wrong.compute()["relief_leak"].item() < 0.95
    centred = ReliefLeak()  # without frames: photos centred on their hotspot, the default FOV
    centred.update(copied, truth)
    assert centred.compute()["relief_leak"].item() < 0.95
    unbatched = ReliefLeak()
    unbatched.update(copied[0], truth[0], frame[0])
    alone = relief_leak(copied[:1], truth[:1], frame[:1])
    torch.testing.assert_close(unbatched.compute()["relief_leak"], alone["relief_leak"])
    with pytest.raises(ValueError, match="flash frame for 1 photos, but the batch holds 2"):
        right.update(copied, truth, frame[:1])


def test_the_collection_routes_flash_to_the_relief_leak_only() -> None:
    truth, frame = bumpy_truth(batch=2, seed=4), frames(2)
    pred = shaded_basecolor(truth, relief_shading(truth, frame).exp() ** 0.5)
    pred = with_metallic(pred, 0.25)
    collection = SVBRDFMetrics(downscale_to=None, rerender_configs=2, prefix="val/")
    collection.update(pred, truth, flash=frame)
    out = collection.compute()
    alone = ReliefLeak()
    alone.update(pred, truth, frame)
    for key, value in alone.compute().items():
        assert torch.equal(out[f"val/{key}"], value), key
    assert out["val/relief_leak"].item() == pytest.approx(1.0, abs=1e-9)
    assert out["val/relief_leak/slope"].item() == pytest.approx(0.5, abs=1e-9)
    assert out["val/false_metal"].item() == pytest.approx(0.25)


# ---------------------------------------------------------------- observable normal angle


def flash_photo(truth: Tensor, frame: Tensor, peak: float = 0.8) -> Tensor:
    """The truth's flash photo (its relief included), exposed so its brightest texel is ``peak``."""
    parts = split_maps(truth)
    render = flash_render(
        srgb_to_linear(parts.basecolor), parts.normal, parts.roughness, parts.metallic, frame
    )
    return render * (peak / render.amax(dim=(1, 2, 3), keepdim=True))


def test_observable_angle_golden_values_and_invariants() -> None:
    truth, frame = bumpy_truth(batch=3, seed=6), frames(3)
    photo = flash_photo(truth, frame)
    mask = observable_mask(relief_shading(truth, frame), srgb8_rounding_log(photo))[:, 0]
    assert 0.2 < mask.double().mean().item() < 1.0  # some relief shows, not all of it
    flat = truth.clone()
    flat[:, 3:6] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).view(3, 1, 1)

    def scores(pred: Tensor) -> tuple[float, float]:
        metric = ObservableNormalAngle()
        metric.update(pred, truth, photo, frame)
        out = metric.compute()
        return out["normal_angle_deg/observable"].item(), out["normal_angle_deg/observable_flat"].item()

    # The flat map's part of the angle the photo shows: Σ θ·mask / N, as the data tables count it
    # (research/relief.py's observable_angle): θ the tilt of each true normal from +Z.
    x, y, z = truth[:, 3:6].unbind(dim=1)
    tilt = torch.rad2deg(torch.atan2(torch.hypot(x, y), z))
    expected_flat = (tilt * mask.to(tilt.dtype)).mean(dim=(-2, -1)).mean().item()
    assert scores(flat) == pytest.approx((expected_flat, expected_flat), rel=1e-12)
    assert scores(truth)[0] == pytest.approx(0.0, abs=1e-4)
    # Half the relief (slopes halved): in between.
    half = truth.clone()
    half[:, 3:5] *= 0.5
    half[:, 3:6] = normalize_normal(half[:, 3:6], dim=1)
    assert 0.2 * expected_flat < scores(half)[0] < 0.8 * expected_flat
    # A flat truth shows no relief: nothing counts; a batch without photos is skipped.
    nothing = ObservableNormalAngle()
    nothing.update(half, flat, flash_photo(flat, frame), frame)
    assert nothing.compute()["normal_angle_deg/observable_flat"].item() == 0.0
    skipped = ObservableNormalAngle()
    skipped.update(half, truth, None, frame)
    assert all(math.isnan(v.item()) for v in skipped.compute().values())
    with pytest.raises(ValueError, match="photo"):
        ObservableNormalAngle().update(half, truth, photo[:, :, :16], frame)


def test_observable_angle_is_exact_over_batch_splits_and_routed_by_the_collection() -> None:
    truth, frame = bumpy_truth(batch=4, seed=7), frames(4)
    photo = flash_photo(truth, frame)
    pred = truth.clone()
    pred[:, 3:5] *= 0.3
    pred[:, 3:6] = normalize_normal(pred[:, 3:6], dim=1)
    whole = ObservableNormalAngle()
    whole.update(pred, truth, photo, frame)
    split = ObservableNormalAngle()
    split.update(pred[:1], truth[:1], photo[:1], frame[:1])
    split.update(pred[1:], truth[1:], photo[1:], frame[1:])
    for key, value in whole.compute().items():
        torch.testing.assert_close(split.compute()[key], value, rtol=1e-13, atol=1e-15)
    collection = SVBRDFMetrics(downscale_to=None, rerender_configs=2)
    collection.update(pred, truth, flash=frame, photo=photo)
    out = collection.compute()
    for key, value in whole.compute().items():
        assert torch.equal(out[key], value), key
    # Darker photos round coarser: less of the relief is observable.
    dim = ObservableNormalAngle()
    dim.update(pred, truth, flash_photo(truth, frame, peak=0.02), frame)
    assert (
        dim.compute()["normal_angle_deg/observable_flat"]
        < whole.compute()["normal_angle_deg/observable_flat"]
    )


# ---------------------------------------------------------------- evaluator


class BaseColourFromPhoto(nn.Module):
    """Predicts the photo's values as the sRGB base colour, flat normals and a constant metallic."""

    def __init__(self, metallic: float) -> None:
        super().__init__()
        self.metallic = metallic

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        maps = flat_maps(*photo.shape[-2:], metallic=self.metallic, batch=(photo.shape[0],))
        maps[:, 0:3] = photo
        return maps


def test_evaluator_tables_report_false_metal_and_relief_leak(tmp_path: Path) -> None:
    truth, frame = bumpy_truth(batch=3, seed=5).float(), frames(3).float()
    copied = shaded_basecolor(truth.double(), relief_shading(truth.double(), frame.double()).exp())
    results: dict[str, dict[str, float]] = {}
    for name, photo, metallic in (("copy", copied, 0.0), ("right", truth, 0.3)):
        batches = [
            {"photo": photo[:2, 0:3].float(), "maps": truth[:2], "flash": frame[:2]},
            {"photo": photo[2:, 0:3].float(), "maps": truth[2:], "flash": frame[2:]},
        ]
        make_metrics = partial(SVBRDFMetrics, downscale_to=None, rerender_configs=2)
        # The metrics take the recorded frames even when the models get centred ones.
        results |= evaluate_models(
            {name: BaseColourFromPhoto(metallic)}, batches, make_metrics, flash_frame="centred"
        )
    assert results["copy"]["relief_leak"] == pytest.approx(1.0, abs=1e-5)
    assert results["copy"]["relief_leak/slope"] == pytest.approx(1.0, abs=1e-4)
    assert results["copy"]["false_metal"] == 0.0
    assert results["right"]["relief_leak"] == 0.0 and results["right"]["false_metal"] == pytest.approx(0.3)

    header, rule, copy, right = markdown_table(results).splitlines()
    columns = [cell.strip() for cell in header.strip("|").split("|")]
    start = columns.index("false metal")
    assert columns[start : start + 7] == [
        "false metal",
        "relief leak",
        "leak slope",
        "normal ° seen",
        "flat ° seen",
        "slope cos",
        "slope ratio",
    ]
    assert start == columns.index("chk metal") + 1
    assert rule.count("---") == len(columns)
    cells = [cell.strip() for cell in copy.strip("|").split("|")]
    assert cells[start : start + 3] == ["0.0000", "1.0000", "1.0000"]
    cells = [cell.strip() for cell in right.strip("|").split("|")]
    assert cells[start : start + 3] == ["0.3000", "0.0000", "0.0000"]
    write_results(results, tmp_path)
    stored = json.loads((tmp_path / "metrics.json").read_text())
    assert {"false_metal", "relief_leak", "relief_leak/slope"} <= set(stored["copy"])
    # The photo reaches the observable angle: both models predict flat normals.
    seen = stored["copy"]["normal_angle_deg/observable"]
    assert seen > 0.0 and seen == pytest.approx(stored["copy"]["normal_angle_deg/observable_flat"], rel=1e-6)
