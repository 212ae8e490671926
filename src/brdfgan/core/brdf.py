"""Cook–Torrance GGX + Burley diffuse BRDF in the metallic workflow (paper §3, docs/conventions.md#brdf).

    f(l, v) = f_d + f_s
    f_d = d/π · (1 + (F_D90 − 1)(1 − n·l)^5) · (1 + (F_D90 − 1)(1 − n·v)^5),  F_D90 = 0.5 + 2 r (h·l)²
    f_s = D(h) F(h·l) G1(l) G1(v) / (4 (n·l)(n·v))
    D   = α² / (π ((n·h)² (α² − 1) + 1)²)                      GGX / Trowbridge–Reitz
    G1  = 2 (n·w) / ((n·w) + sqrt(α² + (1 − α²)(n·w)²))          exact separable Smith for GGX
    F   = F0 + (1 − F0)(1 − h·l)^5                               Schlick

with d = b(1−m), F0 = 0.04(1−m) + b m (b linear base color), α = max(r², 0.001). This is what
Mitsuba 3's ``principled`` (specular = 0.5, everything else default) evaluates, up to its exact
dielectric Fresnel; tests cross-check the two. It is *not* energy conserving at grazing angles
(no multiple-scattering compensation) — Mitsuba agreement comes first.

Vectors and colours live on axis ``-3`` (``(*, C, H, W)``), and every function broadcasts, so the
same code shades a map tensor or a bag of Monte Carlo directions shaped ``(N, 3, 1, 1)``.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from brdfgan.core.svbrdf import diffuse_albedo, roughness_to_alpha, specular_albedo

VECTOR_DIM = -3
EPS = 1e-7  # the smallest norm and cosine divided by


def dot(a: Tensor, b: Tensor) -> Tensor:
    """Dot product along the vector axis. Shape: ``(*, 3, H, W)`` × ``(*, 3, H, W)`` → ``(*, 1, H, W)``."""
    return (a * b).sum(dim=VECTOR_DIM, keepdim=True)


def normalize(v: Tensor) -> Tensor:
    """Unit vectors along the vector axis. Shape: ``(*, 3, H, W)`` → same."""
    return v / torch.linalg.vector_norm(v, dim=VECTOR_DIM, keepdim=True).clamp(min=EPS)


def ggx_distribution(n_dot_h: Tensor, alpha: Tensor) -> Tensor:
    """GGX normal distribution D. Shape: ``(*, 1, H, W)`` each → ``(*, 1, H, W)``.

    Example:
        At the half vector's peak (n·h = 1) D is ``1 / (π α²)``; at α = 1 it is ``1/π`` everywhere:

        >>> round(ggx_distribution(torch.tensor(1.0), torch.tensor(0.5)).item(), 4)
        1.2732
        >>> [round(v, 4) for v in ggx_distribution(torch.tensor([1.0, 0.5, 0.0]), torch.tensor(1.0)).tolist()]
        [0.3183, 0.3183, 0.3183]

        It is a distribution of microfacet normals: ``∫ D(h) (n·h) dω_h = 1`` over the hemisphere.

        >>> steps = 10_000
        >>> theta = (torch.arange(steps, dtype=torch.float64) + 0.5) * (math.pi / 2 / steps)
        >>> d = ggx_distribution(theta.cos(), torch.tensor(0.3, dtype=torch.float64))
        >>> integral = (d * theta.cos() * theta.sin()).sum() * (math.pi / 2 / steps) * 2 * math.pi
        >>> round(integral.item(), 4)
        1.0
    """
    a2 = alpha * alpha
    denom = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0
    return a2 / (math.pi * denom * denom)


def smith_g1_ggx(n_dot_w: Tensor, alpha: Tensor) -> Tensor:
    """Exact Smith masking G1 for GGX, cosine form. Shape: ``(*, 1, H, W)`` → ``(*, 1, H, W)``.

    Example:
        Nothing is masked seen head-on, and a mirror (α → 0) masks nothing at any angle:

        >>> [round(smith_g1_ggx(torch.tensor(1.0), torch.tensor(a)).item(), 4) for a in (0.1, 0.5, 1.0)]
        [1.0, 1.0, 1.0]
        >>> round(smith_g1_ggx(torch.tensor(0.2), torch.tensor(1e-4)).item(), 4)
        1.0
    """
    a2 = alpha * alpha
    return 2.0 * n_dot_w / (n_dot_w + torch.sqrt(a2 + (1.0 - a2) * n_dot_w * n_dot_w)).clamp(min=EPS)


def schlick_fresnel(f0: Tensor, h_dot_l: Tensor) -> Tensor:
    """Schlick's Fresnel approximation.

    Shape: f0 ``(*, 3, H, W)``, h_dot_l ``(*, 1, H, W)`` → ``(*, 3, H, W)``.

    Example:
        F0 at normal incidence, 1 at grazing, ``0.04 + 0.96 · 0.5⁵ = 0.07`` at 60° for a dielectric:

        >>> f0 = torch.tensor([0.04, 0.5, 1.0])
        >>> [round(v, 4) for v in schlick_fresnel(f0, torch.tensor(1.0)).tolist()]
        [0.04, 0.5, 1.0]
        >>> [round(v, 4) for v in schlick_fresnel(f0, torch.tensor(0.0)).tolist()]
        [1.0, 1.0, 1.0]
        >>> round(schlick_fresnel(f0, torch.tensor(0.5))[0].item(), 4)
        0.07
    """
    return f0 + (1.0 - f0) * schlick_weight(h_dot_l)


def burley_diffuse_factor(roughness: Tensor, n_dot_l: Tensor, n_dot_v: Tensor, h_dot_l: Tensor) -> Tensor:
    """The colourless part of the Burley lobe: the lobe is ``diffuse ×`` this,
    ``(1 + (F_D90 − 1)(1 − n·l)^5)(1 + (F_D90 − 1)(1 − n·v)^5) / π`` with F_D90 = 0.5 + 2 r (h·l)².

    Shape: ``(*, 1, H, W)`` each → ``(*, 1, H, W)``.
    """
    fd90_minus_1 = 2.0 * roughness * h_dot_l * h_dot_l - 0.5
    light_scatter = 1.0 + fd90_minus_1 * (1.0 - n_dot_l).pow(5)
    view_scatter = 1.0 + fd90_minus_1 * (1.0 - n_dot_v).pow(5)
    return light_scatter * view_scatter / math.pi


def burley_diffuse(
    diffuse: Tensor, roughness: Tensor, n_dot_l: Tensor, n_dot_v: Tensor, h_dot_l: Tensor
) -> Tensor:
    """Burley (Disney) diffuse lobe with retro-reflection, F_D90 = 0.5 + 2 r (h·l)².

    Shape:
        - diffuse: ``(*, 3, H, W)`` linear diffuse albedo; the rest ``(*, 1, H, W)``
        - output: ``(*, 3, H, W)``
    """
    return diffuse * burley_diffuse_factor(roughness, n_dot_l, n_dot_v, h_dot_l)


def ggx_specular_factor(alpha: Tensor, n_dot_l: Tensor, n_dot_v: Tensor, n_dot_h: Tensor) -> Tensor:
    """The colourless part of the Cook–Torrance lobe, ``D G / (4 (n·l)(n·v))``: the lobe is
    ``F ×`` this.

    Shape: ``(*, 1, H, W)`` each → ``(*, 1, H, W)``.
    """
    d = ggx_distribution(n_dot_h, alpha)
    g = smith_g1_ggx(n_dot_l, alpha) * smith_g1_ggx(n_dot_v, alpha)
    return d * g / (4.0 * n_dot_l * n_dot_v).clamp(min=EPS)


def schlick_weight(h_dot_l: Tensor) -> Tensor:
    """Schlick's ``(1 − h·l)^5``: Fresnel is ``F0 (1 − w) + w``. Shape: ``(*, 1, H, W)`` → same."""
    return (1.0 - h_dot_l).pow(5)


def ggx_specular(
    f0: Tensor, alpha: Tensor, n_dot_l: Tensor, n_dot_v: Tensor, n_dot_h: Tensor, h_dot_l: Tensor
) -> Tensor:
    """Cook–Torrance specular lobe D F G / (4 (n·l)(n·v)).

    Shape:
        - f0: ``(*, 3, H, W)``; the rest ``(*, 1, H, W)``
        - output: ``(*, 3, H, W)``
    """
    return schlick_fresnel(f0, h_dot_l) * ggx_specular_factor(alpha, n_dot_l, n_dot_v, n_dot_h)


def evaluate_brdf(
    basecolor_linear: Tensor,
    normal: Tensor,
    roughness: Tensor,
    metallic: Tensor,
    light_dir: Tensor,
    view_dir: Tensor,
    *,
    diffuse_lobe: bool = True,
    specular_lobe: bool = True,
) -> Tensor:
    """The BRDF value f(l, v) (no cosine factor), zero where l or v is below the shading normal.

    Args:
        basecolor_linear: linear base color b.
        normal: unit shading normal.
        roughness: perceptual roughness r in [0, 1].
        metallic: metallic m in [0, 1].
        light_dir: unit direction from the surface point towards the light.
        view_dir: unit direction from the surface point towards the viewer.
        diffuse_lobe, specular_lobe: switch a lobe off (for tests and analysis).

    Shape:
        - basecolor_linear, normal, light_dir, view_dir: ``(*, 3, H, W)`` (broadcastable)
        - roughness, metallic: ``(*, 1, H, W)`` (broadcastable)
        - output: ``(*, 3, H, W)``

    Example:
        Lit and seen head-on (l = v = n) the Burley lobe is Lambertian, ``d/π``, and the specular
        lobe is ``D F G / 4 = F0 / (4 π α²)``; here d = 0.8, F0 = 0.04, α = 0.5² = 0.25:

        >>> up = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1)
        >>> b, r, m = torch.full((3, 1, 1), 0.8), torch.full((1, 1, 1), 0.5), torch.zeros(1, 1, 1)
        >>> round(evaluate_brdf(b, up, r, m, up, up, specular_lobe=False)[0].item(), 4)
        0.2546
        >>> round(0.8 / math.pi, 4)
        0.2546
        >>> round(evaluate_brdf(b, up, r, m, up, up)[0].item(), 4)
        0.3056
        >>> round(0.8 / math.pi + 0.04 / (4 * math.pi * 0.25**2), 4)
        0.3056

        It is reciprocal, and zero for a light below the surface:

        >>> light = normalize(torch.tensor([0.3, -0.2, 0.9]).view(3, 1, 1))
        >>> view = normalize(torch.tensor([-0.5, 0.1, 0.6]).view(3, 1, 1))
        >>> torch.allclose(evaluate_brdf(b, up, r, m, light, view), evaluate_brdf(b, up, r, m, view, light))
        True
        >>> below = torch.tensor([0.0, 0.6, -0.8]).view(3, 1, 1)
        >>> evaluate_brdf(b, up, r, m, below, up).flatten().tolist()
        [0.0, 0.0, 0.0]
    """
    half = normalize(light_dir + view_dir)
    raw_n_dot_l = dot(normal, light_dir)
    raw_n_dot_v = dot(normal, view_dir)
    n_dot_l = raw_n_dot_l.clamp(min=EPS, max=1.0)
    n_dot_v = raw_n_dot_v.clamp(min=EPS, max=1.0)
    n_dot_h = dot(normal, half).clamp(min=0.0, max=1.0)
    h_dot_l = dot(half, light_dir).clamp(min=0.0, max=1.0)

    value = torch.zeros((), dtype=basecolor_linear.dtype, device=basecolor_linear.device)
    if diffuse_lobe:
        diffuse = diffuse_albedo(basecolor_linear, metallic)
        value = value + burley_diffuse(diffuse, roughness, n_dot_l, n_dot_v, h_dot_l)
    if specular_lobe:
        f0 = specular_albedo(basecolor_linear, metallic)
        alpha = roughness_to_alpha(roughness)
        value = value + ggx_specular(f0, alpha, n_dot_l, n_dot_v, n_dot_h, h_dot_l)
    visible = (raw_n_dot_l > 0) & (raw_n_dot_v > 0)
    return torch.where(visible, value, torch.zeros_like(value))
