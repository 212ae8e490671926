"""The photo-anchored two-decoder U-Net (models.anchored) and the flat flash render it divides by."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from brdfgan.core.delit import delit_photo, flat_flash_render
from brdfgan.core.filtering import binomial_blur
from brdfgan.core.flash_geometry import centred_flash_frame, crop_flash_frame
from brdfgan.core.height import height_slope_channels
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import linear_to_srgb, normalize_normal, srgb_to_linear, validate_maps
from brdfgan.data.materials.base import height_to_normal
from brdfgan.inference.model.tiling import predict_direct
from brdfgan.metrics.svbrdf_metrics import period2_amplitudes
from brdfgan.models.anchored import DEFAULT_ANCHOR_GAIN, METALLIC_BIAS, AnchoredUNet
from brdfgan.runs import load_weights, save_weights
from tests.conftest import random_maps


def test_flat_flash_render_is_our_renderer_on_flat_maps() -> None:
    # render_flash: radiance f·I·cosθ/r² of a flash of intensity 1 at the camera height h; the
    # relative render is π f (1 + |o|²)^-1.5, i.e. π h² times it, for any flat material.
    maps = random_maps(32, 32, seed=2, batch=(2,), dtype=torch.float64)
    maps[:, 3:6] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).view(1, 3, 1, 1)
    fov = 50.0
    frame = centred_flash_frame(2, 32, 32, fov, dtype=torch.float64)
    relative = flat_flash_render(srgb_to_linear(maps[:, :3]), maps[:, 6:7], maps[:, 7:8], frame)
    height = FlashCapture(fov_deg=fov).camera_height
    torch.testing.assert_close(relative, math.pi * height**2 * render_flash(maps, FlashCapture(fov_deg=fov)))


def _photo(size: int = 64, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return 0.05 + 0.8 * torch.rand(2, 3, size, size, generator=generator)


def test_an_untrained_network_returns_the_blurred_delit_photo() -> None:
    torch.manual_seed(0)
    model = AnchoredUNet(width=4, depth=3)
    photo = _photo()
    frame = crop_flash_frame(centred_flash_frame(2, 64, 64, 40.0), 10.0, -6.0)
    maps = model(photo, frame)
    validate_maps(maps)
    # The gained, blurred de-lit photo, 0.7 % of the way to the metal colour's start (grey 0.5).
    metallic = torch.sigmoid(torch.tensor(METALLIC_BIAS))
    anchor = binomial_blur(DEFAULT_ANCHOR_GAIN * delit_photo(photo, frame)).clamp(0.0, 1.0)
    expected = linear_to_srgb(torch.lerp(anchor, torch.full_like(anchor, 0.5), metallic))
    torch.testing.assert_close(maps[:, :3], expected, atol=1e-5, rtol=1e-5)
    assert (expected - linear_to_srgb(anchor)).abs().max() < 0.01
    assert torch.all(maps[:, 3:5] == 0.0) and torch.all(maps[:, 5] == 1.0)  # flat
    assert torch.allclose(maps[:, 6], torch.tensor(0.5)) and torch.allclose(maps[:, 7], metallic)
    # The anchor follows the flash frame: another hotspot gives another base colour.
    assert (model(photo, centred_flash_frame(2, 64, 64, 40.0))[:, :3] - maps[:, :3]).abs().max() > 1e-3


def test_a_checkerboard_on_the_photo_does_not_reach_the_base_colour() -> None:
    photo = _photo()
    frame = centred_flash_frame(2, 64, 64, 40.0)
    checker = (-1.0) ** torch.arange(64).view(1, 1, 1, 64) * (-1.0) ** torch.arange(64).view(1, 1, 64, 1)
    patterned = (photo * (1.0 + 0.2 * checker)).clamp(0.0, 1.0)
    base = AnchoredUNet(width=4, depth=3)(patterned, frame)[:, :3]
    delit = linear_to_srgb((DEFAULT_ANCHOR_GAIN * delit_photo(patterned, frame)).clamp(0.0, 1.0))
    checkerboard = period2_amplitudes(base)[..., 2].abs().sum(), period2_amplitudes(delit)[..., 2].abs().sum()
    assert checkerboard[0] < 0.05 * checkerboard[1]


def test_a_checkerboard_in_the_corrections_does_not_reach_the_base_colour() -> None:
    # A trained decoder's corrections (log-gain, residual, metal colour) are decoded at full
    # resolution; a period-2 pattern in them is removed exactly (the binomial blur's response there
    # is zero), where a smooth change of them does reach the base colour.
    photo = _photo()
    frame = centred_flash_frame(2, 64, 64, 40.0)
    checker = (-1.0) ** (torch.arange(64).view(1, 1, 1, 64) + torch.arange(64).view(1, 1, 64, 1))
    corrections = torch.zeros(1, 11, 1, 1)
    corrections[:, [*range(6), 8, 9, 10]] = 0.05  # logits before the head gain (10)

    model = AnchoredUNet(width=4, depth=3)
    torch.manual_seed(3)
    for parameter in model.material.parameters():  # a metal share and colour that vary
        parameter.data.normal_(0.0, 0.02)
    outputs = {}
    with torch.no_grad():
        clean = model(photo, frame)
        for name, pattern in (("checker", checker), ("smooth", torch.ones_like(checker))):
            handle = model.material.register_forward_hook(
                lambda _module, _inputs, output, pattern=pattern: output + corrections * pattern
            )
            outputs[name] = model(photo, frame)
            handle.remove()
    torch.testing.assert_close(outputs["checker"], clean, atol=1e-5, rtol=1e-5)
    assert (outputs["smooth"][:, :3] - clean[:, :3]).abs().mean() > 0.003


def test_the_head_gain_keeps_the_start_and_scales_every_outputs_step() -> None:
    photo = _photo()
    plain, fast = AnchoredUNet(width=4, depth=3, head_gain=1.0), AnchoredUNet(width=4, depth=3)
    torch.testing.assert_close(fast(photo), plain(photo))  # the same untrained maps
    for model in (plain, fast):
        with torch.no_grad():  # one step's worth of change to each head's bias
            model.material.head_bias[6] += 0.1
            model.surface.head_bias[2] += 0.1
    with torch.no_grad():
        logits = [torch.logit(model(photo)[:, 6:8].mean(dim=(0, 2, 3)).double()) for model in (plain, fast)]
    torch.testing.assert_close(
        logits[0], torch.tensor([0.1, METALLIC_BIAS + 0.1], dtype=torch.float64), atol=1e-5, rtol=0
    )
    torch.testing.assert_close(
        logits[1], torch.tensor([1.0, METALLIC_BIAS + 1.0], dtype=torch.float64), atol=1e-5, rtol=0
    )


def test_at_the_training_learning_rate_the_head_gain_lets_a_batch_be_fitted() -> None:
    # The one-batch overfit that found the slow heads: Adam at the recipe's 2e-4 on one rendered
    # photo. In 60 steps the zero-initialised heads at gain 1 barely move; at the default gain 10
    # the base colour and the normal slopes fit faster (measured L1 after 60 steps, gain 1 / 10:
    # base colour 0.214 / 0.197 — the blurred anchor cannot fit this random texture's finest
    # detail —, slopes 0.117 / 0.072).
    truth = random_maps(32, 32, seed=5, batch=(1,))
    photo = render_flash(truth, FlashCapture(fov_deg=50.0)).clamp(0.0, 1.0)
    photo = photo / photo.mean() * 0.2
    frame = centred_flash_frame(1, 32, 32, 50.0)
    errors = []
    for gain in (1.0, 10.0):
        torch.manual_seed(3)
        model = AnchoredUNet(width=8, depth=2, head_gain=gain, global_features=False, highlight_profile=False)
        optimizer = torch.optim.Adam(model.parameters(), lr=2e-4, betas=(0.5, 0.999))
        for _ in range(60):
            optimizer.zero_grad()
            (model(photo, frame) - truth).abs().mean().backward()
            optimizer.step()
        with torch.no_grad():
            errors.append((model(photo, frame) - truth).abs().mean(dim=(0, 2, 3)))
    slow, fast = errors
    assert fast[0:3].mean() < 0.95 * slow[0:3].mean()
    assert fast[3:5].mean() < 0.7 * slow[3:5].mean()


def test_a_metal_takes_the_free_metal_colour_not_the_delit_photo() -> None:
    model = AnchoredUNet(width=4, depth=3)
    with torch.no_grad():
        model.material.head_bias[6] = 30.0  # metallic 1
        # A copper-like F0 (the head's output is scaled by the head gain).
        model.material.head_bias[8:11] = torch.logit(torch.tensor([0.9, 0.6, 0.3])) / model.head_gain
    maps = model(_photo())
    assert torch.allclose(maps[:, 7], torch.tensor(1.0))
    expected = linear_to_srgb(torch.tensor([0.9, 0.6, 0.3])).view(1, 3, 1, 1).expand_as(maps[:, :3])
    torch.testing.assert_close(maps[:, :3], expected, atol=1e-5, rtol=1e-5)


def test_the_unanchored_variant_reads_the_delit_photo_as_an_input_only() -> None:
    model = AnchoredUNet(width=4, depth=3, anchored=False)
    maps = model(_photo())
    assert torch.allclose(maps[:, :3], linear_to_srgb(torch.full_like(maps[:, :3], 0.5)))


@pytest.mark.parametrize("shading", ["detached", "gradient"])
def test_the_shading_image_reaches_the_surface_decoder_with_or_without_gradient(shading: str) -> None:
    torch.manual_seed(1)
    model = AnchoredUNet(width=4, depth=3, shading=shading)  # type: ignore[arg-type]
    with torch.no_grad():  # heads start at zero: give them weights so gradients can flow
        for head in (model.material.head, model.surface.head):
            head.weight.normal_(0.0, 0.1)
    photo = _photo()
    maps = model(photo)
    maps[:, 3:5].square().sum().backward()  # a loss on the normals only
    material_grad = sum(float(p.grad.abs().sum()) for p in model.material.parameters() if p.grad is not None)
    surface_grad = sum(float(p.grad.abs().sum()) for p in model.surface.parameters() if p.grad is not None)
    assert surface_grad > 0
    # Through the shading image only: the material decoder's gradient from a normal loss.
    assert (material_grad > 0) == (shading == "gradient")


def test_without_shading_the_surface_decoder_ignores_the_albedo_path() -> None:
    model = AnchoredUNet(width=4, depth=3, shading="none")
    assert model.surface.blocks[0][0].in_channels == 2 * 4 + 4  # no extra shading channels


def _slopes_and_curl(model: AnchoredUNet) -> tuple[torch.Tensor, torch.Tensor]:
    """A photo's predicted slope ``∂h/∂x`` and the slopes' discrete curl inside (central
    differences commute, so a height's slopes have none)."""
    normal = model(torch.rand(1, 3, 64, 64))[0, 3:6]
    slope_x, slope_y = -normal[0] / normal[2], -normal[1] / normal[2]  # ∂h/∂x, ∂h/∂y
    curl = (slope_x[:-2, 1:-1] - slope_x[2:, 1:-1]) / 2 - (slope_y[1:-1, 2:] - slope_y[1:-1, :-2]) / 2
    return slope_x, curl


def test_the_height_head_gives_integrable_normals_of_the_generators_convention() -> None:
    torch.manual_seed(3)
    model = AnchoredUNet(width=4, depth=3, head_gain=10.0, normal_head="height")
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    assert model.surface.head.out_channels == 2  # height, roughness logit
    slope_x, curl = _slopes_and_curl(model)
    assert slope_x.abs().mean() > 1e-2  # relief, not a flat map
    assert curl[1:-1, 1:-1].abs().max() < 1e-4 * slope_x.abs().max()  # zero inside
    slopes = AnchoredUNet(width=4, depth=3, head_gain=10.0)  # a slope head's curl is not
    with torch.no_grad():
        slopes.surface.head.weight.normal_(0, 0.1)
    slope_x, curl = _slopes_and_curl(slopes)
    assert curl.abs().max() > 0.1 * slope_x.abs().max()
    # The same slopes as the training data's normals (height_to_normal) away from the borders.
    height = torch.randn(1, 1, 16, 16)
    ours = normalize_normal(torch.cat([height_slope_channels(height), torch.ones_like(height)], dim=1))
    torch.testing.assert_close(ours[0, :, 1:-1, 1:-1], height_to_normal(height[0])[:, 1:-1, 1:-1])
    with pytest.raises(ValueError, match="normal_head"):
        AnchoredUNet(normal_head="depth")  # type: ignore[arg-type]


def test_sizes_configs_and_weights_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(2)
    model = AnchoredUNet(
        width=4, depth=3, shading="gradient", anchor_gain=1.5, head_gain=8.0, global_features=True,
        highlight_profile=True,
    )  # fmt: skip
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    assert model.size_multiple == 8
    with pytest.raises(ValueError, match="multiples of 8"):
        model(torch.rand(1, 3, 60, 64))
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        model(torch.rand(1, 4, 64, 64))
    # predict pads to a size the model takes and crops back.
    assert predict_direct(model.eval(), torch.rand(1, 3, 60, 70)).shape == (1, 8, 60, 70)
    target = "brdfgan.models.anchored.AnchoredUNet"
    path = save_weights(tmp_path / "anchored.safetensors", model, target=target, config=model.config(),
                        model_id="anchored-test", extra={"resolution": 64})  # fmt: skip
    loaded, meta = load_weights(path)
    assert meta["config"] == {
        "width": 4,
        "depth": 3,
        "shading": "gradient",
        "anchored": True,
        "anchor_gain": 1.5,
        "head_gain": 8.0,
        "global_features": True,
        "highlight_profile": True,
        "normal_head": "slopes",
    }
    photo = _photo()
    torch.testing.assert_close(loaded(photo), model(photo))
    with pytest.raises(ValueError, match="shading='sometimes'"):
        AnchoredUNet(shading="sometimes")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="needs global_features"):
        AnchoredUNet(global_features=False)  # the profile (on by default) feeds the track


def test_a_training_step_moves_the_maps_towards_the_truth() -> None:
    # A hundred Adam steps on one photo of known maps: every map's L1 error falls (the network learns
    # through both decoders and the anchor's gain).
    torch.manual_seed(3)
    truth = random_maps(32, 32, seed=5, batch=(1,))
    photo = render_flash(truth, FlashCapture(fov_deg=50.0)).clamp(0.0, 1.0)
    photo = photo / photo.mean() * 0.2
    frame = centred_flash_frame(1, 32, 32, 50.0)
    model = AnchoredUNet(width=8, depth=2, head_gain=1.0)  # at gain 1 this learning rate is stable
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    before = (model(photo, frame) - truth).abs().mean(dim=(0, 2, 3))
    for _ in range(100):
        optimizer.zero_grad()
        loss = (model(photo, frame) - truth).abs().mean()
        loss.backward()
        optimizer.step()
    after = (model(photo, frame) - truth).abs().mean(dim=(0, 2, 3)).detach()
    # Measured: base colour 0.225 -> 0.187 (per-texel noise, which the blurred anchor and
    # corrections cannot copy: the texture is 0.225 from its own blur), normal slopes 0.157 ->
    # 0.062, roughness (per-texel noise) 0.227 -> 0.172, metallic (per-texel coin flips) 0.507 ->
    # 0.242.
    for channels, factor in (
        (slice(0, 3), 0.9),
        (slice(3, 5), 0.6),
        (slice(6, 7), 0.98),
        (slice(7, 8), 0.95),
    ):
        assert after[channels].mean() < factor * before[channels].mean()


@pytest.mark.integration
@pytest.mark.mitsuba
def test_model_anchored_trains_and_validates_in_the_platform(tiny_data: Path) -> None:
    import lightning as L

    from brdfgan.training.run import build
    from tests.conftest import compose_train

    cfg = compose_train(
        ["model=anchored", "model.generator.width=4", "data=tiny", "trainer=cpu", "loss=supervised",
         "loss.compile=false", "logger=csv", "callbacks=none", "trainer.max_epochs=1",
         "trainer.limit_train_batches=2", "trainer.limit_val_batches=1", "trainer.num_sanity_val_steps=0"],
        tiny_data,
    )  # fmt: skip
    L.seed_everything(0)
    datamodule, module, trainer = build(cfg)
    assert isinstance(module.generator, AnchoredUNet) and module.discriminator is None
    before = [p.detach().clone() for p in module.generator.parameters()]
    trainer.fit(module, datamodule=datamodule)
    assert trainer.global_step == 2
    moved = [not torch.equal(a, b) for a, b in zip(before, module.generator.parameters(), strict=True)]
    assert all(moved[-4:])  # the output heads and the anchor gain learnt
    assert math.isfinite(float(trainer.callback_metrics["val/loss"]))


@pytest.mark.integration
def test_experiment_anchored_composes_the_model_data_and_v3_losses(tmp_path: Path) -> None:
    import hydra

    from brdfgan.config_check import check_config
    from brdfgan.losses import GANLoss
    from brdfgan.training.run import CHECKED_GROUPS
    from tests.conftest import compose_train

    cfg = compose_train(["experiment=anchored"], tmp_path)
    check_config(cfg, CHECKED_GROUPS)
    assert cfg.model.generator._target_ == "brdfgan.models.anchored.AnchoredUNet"
    assert cfg.model.generator.normal_head == "slopes"  # not the v3 experiment's unit_z
    assert cfg.data.data_dir.endswith("procedural_and_scans") and cfg.data.sensor.auto_white_balance
    assert cfg.loss.metallic_loss == "bce" and not cfg.loss.switches.adversarial
    assert cfg.data.sensor.auto_white_balance_probability == 0.75
    # The model config carries only what differs from the code's defaults, the shipped model's.
    generator = hydra.utils.instantiate(cfg.model.generator)
    assert generator.config() == AnchoredUNet().config()
    loss = hydra.utils.instantiate(cfg.loss)  # the cross-paired rendering loss
    assert isinstance(loss, GANLoss) and loss.rendering_loss is not None
    assert loss.rendering_loss.pairing == "cross"


@pytest.mark.integration
def test_experiment_anchored_fixres_fine_tunes_stage_one_on_whole_photos(tmp_path: Path) -> None:
    from brdfgan.config_check import check_config
    from brdfgan.training.run import CHECKED_GROUPS
    from tests.conftest import compose_train

    stage_one = compose_train(["experiment=anchored"], tmp_path)
    cfg = compose_train(["experiment=anchored_fixres", "init_from=stage1/last.ckpt"], tmp_path)
    check_config(cfg, CHECKED_GROUPS)
    assert cfg.init_from == "stage1/last.ckpt"
    # Whole photos (stage 1: 128² windows), 1 000 batches.
    assert cfg.data.train_crop is None and stage_one.data.train_crop == 128
    assert cfg.trainer.max_epochs * cfg.data.epoch_samples // cfg.data.batch_size == 1000
    assert cfg.model.optimizer.lr < stage_one.model.optimizer.lr
    # Everything else is stage 1's recipe: the model, the data, the losses.
    assert cfg.model.generator == stage_one.model.generator
    assert cfg.loss == stage_one.loss
    assert cfg.data.data_dir == stage_one.data.data_dir and cfg.data.sensor == stage_one.data.sensor


def test_the_global_track_sets_levels_but_never_tilts_the_normals() -> None:
    # A surface's mean tilt is not an image-wide level: the track feeds every material output and
    # the roughness, not the slopes (with them a trained network tilted every validation photo).
    torch.manual_seed(4)
    # Without the shading image, through which a changed base colour would reach the normals.
    model = AnchoredUNet(width=4, depth=3, shading="none", head_gain=1.0)
    with torch.no_grad():
        for head in (model.material.head, model.surface.head):
            head.weight.normal_(0.0, 0.1)
    photo = _photo()
    before = model(photo)
    assert model.global_track is not None
    with torch.no_grad():
        model.global_track[-1].bias.fill_(0.2)  # × the head gain (10)
    after = model(photo)
    torch.testing.assert_close(after[:, 3:6], before[:, 3:6])  # normals untouched
    assert (after[:, 6] - before[:, 6]).abs().min() > 0.01  # roughness moved everywhere
    assert (after[:, 7] - before[:, 7]).abs().min() > 1e-4  # metallic too


def _flat_photo(
    roughness: float, metallic: float, size: int = 256, exposure: float = 0.9
) -> tuple[torch.Tensor, torch.Tensor]:
    """A flat grey surface's flash photo (linear, clipped at 1 as a sensor does) and its frame."""
    maps = random_maps(size, size, seed=0, batch=(1,))
    maps[:, 0:3] = 0.5
    maps[:, 3:6] = torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1)
    maps[:, 6:7], maps[:, 7:8] = roughness, metallic
    capture = FlashCapture(fov_deg=50.0)
    photo = render_flash(maps, capture)
    return (photo / photo.max() * exposure).clamp(0.0, 1.0), centred_flash_frame(1, size, size, 50.0)


def test_the_highlight_profile_reads_the_lobe_width() -> None:
    from brdfgan.models.image_statistics import PROFILE_RINGS, HighlightProfile

    def profile(photo: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
        return HighlightProfile()(delit_photo(photo, frame, clip=False), photo, frame)

    # A matte surface: the de-lit photo is flat, so every ring reads ~0, nothing clipped.
    relative, clipped, present = profile(*_flat_photo(roughness=1.0, metallic=0.0))[0].split(PROFILE_RINGS)
    assert relative.abs().max() < 0.05 and clipped.max() == 0.0 and present.min() == 1.0
    # Glossy metals: the rings near the hotspot rise above the image's mean, a sharper lobe higher
    # at the centre and narrower (measured 6.6 → 0.6 at ring 5 for roughness 0.15; 3.8 → 2.5 for 0.35).
    sharp = profile(*_flat_photo(roughness=0.15, metallic=1.0))[0].split(PROFILE_RINGS)[0]
    broad = profile(*_flat_photo(roughness=0.35, metallic=1.0))[0].split(PROFILE_RINGS)[0]
    assert sharp[0] > broad[0] + 2.0
    assert sharp[5] < 1.0 < 2.0 < broad[5]
    # Over-exposed, the sensor clips the lobe's middle: the clipped share says how far out.
    clipped = profile(*_flat_photo(roughness=0.15, metallic=1.0, exposure=5.0))[0].split(PROFILE_RINGS)[1]
    assert clipped[0] == 1.0 and clipped[5] == 0.0
    # A crop away from the hotspot does not reach the inner rings: they read 0, flagged absent.
    photo, frame = _flat_photo(roughness=0.15, metallic=1.0)
    corner = profile(photo[..., :32, :32], crop_flash_frame(frame, 0.0, 0.0))[0].split(PROFILE_RINGS)
    assert corner[2][0] == 0.0 and corner[0][0] == 0.0 and corner[2][-1] == 1.0


def test_a_config_stored_before_the_shipped_defaults_keeps_its_own_defaults() -> None:
    from brdfgan.runs import WeightsError, build_network

    target = "brdfgan.models.anchored.AnchoredUNet"
    # Written before issue 48 (no normal_head): a missing key meant the old default, so a network
    # that relied on the unblurred anchor is refused by name, not built with today's defaults.
    with pytest.raises(WeightsError, match="anchor_blur=False is a retired option"):
        build_network(target, {"width": 4, "depth": 3, "head_gain": 10.0}, "old.yaml")
    old = {"width": 4, "depth": 3, "anchor_blur": True, "correction_blur": True}
    built = build_network(target, old, "old.yaml")
    assert isinstance(built, AnchoredUNet)
    assert (built.head_gain, built.global_features, built.highlight_profile) == (1.0, False, False)
    # Written since: missing keys are today's defaults.
    new = build_network(target, {"width": 4, "depth": 3, "normal_head": "slopes"}, "new.yaml")
    assert isinstance(new, AnchoredUNet) and new.head_gain == 10.0
