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
    """GGX normal distribution D. Shape: ``(*, 1, H, W)`` each → ``(*, 1, H, W)``."""
    a2 = alpha * alpha
    denom = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0
    return a2 / (math.pi * denom * denom)


def smith_g1_ggx(n_dot_w: Tensor, alpha: Tensor) -> Tensor:
    """Exact Smith masking G1 for GGX, cosine form. Shape: ``(*, 1, H, W)`` → ``(*, 1, H, W)``."""
    a2 = alpha * alpha
    return 2.0 * n_dot_w / (n_dot_w + torch.sqrt(a2 + (1.0 - a2) * n_dot_w * n_dot_w)).clamp(min=EPS)


def schlick_fresnel(f0: Tensor, h_dot_l: Tensor) -> Tensor:
    """Schlick's Fresnel approximation.

    Shape: f0 ``(*, 3, H, W)``, h_dot_l ``(*, 1, H, W)`` → ``(*, 3, H, W)``.
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
