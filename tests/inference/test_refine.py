"""Test-time refinement (brdfgan.inference.refine): parametrisation, terms, and fits whose answer
is known because the photo is rendered by the refinement's own capture model."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from brdfgan.core.exposure import auto_expose
from brdfgan.core.flash_geometry import centred_flash_frame
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import split_maps, validate_maps
from brdfgan.errors import UserError
from brdfgan.inference.refine import (
    RefineConfig,
    RefinedGenerator,
    maps_to_parameters,
    parameters_to_maps,
    photo_loss,
    refine_maps,
    transfer_correction,
)
from tests.conftest import random_maps

FOV = 57.5


def test_parameters_round_trip_and_always_valid() -> None:
    maps = random_maps(16, 16, batch=(2,))
    back = parameters_to_maps(maps_to_parameters(maps))
    # Only the logit margin (1e-3) and nothing else separates the maps from their parameters' maps.
    assert torch.allclose(back, maps, atol=2e-3)
    wild = 20 * torch.randn(2, 7, 16, 16, generator=torch.Generator().manual_seed(1))
    out = parameters_to_maps(wild)
    validate_maps(out[0])
    validate_maps(out[1])
    assert (split_maps(out).normal[:, 2] > 0).all()


def test_photo_loss_treats_clipped_pixels_as_lower_bounds() -> None:
    photo = torch.full((1, 3, 4, 4), 0.5)
    photo[..., 0, 0] = 1.0  # clipped
    brighter = photo.clone()
    brighter[..., 0, 0] = 3.0  # brighter than the clipped value: the truth may be that bright
    assert float(photo_loss(brighter, photo, 0.98)) == pytest.approx(0.0, abs=1e-7)
    darker = photo.clone()
    darker[..., 0, 0] = 0.5
    assert photo_loss(darker, photo, 0.98) > 0.01
    # Unclipped pixels cost both ways, symmetric in log space.
    up, down = photo.clone(), photo.clone()
    up[..., 1, 1] = 0.5 * math.e
    down[..., 1, 1] = 0.5 / math.e
    assert float(photo_loss(up, photo, 0.98)) == pytest.approx(float(photo_loss(down, photo, 0.98)), rel=0.05)


def test_transfer_correction_carries_a_constant_change_to_full_resolution() -> None:
    full = random_maps(32, 32, batch=(1,))
    full[:, 6] = full[:, 6].clamp(0.1, 0.9)
    before = random_maps(8, 8, batch=(1,), seed=3)
    before[:, 6] = 0.5
    assert torch.allclose(
        transfer_correction(full, before, before), parameters_to_maps(maps_to_parameters(full))
    )
    after_params = maps_to_parameters(before)
    after_params[:, 5] += 1.0  # roughness logit +1 everywhere
    moved = transfer_correction(full, before, parameters_to_maps(after_params))
    expected = torch.sigmoid(maps_to_parameters(full)[:, 5] + 1.0)
    assert torch.allclose(moved[:, 6], expected, atol=1e-4)


def _shifted_basecolor(maps: torch.Tensor, logit_shift: float) -> torch.Tensor:
    """``maps`` with the base colour's logits shifted alike in every channel and pixel."""
    shifted = maps.clone()
    shifted[0:3] = torch.sigmoid(torch.logit(maps[0:3].clamp(1e-3, 1 - 1e-3)) + logit_shift)
    return shifted


def test_refinement_recovers_the_base_colour_level_of_an_exact_capture() -> None:
    # The photo has an unknown exposure and white balance (the fitted gain takes them); the base
    # colour's level against the specular highlight is what the base colour's offset sets.
    truth = random_maps(32, 32, seed=5)
    truth[6] = 0.3
    photo, _ = auto_expose(
        render_flash(truth[None], FlashCapture(fov_deg=FOV))[0] * torch.tensor([2.0, 1.5, 1.0]).view(3, 1, 1)
    )
    start = _shifted_basecolor(truth, 1.0)
    config = RefineConfig(steps=100, learning_rate=0.05, ambient=False)
    result = refine_maps(photo, start, centred_flash_frame(1, 32, 32, FOV), config)
    assert result.photo_rmse_end < 0.5 * result.photo_rmse_start
    assert result.maps.shape == truth.shape
    validate_maps(result.maps)
    before = (start[0:3] - truth[0:3]).abs().mean()
    after = (result.maps[0:3] - truth[0:3]).abs().mean()
    assert after < 0.3 * before
    # White balance is the gain's: the fitted gains keep the photo's channel ratios 2 : 1.5 : 1.
    assert result.gain[0] / result.gain[2] == pytest.approx(2.0, rel=0.05)
    assert result.gain[1] / result.gain[2] == pytest.approx(1.5, rel=0.05)


def test_refinement_at_a_working_size_keeps_the_output_size() -> None:
    truth = random_maps(64, 64, seed=2)
    photo = render_flash(truth[None], FlashCapture(fov_deg=FOV))[0]
    frame = centred_flash_frame(1, 64, 64, FOV)
    result = refine_maps(photo, truth, frame, RefineConfig(steps=3, working_size=32))
    assert result.maps.shape == (8, 64, 64)
    validate_maps(result.maps)
    assert set(result.to_json()) >= {"gain", "steps", "loss_start", "loss_end", "photo_rmse_end"}


def _too_rough_start(
    seed: int, metallic: float | None = None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A 32² truth of roughness 0.3 (and ``metallic`` when given), its photo under the refinement's
    own capture model, and a start equal to the truth but for a roughness of 0.55."""
    truth = random_maps(32, 32, seed=seed)
    truth[6] = 0.3
    if metallic is not None:
        truth[7] = metallic
    photo = render_flash(truth[None], FlashCapture(fov_deg=FOV))[0]
    start = truth.clone()
    start[6] = 0.55
    return truth, photo, start


def _unchanged(maps: torch.Tensor) -> torch.Tensor:
    """``maps`` as a refinement returns them when nothing moves (the logit margin applied)."""
    return parameters_to_maps(maps_to_parameters(maps[None]))[0]


def test_a_global_correction_moves_each_map_by_one_logit_and_keeps_the_normals() -> None:
    # The default: the normals stay as predicted; base colour, roughness
    # and metallic move by one logit offset each, everywhere — the roughness toward the truth.
    _, photo, start = _too_rough_start(12, metallic=0.2)
    config = RefineConfig(steps=60, learning_rate=0.05, ambient=False)  # the default: one offset per map
    result = refine_maps(photo, start, centred_flash_frame(1, 32, 32, FOV), config)
    kept = _unchanged(start)
    torch.testing.assert_close(result.maps[3:6], kept[3:6])
    for channels in (slice(0, 3), slice(6, 7), slice(7, 8)):
        delta = torch.logit(result.maps[channels].clamp(1e-3, 1 - 1e-3)) - torch.logit(
            kept[channels].clamp(1e-3, 1 - 1e-3)
        )
        assert float(delta.std()) < 1e-3
    assert abs(float(result.maps[6].mean()) - 0.3) < abs(0.55 - 0.3) / 4


def test_a_map_left_out_of_the_fit_keeps_its_prediction() -> None:
    # fit_roughness=False: the photo asks for a smoother lobe, but the roughness map stays as
    # predicted (to the logit margin) while metallic still moves toward the truth.
    _, photo, start = _too_rough_start(12, metallic=0.1)
    start[7] = 0.5
    config = RefineConfig(steps=40, learning_rate=0.05, ambient=False, fit_roughness=False)
    result = refine_maps(photo, start, centred_flash_frame(1, 32, 32, FOV), config)
    torch.testing.assert_close(result.maps[3:7], _unchanged(start)[3:7])
    assert abs(float(result.maps[7].mean()) - 0.1) < 0.5 * abs(0.5 - 0.1)
    # fit_basecolor=False as well: only metallic moves, and the base colour is the prediction's.
    metallic_only = RefineConfig(
        steps=40, learning_rate=0.05, ambient=False, fit_roughness=False, fit_basecolor=False
    )
    result = refine_maps(photo, start, centred_flash_frame(1, 32, 32, FOV), metallic_only)
    torch.testing.assert_close(result.maps[:7], _unchanged(start)[:7])
    assert abs(float(result.maps[7].mean()) - 0.1) < 0.5 * abs(0.5 - 0.1)


def test_a_nuisance_roughness_is_fitted_jointly_but_not_returned() -> None:
    # roughness_nuisance: the same fit as with a roughness offset (base colour and metallic move
    # exactly as they do there), but the maps keep the predicted roughness.
    truth, photo, start = _too_rough_start(14)
    start[7] = (truth[7] * 0.5 + 0.25).clamp(0, 1)
    frame = centred_flash_frame(1, 32, 32, FOV)
    joint = refine_maps(photo, start, frame, RefineConfig(steps=30, ambient=False, fit_roughness=True))
    nuisance = RefineConfig(steps=30, ambient=False, fit_roughness=True, roughness_nuisance=True)
    hidden = refine_maps(photo, start, frame, nuisance)
    kept = _unchanged(start)
    torch.testing.assert_close(hidden.maps[6], kept[6])
    torch.testing.assert_close(hidden.maps[[0, 1, 2, 7]], joint.maps[[0, 1, 2, 7]])
    assert float((joint.maps[6] - kept[6]).abs().mean()) > 0.05  # the joint fit did move it
    assert hidden.loss_end == joint.loss_end  # the loss is that of the fitted (joint) state


def test_refinement_is_deterministic() -> None:
    # No random draws anywhere (the start is the prediction, the optimiser is Adam): the same
    # photo and maps give the same result, bit for bit, so predict --refine is reproducible.
    truth = random_maps(32, 32, seed=13)
    photo = render_flash(truth[None], FlashCapture(fov_deg=FOV))[0]
    start = truth.clone()
    start[6] = (start[6] + 0.2).clamp(0, 1)
    frame = centred_flash_frame(1, 32, 32, FOV)
    first, second = (refine_maps(photo, start, frame, RefineConfig(steps=20)) for _ in range(2))
    assert torch.equal(first.maps, second.maps) and first.gain == second.gain


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(UserError, match=r"refine\.steps"):
        RefineConfig(steps=-1)
    with pytest.raises(UserError, match=r"refine\.clip_level"):
        RefineConfig(clip_level=0.0)
    with pytest.raises(ValueError, match="square"):
        refine_maps(torch.rand(3, 8, 16), random_maps(8, 16), centred_flash_frame(1, 8, 16, FOV))


class _ConstantGenerator(nn.Module):
    def __init__(self, maps: torch.Tensor) -> None:
        super().__init__()
        self.maps = maps

    def forward(self, photo: torch.Tensor, flash: torch.Tensor | None = None) -> torch.Tensor:
        return self.maps.expand(photo.shape[0], -1, -1, -1)


def test_refined_generator_reads_the_field_of_view_from_the_flash_frame() -> None:
    truth = random_maps(16, 16, seed=7)
    wide = render_flash(truth[None], FlashCapture(fov_deg=75.0))
    start = truth.clone()
    start[0:3] *= 0.8
    refined = RefinedGenerator(_ConstantGenerator(start[None]), RefineConfig(steps=40, ambient=False))
    told = refined(wide, centred_flash_frame(1, 16, 16, 75.0))
    untold = refined(wide, None)  # assumes the 57.5° default
    assert told.shape == (1, 8, 16, 16)

    def error(maps: torch.Tensor) -> float:
        render = render_flash(maps, FlashCapture(fov_deg=75.0))
        return float((render / render.mean() - wide / wide.mean()).abs().mean())

    assert error(told) < error(untold)


def test_the_evaluator_scores_refined_variants_beside_the_models() -> None:
    from brdfgan.evaluation.evaluator import evaluate_models
    from brdfgan.evaluation.run import refined_variants
    from brdfgan.metrics import SVBRDFMetrics

    truth = random_maps(16, 16, seed=8)
    truth[6] = 0.3
    start = _shifted_basecolor(truth, 1.0)
    models = refined_variants({"net": _ConstantGenerator(start[None])}, [20], {"learning_rate": 0.05})
    assert set(models) == {"net", "net+refine20"} and isinstance(models["net+refine20"], RefinedGenerator)
    photo, _ = auto_expose(render_flash(truth[None], FlashCapture(fov_deg=FOV)))
    batch = {"photo": photo, "maps": truth[None], "flash": centred_flash_frame(1, 16, 16, FOV)}
    results = evaluate_models(models, [batch], lambda: SVBRDFMetrics(downscale_to=None))
    assert results["net+refine20"]["rmse/diffuse"] < results["net"]["rmse/diffuse"]
    with pytest.raises(UserError, match="refine_steps"):
        refined_variants(models, [0])
    # evaluate.py's refine.<key>: settings besides the steps, checked by name and type.
    tuned = refined_variants({"net": models["net"]}, [5], {"fit_roughness": False, "ambient_grid": 2})
    assert tuned["net+refine5"].config == RefineConfig(steps=5, fit_roughness=False, ambient_grid=2)
    with pytest.raises(UserError, match=r"refine\.bogus: not a refinement setting"):
        refined_variants(models, [5], {"bogus": 1})
    with pytest.raises(UserError, match=r"refine\.ambient=1: expected bool"):
        refined_variants(models, [5], {"ambient": 1})
