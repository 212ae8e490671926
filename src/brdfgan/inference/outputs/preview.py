"""Relit previews of predicted maps for the CLI: still images and turntable-light animations.

Everything is rendered by the project's own renderer (:func:`brdfgan.core.render.shade_point_lights`,
the BRDF the network was trained with, from the capture camera), so a preview shows what the maps do,
not what some other shading model makes of them. The still preview renders exactly the lights of
:func:`~brdfgan.core.relight.relight` and :func:`~brdfgan.core.relight.render_sky`, batched
(:func:`render_preview_tiles`).

Lighting:

- **Point lights** (:func:`preview_lights`): novel positions, never the flash — ``count − 1`` lights at
  45° elevation with azimuths spread evenly (azimuth measured from +X towards +Y, i.e. counter-clockwise
  in the image), plus one grazing light at 12° between the first two, which shows the normal map's
  relief. Distance 3 plane half-sizes, intensity 1 W/sr (the flash's default).
- **Environment** tile: the procedural sky of :class:`~brdfgan.core.sky.ProceduralSky`, importance
  sampled into :data:`PREVIEW_SKY_SAMPLES` distant lights (:func:`~brdfgan.core.sky.sample_sky`, placed
  as :func:`~brdfgan.core.relight.render_sky` places them).
- **Exposure**: each still rendering goes through the paper's auto exposure
  (:func:`brdfgan.core.exposure.auto_expose`) and then the sRGB curve; an animation uses one exposure for
  all frames so it does not flicker.

Memory stays bounded for big maps: the maps are area-downscaled to the tile size *before* rendering.

Speed: in eager torch every elementwise step is one pass over memory and a thread fork-join, so
:func:`render_preview_tiles` decodes the maps once (:func:`~brdfgan.core.render.shading_inputs`)
and shades all lights, point and sky, as configurations of a few
:func:`~brdfgan.core.render.shade_point_lights` calls (:data:`RENDER_CHUNK` lights each): far fewer
steps for the same images to float32 rounding. The timings, and the alternatives not taken (fewer
sky lights, half-size rendering, ``torch.compile``): docs/benchmarks.md#predict-time-and-memory.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import auto_expose, auto_exposure_scale
from brdfgan.core.lighting import spherical_direction
from brdfgan.core.relight import SKY_LIGHT_DISTANCE, relight
from brdfgan.core.render import FlashCapture, PointLights, shade_point_lights, shading_inputs
from brdfgan.core.sky import ProceduralSky, sample_sky
from brdfgan.core.svbrdf import check_single_maps, linear_to_srgb, resize_image, resize_maps
from brdfgan.io.atomic import atomic_replace
from brdfgan.io.video import write_video

__all__ = [
    "animation_frames",
    "preview_image",
    "preview_lights",
    "render_preview_tiles",
    "write_animation",
    "write_preview",
]

PREVIEW_LIGHT_DISTANCE = 3.0  # in plane half-sizes: outside the sample, close enough for visible falloff
PREVIEW_ELEVATION_DEG = 45.0
GRAZING_ELEVATION_DEG = 12.0
ANIMATION_ELEVATION_DEG = 30.0
SEPARATOR = 4  # px between tiles
SEPARATOR_COLOR = (48, 48, 48)
LABEL_HEIGHT = 18  # px strip above each tile for its label
# Sky lights of the environment tile: fewer are visibly noisier on normal-mapped glossy maps
# (bench_preview's sampling error: docs/benchmarks.md#predict-time-and-memory), so the count stays
# and the speed comes from RENDER_CHUNK.
PREVIEW_SKY_SAMPLES = 64
# Lights shaded per renderer call (as configurations): fewer, bigger calls mean fewer elementwise
# steps, each a pass over memory and a thread fork-join; 17 splits 4 point + 64 sky lights into 4
# calls at a modest peak memory, where twice that was slower (docs/benchmarks.md#predict-time-and-memory).
RENDER_CHUNK = 17


# ---------------------------------------------------------------------------------------------- maps


# -------------------------------------------------------------------------------------------- lights


def _spherical(azimuth_deg: Tensor, elevation_deg: Tensor, distance: float) -> Tensor:
    return distance * spherical_direction(torch.deg2rad(azimuth_deg), torch.deg2rad(elevation_deg))


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


# ------------------------------------------------------------------------------------------- preview


def render_preview_tiles(
    maps: Tensor,
    light_positions: Tensor,
    sky: ProceduralSky,
    *,
    samples: int = PREVIEW_SKY_SAMPLES,
    seed: int = 0,
    capture: FlashCapture = FlashCapture(),
    chunk: int = RENDER_CHUNK,
) -> Tensor:
    """The maps under each point light (intensity 1 W/sr) and under the sky, in one batched pass.

    The same lights and the same renderer as ``relight(maps, light_positions)`` followed by
    ``render_sky(maps, sky, samples=samples, seed=seed)`` (:mod:`brdfgan.core.relight`), so the
    same images up to float32 rounding (the sky's lights are summed in another order): the sky
    becomes ``samples`` distant lights (:func:`~brdfgan.core.sky.sample_sky`) placed
    :data:`~brdfgan.core.relight.SKY_LIGHT_DISTANCE` plane half-sizes away with intensity ``E·D²``,
    those below the horizon dropped. What differs is the cost: the per-texel terms of the maps are
    computed once (:func:`~brdfgan.core.render.shading_inputs`) and all lights, point and sky, are
    shaded as configurations of :func:`~brdfgan.core.render.shade_point_lights`, ``chunk`` (at most)
    per call, in calls of equal size. Peak memory grows with ``chunk`` (~12 MiB per light at 256²),
    not with the number of lights.

    Returns:
        Linear HDR radiance: ``L`` point-light renderings, then the sky's.

    Shape:
        - maps: ``(8, H, W)``
        - light_positions: ``(L, 3)`` world positions (plane units)
        - output: ``(L + 1, 3, H, W)``
    """
    check_single_maps(maps)
    check_shape(light_positions, "L 3", name="light_positions")
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    directions, irradiance = sample_sky(sky, samples, seed=seed)
    keep = irradiance.amax(dim=-1) > 0.0
    distance = SKY_LIGHT_DISTANCE * capture.plane_half_size
    point_count = light_positions.shape[0]
    positions = torch.cat([light_positions.to(directions), directions[keep] * distance]).to(maps)
    rgb = torch.cat([irradiance.new_ones(point_count, 3), irradiance[keep] * distance**2]).to(maps)
    total = positions.shape[0]
    size = math.ceil(total / max(math.ceil(total / chunk), 1)) if total else 1
    inputs = shading_inputs(maps[None])
    camera = maps.new_tensor([0.0, 0.0, capture.camera_height])
    point_images: list[Tensor] = []
    sky_image = maps.new_zeros(3, *maps.shape[-2:])
    for start in range(0, total, size):
        views = min(size, total - start)
        lights = PointLights(
            position=positions[start : start + views].view(1, views, 1, 3),
            intensity=maps.new_ones(1, views, 1),
            color=rgb[start : start + views].view(1, views, 1, 3),
        )
        rendered = shade_point_lights(inputs, camera.expand(1, views, 3), lights, capture.plane_half_size)[0]
        points_here = min(max(point_count - start, 0), views)
        if points_here:
            point_images.append(rendered[:points_here])
        if points_here < views:
            sky_image = sky_image + rendered[points_here:].sum(dim=0)
    return torch.cat([*point_images, sky_image[None]])


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
    sky: ProceduralSky | None = None,
    samples: int = PREVIEW_SKY_SAMPLES,
    labels: bool = True,
    capture: FlashCapture = FlashCapture(),
) -> np.ndarray:
    """The input photo beside re-renderings of the predicted maps, as one sRGB image.

    Tiles, left to right: the input (what the network saw, sRGB-encoded), the maps under each of
    :func:`preview_lights` ``(lights)``, and under ``sky`` (default :class:`~brdfgan.core.sky.ProceduralSky`)
    as ``samples`` distant lights, all rendered by :func:`render_preview_tiles`.
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
    check_single_maps(maps)
    check_shape(photo, "3 h w", name="photo")
    if tile < 1 or lights < 0:
        raise ValueError(f"tile must be >= 1 and lights >= 0, got tile={tile}, lights={lights}")
    sky = sky if sky is not None else ProceduralSky()
    positions = preview_lights(lights) * capture.plane_half_size if lights else torch.zeros(0, 3)
    with torch.no_grad():
        small = resize_maps(maps.detach().float(), tile)
        ldr, _ = auto_expose(render_preview_tiles(small, positions, sky, samples=samples, capture=capture))
        input_tile = resize_image(photo.detach().float().to(small.device), tile, tile)
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


def write_preview(path: str | os.PathLike[str], photo: Tensor, maps: Tensor, **kwargs: Any) -> Path:
    """Write :func:`preview_image` (``kwargs`` passed on) as a PNG, atomically. Returns the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path}: preview must be a .png file")
    image = preview_image(photo, maps, **kwargs)
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
    check_single_maps(maps)
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


def write_animation(
    path: str | os.PathLike[str],
    maps: Tensor,
    *,
    frames: int = 36,
    size: int = 256,
    fps: float = 12,
    **kwargs: Any,
) -> Path:
    """Write :func:`animation_frames` (``kwargs`` passed on) as a looping ``.gif`` (Pillow) or an
    ``.mp4`` (OpenCV, ``mp4v``), atomically. Returns the path.

    Raises:
        ValueError: another suffix, a bad argument, or no mp4v writer in this OpenCV build.
    """
    # animation_frames checks its arguments now and renders lazily, frame by frame, as written.
    return write_video(path, animation_frames(maps, frames=frames, size=size, **kwargs), fps=fps, size=size)
