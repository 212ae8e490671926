from __future__ import annotations

import math

import pytest
import torch
from torch import Tensor, nn

import brdfgan.losses.rendering as rendering_module
import brdfgan.losses.total as total_module
from brdfgan.core.sampling import RenderingLossSampling, sample_rendering_loss_configs
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, NORMAL, ROUGHNESS, flat_maps, join_maps
from brdfgan.errors import UserError
from brdfgan.losses import (
    ANGULAR_EPS,
    GANLoss,
    LossSwitches,
    RenderingLoss,
    angular_distance,
    discriminator_total,
    feature_matching_loss,
    generator_total,
    lsgan_discriminator_loss,
    lsgan_generator_loss,
    parameter_loss,
    rendering_loss,
)
from tests.conftest import random_maps

# -- parameter loss -------------------------------------------------------------------------


def _normals(*vectors: tuple[float, float, float]) -> Tensor:
    """One pixel per vector: ``(N, 3, 1, 1)``."""
    return torch.tensor(vectors, dtype=torch.float64).view(-1, 3, 1, 1)


def test_angular_distance_golden_values() -> None:
    a = _normals((0, 0, 1), (0, 0, 1), (0, 0, 1), (1, 0, 0))
    b = _normals((1, 0, 0), (0, 0, -1), (0, 0, 1), (0, math.sqrt(0.5), math.sqrt(0.5)))
    d = angular_distance(a, b)
    assert d.shape == (4, 1, 1)
    floor = math.acos(1 - ANGULAR_EPS) / math.pi  # documented cost of the clamp
    torch.testing.assert_close(d.flatten(), torch.tensor([0.5, 1 - floor, floor, 0.5], dtype=torch.float64))
    assert floor < 1e-3


def test_angular_distance_renormalises_and_checks_input() -> None:
    a, b = _normals((0, 0, 2)), _normals((0, 3, 0))
    torch.testing.assert_close(angular_distance(a, b), torch.full((1, 1, 1), 0.5, dtype=torch.float64))
    with pytest.raises(ValueError, match="same shape"):
        angular_distance(a, b[..., :0])
    with pytest.raises(ValueError, match="3 components"):
        angular_distance(torch.ones(1, 2, 1, 1), torch.ones(1, 2, 1, 1))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.bfloat16])
def test_angular_distance_gradient_is_finite_for_identical_and_opposite_normals(dtype: torch.dtype) -> None:
    normal = random_maps(4, 4, batch=(2,))[:, NORMAL].to(dtype)
    for other in (normal.clone(), -normal.clone()):
        a = normal.clone().requires_grad_(True)
        angular_distance(a, other).sum().backward()
        assert a.grad is not None and torch.isfinite(a.grad).all()


def test_angular_distance_gradcheck() -> None:
    a = random_maps(3, 3, seed=1, dtype=torch.float64)[NORMAL].requires_grad_(True)
    b = random_maps(3, 3, seed=2, dtype=torch.float64)[NORMAL]
    assert torch.autograd.gradcheck(lambda x: angular_distance(x, b), (a,))


def test_parameter_loss_golden_values() -> None:
    pred = join_maps(
        torch.full((1, 3, 2, 2), 0.5), _normals((1, 0, 0)).float().expand(1, 3, 2, 2),
        torch.full((1, 1, 2, 2), 0.6), torch.ones(1, 1, 2, 2),
    )  # fmt: skip
    target = flat_maps(2, 2, basecolor=(0.25, 0.25, 0.25), roughness=0.5, metallic=0.0, batch=(1,))
    terms = parameter_loss(pred, target)
    expected = {
        "param_basecolor": 0.25,  # compared in the stored sRGB encoding
        "param_normal": 0.5,  # orthogonal normals
        "param_roughness": 0.1,
        "param_metallic": 1.0,
        "param": 1.85,  # the sum of the four per-map means
    }
    assert set(terms) == set(expected)
    for name, value in expected.items():
        torch.testing.assert_close(terms[name], torch.tensor(value), msg=name)


def test_parameter_loss_zero_for_identical_maps_and_checks_input() -> None:
    maps = random_maps(8, 8, batch=(2,))
    terms = parameter_loss(maps, maps.clone())
    assert terms["param"] < 1e-3
    assert terms["param_basecolor"] == 0 and terms["param_roughness"] == 0
    with pytest.raises(ValueError, match="same shape"):
        parameter_loss(maps, maps[:1])
    with pytest.raises(ValueError, match="8, H, W"):
        parameter_loss(maps[:, :7], maps[:, :7])


# -- rendering loss -------------------------------------------------------------------------


def _configs(batch: int, seed: int = 0, dtype: torch.dtype = torch.float64):
    return sample_rendering_loss_configs(batch, generator=torch.Generator().manual_seed(seed), dtype=dtype)


def test_rendering_loss_zero_for_identical_maps_positive_otherwise() -> None:
    maps = random_maps(8, 8, batch=(2,))
    configs = _configs(2, dtype=torch.float32)
    assert rendering_loss(maps, maps.clone(), configs) == 0
    assert rendering_loss(random_maps(8, 8, seed=1, batch=(2,)), maps, configs) > 0.01


def test_rendering_loss_detects_a_roughness_only_change() -> None:
    target = random_maps(8, 8, batch=(2,))
    pred = target.clone()
    pred[:, ROUGHNESS] = (pred[:, ROUGHNESS] + 0.2).clamp(max=1.0)
    assert rendering_loss(pred, target, _configs(2, dtype=torch.float32)) > 1e-3


def test_rendering_loss_gradcheck_wrt_prediction_and_no_grad_for_target() -> None:
    target = random_maps(4, 4, seed=3, batch=(1,), dtype=torch.float64).requires_grad_(True)
    pred = random_maps(4, 4, seed=4, batch=(1,), dtype=torch.float64).requires_grad_(True)
    configs = _configs(1)
    assert torch.autograd.gradcheck(lambda p: rendering_loss(p, target, configs), (pred,))
    rendering_loss(pred, target, configs).backward()
    assert target.grad is None  # the target is rendered without autograd


def test_rendering_loss_checks_input() -> None:
    maps = random_maps(4, 4, batch=(2,))
    with pytest.raises(ValueError, match="same shape"):
        rendering_loss(maps, maps[:1], _configs(2))
    with pytest.raises(ValueError, match="batch of 3"):
        rendering_loss(maps, maps, _configs(3))


def test_rendering_loss_module_draws_ten_fresh_reproducible_configurations() -> None:
    pred, target = random_maps(4, 4, seed=1, batch=(2,)), random_maps(4, 4, seed=2, batch=(2,))
    loss_a, configs_a = RenderingLoss(seed=7)(pred, target, return_configs=True)
    assert configs_a.camera_position.shape == (2, 10, 3)  # the paper's ten renderings per sample

    module = RenderingLoss(seed=7)
    loss_b = module(pred, target)
    torch.testing.assert_close(loss_a, loss_b)  # same seed, same configurations
    loss_next, configs_next = module(pred, target, return_configs=True)
    assert not torch.equal(configs_next.camera_position, configs_a.camera_position)  # fresh per call
    module.reseed(7)
    torch.testing.assert_close(module(pred, target), loss_a)
    _, configs_other = RenderingLoss(seed=8)(pred, target, return_configs=True)
    assert not torch.equal(configs_other.camera_position, configs_a.camera_position)
    assert not torch.equal(loss_next, loss_a)


def test_rendering_loss_module_honours_its_sampling() -> None:
    module = RenderingLoss(RenderingLossSampling(random_configs=2, specular_configs=1))
    maps = random_maps(4, 4, batch=(1,))
    _, configs = module(maps, maps, return_configs=True)
    assert configs.camera_position.shape == (1, 3, 3)


def test_cross_pairing_stops_a_bright_base_colour_from_pulling_roughness_down() -> None:
    """A uniform metal (roughness 0.3) predicted with too bright a base colour: the joint render
    is matched best by a glossier roughness (the error paid back), the cross-paired one by the
    true roughness, since the roughness is rendered beside the true base colour."""
    target = flat_maps(32, 32, batch=(4,))
    target[:, BASECOLOR] = 0.6
    target[:, METALLIC] = 1.0
    target[:, ROUGHNESS] = 0.3
    configs = _configs(4, dtype=torch.float32)
    scales = (0.5, 0.7, 1.0, 1.4)

    def best_scale(pairing: str) -> float:
        losses = []
        for k in scales:
            pred = target.clone()
            pred[:, BASECOLOR] = 0.8
            pred[:, ROUGHNESS] = 0.3 * k
            losses.append(rendering_loss(pred, target, configs, pairing=pairing).item())
        return scales[losses.index(min(losses))]

    assert best_scale("joint") < 1.0
    assert best_scale("cross") == 1.0


def test_cross_pairing_routes_each_error_to_its_half_and_gradients_to_the_predicted_maps() -> None:
    target = random_maps(8, 8, batch=(2,), dtype=torch.float64)
    configs = _configs(2)
    assert rendering_loss(target, target.clone(), configs, pairing="cross") == 0
    # A roughness error shows only in the (normal, roughness) half: the same loss as rendering
    # the joint maps under the odd-numbered configurations, halved (the other half is exact).
    pred = target.clone()
    pred[:, ROUGHNESS] = (pred[:, ROUGHNESS] + 0.2).clamp(max=1.0)
    odd = configs.map_tensors(lambda t: t[:, 1::2])
    torch.testing.assert_close(
        rendering_loss(pred, target, configs, pairing="cross"), rendering_loss(pred, target, odd) / 2
    )
    pred = random_maps(8, 8, seed=4, batch=(2,), dtype=torch.float64).requires_grad_(True)
    rendering_loss(pred, target, configs, pairing="cross").backward()
    assert pred.grad is not None
    assert all(pred.grad[:, part].abs().sum() > 0 for part in (BASECOLOR, NORMAL, ROUGHNESS))
    with pytest.raises(ValueError, match="pairing"):
        rendering_loss(pred, target, configs, pairing="both")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="even number"):
        RenderingLoss(RenderingLossSampling(random_configs=2, specular_configs=1), pairing="cross")
    with pytest.raises(UserError, match="rendering_pairing"):
        GANLoss(
            rendering_sampling=RenderingLossSampling(random_configs=2, specular_configs=1),
            rendering_pairing="cross",
        )
    with pytest.raises(UserError, match="rendering_pairing"):
        GANLoss(rendering_pairing="both")  # type: ignore[arg-type]


# -- adversarial and feature matching -------------------------------------------------------


def _outputs(*scales: tuple[float, ...], shapes=((2, 4, 8, 8), (2, 8, 4, 4))) -> list[list[Tensor]]:
    """Per scale, constant layers with the given values (layer shapes cycle through ``shapes``)."""
    return [
        [torch.full(shapes[(i + k) % len(shapes)], float(v)) for i, v in enumerate(values)]
        for k, values in enumerate(scales)
    ]


def test_lsgan_golden_values() -> None:
    ones, zeros = _outputs((0, 1), (0, 1)), _outputs((0, 0), (0, 0))
    assert lsgan_discriminator_loss(ones, zeros) == 0  # real → 1, fake → 0: a perfect discriminator
    torch.testing.assert_close(lsgan_discriminator_loss(zeros, ones), torch.tensor(1.0))  # ½·1 + ½·1
    torch.testing.assert_close(lsgan_discriminator_loss(ones, ones), torch.tensor(0.5))
    assert lsgan_generator_loss(ones) == 0
    torch.testing.assert_close(lsgan_generator_loss(zeros), torch.tensor(0.5))
    # Scales are averaged: ½ on one scale, 0 on the other.
    torch.testing.assert_close(lsgan_generator_loss(_outputs((5, 0), (5, 1))), torch.tensor(0.25))
    # Only the last layer (the patch scores) counts.
    assert lsgan_generator_loss(_outputs((123, 1), (-4, 1))) == 0


def test_feature_matching_golden_value_and_only_first_layers() -> None:
    real = _outputs((1, 2, 3, 4, 5, 0), (1, 2, 3, 4, 5, 0))
    fake = _outputs((0, 0, 3, 4, 9, 1), (1, 2, 3, 1, -7, 1))
    # scale 1: (1² + 2² + 0 + 0)/4 = 1.25; scale 2: (0 + 0 + 0 + 3²)/4 = 2.25; mean over scales 1.75
    torch.testing.assert_close(feature_matching_loss(real, fake), torch.tensor(1.75))
    fake[0][4] = fake[0][4] + 100.0  # layer 5 is not among the first four
    torch.testing.assert_close(feature_matching_loss(real, fake), torch.tensor(1.75))
    torch.testing.assert_close(feature_matching_loss(real, fake, layers=1), torch.tensor(0.5))


def test_feature_matching_detaches_real_features_unless_asked() -> None:
    real = [[t.requires_grad_(True) for t in scale] for scale in _outputs((1, 2, 3, 4, 5))]
    fake = [[t.requires_grad_(True) for t in scale] for scale in _outputs((0, 0, 0, 0, 0))]
    feature_matching_loss(real, fake).backward()
    assert all(t.grad is None for t in real[0])
    assert all(t.grad is not None for t in fake[0][:4]) and fake[0][4].grad is None
    feature_matching_loss(real, fake, detach_real=False).backward()
    assert all(t.grad is not None for t in real[0][:4])


def test_adversarial_losses_check_input() -> None:
    two, one = _outputs((0, 1), (0, 1)), _outputs((0, 1))
    with pytest.raises(ValueError, match="numbers of scales"):
        lsgan_discriminator_loss(two, one)
    with pytest.raises(ValueError, match="non-empty"):
        lsgan_generator_loss([])
    with pytest.raises(ValueError, match="per-layer"):
        lsgan_generator_loss([torch.zeros(1)])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="need at least 4"):
        feature_matching_loss(two, two)
    with pytest.raises(ValueError, match="differ"):
        feature_matching_loss(two, _outputs((0, 1), (0, 1), shapes=((1, 1, 2, 2),)), layers=1)


# -- totals and GANLoss ---------------------------------------------------------------------

_TERMS = {"g_adv": 1.0, "g_feat": 2.0, "param": 3.0, "render": 4.0}
_SWITCH_OF = {"g_adv": "adversarial", "g_feat": "feature", "param": "parameter", "render": "rendering"}


def test_generator_total_is_a_quarter_of_the_enabled_terms() -> None:
    terms = {name: torch.tensor(v) for name, v in _TERMS.items()} | {"param_normal": torch.tensor(99.0)}
    torch.testing.assert_close(generator_total(terms), torch.tensor(2.5))
    for name, switch in _SWITCH_OF.items():
        total = generator_total(terms, LossSwitches(**{switch: False}))
        # the ¼ stays: switching a term off removes exactly that term
        torch.testing.assert_close(total, torch.tensor(2.5 - _TERMS[name] / 4))
    with pytest.raises(KeyError, match="render"):
        generator_total({k: v for k, v in terms.items() if k != "render"})


def test_discriminator_total_and_switches() -> None:
    torch.testing.assert_close(discriminator_total(torch.tensor(1.0), torch.tensor(3.0)), torch.tensor(1.03))
    torch.testing.assert_close(discriminator_total(torch.tensor(1.0)), torch.tensor(1.0))
    assert LossSwitches().needs_discriminator
    assert LossSwitches(adversarial=False).needs_discriminator
    assert LossSwitches(feature=False).needs_discriminator
    assert not LossSwitches(adversarial=False, feature=False).needs_discriminator
    with pytest.raises(ValueError, match="at least one"):
        LossSwitches(False, False, False, False)


class _TinyDiscriminator(nn.Module):
    """Two scales of five layers (four features + patch scores), like the paper's D1/D2."""

    def __init__(self) -> None:
        super().__init__()
        self.scales = nn.ModuleList(
            nn.ModuleList([nn.Conv2d(8, 4, 3, padding=1)] + [nn.Conv2d(4, 4, 3, padding=1) for _ in range(3)]
                          + [nn.Conv2d(4, 1, 3, padding=1)])
            for _ in range(2)
        )  # fmt: skip

    def forward(self, maps: Tensor) -> list[list[Tensor]]:
        outputs = []
        for k, layers in enumerate(self.scales):
            x = nn.functional.avg_pool2d(maps, 2) if k else maps
            features = []
            for layer in layers:
                x = layer(x)
                features.append(x)
                x = nn.functional.leaky_relu(x, 0.2)
            outputs.append(features)
        return outputs


def _spy(monkeypatch: pytest.MonkeyPatch, module, name: str) -> list[int]:
    calls: list[int] = []
    original = getattr(module, name)

    def wrapper(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, wrapper)
    return calls


def test_gan_loss_full_terms_gradients_and_detaching() -> None:
    torch.manual_seed(0)
    disc = _TinyDiscriminator()
    true_maps = random_maps(8, 8, seed=1, batch=(2,))
    pred = random_maps(8, 8, seed=2, batch=(2,)).requires_grad_(True)
    loss = GANLoss(seed=3)

    terms = loss.generator_terms(pred, true_maps, disc(pred), disc(true_maps))
    assert set(terms) == {"g_adv", "g_feat", "param", "param_basecolor", "param_normal", "param_roughness",
                          "param_metallic", "render", "g_total"}  # fmt: skip
    torch.testing.assert_close(terms["g_total"], 0.25 * sum(terms[n] for n in _TERMS))
    terms["g_total"].backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0

    # D step: the caller detaches the prediction, so nothing reaches the generator output.
    pred.grad = None
    d_terms = loss.discriminator_terms(disc(true_maps), disc(pred.detach()))
    assert set(d_terms) == {"d_adv", "d_feat", "d_total"}
    torch.testing.assert_close(d_terms["d_total"], d_terms["d_adv"] + 0.01 * d_terms["d_feat"])
    d_terms["d_total"].backward()
    assert pred.grad is None
    assert all(p.grad is not None for p in disc.parameters())


@pytest.mark.parametrize("term", list(_TERMS))
def test_gan_loss_switched_off_term_is_never_computed(monkeypatch: pytest.MonkeyPatch, term: str) -> None:
    spies = {
        "g_adv": _spy(monkeypatch, total_module, "lsgan_generator_loss"),
        "g_feat": _spy(monkeypatch, total_module, "feature_matching_loss"),
        "param": _spy(monkeypatch, total_module, "parameter_loss"),
        # RenderingLoss binds the loss function when it is built, after this patch.
        "render": _spy(monkeypatch, rendering_module, "rendering_loss"),
    }
    disc = _TinyDiscriminator()
    true_maps, pred = random_maps(4, 4, seed=1, batch=(1,)), random_maps(4, 4, seed=2, batch=(1,))
    loss = GANLoss(LossSwitches(**{_SWITCH_OF[term]: False}))
    terms = loss.generator_terms(pred, true_maps, disc(pred), disc(true_maps))
    assert term not in terms
    assert spies[term] == []
    assert all(spy for name, spy in spies.items() if name != term)
    others = [n for n in _TERMS if n != term]
    torch.testing.assert_close(terms["g_total"], 0.25 * sum(terms[n] for n in others))
    if term == "render":
        assert loss.rendering_loss is None


def test_gan_loss_without_discriminator_terms() -> None:
    loss = GANLoss(LossSwitches(adversarial=False, feature=False))
    assert not loss.switches.needs_discriminator
    true_maps, pred = random_maps(4, 4, seed=1, batch=(1,)), random_maps(4, 4, seed=2, batch=(1,))
    terms = loss.generator_terms(pred, true_maps)  # no discriminator outputs needed
    torch.testing.assert_close(terms["g_total"], 0.25 * (terms["param"] + terms["render"]))
    with pytest.raises(RuntimeError, match="discriminator"):
        loss.discriminator_terms(_outputs((0, 1)), _outputs((0, 1)))
    # Without the feature term the D total is L_a(D) alone.
    d_terms = GANLoss(LossSwitches(feature=False)).discriminator_terms(_outputs((0, 1)), _outputs((0, 0)))
    assert set(d_terms) == {"d_adv", "d_total"} and d_terms["d_total"] == 0


def test_gan_loss_asks_for_missing_discriminator_outputs() -> None:
    maps = random_maps(4, 4, batch=(1,))
    with pytest.raises(ValueError, match="d_fake"):
        GANLoss().generator_terms(maps, maps)
    with pytest.raises(ValueError, match="d_real"):
        GANLoss(LossSwitches(adversarial=False)).generator_terms(maps, maps, _outputs((0, 1)))


@pytest.mark.slow  # one torch.compile of forward and backward: ~10–30 s on CPU
@pytest.mark.parametrize("pairing", ["joint", "cross"])
def test_compiled_rendering_loss_matches_eager_and_logs_compile_time(
    caplog: pytest.LogCaptureFixture, pairing: str
) -> None:
    import logging

    from brdfgan.losses.rendering import RenderingLoss

    pred_maps = random_maps(16, 16, batch=(2,))
    true_maps = random_maps(16, 16, batch=(2,), seed=1)
    results = []
    for compiled in (False, True):
        loss_fn = RenderingLoss(seed=5, compile=compiled, pairing=pairing)  # type: ignore[arg-type]
        values, grads = [], []
        for _ in range(2):  # the second call runs the compiled code without compiling again
            pred = pred_maps.clone().requires_grad_(True)
            with caplog.at_level(logging.INFO, logger="brdfgan.losses.rendering"):
                value = loss_fn(pred, true_maps)
            value.backward()
            values.append(value.detach())
            grads.append(pred.grad)
        results.append((values, grads))
    compile_lines = [r.getMessage() for r in caplog.records if "compiled" in r.getMessage()]
    assert len(compile_lines) == 1 and "(2, 8, 16, 16)" in compile_lines[0]
    (eager_values, eager_grads), (compiled_values, compiled_grads) = results
    for eager, compiled in zip(eager_values, compiled_values, strict=True):
        torch.testing.assert_close(compiled, eager, rtol=1e-4, atol=1e-6)
    # Gradients to a thousandth of their largest element: the fused kernels sum in another order,
    # and a few texels next to a clamp's bound came out 1 % apart (1e-5 of a largest 1e-2).
    for eager, compiled in zip(eager_grads, compiled_grads, strict=True):
        torch.testing.assert_close(compiled, eager, rtol=1e-4, atol=1e-3 * eager.abs().max().item())


def test_metallic_bce_golden_values_and_its_minimiser_is_the_mean() -> None:
    from brdfgan.losses.parameter import metallic_bce

    pred = torch.tensor([0.25, 0.5, 0.9]).view(1, 3, 1)
    target = torch.tensor([0.0, 1.0, 1.0]).view(1, 3, 1)
    expected = torch.tensor([-math.log(0.75), -math.log(0.5), -math.log(0.9)]).view(1, 3, 1)
    torch.testing.assert_close(metallic_bce(pred, target), expected)
    # A constant prediction against a map with 20 % metal: BCE is lowest at 0.2 (the mean), L1
    # at 0 (the median) — why the option exists.
    truth = (torch.arange(100) < 20).float().view(1, 1, 10, 10)
    candidates = torch.linspace(0.0, 1.0, 101)
    bce = torch.stack([metallic_bce(torch.full_like(truth, float(c)), truth).mean() for c in candidates])
    l1 = torch.stack([(torch.full_like(truth, float(c)) - truth).abs().mean() for c in candidates])
    assert candidates[bce.argmin()].item() == pytest.approx(0.2)
    assert candidates[l1.argmin()].item() == 0.0


def test_parameter_loss_metallic_option_changes_only_the_metallic_term() -> None:
    pred, true_maps = random_maps(8, 8, seed=1, batch=(2,)), random_maps(8, 8, seed=2, batch=(2,))
    pred[:, METALLIC] = pred[:, METALLIC].clamp(0.1, 0.9)
    l1 = parameter_loss(pred, true_maps)
    bce = parameter_loss(pred, true_maps, metallic="bce")
    for name in ("param_basecolor", "param_normal", "param_roughness"):
        torch.testing.assert_close(l1[name], bce[name])
    assert not torch.allclose(l1["param_metallic"], bce["param_metallic"])
    torch.testing.assert_close(bce["param"] - l1["param"], bce["param_metallic"] - l1["param_metallic"])
    with pytest.raises(ValueError, match="metallic"):
        parameter_loss(pred, true_maps, metallic="l2")  # type: ignore[arg-type]
    loss = GANLoss(LossSwitches(adversarial=False, feature=False, rendering=False), metallic_loss="bce")
    torch.testing.assert_close(loss.generator_terms(pred, true_maps)["param_metallic"], bce["param_metallic"])


def test_tilt_squared_error_golden_values_and_its_minimiser_is_the_mean() -> None:
    from brdfgan.losses.parameter import tilt_squared_error

    flat = torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1)
    tilted = torch.tensor([0.6, 0.0, 0.8]).view(1, 3, 1, 1)  # slope 0.75 along x
    both = torch.tensor([0.0, 0.6, 0.8]).view(1, 3, 1, 1)
    torch.testing.assert_close(tilt_squared_error(tilted, flat), torch.full((1, 1, 1), 0.5625))
    torch.testing.assert_close(tilt_squared_error(tilted, both), torch.full((1, 1, 1), 2 * 0.5625))
    assert tilt_squared_error(tilted, tilted).item() == 0.0
    # Against a field that is flat on 60 % of the texels and tilted on the rest, a constant slope
    # scores best at the mean slope with this error and at flat with the angle — why the term exists.
    truth = torch.zeros(1, 3, 10, 10)
    truth[:, 2] = 1.0
    truth[:, :, 6:] = tilted
    candidates = torch.linspace(0.0, 0.75, 16)

    def constant(slope: float) -> Tensor:
        vector = torch.tensor([slope, 0.0, 1.0])
        return (vector / vector.norm()).view(1, 3, 1, 1).expand(1, 3, 10, 10)

    squared = torch.stack([tilt_squared_error(constant(float(c)), truth).mean() for c in candidates])
    angle = torch.stack([angular_distance(constant(float(c)), truth).mean() for c in candidates])
    assert candidates[squared.argmin()].item() == pytest.approx(0.3)
    assert candidates[angle.argmin()].item() == 0.0


def test_normal_tilt_weight_adds_to_the_normal_term_only() -> None:
    from brdfgan.losses.parameter import tilt_squared_error

    pred, true_maps = random_maps(8, 8, seed=1, batch=(2,)), random_maps(8, 8, seed=2, batch=(2,))
    paper = parameter_loss(pred, true_maps)
    tilted = parameter_loss(pred, true_maps, normal_tilt_weight=2.0)
    extra = 2.0 * tilt_squared_error(pred[:, NORMAL], true_maps[:, NORMAL]).mean()
    torch.testing.assert_close(tilted["param_normal"], paper["param_normal"] + extra)
    torch.testing.assert_close(tilted["param"], paper["param"] + extra)
    for name in ("param_basecolor", "param_roughness", "param_metallic"):
        torch.testing.assert_close(tilted[name], paper[name])
    with pytest.raises(ValueError, match="normal_tilt_weight"):
        parameter_loss(pred, true_maps, normal_tilt_weight=-1.0)
    loss = GANLoss(LossSwitches(adversarial=False, feature=False, rendering=False), normal_tilt_weight=2.0)
    torch.testing.assert_close(loss.generator_terms(pred, true_maps)["param_normal"], tilted["param_normal"])


def test_parameter_maps_sum_only_the_chosen_terms_and_train_only_those_maps() -> None:
    pred, true_maps = random_maps(8, 8, seed=3, batch=(2,)), random_maps(8, 8, seed=4, batch=(2,))
    every = parameter_loss(pred, true_maps)
    chosen = parameter_loss(pred, true_maps, maps=("normal", "metallic"))
    for name in ("param_basecolor", "param_normal", "param_roughness", "param_metallic"):
        torch.testing.assert_close(chosen[name], every[name])  # all four still reported
    torch.testing.assert_close(chosen["param"], every["param_normal"] + every["param_metallic"])
    for maps in ((), ("albedo",)):
        with pytest.raises(ValueError, match="maps must be"):
            parameter_loss(pred, true_maps, maps=maps)

    # Normals alone: no other channel of the prediction gets a gradient.
    live = pred.clone().requires_grad_(True)
    loss = GANLoss(LossSwitches(adversarial=False, feature=False, rendering=False), parameter_maps=["normal"])
    loss.generator_terms(live, true_maps)["g_total"].backward()
    assert live.grad is not None
    assert live.grad[:, NORMAL].abs().sum() > 0
    for index in (BASECOLOR, ROUGHNESS, METALLIC):
        assert live.grad[:, index].abs().sum() == 0
    with pytest.raises(UserError, match=r"loss.parameter_maps=\['normals'\]"):
        GANLoss(parameter_maps=["normals"])
