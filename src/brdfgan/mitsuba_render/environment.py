"""The Mitsuba side of environment lighting: the envmap frame and sun/sky evaluation.

- :data:`ENVMAP_TO_WORLD` (+90° about X) takes the ``envmap`` emitter's local frame (+Y up,
  φ = 0 at −Z) to ours (+Z up), so its texels lie at
  :func:`brdfgan.core.lighting.equirect_directions`.
- :func:`sunsky_environment`: Mitsuba's Hosek–Wilkie ``sunsky`` emitter evaluated on the texel
  directions with ``sun_scale = 0``. The sun disc (0.53° across) covers about half a texel of a
  256×512 map (0.7° texels) and far less of the small maps of tests: a texel's point sample
  either misses it, and the sun — most of the daylight — vanishes, or hits it, and bilinear
  interpolation spreads the disc radiance over ~2×2 texels, a ~1.4° sun with several times its
  power. The sun is instead a separate :class:`~brdfgan.core.lighting.SunLight`, rendered as a
  ``directional`` emitter whose irradiance is the sun radiance integrated over the disc (a delta
  direction instead of a 0.53° disc only matters for near-mirror surfaces).

Mitsuba is imported on first use (:func:`brdfgan.mitsuba_render.variant.mitsuba`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from brdfgan.core.lighting import (
    Environment,
    SunLight,
    equirect_directions,
    orthonormal_frame,
    spherical_direction,
    upper_hemisphere_irradiance_rgb,
)
from brdfgan.mitsuba_render.variant import mitsuba

# Mitsuba envmap local frame (+Y up, φ = 0 at −Z) → our world (+Z up): +90° about X maps
# local +Y to world +Z and local −Z to world +Y.
ENVMAP_TO_WORLD: tuple[tuple[float, ...], ...] = (
    (1.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, -1.0, 0.0),
    (0.0, 1.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, 1.0),
)
# Angular diameter of the sun used by Mitsuba's sunsky (its default, degrees).
SUN_APERTURE_DEG = 0.5358


def eval_emitter(emitter: Any, directions: np.ndarray) -> np.ndarray:
    """Radiance an emitter sends towards the origin from world ``directions``.

    Shape:
        - directions: ``(N, 3)``
        - output: ``(N, 3)`` float32
    """
    mi = mitsuba()
    import drjit as dr

    wi = -np.ascontiguousarray(directions, dtype=np.float32)
    if mi.variant().startswith("scalar"):  # no vectorised evaluation: one direction at a time
        out = np.empty_like(wi)
        si = dr.zeros(mi.SurfaceInteraction3f)
        for n, w in enumerate(wi):
            si.wi = mi.Vector3f(*map(float, w))
            out[n] = np.array(emitter.eval(si))
        return out
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2])
    return np.array(emitter.eval(si), dtype=np.float32).T.copy()


def sunsky_environment(
    elevation_deg: float, azimuth_deg: float, turbidity: float, ground_albedo: float, resolution: int
) -> Environment:
    """Sky map at equirect height ``resolution`` plus the sun as a :class:`SunLight`.

    The sun sits at ``elevation_deg`` above the plane and ``azimuth_deg`` from +X towards +Y.
    Below the horizon the map shows a Lambertian plain of ``ground_albedo`` lit by sky and sun.
    """
    mi = mitsuba()
    sun = spherical_direction(np.array(math.radians(azimuth_deg)), np.array(math.radians(elevation_deg)))
    base = {
        "type": "sunsky",
        "sun_direction": [float(c) for c in sun],
        "turbidity": float(turbidity),
        "albedo": ground_albedo,
        "sun_aperture": SUN_APERTURE_DEG,
    }
    # The emitter's own frame is the world frame (+Z up; the tests check the sky is above).
    sky = mi.load_dict({**base, "sun_scale": 0.0})
    directions = equirect_directions(resolution).reshape(-1, 3)
    radiance = np.maximum(eval_emitter(sky, directions), 0.0).reshape(resolution, 2 * resolution, 3)

    # Sun irradiance: integrate the disc radiance (limb darkening included) on a polar grid
    # uniform in solid angle; the sky alone is evaluated from the sun-less emitter.
    sun_only = mi.load_dict({**base, "sky_scale": 0.0})
    half = math.radians(SUN_APERTURE_DEG) / 2.0
    n_r, n_phi = 16, 32
    u = (np.arange(n_r) + 0.5) / n_r
    cos_a = 1.0 - u * (1.0 - math.cos(half))  # uniform in cos(angle) = uniform in solid angle
    sin_a = np.sqrt(1.0 - cos_a**2)
    psi = (np.arange(n_phi) + 0.5) * (2.0 * math.pi / n_phi)
    tangent, bitangent = orthonormal_frame(sun)
    disc = (
        cos_a[:, None, None] * sun
        + (sin_a[:, None] * np.cos(psi)[None, :])[..., None] * tangent
        + (sin_a[:, None] * np.sin(psi)[None, :])[..., None] * bitangent
    ).reshape(-1, 3)
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(half))
    sun_radiance = np.maximum(eval_emitter(sun_only, disc), 0.0).astype(np.float64)
    sun_irradiance = sun_radiance.mean(axis=0) * solid_angle

    # Ground below the horizon: a Lambertian plain of the model's ground albedo lit by sky + sun.
    # The sample plane hides it, but reflections off tilted normals near grazing may see it.
    ground_e = upper_hemisphere_irradiance_rgb(radiance) + sun_irradiance * sun[2]
    below = equirect_directions(resolution)[..., 2] < 0.0
    radiance[below] = (ground_albedo * ground_e / math.pi).astype(np.float32)
    light = SunLight(
        (float(sun[0]), float(sun[1]), float(sun[2])),
        (float(sun_irradiance[0]), float(sun_irradiance[1]), float(sun_irradiance[2])),
    )
    return Environment(radiance.astype(np.float32), light)
