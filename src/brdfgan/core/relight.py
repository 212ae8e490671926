"""Re-rendering one map set from the capture camera under new lights: point lights and a sky.

The project's own renderer (:func:`brdfgan.core.render.render_point_lights`, the BRDF the network
was trained with) from the camera of :class:`~brdfgan.core.render.FlashCapture` (above the
sample centre, looking down −Z, row 0 = +Y). Point lights are rendered one at a time and sky
lights in small chunks, so memory stays at a few renderings whatever the number of lights.
"""

from __future__ import annotations

import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.render import FlashCapture, PointLights, render_point_lights
from brdfgan.core.sky import ProceduralSky, sample_sky
from brdfgan.core.svbrdf import check_single_maps

# Sky lights sit this many plane half-sizes away. A light at distance D with intensity E·D² gives
# irradiance E at the centre; over the sample (|p| ≤ √2 s) |x − p|² = D² − 2D ω·p + |p|² differs
# from D² by at most ~2√2 s/D relative: 0.03 % here, i.e. a directional light for all practical purposes.
# float32 still resolves it: D² = 1e8 is exact to 1e-7 relative and the direction to ~1e-7 rad.
SKY_LIGHT_DISTANCE = 1.0e4
SKY_CHUNK = 8  # sky lights rendered per render_point_lights call (as configurations)


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
    sky: ProceduralSky | None = None,
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
        sky: if given, its rendering (:func:`render_sky`, ``samples`` lights) is added to every
            point-light rendering.
        capture: camera (field of view) and plane size; its flash is not used.

    Returns:
        Linear HDR radiance, one rendering per light. Differentiable w.r.t. ``maps``.

    Shape:
        - maps: ``(8, H, W)``
        - light_positions: ``(L, 3)``
        - intensity: ``()``, ``(L,)`` or ``(L, 3)``
        - output: ``(L, 3, H, W)``

    Example:
        One texel at the centre lit from straight above at distances 2 and 4 (the same BRDF
        value): inverse-square falloff, ``(4/2)² = 4``; a light below the plane gives nothing:

        >>> from brdfgan.core.svbrdf import flat_maps
        >>> lights = torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, 4.0], [0.0, 0.0, -1.0]])
        >>> images = relight(flat_maps(1, 1), lights)
        >>> tuple(images.shape)
        (3, 3, 1, 1)
        >>> round((images[0] / images[1]).mean().item(), 4), images[2].flatten().tolist()
        (4.0, [0.0, 0.0, 0.0])
    """
    check_single_maps(maps)
    check_shape(light_positions, "L 3", name="light_positions")
    rgb = _light_rgb(intensity, light_positions.shape[0], maps)
    # One light per renderer call: L is small and this keeps memory at one rendering's worth.
    images = _render_lights(maps, light_positions, rgb, capture, chunk=1, combine=False)
    if sky is not None:
        images = images + render_sky(maps, sky, samples=samples, capture=capture)
    return images


def render_sky(
    maps: Tensor,
    sky: ProceduralSky,
    *,
    samples: int = 64,
    seed: int = 0,
    capture: FlashCapture = FlashCapture(),
    chunk: int = SKY_CHUNK,
) -> Tensor:
    """Render a map set from the capture camera under a sky.

    The sky becomes ``samples`` distant lights (:func:`~brdfgan.core.sky.sample_sky`). The renderer only
    knows point lights, so each is placed :data:`SKY_LIGHT_DISTANCE` plane half-sizes away
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
    check_single_maps(maps)
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    directions, irradiance = sample_sky(sky, samples, seed=seed)
    keep = irradiance.amax(dim=-1) > 0.0
    distance = SKY_LIGHT_DISTANCE * capture.plane_half_size
    positions = (directions[keep] * distance).to(maps)
    rgb = (irradiance[keep] * distance**2).to(maps)
    if positions.shape[0] == 0:
        return maps.new_zeros(3, *maps.shape[-2:])
    return _render_lights(maps, positions, rgb, capture, chunk=chunk, combine=True)
