"""Rusted and painted metal: a steel sheet under chipped paint, with patches of rust.

Depicts weathered painted steel (old machinery, gates, containers): a dielectric paint layer that
has chipped off in irregular patches (fbm thresholded) revealing bare steel (metallic 1), and
rust patches (thresholded fbm, more likely where the paint is gone) that are non-metallic,
orange-brown, very rough, slightly raised and pitted. With no paint it is bare rusting steel.

Parameters:
    rust_coverage: fraction of the surface covered by rust.
    rust_scale: size of the rust patches (fbm lattice cells per side, rounded; larger = smaller).
    paint_coverage: fraction of the surface still painted (0 = bare steel).
    paint_hue, paint_saturation, paint_value: HSV of the paint colour (sRGB).
    paint_roughness: perceptual roughness of the paint.
    metal_roughness: perceptual roughness of the bare steel.
    relief: rust crust height, as a fraction of the image width (paint thickness follows it).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import fbm, hsv_to_rgb, lerp_color, value_noise

STEEL = (0.77, 0.78, 0.78)  # F0 of iron/steel, sRGB
RUST_ORANGE = (0.58, 0.29, 0.11)
RUST_BROWN = (0.29, 0.14, 0.07)


def _threshold_for_coverage(field: Tensor, coverage: float) -> float:
    """The level above which ``coverage`` of ``field`` lies (estimated on a subsample, for speed)."""
    sample = field.flatten()[:: max(1, field.numel() // 65536)]
    return torch.quantile(sample, 1.0 - coverage).item()


def _coverage_mask(field: Tensor, coverage: float, edge: float) -> tuple[Tensor, float]:
    """Soft mask of the ``coverage`` share of ``field`` with the highest values (edge width
    ``edge``) and the level used. Coverage 0 and 1 give exact all-0 and all-1 masks: the
    quantile level would be ±∞ there, and smoothstep of ∞ is NaN."""
    if coverage <= 0.0:
        return torch.zeros_like(field), float(field.max())
    if coverage >= 1.0:
        return torch.ones_like(field), float(field.min())
    level = _threshold_for_coverage(field, coverage)
    return smoothstep(level - edge, level + edge, field), level


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    amplitude = params["relief"] * size

    # Paint chips: the paint survives where a fbm field is above the coverage level; the chip
    # boundary is sharp because paint flakes off as a film, not gradually.
    chip_field = fbm(size, 6, generator, octaves=6, persistence=0.55)
    painted, _ = _coverage_mask(chip_field, params["paint_coverage"], 0.005)

    # Rust: thresholded fbm, biased towards exposed steel (paint protects the metal beneath it).
    rust_field = fbm(size, max(1, round(params["rust_scale"])), generator, octaves=6, persistence=0.6)
    rust_field = rust_field + 0.25 * (1.0 - painted)
    rust, rust_level = _coverage_mask(rust_field, params["rust_coverage"], 0.03)
    # Paint over rust blisters and is lost; so rust covers paint wherever both are present.
    paint = painted * (1.0 - rust)
    bare = (1.0 - painted) * (1.0 - rust)

    # Rust crust: raised, thicker inside a patch, with a granular texture and deep pits.
    grain = fbm(size, 48, generator, octaves=3)
    pits = smoothstep(0.72, 0.85, value_noise(size, min(size, 96), generator))
    depth_in = smoothstep(0.0, 0.15, rust_field - rust_level)
    height = amplitude * (
        0.35 * painted  # paint film thickness: chip edges become small steps
        + rust * (0.6 + 0.6 * depth_in + 0.3 * grain)
        - 0.8 * rust * pits
        + 0.05 * grain * bare  # a little tooth in the sand-blasted steel
    )

    tone = fbm(size, 8, generator, octaves=4)
    rust_color = lerp_color(RUST_ORANGE, RUST_BROWN, (0.5 + 0.6 * tone + 0.4 * pits).clamp(0.0, 1.0))
    paint_value = (params["paint_value"] * (1.0 + 0.08 * tone)).clamp(0.02, 0.95)
    paint_color = hsv_to_rgb(
        torch.full_like(tone, params["paint_hue"]),
        torch.full_like(tone, params["paint_saturation"]) * (1.0 - 0.15 * (tone + 1.0)),
        paint_value,
    ).clamp(0.02, 0.95)
    # Bare steel is a little darker where it is weathered (oxide film), never above the F0 of iron.
    steel = lerp_color(STEEL, (0.6, 0.6, 0.6), (0.5 + 0.5 * tone).clamp(0.0, 1.0))
    basecolor = rust[None] * rust_color + paint[None] * paint_color + bare[None] * steel

    roughness = (
        rust * (0.9 + 0.05 * grain + 0.05 * pits)
        + paint * (params["paint_roughness"] + 0.05 * tone)
        + bare * (params["metal_roughness"] + 0.08 * grain)
    )
    return MaterialLayers(
        basecolor=basecolor.clamp(0.02, 0.97),
        height=height[None],
        roughness=roughness.clamp(0.0, 1.0)[None],
        metallic=bare[None],
    )


FAMILY = MaterialFamily(
    name="rusted_metal",
    parameters={
        "rust_coverage": Parameter(0.3, 0.0, 0.85, "fraction of the surface covered by rust"),
        "rust_scale": Parameter(4.0, 2.0, 12.0, "rust patch frequency (fbm cells per side, rounded)"),
        "paint_coverage": Parameter(0.6, 0.0, 1.0, "fraction of the surface still painted (0 = bare)"),
        "paint_hue": Parameter(0.55, 0.0, 1.0, "hue of the paint, in turns"),
        "paint_saturation": Parameter(0.45, 0.0, 0.85, "saturation of the paint"),
        "paint_value": Parameter(0.5, 0.15, 0.85, "brightness of the paint (sRGB)"),
        "paint_roughness": Parameter(0.45, 0.2, 0.75, "perceptual roughness of the paint"),
        "metal_roughness": Parameter(0.35, 0.15, 0.6, "perceptual roughness of the bare steel"),
        "relief": Parameter(0.003, 0.001, 0.008, "rust crust height, fraction of the image width"),
    },
    generate=_generate,
    description="Steel under chipped paint with rough, raised, pitted non-metallic rust patches.",
    tags=("metal", "rust", "paint", "mixed-metallic", "tileable"),
)

__all__ = ["FAMILY"]
