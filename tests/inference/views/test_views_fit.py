"""The multi-view fit (brdfgan.inference.views.fit): views rendered with the project's renderer from
a known material at several camera/flash positions, each with its own exposure and noise, fitted
from a corrupted prediction; the guard, the masks and the settings' checks."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import pytest
import torch
from torch import Tensor

from brdfgan.core.render import texel_centres
from brdfgan.core.svbrdf import join_maps, normalize_normal, resize_maps, split_maps
from brdfgan.errors import UserError
from brdfgan.evaluation.real_captures import fit_gain, srgb_rmse
from brdfgan.inference.refine import photo_loss
from brdfgan.inference.views import fit as fit_module
from brdfgan.inference.views.config import ViewFitConfig
from brdfgan.inference.views.fit import (
    ViewFitResult,
    fit_views,
    outlier_views,
    render_views,
    views_at_size,
)
from tests.conftest import random_maps

SIZE = 64
HALF = 1.0  # plane_half_size
# The reference straight above the centre, then tilted, off-centre views; the flash at the lens.
CAMERAS = ((0.0, 0.0, 2.0), (0.9, 0.4, 1.8), (-0.8, 0.6, 1.9), (0.3, -1.0, 1.7), (-0.6, -0.7, 2.1))
HELD_OUT = ((1.2, -0.2, 1.6), (-0.2, 1.1, 1.8))
# Exposure × white balance per view (the renderer's radiance is ~0.03 at unit intensity).
GAINS = ((14.0, 13.3, 15.4), (18.2, 16.8, 18.2), (11.2, 11.2, 10.5), (15.4, 14.7, 16.8), (9.8, 10.5, 9.8))
# 80 steps in all: enough for the relief and the base colour's level, not for the roughness.
FAST = ViewFitConfig(levels=(32, 64), steps=(40, 40))


def truth_maps(size: int = SIZE) -> Tensor:
    """A dielectric with a coloured texture, a sinusoidal relief (~24° mean normal angle) and
    roughness 0.25–0.65 varying on another pattern.

    Shape: ``(8, size, size)``."""
    xs, ys = texel_centres(size, size, HALF)
    x, y = xs.view(1, -1), ys.view(-1, 1)
    amplitude, fx, fy = 0.06, 2.0, 1.5
    wave_x, wave_y = 2 * math.pi * fx * x, 2 * math.pi * fy * y
    dh_dx = amplitude * 2 * math.pi * fx * torch.cos(wave_x) * torch.cos(wave_y)
    dh_dy = -amplitude * 2 * math.pi * fy * torch.sin(wave_x) * torch.sin(wave_y)
    normal = normalize_normal(torch.stack([-dh_dx, -dh_dy, torch.ones_like(dh_dx)]))
    pattern = 0.5 + 0.5 * torch.sin(3.0 * x + 2.0 * y) * torch.cos(4.0 * y - x)
    base = torch.stack([0.35 + 0.3 * pattern, 0.45 + 0.2 * (1 - pattern), 0.3 + 0.15 * pattern])
    roughness = 0.25 + 0.4 * (0.5 + 0.5 * torch.cos(2.5 * x - 3.0 * y))
    return join_maps(base, normal, roughness[None], torch.zeros(1, size, size))


def corrupted(truth: Tensor) -> Tensor:
    """A poor prediction: base colour 30 % too dark, flat normals, constant roughness."""
    maps = truth.clone()
    maps[0:3] = 0.7 * truth[0:3]
    maps[3:6] = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1)
    maps[6] = 0.45
    return maps


def photograph(
    maps: Tensor, cameras: tuple[tuple[float, float, float], ...], gains: Tensor, seed: int
) -> Tensor:
    """Flash photos in the texture frame: render × gain, 1 % multiplicative and 0.003 additive
    noise, clipped at 1.

    Shape: gains ``(V, 3)`` → ``(V, 3, H, W)``."""
    generator = torch.Generator().manual_seed(seed)
    position = torch.tensor(cameras)
    photos = render_views(maps[None], position, position, HALF) * gains.view(-1, 3, 1, 1)
    photos = photos * (1 + 0.01 * torch.randn(photos.shape, generator=generator))
    return (photos + 0.003 * torch.randn(photos.shape, generator=generator)).clamp(0.0, 1.0)


@dataclass(frozen=True)
class Scene:
    truth: Tensor
    prediction: Tensor
    photos: Tensor  # (5, 3, SIZE, SIZE), views of CAMERAS
    held_out: Tensor  # (2, 3, SIZE, SIZE), views of HELD_OUT


@pytest.fixture(scope="module")
def scene() -> Scene:
    truth = truth_maps()
    return Scene(
        truth=truth,
        prediction=corrupted(truth),
        photos=photograph(truth, CAMERAS, torch.tensor(GAINS), seed=1),
        held_out=photograph(truth, HELD_OUT, torch.full((2, 3), 14.0), seed=2),
    )


def held_out_error(maps: Tensor, held_out: Tensor) -> float:
    """Mean sRGB RMSE of the held-out views re-rendered from ``maps``, each with its best gain."""
    position = torch.tensor(HELD_OUT)
    renders = render_views(maps[None], position, position, HALF)
    errors = [srgb_rmse(fit_gain(r, p) * r, p) for r, p in zip(renders, held_out, strict=True)]
    return sum(errors) / len(errors)


def map_errors(maps: Tensor, truth: Tensor) -> dict[str, float]:
    """RMSE of the base colour (sRGB-encoded), roughness and all eight channels, and the mean
    angle between the normals in degrees."""
    pred, true = split_maps(maps), split_maps(truth)
    cosine = (normalize_normal(pred.normal) * normalize_normal(true.normal)).sum(0).clamp(-1.0, 1.0)
    return {
        "basecolor": float((pred.basecolor - true.basecolor).square().mean().sqrt()),
        "roughness": float((pred.roughness - true.roughness).square().mean().sqrt()),
        "all": float((maps - truth).square().mean().sqrt()),
        "normal_deg": float(torch.rad2deg(torch.acos(cosine)).mean()),
    }


def fit(scene: Scene, views: list[int], config: ViewFitConfig = FAST, **kw: Tensor) -> ViewFitResult:
    photos = kw.get("photos", scene.photos[views])
    seen = kw.get("seen", torch.ones(len(views), 1, SIZE, SIZE))
    position = torch.tensor(CAMERAS)[views]
    return fit_views(photos, seen, position, position, scene.prediction, HALF, config)


# --- the fit recovers the material ---------------------------------------------------------------


def test_three_views_beat_the_prediction_and_one_view(scene: Scene) -> None:
    one, three = fit(scene, [0]), fit(scene, [0, 1, 2])
    assert one.kept == three.kept == "fit"
    held = {name: held_out_error(r.maps, scene.held_out) for name, r in (("one", one), ("three", three))}
    held_prediction = held_out_error(scene.prediction, scene.held_out)
    assert held["three"] < 0.7 * held_prediction  # measured 0.035 against 0.077
    assert held["three"] < 0.7 * held["one"]
    errors = {name: map_errors(r.maps, scene.truth) for name, r in (("one", one), ("three", three))}
    before = map_errors(scene.prediction, scene.truth)
    # The relief and the base colour's level come back; the roughness needs more steps than these 80.
    assert errors["three"]["normal_deg"] < 0.5 * before["normal_deg"]  # measured 8° against 24°
    assert errors["three"]["normal_deg"] < 0.5 * errors["one"]["normal_deg"]
    assert errors["three"]["basecolor"] < 0.7 * before["basecolor"]
    assert errors["three"]["all"] < before["all"]
    assert errors["three"]["all"] < errors["one"]["all"]
    # Every fitted view's residual fell, and the record says so.
    for record in three.views:
        assert record.dropped is None and record.residual_after is not None
        assert record.residual_after < 0.5 * record.residual_before
    assert three.loss_end < three.loss_start


def test_result_records_and_serialises(scene: Scene) -> None:
    steps: list[tuple[int, float]] = []
    config = ViewFitConfig(levels=(16, 32), steps=(4, 3))
    position = torch.tensor(CAMERAS)[:2]
    seen = torch.ones(2, 1, SIZE, SIZE)
    result = fit_views(
        scene.photos[:2],
        seen,
        position,
        position,
        scene.prediction,
        HALF,
        config,
        on_step=lambda step, loss: steps.append((step, loss)),
    )
    assert [s for s, _ in steps] == list(range(1, 8))
    assert len(result.loss_curve) == 7 and result.levels == (16, 32)
    assert result.maps.shape == scene.prediction.shape
    # The fitted gain of the reference is near its exposure (14 for red, up to the base colour's level).
    assert 0.5 < result.views[0].gain[0] / 14.0 < 2.0
    record = json.loads(json.dumps(result.to_json(), allow_nan=False))
    assert record["kept"] == result.kept and len(record["views"]) == 2
    assert set(record["views"][0]) == {
        "index",
        "coverage",
        "gain",
        "residual_before",
        "residual_after",
        "dropped",
    }


# --- robustness ------------------------------------------------------------------------------------


def test_a_view_of_another_material_is_dropped(scene: Scene) -> None:
    other = random_maps(SIZE, SIZE, seed=5)
    stranger = photograph(other, CAMERAS[3:4], torch.tensor(GAINS[3:4]), seed=3)
    photos = torch.cat([scene.photos[:3], stranger])
    result = fit(scene, [0, 1, 2, 3], photos=photos)
    assert [r.dropped is None for r in result.views] == [True, True, True, False]
    assert "stands out" in str(result.views[3].dropped)
    assert result.views[3].residual_after is None
    assert held_out_error(result.maps, scene.held_out) < held_out_error(scene.prediction, scene.held_out)


def test_a_view_eight_times_overexposed_does_no_harm(scene: Scene) -> None:
    photos = scene.photos[:4].clone()
    photos[3] = (photos[3] * 8.0).clamp(max=1.0)  # mostly clipped: lower bounds only
    result = fit(scene, [0, 1, 2, 3], photos=photos)
    held = held_out_error(result.maps, scene.held_out)
    assert held < held_out_error(scene.prediction, scene.held_out)
    assert torch.isfinite(result.maps).all()


def test_guard_restores_the_best_state_when_a_step_gives_nan(
    scene: Scene, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = {"count": 0}

    def failing_render(*args: Tensor | float) -> Tensor:
        calls["count"] += 1
        out = render_views(*args)  # type: ignore[arg-type]
        return out * math.nan if torch.is_grad_enabled() and calls["count"] % 7 == 0 else out

    monkeypatch.setattr(fit_module, "render_views", failing_render)
    result = fit(scene, [0, 1, 2], ViewFitConfig(levels=(32,), steps=(30,)))
    assert result.restores > 0
    assert any(math.isnan(v) for v in result.loss_curve)
    assert torch.isfinite(result.maps).all()
    assert result.kept == "fit"  # the steps between the failures still improved the maps
    json.dumps(result.to_json(), allow_nan=False)


def test_guard_survives_a_runaway_learning_rate(scene: Scene) -> None:
    result = fit(scene, [0, 1, 2], ViewFitConfig(levels=(32,), steps=(20,), learning_rate=50.0))
    assert result.restores > 0
    assert torch.isfinite(result.maps).all()
    if result.kept == "prediction":
        assert torch.equal(result.maps, scene.prediction)
    else:
        assert result.loss_end < result.loss_start


def test_no_improvement_keeps_the_prediction(scene: Scene) -> None:
    unchanged = fit(scene, [0, 1, 2], ViewFitConfig(levels=(32,), steps=(0,)))
    assert unchanged.kept == "prediction" and torch.equal(unchanged.maps, scene.prediction)
    assert unchanged.views[0].residual_after == unchanged.views[0].residual_before
    demanding = fit(scene, [0, 1, 2], ViewFitConfig(levels=(32,), steps=(5,), min_improvement=0.99))
    assert demanding.kept == "prediction" and torch.equal(demanding.maps, scene.prediction)


def test_non_finite_photo_pixels_are_ignored(scene: Scene) -> None:
    photos = scene.photos[:3].clone()
    photos[1, :, 10:20, 10:20] = math.nan
    photos[2, 0, 30:34, 5:9] = math.inf
    result = fit(scene, [0, 1, 2], ViewFitConfig(levels=(32,), steps=(10,)), photos=photos)
    assert torch.isfinite(result.maps).all() and result.kept == "fit"


# --- masks -----------------------------------------------------------------------------------------


def test_texels_no_view_sees_keep_the_prediction(scene: Scene) -> None:
    seen = torch.ones(3, 1, SIZE, SIZE)
    seen[:, :, :, :20] = 0  # the left band: no view
    seen[1:, :, 40:, :] = 0  # the bottom: the reference only
    photos = scene.photos[:3].clone()
    garbage = photos.clone()
    garbage[seen.expand_as(garbage) == 0] = math.nan
    config = ViewFitConfig(levels=(32, 64), steps=(10, 10))
    clean = fit(scene, [0, 1, 2], config, photos=photos, seen=seen)
    dirty = fit(scene, [0, 1, 2], config, photos=garbage, seen=seen)
    assert clean.kept == "fit"
    assert torch.equal(clean.maps[:, :, :20], scene.prediction[:, :, :20])
    assert not torch.allclose(clean.maps[:, :, 24:], scene.prediction[:, :, 24:])
    # What lies outside a view's mask never reaches the fit.
    assert torch.equal(clean.maps, dirty.maps)
    assert clean.views[1].coverage == pytest.approx((44 / 64) * (40 / 64), abs=0.03)


def test_maps_larger_than_the_photos_get_the_correction_carried_over(scene: Scene) -> None:
    large = resize_maps(scene.prediction, 2 * SIZE)
    seen = torch.ones(3, 1, SIZE, SIZE)
    seen[:, :, :, :20] = 0
    position = torch.tensor(CAMERAS)[:3]
    config = ViewFitConfig(levels=(32, 128), steps=(20, 20))
    result = fit_views(scene.photos[:3], seen, position, position, large, HALF, config)
    assert result.levels == (32, 64)  # capped at the photos' size
    assert result.kept == "fit" and result.maps.shape == large.shape
    assert torch.equal(result.maps[:, :, :40], large[:, :, :40])
    upsampled_truth = resize_maps(scene.truth, 2 * SIZE)
    assert (
        map_errors(result.maps, upsampled_truth)["normal_deg"]
        < map_errors(large, upsampled_truth)["normal_deg"]
    )


def test_a_view_that_sees_nothing_is_dropped(scene: Scene) -> None:
    seen = torch.ones(3, 1, SIZE, SIZE)
    seen[2] = 0
    result = fit(scene, [0, 1, 2], ViewFitConfig(levels=(32,), steps=(5,)), seen=seen)
    assert result.views[2].dropped == "sees no texel of the reference"
    assert result.views[2].residual_before != result.views[2].residual_before  # NaN
    assert result.to_json()["views"][2]["residual_before"] is None


def test_views_at_size_masks_partial_and_mixed_clipped_texels() -> None:
    photos = torch.full((1, 3, 4, 4), 0.5)
    photos[0, :, 0, 0] = 1.0  # one clipped pixel in the top-left 2×2 block: a mixed texel
    photos[0, :, 2:, 2:] = 1.0  # a fully clipped block: still a lower bound
    seen = torch.ones(1, 1, 4, 4)
    seen[0, 0, 0, 3] = 0  # the top-right block is partly unseen
    small, mask = views_at_size(photos, seen, 2, 0.98)
    assert mask[0, 0].tolist() == [[0.0, 0.0], [1.0, 1.0]]
    assert small[0, 0, 1, 1] == pytest.approx(1.0)
    same, full_mask = views_at_size(photos, seen, 4, 0.98)
    assert torch.equal(full_mask, seen) and torch.equal(same * seen, photos * seen)


def test_photo_loss_mask_weights_pixels() -> None:
    render = torch.full((1, 3, 2, 2), 0.5)
    photo = render.clone()
    photo[..., 0, 0] = 0.1  # wrong, but masked out
    mask = torch.ones(1, 1, 2, 2)
    mask[..., 0, 0] = 0
    assert float(photo_loss(render, photo, 0.98, mask)) == pytest.approx(0.0, abs=1e-7)
    assert float(photo_loss(render, photo, 0.98, torch.zeros(1, 1, 2, 2))) == 0.0
    assert float(photo_loss(render, photo, 0.98, torch.ones(1, 1, 2, 2))) == pytest.approx(
        float(photo_loss(render, photo, 0.98))
    )


def test_outlier_views() -> None:
    assert outlier_views(torch.tensor([0.10, 0.12, 0.11, 0.45]), 3.0).tolist() == [False] * 3 + [True]
    assert not outlier_views(torch.tensor([0.100, 0.101, 0.102, 0.115]), 3.0).any()  # spread floor
    assert not outlier_views(torch.tensor([0.1, 0.9]), 3.0).any()  # two views: cannot tell
    assert outlier_views(torch.tensor([0.1, math.nan, 0.12]), 3.0).tolist() == [False, True, False]


# --- settings ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("settings", "option"),
    [
        ({"levels": (128, 64), "steps": (1, 1)}, "views.levels"),
        ({"levels": (4,), "steps": (1,)}, "views.levels"),
        ({"levels": (64, 128), "steps": (10,)}, "views.steps"),
        ({"levels": (64,), "steps": (-1,)}, "views.steps"),
        ({"levels": "64"}, "views.levels"),
        ({"learning_rate": 0.0}, "views.learning_rate"),
        ({"learning_rate": "fast"}, "views.learning_rate"),
        ({"prior_slopes": -1.0}, "views.prior_slopes"),
        ({"tv_weight": -0.1}, "views.tv_weight"),
        ({"clip_level": 1.5}, "views.clip_level"),
        ({"outlier_mads": 0.0}, "views.outlier_mads"),
        ({"spike_factor": 1.0}, "views.spike_factor"),
        ({"max_restores": 2.5}, "views.max_restores"),
        ({"min_improvement": 1.0}, "views.min_improvement"),
    ],
)
def test_config_errors_name_the_option(settings: dict[str, object], option: str) -> None:
    with pytest.raises(UserError) as error:
        ViewFitConfig(**settings)  # type: ignore[arg-type]
    message = str(error.value)
    assert message.startswith(option + "=") and "\n" not in message


def test_config_json_round_trip() -> None:
    config = ViewFitConfig(levels=(64, 128), steps=(100, 50), tv_weight=0.1)
    record = json.loads(json.dumps(config.to_json()))
    assert record["levels"] == [64, 128]
    assert ViewFitConfig(**record) == config
