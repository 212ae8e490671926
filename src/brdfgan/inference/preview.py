"""Relit previews of predicted maps for the CLI: still images and turntable-light animations.

Everything is rendered with the project's own renderer (:func:`brdfgan.core.render.render_point_lights`,
the BRDF the network was trained with) from the capture camera of :class:`~brdfgan.core.render.FlashCapture`
(above the sample centre, looking down −Z, row 0 = +Y), so a preview shows what the maps do, not what
some other shading model makes of them.

Lighting:

- **Point lights** (:func:`preview_lights`): novel positions, never the flash — ``count − 1`` lights at
  45° elevation with azimuths spread evenly (azimuth measured from +X towards +Y, i.e. counter-clockwise
  in the image), plus one grazing light at 12° between the first two, which shows the normal map's
  relief. Distance 3 plane half-sizes, intensity 1 W/sr (the flash's default).
- **Environment** (:class:`Environment`): a procedural sky — a horizon-to-zenith gradient plus a sun
  lobe (a von Mises–Fisher lobe, so it can be sampled exactly). :func:`render_environment` turns it
  into ``samples`` distant lights drawn by importance and renders them as point lights.
- **Exposure**: each still rendering goes through the paper's auto exposure
  (:func:`brdfgan.core.exposure.auto_expose`) and then the sRGB curve; an animation uses one exposure for
  all frames so it does not flicker.

Memory stays bounded for big maps: the maps are area-downscaled to the tile size *before* rendering,
point lights are rendered one at a time and environment lights in small chunks.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image
from torch import Tensor

from brdfgan.core.exposure import LUMINANCE_WEIGHTS, auto_expose, auto_exposure_scale
from brdfgan.core.render import FlashCapture, PointLights, render_point_lights
from brdfgan.core.svbrdf import (
    check_map_shape,
    join_maps,
    linear_to_srgb,
    normalize_normal,
    split_maps,
    srgb_to_linear,
)
from brdfgan.io.atomic import atomic_replace, fsync_directory, temp_path

__all__ = [
    "ANIMATION_SUFFIXES",
    "ENVIRONMENT_LIGHT_DISTANCE",
    "Environment",
    "animation_frames",
    "preview_image",
    "preview_lights",
    "relight",
    "render_environment",
    "resize_maps",
    "sample_environment",
    "write_animation",
    "write_preview",
]

PREVIEW_LIGHT_DISTANCE = 3.0  # in plane half-sizes: outside the sample, close enough for visible falloff
PREVIEW_ELEVATION_DEG = 45.0
GRAZING_ELEVATION_DEG = 12.0
ANIMATION_ELEVATION_DEG = 30.0
# Environment lights sit this many plane half-sizes away. A light at distance D with intensity E·D²
# gives irradiance E at the centre; over the sample (|p| ≤ √2 s) |x − p|² = D² − 2D ω·p + |p|² differs
# from D² by at most ~2√2 s/D relative: 0.03 % here, i.e. a directional light for all practical purposes.
# float32 still resolves it: D² = 1e8 is exact to 1e-7 relative and the direction to ~1e-7 rad.
ENVIRONMENT_LIGHT_DISTANCE = 1.0e4
ENVIRONMENT_CHUNK = 8  # environment lights rendered per render_point_lights call (as configurations)
SKY_TABLE_ROWS = 32  # importance table over (cos θ, φ): equal-solid-angle cells
SKY_TABLE_COLS = 64
SEPARATOR = 4  # px between tiles
SEPARATOR_COLOR = (48, 48, 48)
LABEL_HEIGHT = 18  # px strip above each tile for its label
ANIMATION_SUFFIXES = frozenset({".gif", ".mp4"})
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0

RGB = tuple[float, float, float]


# ---------------------------------------------------------------------------------------------- maps


def _check_single_maps(maps: Tensor) -> None:
    check_map_shape(maps)
    if maps.ndim != 3:
        raise ValueError(f"maps must have shape (8, H, W), got {tuple(maps.shape)}")


def _resize_image(image: Tensor, height: int, width: int) -> Tensor:
    """Area averaging when shrinking (every texel counts, no aliasing), bilinear when enlarging.

    Shape:
        - image: ``(C, H, W)``
        - output: ``(C, height, width)``
    """
    if tuple(image.shape[-2:]) == (height, width):
        return image
    batch = image.unsqueeze(0)
    if height <= image.shape[-2] and width <= image.shape[-1]:
        return F.interpolate(batch, size=(height, width), mode="area")[0]
    return F.interpolate(batch, size=(height, width), mode="bilinear", align_corners=False)[0]


def resize_maps(maps: Tensor, size: int | tuple[int, int]) -> Tensor:
    """Resize a map set for rendering at preview resolution.

    Base color is averaged in linear (what light does) and re-encoded; normals are averaged and
    renormalised; roughness and metallic are averaged as stored. Averaging normals and roughness
    separately loses the sub-pixel normal variation a prefiltered roughness would keep — acceptable
    for a preview.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(8, h, w)`` with ``(h, w) = size`` (an int means square)
    """
    _check_single_maps(maps)
    height, width = (size, size) if isinstance(size, int) else size
    if height < 1 or width < 1:
        raise ValueError(f"size must be positive, got {size}")
    if tuple(maps.shape[-2:]) == (height, width):
        return maps
    parts = split_maps(maps)
    basecolor = linear_to_srgb(_resize_image(srgb_to_linear(parts.basecolor), height, width).clamp(0.0, 1.0))
    normal = normalize_normal(_resize_image(parts.normal, height, width))
    roughness = _resize_image(parts.roughness, height, width).clamp(0.0, 1.0)
    metallic = _resize_image(parts.metallic, height, width).clamp(0.0, 1.0)
    return join_maps(basecolor, normal, roughness, metallic)


# -------------------------------------------------------------------------------------------- lights


def _spherical(azimuth_deg: Tensor, elevation_deg: Tensor, distance: float) -> Tensor:
    azimuth, elevation = torch.deg2rad(azimuth_deg), torch.deg2rad(elevation_deg)
    return distance * torch.stack(
        [
            torch.cos(elevation) * torch.cos(azimuth),
            torch.cos(elevation) * torch.sin(azimuth),
            torch.sin(elevation),
        ],
        dim=-1,
    )


def preview_lights(
    count: int = 4,
    *,
    elevation_deg: float = PREVIEW_ELEVATION_DEG,
    grazing_elevation_deg: float = GRAZING_ELEVATION_DEG,
    distance: float = PREVIEW_LIGHT_DISTANCE,
) -> Tensor:
    """Novel point-light positions (none of them the flash) for a plane of half-size 1.

    ``count − 1`` lights at ``elevation_deg`` with azimuths 45°, 45° + 360°/(count − 1), … (from +X
    towards +Y), then one grazing light at ``grazing_elevation_deg`` midway between the first two.
    ``count = 1`` gives only the first, non-grazing light. Multiply by the plane half-size for other
    scenes.

    Shape:
        - output: ``(count, 3)`` float32
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    if not 0.0 < grazing_elevation_deg <= 90.0 or not 0.0 < elevation_deg <= 90.0:
        raise ValueError("elevations must lie in (0, 90] degrees")
    main = max(count - 1, 1)
    azimuth = [45.0 + 360.0 * k / main for k in range(main)]
    elevation = [elevation_deg] * main
    if count > 1:
        azimuth.append(45.0 + 180.0 / main)
        elevation.append(grazing_elevation_deg)
    return _spherical(torch.tensor(azimuth), torch.tensor(elevation), distance)


def _light_rgb(intensity: float | Tensor, count: int, like: Tensor) -> Tensor:
    """Radiant intensities ``(count, 3)`` from a scalar, per-light ``(L,)`` or per-light RGB ``(L, 3)``."""
    value = torch.as_tensor(intensity, dtype=like.dtype, device=like.device)
    if value.ndim == 0:
        return value.expand(count, 3)
    if value.shape == (count,):
        return value.unsqueeze(-1).expand(count, 3)
    if value.shape == (count, 3):
        return value
    raise ValueError(f"intensity must be a scalar, ({count},) or ({count}, 3), got {tuple(value.shape)}")


def _render_lights(
    maps: Tensor, positions: Tensor, rgb: Tensor, capture: FlashCapture, *, chunk: int, combine: bool
) -> Tensor:
    """Render ``maps`` under each light (``combine=False``: ``(L, 3, H, W)``) or their sum
    (``combine=True``: ``(3, H, W)``), ``chunk`` lights per renderer call as separate configurations
    so peak memory is ``chunk`` single-light renderings whatever ``L`` is."""
    camera_height = capture.camera_height
    batch = maps.unsqueeze(0)
    images: list[Tensor] = []
    total = maps.new_zeros(3, *maps.shape[-2:])
    for start in range(0, positions.shape[0], chunk):
        pos = positions[start : start + chunk].to(maps)
        views = pos.shape[0]
        lights = PointLights(
            position=pos.view(1, views, 1, 3),
            intensity=maps.new_ones(1, views, 1),
            color=rgb[start : start + chunk].to(maps).reshape(1, views, 1, 3),
        )
        camera = maps.new_tensor([0.0, 0.0, camera_height]).expand(1, views, 3)
        rendered = render_point_lights(batch, camera, lights, capture.plane_half_size)[0]
        if combine:
            total = total + rendered.sum(dim=0)
        else:
            images.append(rendered)
    return total if combine else torch.cat(images)


def relight(
    maps: Tensor,
    light_positions: Tensor,
    *,
    intensity: float | Tensor = 1.0,
    environment: Environment | None = None,
    samples: int = 64,
    capture: FlashCapture = FlashCapture(),
) -> Tensor:
    """Render a map set from the capture camera under each of several point lights.

    Args:
        maps: one map set (base color sRGB-encoded, unit normals).
        light_positions: world positions (plane units: the sample is ``[-s, s]²`` of z = 0,
            ``s = capture.plane_half_size``).
        intensity: radiant intensity in W/sr — a scalar, one per light or RGB per light. The default
            matches :class:`FlashCapture`; the flash then gives ``1 / h² ≈ 0.17`` at the sample centre.
        environment: if given, its rendering (:func:`render_environment`, ``samples`` lights) is added
            to every point-light rendering.
        capture: camera (field of view) and plane size; its flash is not used.

    Returns:
        Linear HDR radiance, one rendering per light. Differentiable w.r.t. ``maps``.

    Shape:
        - maps: ``(8, H, W)``
        - light_positions: ``(L, 3)``
        - intensity: ``()``, ``(L,)`` or ``(L, 3)``
        - output: ``(L, 3, H, W)``
    """
    _check_single_maps(maps)
    if light_positions.ndim != 2 or light_positions.shape[-1] != 3:
        raise ValueError(f"light_positions must have shape (L, 3), got {tuple(light_positions.shape)}")
    rgb = _light_rgb(intensity, light_positions.shape[0], maps)
    # One light per renderer call: L is small and this keeps memory at one rendering's worth.
    images = _render_lights(maps, light_positions, rgb, capture, chunk=1, combine=False)
    if environment is not None:
        images = images + render_environment(maps, environment, samples=samples, capture=capture)
    return images


# --------------------------------------------------------------------------------------- environment


def _luminance(rgb: Tensor) -> Tensor:
    return rgb @ rgb.new_tensor(LUMINANCE_WEIGHTS)


@dataclass(frozen=True)
class Environment:
    """A procedural outdoor environment over the upper hemisphere: sky gradient plus a sun lobe.

    Radiance in direction ω (unit, +Z up, azimuth from +X towards +Y), zero below the horizon
    (the sample plane hides it):

        L(ω) = horizon + (zenith − horizon)·√(ω_z) + sun_irradiance · sun_color · vMF(ω; d, κ)

    with ``vMF(ω; d, κ) = κ / (2π (1 − e^{−2κ})) · exp(κ (d·ω − 1))`` the unit-integral von Mises–Fisher
    lobe around the sun direction ``d`` (angular radius ≈ 1/√κ rad: 1.3° at the default κ = 2000). So a
    surface facing the sun receives ``sun_irradiance`` (W/m², RGB-scaled by ``sun_color``) from it.
    Sky colours are radiances (W/m²/sr). Defaults: a late-morning sky, sun from the upper left
    (azimuth 135°) at 40° elevation, sun and sky each about half of the light on the sample.
    """

    zenith: RGB = (0.30, 0.45, 0.80)
    horizon: RGB = (0.80, 0.82, 0.85)
    sun_irradiance: float = 3.0
    sun_color: RGB = (1.0, 0.9, 0.75)
    sun_elevation_deg: float = 40.0
    sun_azimuth_deg: float = 135.0
    sun_sharpness: float = 2000.0

    def __post_init__(self) -> None:
        for name in ("zenith", "horizon", "sun_color"):
            value = getattr(self, name)
            if len(value) != 3 or any(not math.isfinite(c) or c < 0.0 for c in value):
                raise ValueError(f"{name} must be three finite non-negative numbers, got {value}")
        if not math.isfinite(self.sun_irradiance) or self.sun_irradiance < 0.0:
            raise ValueError(f"sun_irradiance must be finite and >= 0, got {self.sun_irradiance}")
        if not 0.0 < self.sun_elevation_deg <= 90.0:
            raise ValueError(f"sun_elevation_deg must lie in (0, 90], got {self.sun_elevation_deg}")
        if not math.isfinite(self.sun_sharpness) or self.sun_sharpness <= 0.0:
            raise ValueError(f"sun_sharpness must be finite and > 0, got {self.sun_sharpness}")

    def sun_direction(self, dtype: torch.dtype = torch.float64) -> Tensor:
        """Unit vector towards the sun centre. Shape: ``(3,)``."""
        angles = torch.tensor([self.sun_azimuth_deg, self.sun_elevation_deg], dtype=dtype)
        return _spherical(angles[0], angles[1], 1.0)

    def sky_radiance(self, directions: Tensor) -> Tensor:
        """Sky gradient only. Shape: ``(*, 3)`` → ``(*, 3)``."""
        up = directions[..., 2:3]
        zenith, horizon = directions.new_tensor(self.zenith), directions.new_tensor(self.horizon)
        sky = horizon + (zenith - horizon) * up.clamp(min=0.0).sqrt()
        return torch.where(up > 0.0, sky, torch.zeros_like(sky))

    def sun_density(self, directions: Tensor) -> Tensor:
        """The sun's vMF lobe (per steradian, unit integral over the sphere). Shape: ``(*, 3)`` → ``(*)``."""
        kappa = self.sun_sharpness
        norm = kappa / (2.0 * math.pi * -math.expm1(-2.0 * kappa))
        cosine = directions @ self.sun_direction(directions.dtype).to(directions.device)
        return norm * torch.exp(kappa * (cosine - 1.0))

    def radiance(self, directions: Tensor) -> Tensor:
        """Total radiance arriving from ``directions`` (unit vectors). Shape: ``(*, 3)`` → ``(*, 3)``."""
        sun = (
            self.sun_irradiance
            * directions.new_tensor(self.sun_color)
            * self.sun_density(directions)[..., None]
        )
        return self.sky_radiance(directions) + torch.where(
            directions[..., 2:3] > 0.0, sun, torch.zeros_like(sun)
        )


def _stratified(count: int, generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """``count`` points of [0, 1)²: one per 1/count stratum of the first coordinate, a golden-ratio
    lattice in the second, the whole set shifted by a random offset (mod 1) — well spread in 2D for any
    count, deterministic for a fixed generator seed."""
    shift = torch.rand(2, generator=generator, dtype=torch.float64)
    index = torch.arange(count, dtype=torch.float64)
    return ((index + 0.5) / count + shift[0]) % 1.0, (index * _GOLDEN + shift[1]) % 1.0


def _sky_table(environment: Environment) -> Tensor:
    """Importance weights of the sky per equal-solid-angle cell ``(rows over cos θ, cols over φ)``:
    luminance times cos θ at the cell centre, so samples go where the sky lights an upward surface."""
    u = (torch.arange(SKY_TABLE_ROWS, dtype=torch.float64) + 0.5) / SKY_TABLE_ROWS
    phi = (torch.arange(SKY_TABLE_COLS, dtype=torch.float64) + 0.5) * (2.0 * math.pi / SKY_TABLE_COLS)
    sin_theta = (1.0 - u * u).sqrt()[:, None]
    directions = torch.stack(
        [sin_theta * phi.cos(), sin_theta * phi.sin(), u[:, None].expand(-1, SKY_TABLE_COLS)], dim=-1
    )
    return _luminance(environment.sky_radiance(directions)) * u[:, None]


_CELL_AREA = 2.0 * math.pi / (SKY_TABLE_ROWS * SKY_TABLE_COLS)  # solid angle of one table cell


def _sample_table(table: Tensor, xi_row: Tensor, xi_col: Tensor) -> Tensor:
    """Invert the piecewise-constant 2D distribution ``table`` (marginal over rows, then conditional
    over columns, continuous within a cell). Returns unit directions ``(N, 3)``."""
    rows, cols = table.shape
    row_mass = table.sum(dim=1)
    row_cdf = torch.cumsum(row_mass, 0) / row_mass.sum()
    row_cdf[-1] = 1.0  # rounding must not leave a sliver past the last row
    row = torch.searchsorted(row_cdf, xi_row, right=True).clamp(max=rows - 1)
    below = torch.where(row > 0, row_cdf[(row - 1).clamp(min=0)], torch.zeros_like(xi_row))
    row_frac = ((xi_row - below) / (row_cdf[row] - below)).clamp(0.0, 1.0)
    col_cdf = torch.cumsum(table[row], 1) / row_mass[row, None]
    col_cdf[:, -1] = 1.0
    col = torch.searchsorted(col_cdf, xi_col[:, None], right=True)[:, 0].clamp(max=cols - 1)
    col_below = torch.where(col > 0, col_cdf.gather(1, (col - 1).clamp(min=0)[:, None])[:, 0], 0.0)
    col_above = col_cdf.gather(1, col[:, None])[:, 0]
    col_frac = ((xi_col - col_below) / (col_above - col_below)).clamp(0.0, 1.0)
    u = (row + row_frac) / rows
    phi = (col + col_frac) * (2.0 * math.pi / cols)
    sin_theta = (1.0 - u * u).clamp(min=0.0).sqrt()
    return torch.stack([sin_theta * phi.cos(), sin_theta * phi.sin(), u], dim=-1)


def _table_pdf(table: Tensor, directions: Tensor) -> Tensor:
    """Solid-angle density of :func:`_sample_table` at ``directions`` ``(N, 3)``; 0 below the horizon."""
    rows, cols = table.shape
    u = directions[:, 2]
    row = (u * rows).floor().long().clamp(0, rows - 1)
    phi = torch.atan2(directions[:, 1], directions[:, 0]) % (2.0 * math.pi)
    col = (phi * (cols / (2.0 * math.pi))).floor().long().clamp(0, cols - 1)
    pdf = table[row, col] / (table.sum() * _CELL_AREA)
    return torch.where(u > 0.0, pdf, torch.zeros_like(pdf))


def _sample_sun(environment: Environment, xi_cos: Tensor, xi_phi: Tensor) -> Tensor:
    """Exact vMF sampling around the sun direction (Jakob 2012, stable form). Shape: ``(N, 3)``."""
    kappa = environment.sun_sharpness
    # 1 − xi ∈ (0, 1] keeps the log finite; the e^{−2κ} term underflows harmlessly for a sharp lobe.
    w = 1.0 + torch.log((1.0 - xi_cos) + xi_cos * math.exp(-2.0 * kappa)) / kappa
    w = w.clamp(-1.0, 1.0)
    radial = (1.0 - w * w).clamp(min=0.0).sqrt()
    phi = 2.0 * math.pi * xi_phi
    axis = environment.sun_direction()
    helper = torch.tensor(
        [1.0, 0.0, 0.0] if abs(float(axis[2])) > 0.9 else [0.0, 0.0, 1.0], dtype=torch.float64
    )
    tangent = torch.linalg.cross(helper, axis)
    tangent = tangent / tangent.norm()
    bitangent = torch.linalg.cross(axis, tangent)
    return (
        w[:, None] * axis
        + (radial * phi.cos())[:, None] * tangent
        + (radial * phi.sin())[:, None] * bitangent
    )


def sample_environment(
    environment: Environment, samples: int = 64, *, seed: int = 0
) -> tuple[Tensor, Tensor]:
    """Turn an environment into ``samples`` distant lights by multiple importance sampling.

    Two strategies share the samples in proportion to the light each puts on an upward-facing sample
    (luminance-weighted horizontal irradiance): the sun lobe, sampled exactly, and the sky, sampled
    from a 32×64 equal-solid-angle table of luminance·cos θ. Both use stratified points
    (:func:`_stratified`, seeded with ``seed``). Each sample ω gets the balance-heuristic weight, so
    light i delivers irradiance (at normal incidence)

        E_i = L(ω_i) / (n_sun p_sun(ω_i) + n_sky p_sky(ω_i))

    and ``Σ_i f(ω_i, v) cos θ_i E_i`` is an unbiased estimate of the environment's reflected radiance.
    Samples that land below the horizon get ``E = 0``.

    Returns:
        ``(directions, irradiance)``: unit vectors towards the lights and their RGB irradiance,
        float64 on the CPU.

    Shape:
        - output: ``(samples, 3)``, ``(samples, 3)``
    """
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    generator = torch.Generator().manual_seed(seed)
    table = _sky_table(environment)
    sky_power = float(table.sum()) * _CELL_AREA
    sun_power = (
        environment.sun_irradiance
        * float(_luminance(torch.tensor(environment.sun_color, dtype=torch.float64)))
        * math.sin(math.radians(environment.sun_elevation_deg))
    )
    if sky_power <= 0.0 and sun_power <= 0.0:
        zeros = torch.zeros(samples, 3, dtype=torch.float64)
        return zeros + torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64), zeros
    n_sun = round(samples * sun_power / (sun_power + sky_power))
    if sun_power > 0.0 and sky_power > 0.0 and samples > 1:
        n_sun = min(max(n_sun, 1), samples - 1)  # each strategy keeps at least one sample
    n_sky = samples - n_sun
    parts = []
    if n_sun:
        parts.append(_sample_sun(environment, *_stratified(n_sun, generator)))
    if n_sky:
        parts.append(_sample_table(table, *_stratified(n_sky, generator)))
    directions = torch.cat(parts)
    density = n_sky * _table_pdf(table, directions) if n_sky else torch.zeros(samples, dtype=torch.float64)
    if n_sun:
        density = density + n_sun * environment.sun_density(directions)
    radiance = environment.radiance(directions)
    irradiance = torch.where(
        density[:, None] > 0.0, radiance / density.clamp(min=1e-300)[:, None], torch.zeros_like(radiance)
    )
    return directions, irradiance


def render_environment(
    maps: Tensor,
    environment: Environment,
    *,
    samples: int = 64,
    seed: int = 0,
    capture: FlashCapture = FlashCapture(),
    chunk: int = ENVIRONMENT_CHUNK,
) -> Tensor:
    """Render a map set from the capture camera under an environment.

    The environment becomes ``samples`` distant lights (:func:`sample_environment`). The renderer only
    knows point lights, so each is placed :data:`ENVIRONMENT_LIGHT_DISTANCE` plane half-sizes away
    along its direction ω with intensity ``E·D²``: its irradiance at the sample is then
    ``E·cos θ·D²/|x − p|²``, which is the directional light's ``E·cos θ`` to within 0.03 %. Lights are
    rendered ``chunk`` at a time (peak memory ``chunk`` single-light renderings); lights below the
    horizon (zero irradiance) are skipped.

    Returns:
        Linear HDR radiance.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(3, H, W)``
    """
    _check_single_maps(maps)
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    directions, irradiance = sample_environment(environment, samples, seed=seed)
    keep = irradiance.amax(dim=-1) > 0.0
    distance = ENVIRONMENT_LIGHT_DISTANCE * capture.plane_half_size
    positions = (directions[keep] * distance).to(maps)
    rgb = (irradiance[keep] * distance**2).to(maps)
    if positions.shape[0] == 0:
        return maps.new_zeros(3, *maps.shape[-2:])
    return _render_lights(maps, positions, rgb, capture, chunk=chunk, combine=True)


# ------------------------------------------------------------------------------------------- preview


def _to_uint8_srgb(linear: Tensor) -> np.ndarray:
    """Linear [0, 1] RGB → 8-bit sRGB image. Shape: ``(3, H, W)`` → ``(H, W, 3)`` uint8."""
    encoded = linear_to_srgb(linear.detach().float().clamp(0.0, 1.0))
    return (encoded * 255.0).round().to(torch.uint8).permute(1, 2, 0).cpu().numpy()


def _label_strip(text: str, width: int) -> np.ndarray:
    strip = np.zeros((LABEL_HEIGHT, width, 3), dtype=np.uint8)
    # Drawn per strip, so text longer than a small tile is clipped at its own tile's edge.
    cv2.putText(
        strip, text, (4, LABEL_HEIGHT - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (230, 230, 230), 1, cv2.LINE_AA
    )
    return strip


def _light_label(position: Tensor) -> str:
    x, y, z = (float(c) for c in position)
    azimuth = math.degrees(math.atan2(y, x)) % 360.0
    elevation = math.degrees(math.atan2(z, math.hypot(x, y)))
    return f"light az {azimuth:.0f} el {elevation:.0f}"


def preview_size(tile: int = 256, lights: int = 4, *, labels: bool = True) -> tuple[int, int]:
    """``(rows, cols)`` of :func:`preview_image`: ``1 + lights + 1`` tiles in a row, separators between."""
    tiles = lights + 2
    return tile + (LABEL_HEIGHT if labels else 0), tiles * tile + (tiles - 1) * SEPARATOR


def preview_image(
    photo: Tensor,
    maps: Tensor,
    *,
    tile: int = 256,
    lights: int = 4,
    environment: Environment | None = None,
    samples: int = 64,
    labels: bool = True,
    capture: FlashCapture = FlashCapture(),
) -> np.ndarray:
    """The input photo beside re-renderings of the predicted maps, as one sRGB image.

    Tiles, left to right: the input (what the network saw, sRGB-encoded), the maps under each of
    :func:`preview_lights` ``(lights)``, and under ``environment`` (default :class:`Environment`).
    Every tile is ``tile²`` (the renderer maps any ``H×W`` onto the square sample, so non-square
    inputs are stretched the same way); the maps are area-downscaled to ``tile²`` before rendering,
    so the cost does not grow with the map resolution. Each rendering is tone-mapped on its own with
    the paper's auto exposure and sRGB-encoded. Tiles are separated by :data:`SEPARATOR` px; with
    ``labels`` a :data:`LABEL_HEIGHT` px strip above each tile names it.

    Shape:
        - photo: ``(3, h, w)`` linear LDR in [0, 1]
        - maps: ``(8, H, W)``
        - output: ``(rows, cols, 3)`` uint8 with ``(rows, cols) = preview_size(tile, lights, labels=labels)``
    """
    _check_single_maps(maps)
    if photo.ndim != 3 or photo.shape[0] != 3:
        raise ValueError(f"photo must have shape (3, h, w), got {tuple(photo.shape)}")
    if tile < 1 or lights < 0:
        raise ValueError(f"tile must be >= 1 and lights >= 0, got tile={tile}, lights={lights}")
    environment = environment if environment is not None else Environment()
    positions = preview_lights(lights) * capture.plane_half_size if lights else torch.zeros(0, 3)
    with torch.no_grad():
        small = resize_maps(maps.detach().float(), tile)
        renders = [render_environment(small, environment, samples=samples, capture=capture)[None]]
        if lights:
            renders.insert(0, relight(small, positions, capture=capture))
        ldr, _ = auto_expose(torch.cat(renders))
        input_tile = _resize_image(photo.detach().float().to(small.device), tile, tile)
        tiles = [_to_uint8_srgb(input_tile), *(_to_uint8_srgb(image) for image in ldr)]
    names = ["input", *(_light_label(p) for p in positions), "environment"]
    rows = tile + (LABEL_HEIGHT if labels else 0)
    separator = np.empty((rows, SEPARATOR, 3), dtype=np.uint8)
    separator[:] = SEPARATOR_COLOR
    columns: list[np.ndarray] = []
    for index, (image, name) in enumerate(zip(tiles, names, strict=True)):
        if index:
            columns.append(separator)
        columns.append(np.concatenate([_label_strip(name, tile), image]) if labels else image)
    return np.ascontiguousarray(np.concatenate(columns, axis=1))


def write_preview(path: str | os.PathLike[str], photo: Tensor, maps: Tensor, **kwargs: object) -> Path:
    """Write :func:`preview_image` (``kwargs`` passed on) as a PNG, atomically. Returns the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path}: preview must be a .png file")
    image = preview_image(photo, maps, **kwargs)  # type: ignore[arg-type]
    ok, encoded = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"{path}: PNG encoding failed")
    with atomic_replace(path) as temp:
        temp.write_bytes(encoded.tobytes())
    return path


# ----------------------------------------------------------------------------------------- animation


def animation_frames(
    maps: Tensor,
    *,
    frames: int = 36,
    size: int = 256,
    elevation_deg: float = ANIMATION_ELEVATION_DEG,
    distance: float = PREVIEW_LIGHT_DISTANCE,
    intensity: float = 1.0,
    capture: FlashCapture = FlashCapture(),
) -> Iterator[np.ndarray]:
    """A turntable light: one point light circling the sample at a fixed elevation.

    Frame k has the light at azimuth ``360°·k/frames`` (frame 0 at +X, then towards +Y, i.e.
    counter-clockwise in the image), ``distance`` plane half-sizes from the centre. The maps are
    area-downscaled to ``size²`` once. One exposure serves every frame so brightness changes are the
    material's, not the meter's: the auto-exposure scale of the mean of four probe renderings at
    azimuths 0°, 90°, 180°, 270° (a single frame could be a dim one when the normals lean one way).
    Arguments are checked and the exposure computed on call; frames are rendered lazily.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``frames`` arrays ``(size, size, 3)`` uint8 sRGB
    """
    _check_single_maps(maps)
    if frames < 1 or size < 1:
        raise ValueError(f"frames and size must be >= 1, got frames={frames}, size={size}")
    if not 0.0 < elevation_deg <= 90.0:
        raise ValueError(f"elevation_deg must lie in (0, 90], got {elevation_deg}")
    azimuths = torch.arange(frames, dtype=torch.float64) * (360.0 / frames)
    scale = distance * capture.plane_half_size
    positions = _spherical(azimuths, torch.full_like(azimuths, elevation_deg), scale)
    probe_positions = _spherical(
        torch.tensor([0.0, 90.0, 180.0, 270.0], dtype=torch.float64),
        torch.full((4,), elevation_deg, dtype=torch.float64),
        scale,
    )
    with torch.no_grad():
        small = resize_maps(maps.detach().float(), size)
        probes = relight(small, probe_positions.to(small), intensity=intensity, capture=capture)
        exposure = auto_exposure_scale(probes.mean(dim=0))

    def generate() -> Iterator[np.ndarray]:
        for position in positions:
            # no_grad per frame, not around the yield: grad mode is thread state and would leak to the
            # caller while the generator is suspended.
            with torch.no_grad():
                hdr = relight(small, position[None].to(small), intensity=intensity, capture=capture)[0]
            yield _to_uint8_srgb(hdr * exposure)

    return generate()


@contextmanager
def _atomic_replace_keeping_suffix(path: Path) -> Iterator[Path]:
    """Like :func:`brdfgan.io.atomic.atomic_replace`, but the temporary name ends with the target's
    suffix (``.<name>.<random>.tmp.mp4``): video writers choose the container from it."""
    temp = temp_path(path)
    temp = temp.with_name(temp.name + path.suffix)
    try:
        yield temp
        with temp.open("rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temp, path)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    fsync_directory(path.parent)


def _write_gif(temp: Path, frames: Iterator[np.ndarray], fps: float) -> None:
    images = [Image.fromarray(frame) for frame in frames]
    # GIF delays are in centiseconds; Pillow rounds the millisecond duration. Pillow merges
    # consecutive identical frames, which only happens for maps no light changes (e.g. all black).
    images[0].save(
        temp, format="GIF", save_all=True, append_images=images[1:], duration=round(1000.0 / fps), loop=0
    )


def _write_mp4(path: Path, temp: Path, frames: Iterator[np.ndarray], fps: float, size: int) -> None:
    writer = cv2.VideoWriter(str(temp), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (size, size))
    try:
        if not writer.isOpened():
            raise ValueError(f"{path}: cannot open an mp4v video writer (OpenCV built without FFmpeg?)")
        for frame in frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()


def write_animation(
    path: str | os.PathLike[str],
    maps: Tensor,
    *,
    frames: int = 36,
    size: int = 256,
    fps: float = 12,
    **kwargs: object,
) -> Path:
    """Write :func:`animation_frames` (``kwargs`` passed on) as a looping ``.gif`` (Pillow) or an
    ``.mp4`` (OpenCV, ``mp4v``), atomically. Returns the path.

    Raises:
        ValueError: another suffix, a bad argument, or no mp4v writer in this OpenCV build.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise ValueError(f"{path}: animation must be one of {sorted(ANIMATION_SUFFIXES)}, got {suffix!r}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    images = animation_frames(maps, frames=frames, size=size, **kwargs)  # type: ignore[arg-type]
    with _atomic_replace_keeping_suffix(path) as temp:
        if suffix == ".gif":
            _write_gif(temp, images, fps)
        else:
            _write_mp4(path, temp, images, fps, size)
    return path
