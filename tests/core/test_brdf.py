from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.brdf import evaluate_brdf, normalize
from brdfgan.core.sampling import sample_cosine_hemisphere
from brdfgan.core.svbrdf import roughness_to_alpha, srgb_to_linear


def _vec(x: float, y: float, z: float) -> torch.Tensor:
    return normalize(torch.tensor([x, y, z], dtype=torch.float64).view(3, 1, 1))


def _scalar(v: float) -> torch.Tensor:
    return torch.full((1, 1, 1), v, dtype=torch.float64)


def test_golden_value_at_normal_incidence() -> None:
    # l = v = n: Burley factors are 1, G1 = 1, D = 1/(π α²), F = F0 → f = d/π + F0/(4 π α²).
    base = torch.full((3, 1, 1), 0.5, dtype=torch.float64)
    n = _vec(0, 0, 1)
    f = evaluate_brdf(srgb_to_linear(base), n, _scalar(0.5), _scalar(0.0), n, n)
    expected = 0.21404114048223255 / math.pi + 0.04 / (4 * math.pi * 0.25**2)
    torch.testing.assert_close(f, torch.full_like(f, expected), rtol=1e-9, atol=0)
    assert expected == pytest.approx(0.1190610, abs=1e-7)


def test_reciprocity() -> None:
    g = torch.Generator().manual_seed(1)
    n = 64
    dirs_a = sample_cosine_hemisphere((n,), g, dtype=torch.float64).view(n, 3, 1, 1)
    dirs_b = sample_cosine_hemisphere((n,), g, dtype=torch.float64).view(n, 3, 1, 1)
    normal = normalize(torch.tensor([0.2, -0.1, 1.0], dtype=torch.float64).view(3, 1, 1))
    base = torch.rand((n, 3, 1, 1), generator=g, dtype=torch.float64)
    rough = 0.1 + 0.9 * torch.rand((n, 1, 1, 1), generator=g, dtype=torch.float64)
    metal = torch.rand((n, 1, 1, 1), generator=g, dtype=torch.float64)
    forward = evaluate_brdf(base, normal, rough, metal, dirs_a, dirs_b)
    backward = evaluate_brdf(base, normal, rough, metal, dirs_b, dirs_a)
    assert (forward > 0).any()
    torch.testing.assert_close(forward, backward, rtol=1e-12, atol=1e-14)


def test_metallic_one_has_no_diffuse_and_zero_has_dielectric_f0() -> None:
    light, view, n = _vec(0.3, 0.1, 1), _vec(-0.2, 0.2, 1), _vec(0, 0, 1)
    base = torch.tensor([0.9, 0.4, 0.1], dtype=torch.float64).view(3, 1, 1)
    diffuse_only = evaluate_brdf(base, n, _scalar(0.4), _scalar(1.0), light, view, specular_lobe=False)
    assert torch.count_nonzero(diffuse_only) == 0
    full = evaluate_brdf(base, n, _scalar(0.4), _scalar(1.0), light, view)
    spec = evaluate_brdf(base, n, _scalar(0.4), _scalar(1.0), light, view, diffuse_lobe=False)
    torch.testing.assert_close(full, spec)
    # Dielectric specular is grey whatever the base color.
    dielectric_spec = evaluate_brdf(base, n, _scalar(0.4), _scalar(0.0), light, view, diffuse_lobe=False)
    torch.testing.assert_close(dielectric_spec, dielectric_spec[:1].expand(3, 1, 1))


def test_zero_below_the_horizon() -> None:
    base = torch.full((3, 1, 1), 0.5, dtype=torch.float64)
    f = evaluate_brdf(base, _vec(0, 0, 1), _scalar(0.5), _scalar(0.0), _vec(1, 0, -0.1), _vec(0, 0, 1))
    assert torch.count_nonzero(f) == 0


def _directional_albedo(
    base_linear: float, roughness: float, metallic: float, view_deg: float, samples: int
) -> float:
    """∫ f(l, v) cos θ_l dl by importance sampling: GGX half vectors for the specular lobe, the
    cosine for the diffuse lobe (the lobes add, so each is integrated with its own estimator)."""
    g = torch.Generator().manual_seed(7)
    t = math.radians(view_deg)
    v = torch.tensor([math.sin(t), 0.0, math.cos(t)], dtype=torch.float64).view(1, 3, 1, 1)
    n = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).view(1, 3, 1, 1)
    b = torch.full((1, 3, 1, 1), base_linear, dtype=torch.float64)
    r, m = _scalar(roughness)[None], _scalar(metallic)[None]

    l_cos = sample_cosine_hemisphere((samples,), g, dtype=torch.float64).view(samples, 3, 1, 1)
    f_d = evaluate_brdf(b, n, r, m, l_cos, v, specular_lobe=False)
    diffuse = (f_d * math.pi).mean(dim=0)  # f cos / (cos/π)

    alpha = roughness_to_alpha(torch.tensor(roughness, dtype=torch.float64))
    u1 = torch.rand(samples, generator=g, dtype=torch.float64)
    u2 = torch.rand(samples, generator=g, dtype=torch.float64)
    cos_h = torch.sqrt((1 - u1) / (1 + (alpha**2 - 1) * u1))
    sin_h = torch.sqrt(1 - cos_h**2)
    phi = 2 * math.pi * u2
    h = torch.stack([sin_h * torch.cos(phi), sin_h * torch.sin(phi), cos_h], dim=-1).view(samples, 3, 1, 1)
    v_dot_h = (v * h).sum(dim=1, keepdim=True)
    l_spec = 2 * v_dot_h * h - v
    a2 = alpha**2
    d = a2 / (math.pi * (cos_h**2 * (a2 - 1) + 1) ** 2)
    pdf = (d * cos_h).view(samples, 1, 1, 1) / (4 * v_dot_h.abs())
    f_s = evaluate_brdf(b, n, r, m, l_spec, v, diffuse_lobe=False)
    cos_l = l_spec[:, 2:3].clamp(min=0)
    specular = (f_s * cos_l / pdf).mean(dim=0)
    return float((diffuse + specular).max())


@pytest.mark.parametrize("metallic", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("roughness", [0.1, 0.3, 0.6, 1.0])
@pytest.mark.parametrize("view_deg", [0.0, 30.0, 60.0])
def test_energy_bound_for_real_albedos(metallic: float, roughness: float, view_deg: float) -> None:
    # docs/conventions.md#energy: Burley + single-scattering GGX exceeds 1 only at grazing views or
    # base color 1, so the bound is checked for a linear base color of 0.8 and views ≤ 60°.
    albedo = _directional_albedo(0.8, roughness, metallic, view_deg, samples=40_000)
    assert 0.1 < albedo <= 1.0


def test_energy_estimator_sees_the_known_excess_at_grazing_angles() -> None:
    # The same estimator reports the documented > 1 albedo for base color 1 at 80°: the bound test
    # above is not passing because the estimator is blind.
    assert _directional_albedo(1.0, 1.0, 0.0, 80.0, samples=40_000) > 1.05
