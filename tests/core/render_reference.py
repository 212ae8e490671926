"""The point-light renderer written out directly: :func:`~brdfgan.core.brdf.evaluate_brdf` on full
``(B, V, 3, H, W)`` vector fields, as the renderer's docstring defines it. The library's
:func:`~brdfgan.core.render.render_point_lights` evaluates the same sum in a factored, faster form;
tests hold the two to each other (values and gradients) and ``benchmarks.bench_renderer`` times
this one as the "before" row."""

from __future__ import annotations

from torch import Tensor

from brdfgan.core.brdf import VECTOR_DIM, dot, evaluate_brdf, normalize
from brdfgan.core.render import PointLights, plane_positions
from brdfgan.core.svbrdf import normalize_normal, split_maps, srgb_to_linear


def render_point_lights_direct(
    maps: Tensor, camera_position: Tensor, lights: PointLights, plane_half_size: float = 1.0
) -> Tensor:
    """Shape: maps ``(B, 8, H, W)``, camera ``(B, V, 3)``, lights ``(B, V, K, ·)`` → ``(B, V, 3, H, W)``."""
    _, _, height, width = maps.shape
    parts = split_maps(maps.unsqueeze(1))
    basecolor = srgb_to_linear(parts.basecolor)
    normal = normalize_normal(parts.normal, dim=VECTOR_DIM)
    surface = plane_positions(height, width, plane_half_size, dtype=maps.dtype, device=maps.device)
    view_dir = normalize(camera_position[..., None, None] - surface)
    radiance = maps.new_zeros(())
    intensity = lights.radiant_intensity()
    for k in range(lights.position.shape[2]):
        to_light = lights.position[:, :, k, :, None, None] - surface
        distance_sq = (to_light * to_light).sum(dim=VECTOR_DIM, keepdim=True)
        light_dir = to_light / distance_sq.sqrt().clamp(min=1e-7)
        brdf = evaluate_brdf(basecolor, normal, parts.roughness, parts.metallic, light_dir, view_dir)
        cosine = dot(normal, light_dir).clamp(min=0.0)
        irradiance = intensity[:, :, k, :, None, None] * cosine / distance_sq.clamp(min=1e-12)
        radiance = radiance + brdf * irradiance
    return radiance
