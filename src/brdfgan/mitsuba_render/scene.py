"""A Mitsuba 3 scene of a planar map set: ``principled`` + ``normalmap`` on a rectangle.

Geometry matches :mod:`brdfgan.core.render`: the sample covers ``[-s, s]²`` of z = 0, the camera
looks down −Z from above the centre and frames the square, or takes any
:class:`~brdfgan.core.render.CameraPose` (``look_at`` with ``fov_axis = "x"``: its image frame is
:func:`~brdfgan.core.render.camera_frame`'s). Mitsuba's ``rectangle`` maps bitmap
row 0 to y = −s (the bottom of the image) while our row 0 is +Y, so rows are flipped on the way
in — rows only; the Y component of the normals stays as it is (docs/conventions.md#mitsuba-row-flip).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.render import CameraPose, FlashCapture, nominal_camera
from brdfgan.core.svbrdf import encode_normal, split_maps, srgb_to_linear, validate_maps
from brdfgan.mitsuba_render.variant import mitsuba


@dataclass(frozen=True)
class MitsubaPointLight:
    """A point light: world ``position`` and RGB radiant ``intensity`` in W/sr."""

    position: tuple[float, float, float]
    intensity: tuple[float, float, float]


def _bitmap_texture(mi: Any, image: Tensor) -> dict[str, Any]:
    """(C, H, W) tensor in our orientation → nearest-filtered raw bitmap texture, rows flipped."""
    array = image.detach().to("cpu", torch.float32).flip(-2).permute(1, 2, 0).contiguous().numpy()
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(array)),
        "raw": True,
        "filter_type": "nearest",
    }


def camera_to_world(pose: CameraPose) -> Any:
    """The sensor's ``to_world`` of ``pose`` (a ``look_at``; Mitsuba's frame: local +X is the
    image's left, +Y its up, +Z the view direction)."""
    mi = mitsuba()
    return mi.ScalarTransform4f().look_at(
        origin=[float(c) for c in pose.origin],
        target=[float(c) for c in pose.target],
        up=[float(c) for c in pose.up],
    )


def material_dict(maps: Tensor) -> dict[str, Any]:
    """Mitsuba BSDF dict for one map set: normalmap( principled(base color, roughness, metallic) ).

    Shape:
        - maps: ``(8, H, W)``
    """
    mi = mitsuba()
    validate_maps(maps)
    parts = split_maps(maps)
    principled = {
        "type": "principled",
        "base_color": _bitmap_texture(mi, srgb_to_linear(parts.basecolor)),
        "roughness": _bitmap_texture(mi, parts.roughness),
        "metallic": _bitmap_texture(mi, parts.metallic),
        "specular": 0.5,
    }
    return {
        "type": "normalmap",
        "normalmap": _bitmap_texture(mi, encode_normal(parts.normal)),
        "bsdf": principled,
    }


def plane_scene_dict(
    maps: Tensor,
    *,
    lights: Sequence[MitsubaPointLight] = (),
    fov_deg: float = 45.0,
    plane_half_size: float = 1.0,
    spp: int = 64,
    seed: int = 0,
    resolution: int | tuple[int, int] | None = None,
    integrator: dict[str, Any] | None = None,
    extra_emitters: dict[str, dict[str, Any]] | None = None,
    camera: CameraPose | None = None,
) -> dict[str, Any]:
    """Scene dict for ``mi.load_dict``: the textured plane, the capture camera and the lights.

    Args:
        maps: the map set to render.
        lights: point lights (e.g. the flash at the camera position).
        fov_deg: horizontal field of view of the nominal camera; its height follows from it.
        plane_half_size: half the side of the sample square.
        spp: samples per pixel.
        seed: sampler seed.
        resolution: film size, square or ``(width, height)`` (default: the map size).
        integrator: integrator dict (default: ``direct``, enough for a single plane).
        extra_emitters: further emitters by name (environment maps, sun/sky).
        camera: the camera pose, field of view included (default: the nominal camera of
            ``fov_deg``, :func:`~brdfgan.core.render.nominal_camera`).

    Shape:
        - maps: ``(8, H, W)``
    """
    mi = mitsuba()
    _, height, width = maps.shape
    pose = camera if camera is not None else nominal_camera(fov_deg, plane_half_size)
    if resolution is None:
        film_w, film_h = width, height
    else:
        film_w, film_h = (resolution, resolution) if isinstance(resolution, int) else resolution
    scene: dict[str, Any] = {
        "type": "scene",
        "integrator": integrator or {"type": "direct"},
        "sensor": {
            "type": "perspective",
            "fov": float(pose.fov_deg),
            "fov_axis": "x",
            "to_world": camera_to_world(pose),
            "film": {
                "type": "hdrfilm",
                "width": film_w,
                "height": film_h,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
        },
        "sample": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().scale([plane_half_size, plane_half_size, 1.0]),
            "bsdf": material_dict(maps),
        },
    }
    for index, light in enumerate(lights):
        scene[f"point_light_{index}"] = {
            "type": "point",
            "position": list(map(float, light.position)),
            "intensity": {"type": "rgb", "value": list(map(float, light.intensity))},
        }
    scene.update(extra_emitters or {})
    return scene


def render_scene(scene_dict: dict[str, Any], spp: int | None = None, seed: int = 0) -> Tensor:
    """Load and render a scene dict; linear HDR image ``(3, H, W)`` in our orientation (row 0 = +Y)."""
    mi = mitsuba()
    scene = mi.load_dict(scene_dict)
    image = mi.render(scene, spp=spp or 0, seed=seed)
    return torch.from_numpy(np.array(image, dtype=np.float32)).permute(2, 0, 1)[:3].contiguous()


def render_flash_mitsuba(
    maps: Tensor, capture: FlashCapture = FlashCapture(), *, spp: int = 64, seed: int = 0
) -> Tensor:
    """Mitsuba reference of :func:`brdfgan.core.render.render_flash`: point light at the camera.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(3, H, W)``
    """
    flash = MitsubaPointLight((0.0, 0.0, capture.camera_height), capture.radiant_intensity)
    scene = plane_scene_dict(
        maps,
        lights=[flash],
        fov_deg=capture.fov_deg,
        plane_half_size=capture.plane_half_size,
        spp=spp,
        seed=seed,
    )
    return render_scene(scene, seed=seed)
