"""Distant lighting: equirect environment maps, the sun, irradiance balance, direction helpers.

An environment is an equirectangular linear-RGB HDR array ``(H, 2H, 3)`` float32, in the layout
of Mitsuba's ``envmap`` (so one scene renders every kind by swapping data; the frame matrix that
turns Mitsuba's +Y-up emitter into our +Z-up world lives in :mod:`brdfgan.mitsuba_render.environment`):

- texel column j is at ``φ = 2π(j + ½)/W`` and row i at ``θ = iπ/(H − 1)`` (measured on Mitsuba
  3.9: rows are point samples that include both poles, columns are cell centres; the emitter
  interpolates bilinearly between them);
- a texel's world direction (+Z up, docs/conventions.md#scene-and-orientation) is
  ``(sinθ sinφ, sinθ cosφ, cosθ)``: φ runs from +Y towards +X and row 0 is the zenith.

The sun of sun/sky environments is kept out of the map as a :class:`SunLight` (a delta
direction; a 0.53° disc would cover about half a 0.7° texel and either vanish or be smeared).
Random rotation about the up axis is a circular shift of the columns (:func:`rotate_environment`);
the sun direction turns with it. Balance against the flash scales map and sun together so the
irradiance on the upward-facing sample (:func:`upper_hemisphere_irradiance`, sun included) hits a
target (:func:`normalize_environment`).

Direction helpers work on numpy arrays and torch tensors alike, each with its own library's
arithmetic (so a numpy caller gets numpy's sin/cos/cross, a torch caller torch's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import TypeVar

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.exposure import LUMINANCE_WEIGHTS, luminance_value

# Sub-intervals per texel row of the quadrature behind the irradiance weights (error ~1e-6).
_QUADRATURE_PER_ROW = 64

ArrayT = TypeVar("ArrayT", np.ndarray, Tensor)


# ----------------------------------------------------------------------------- directions


def spherical_direction(azimuth_rad: ArrayT, elevation_rad: ArrayT) -> ArrayT:
    """Unit vectors from azimuth (from +X towards +Y) and elevation above the plane z = 0.

    Shape:
        - azimuth_rad, elevation_rad: ``(*)`` (same shape)
        - output: ``(*, 3)``

    Example:
        >>> [round(v, 4) for v in spherical_direction(np.array(0.0), np.array(0.0)).tolist()]
        [1.0, 0.0, 0.0]
        >>> [round(v, 4) for v in spherical_direction(np.array(math.pi / 2), np.array(math.pi / 4)).tolist()]
        [0.0, 0.7071, 0.7071]
        >>> d = spherical_direction(torch.rand(5, generator=torch.Generator().manual_seed(0)), torch.ones(5))
        >>> tuple(d.shape), torch.allclose(d.norm(dim=-1), torch.ones(5))
        ((5, 3), True)
    """
    xp = torch if isinstance(azimuth_rad, Tensor) else np
    cos_elevation = xp.cos(elevation_rad)
    return xp.stack(
        [cos_elevation * xp.cos(azimuth_rad), cos_elevation * xp.sin(azimuth_rad), xp.sin(elevation_rad)], -1
    )


def orthonormal_frame(axis: ArrayT) -> tuple[ArrayT, ArrayT]:
    """Two unit vectors completing the unit ``axis`` to a right-handed frame
    ``(tangent, bitangent, axis)``, with ``tangent = normalize(axis × h)`` for a helper ``h``
    (+X when the axis is within ~26° of ±Z, else +Z) and ``bitangent = axis × tangent``.

    Shape:
        - axis: ``(3,)``
        - output: ``(3,)``, ``(3,)``

    Example:
        >>> tangent, bitangent = orthonormal_frame(np.array([0.0, 0.0, 1.0]))
        >>> tangent.tolist(), bitangent.tolist()
        ([0.0, 1.0, 0.0], [-1.0, 0.0, 0.0])
        >>> np.allclose(np.cross(tangent, bitangent), [0.0, 0.0, 1.0])  # right-handed
        True
    """
    helper = [1.0, 0.0, 0.0] if abs(float(axis[2])) >= 0.9 else [0.0, 0.0, 1.0]
    if isinstance(axis, Tensor):
        tangent = torch.linalg.cross(axis, axis.new_tensor(helper))
        tangent = tangent / torch.linalg.norm(tangent)
        return tangent, torch.linalg.cross(axis, tangent)
    tangent = np.cross(axis, helper)
    tangent = tangent / np.linalg.norm(tangent)
    return tangent, np.cross(axis, tangent)


# ----------------------------------------------------------------------------- environments


@dataclass(frozen=True)
class SunLight:
    """The sun as a directional light: unit ``direction`` towards the sun (world frame, +Z up)
    and RGB ``irradiance`` on a surface facing it (W/m², or the environment's relative units)."""

    direction: tuple[float, float, float]
    irradiance: tuple[float, float, float]

    def rotated(self, angle_rad: float) -> SunLight:
        """Turned by ``angle_rad`` about +Z (right-handed: +X towards +Y)."""
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        x, y, z = self.direction
        return replace(self, direction=(c * x - s * y, s * x + c * y, z))

    def scaled(self, factor: float) -> SunLight:
        r, g, b = self.irradiance
        f = float(factor)
        return replace(self, irradiance=(f * r, f * g, f * b))

    def plane_irradiance(self) -> float:
        """Luminance of the irradiance it puts on the upward-facing plane z = 0."""
        return luminance_value(self.irradiance) * max(self.direction[2], 0.0)


@dataclass(frozen=True, eq=False)
class Environment:
    """Environment radiance ``(H, 2H, 3)`` (Mitsuba envmap convention) plus an optional sun."""

    radiance: np.ndarray
    sun: SunLight | None = None

    def rotated(self, angle_rad: float) -> Environment:
        """Turned by ``angle_rad`` about the up axis (+Z), sun included."""
        sun = self.sun.rotated(angle_rad) if self.sun else None
        return Environment(rotate_environment(self.radiance, angle_rad), sun)

    def scaled(self, factor: float) -> Environment:
        sun = self.sun.scaled(factor) if self.sun else None
        return Environment((self.radiance * np.float32(factor)).astype(np.float32), sun)

    def plane_irradiance(self) -> float:
        """Luminance of the irradiance on the upward-facing plane, sun included."""
        sun = self.sun.plane_irradiance() if self.sun else 0.0
        return upper_hemisphere_irradiance(self.radiance) + sun


def check_equirect(array: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``array`` is an equirect map ``(H, 2H, 3)`` with ``H >= 3``."""
    if array.ndim != 3 or array.shape[2] != 3 or array.shape[1] != 2 * array.shape[0] or array.shape[0] < 3:
        raise ValueError(f"expected an equirect array of shape (H, 2H, 3) with H >= 3, got {array.shape}")


def equirect_directions(height: int, supersample: int = 1) -> np.ndarray:
    """World directions (+Z up) of the texels of an ``(height, 2·height)`` map.

    With ``supersample = s > 1``, ``s²`` directions spread evenly over each texel's cell
    (``Δθ = π/(H − 1)`` by ``Δφ = 2π/W`` around the texel's sample point), for box filtering.

    Shape:
        - output: ``(H, 2H, 3)``, or ``(H, 2H, s², 3)`` with supersampling
    """
    if height < 3:
        raise ValueError(f"equirect height must be >= 3, got {height}")
    width = 2 * height
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5  # (s,) in (−½, ½)
    rows = np.arange(height)[:, None] + offsets[None, :]  # (H, s)
    cols = np.arange(width)[:, None] + 0.5 + offsets[None, :]  # (W, s)
    theta = np.clip(rows * (math.pi / (height - 1)), 0.0, math.pi)
    phi = cols * (2.0 * math.pi / width)
    # (H, W, s_theta, s_phi)
    theta = theta[:, None, :, None]
    phi = phi[None, :, None, :]
    sin_theta = np.sin(theta)
    directions = np.stack(
        np.broadcast_arrays(sin_theta * np.sin(phi), sin_theta * np.cos(phi), np.cos(theta)), axis=-1
    )
    directions = directions.reshape(height, width, supersample * supersample, 3)
    return directions[:, :, 0] if supersample == 1 else directions


@lru_cache(maxsize=16)
def _row_irradiance_weights(height: int) -> np.ndarray:
    # Mitsuba interpolates rows linearly in θ between samples at θ_i = iπ/(H − 1), so texel row i
    # carries the hat function around θ_i; its weight is ∫ hat_i(θ) cosθ sinθ dθ over the upper
    # hemisphere (θ ≤ π/2), times the column width Δφ (each column's hat integrates to Δφ in φ).
    delta = math.pi / (height - 1)
    count = max(_QUADRATURE_PER_ROW * (height - 1), 8192)
    theta = (np.arange(count) + 0.5) * (math.pi / count)  # midpoints over [0, π]
    integrand = np.where(theta <= math.pi / 2, np.cos(theta) * np.sin(theta), 0.0) * (math.pi / count)
    position = theta / delta
    lower = np.minimum(np.floor(position).astype(np.int64), height - 2)
    frac = position - lower
    # float64: bincount with weights sums them (its stubs only know the integer counting form).
    weights: np.ndarray = np.bincount(lower, integrand * (1.0 - frac), minlength=height)
    weights += np.bincount(lower + 1, integrand * frac, minlength=height)
    weights *= 2.0 * math.pi / (2 * height)
    weights.setflags(write=False)
    return weights


def upper_hemisphere_irradiance_rgb(array: np.ndarray) -> np.ndarray:
    """RGB irradiance on the upward-facing plane (cosine-weighted over θ ≤ 90°).

    Shape:
        - array: ``(H, 2H, 3)``
        - output: ``(3,)`` float64
    """
    check_equirect(array)
    weights = _row_irradiance_weights(array.shape[0])
    return np.einsum("h,hwc->c", weights, array.astype(np.float64))


def upper_hemisphere_irradiance(array: np.ndarray) -> float:
    """Luminance of the irradiance the environment puts on the upward-facing plane.

    A constant environment of radiance L gives π·L.

    Shape:
        - array: ``(H, 2H, 3)``

    Example:
        >>> round(upper_hemisphere_irradiance(np.full((16, 32, 3), 2.0, np.float32)) / math.pi, 4)
        2.0
    """
    return luminance_value(upper_hemisphere_irradiance_rgb(array))


def rotate_environment(array: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotate an environment about the up axis (+Z) by ``angle_rad`` (right-handed, +X → +Y).

    A light at azimuth φ (from +Y towards +X) moves to φ − angle, i.e. the columns shift by
    ``angle·W/2π``. Fractional shifts interpolate linearly between the two neighbouring integer
    shifts (exact for multiples of 2π/W; otherwise a blur of under one texel). Column sums are
    preserved, so the plane irradiance does not change.

    Shape:
        - array: ``(H, 2H, C)``
        - output: same
    """
    width = array.shape[1]
    shift = (angle_rad * width / (2.0 * math.pi)) % width
    whole = math.floor(shift)
    frac = shift - whole
    base = np.roll(array, -whole, axis=1)
    if frac < 1e-9:
        return base.astype(np.float32, copy=True)
    nxt = np.roll(base, -1, axis=1)
    return ((1.0 - frac) * base + frac * nxt).astype(np.float32)


def flash_irradiance(radiant_intensity: Sequence[float], distance: float) -> float:
    """Luminance of the flash irradiance ``I / d²`` at the sample centre (flash at the camera)."""
    if distance <= 0:
        raise ValueError(f"flash distance must be positive, got {distance}")
    return luminance_value(radiant_intensity) / (distance * distance)


def normalize_environment(environment: Environment, target_irradiance: float) -> Environment:
    """Scale radiance and sun together so the plane irradiance equals ``target_irradiance``."""
    current = environment.plane_irradiance()
    if not current > 0.0:
        raise ValueError("cannot normalise an environment that puts no light on the sample plane")
    return environment.scaled(target_irradiance / current)


# ----------------------------------------------------------------------------- distant lights


@lru_cache(maxsize=16)
def _texel_solid_angles(height: int) -> np.ndarray:
    # Row i is a point sample at θ_i = iπ/(H − 1) standing for the band of half a row either side;
    # below the horizon the sample plane hides the light, so those rows weigh nothing.
    delta = math.pi / (height - 1)
    theta = np.arange(height) * delta
    top = np.clip(theta - delta / 2.0, 0.0, math.pi / 2.0)
    bottom = np.clip(theta + delta / 2.0, 0.0, math.pi / 2.0)
    solid = (np.cos(top) - np.cos(bottom)) * (2.0 * math.pi / (2 * height))
    solid.setflags(write=False)
    return solid


def environment_lights(
    environment: Environment, count: int, generator: torch.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Distant lights whose sum stands for the environment's upper hemisphere, plus its sun.

    ``count`` texels are drawn, stratified, with probability proportional to their luminance times
    their solid angle ``Ω``; each becomes a light along its texel's direction (jittered inside the
    cell) carrying the irradiance ``L Ω / (count · p)`` at normal incidence, so the lights' sum is
    an unbiased estimate of the environment's light on any surface; the sun comes last as one more
    light (zero irradiance when there is none or it is set). Why lights: the project's renderer
    shades point lights (:mod:`brdfgan.core.render`), and a few dozen lights drawn afresh for every
    photo light each photo plausibly while the set of photos covers the environment.

    Returns:
        ``(directions, irradiance)``: unit world directions (+Z up) and RGB irradiance on a surface
        facing each light, float64.

    Shape:
        - environment.radiance: ``(H, 2H, 3)``
        - output: ``(count + 1, 3)``, ``(count + 1, 3)``

    Example:
        A constant sky of radiance 1 puts π on the upward-facing plane; the lights' cosine-weighted
        sum estimates it without bias (exactly here, since every texel has the same luminance per
        solid angle):

        >>> sky = Environment(np.ones((16, 32, 3), np.float32))
        >>> directions, irradiance = environment_lights(sky, 64, torch.Generator().manual_seed(0))
        >>> round(float((irradiance[:, 1] * directions[:, 2]).sum() / math.pi), 2)
        1.0
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    radiance = environment.radiance
    check_equirect(radiance)
    height, width = radiance.shape[:2]
    solid = np.broadcast_to(_texel_solid_angles(height)[:, None], (height, width))
    luma = np.einsum("hwc,c->hw", radiance.astype(np.float64), np.asarray(LUMINANCE_WEIGHTS))
    weights = (np.maximum(luma, 0.0) * solid).ravel()
    total = weights.sum()
    directions = np.zeros((count + 1, 3))
    irradiance = np.zeros((count + 1, 3))
    u = torch.rand(count, 3, generator=generator, dtype=torch.float64).numpy()
    if total > 0.0:
        cdf = np.cumsum(weights) / total
        strata = (np.arange(count) + u[:, 0]) / count
        texels = np.minimum(np.searchsorted(cdf, strata, side="right"), weights.size - 1)
        rows, cols = np.divmod(texels, width)
        theta = np.clip((rows + u[:, 1] - 0.5) * (math.pi / (height - 1)), 0.0, math.pi / 2.0)
        phi = (cols + u[:, 2]) * (2.0 * math.pi / width)
        directions[:count] = np.stack(
            [np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)], axis=-1
        )
        # L·Ω / (count · p) with p = luma·Ω / total: the texel's colour at total / (count · luma).
        colour = radiance[rows, cols].astype(np.float64)
        irradiance[:count] = colour * (total / (count * luma[rows, cols]))[:, None]
    sun = environment.sun
    if sun is not None and sun.direction[2] > 0.0:
        directions[count] = sun.direction
        irradiance[count] = sun.irradiance
    else:
        directions[count] = (0.0, 0.0, 1.0)
    return directions, irradiance
