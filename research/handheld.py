"""Handheld flash photos of a flat sample, rendered with Mitsuba: the ground truth of ``predict --views``.

Several photos of one material from cameras anywhere above it (tilted, rolled, nearer or farther,
off centre), each lit by its own flash, as a phone held by hand takes them. The plane is three
times the sample's side (:func:`surrounded_maps` lays the sample 3 × 3 where no larger surface is
at hand), so a photo that sees past the sample square sees more surface, never the plane's edge
or the void: a real surface goes on past the part that is measured. Rendered by Mitsuba, not the
project's renderer, so a fit of the project's renderer to these photos is graded by another model
of the light (docs/views.md).

Integrator ``direct`` and an independent sampler, as
:func:`~brdfgan.mitsuba_render.scene.render_flash_mitsuba`: a point light is the only emitter, so
no emitter choice adds noise.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.render import CameraPose, Vector3
from brdfgan.core.svbrdf import validate_maps
from brdfgan.mitsuba_render.scene import MitsubaPointLight, plane_scene_dict, render_scene

# Copies of the maps along each side of the plane; odd, so the sample square is the central copy.
SURROUND_TILES = 3


def surrounded_maps(maps: Tensor, tiles: int = SURROUND_TILES) -> Tensor:
    """The maps repeated ``tiles × tiles`` times: the texture of a plane ``tiles`` times the
    sample's side whose central copy is the sample square.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(8, tiles·H, tiles·W)``
    """
    check_shape(maps, "8 H W", name="maps")
    if tiles < 1 or tiles % 2 == 0:
        raise ValueError(f"tiles must be a positive odd number, got {tiles}")
    return maps.repeat(1, tiles, tiles)


def render_handheld(
    maps: Tensor,
    cameras: Sequence[CameraPose],
    flash_positions: Sequence[Vector3],
    flash_intensity: tuple[float, float, float],
    width: int,
    height: int,
    *,
    plane_half_size: float = 1.0,
    spp: int = 64,
    seed: int = 0,
) -> Tensor:
    """Linear HDR photos of the plane ``[-s, s]²`` of z = 0 (``maps`` cover it, row 0 at +Y; for a
    sample that continues past the part measured, :func:`surrounded_maps` of it with ``s`` the
    sample's half side times :data:`SURROUND_TILES`) from each camera, lit by a point flash of RGB
    radiant ``flash_intensity`` (W/sr) at that view's ``flash_positions`` entry.

    Each view has its own sampler seed (``seed + view``), so the views' noise is independent.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(V, 3, height, width)``
    """
    validate_maps(maps)
    check_shape(maps, "8 H W", name="maps")
    if len(cameras) != len(flash_positions) or not cameras:
        raise ValueError(f"need one flash position per camera, got {len(flash_positions)} for {len(cameras)}")
    if width < 1 or height < 1:
        raise ValueError(f"film size must be positive, got {width}×{height}")
    plane = maps.float().cpu()
    photos = []
    for view, (camera, flash) in enumerate(zip(cameras, flash_positions, strict=True)):
        scene = plane_scene_dict(
            plane,
            lights=[MitsubaPointLight((float(flash[0]), float(flash[1]), float(flash[2])), flash_intensity)],
            plane_half_size=plane_half_size,
            spp=spp,
            seed=seed + view,
            resolution=(width, height),
            camera=camera,
        )
        photos.append(render_scene(scene, seed=seed + view))
    return torch.stack(photos)
