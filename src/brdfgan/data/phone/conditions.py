"""Randomised capture geometry and exposure, as phone photos vary: field of view, flash offset,
camera tilt, camera distance and exposure error.

Today's photo (every range at its default) has the nominal geometry of
docs/conventions.md#scene-and-orientation: the camera above the sample centre at the framing height
of a 45° horizontal field of view, looking down −Z with +Y up, the flash at the lens, the auto
exposure exact. :class:`CaptureSampling` draws, per photo:

- **field of view** ``fov_deg`` (horizontal, uniform): phones' main and wide cameras after the
  preprocessing's square crop, about 40–75°. The framing distance follows from it
  (:func:`~brdfgan.core.render.capture_camera_height`).
- **tilt** ``tilt_deg`` (uniform in [0, ``tilt_max_deg``]) about a horizontal axis through the
  sample centre at a uniform azimuth ``tilt_axis_deg``: the camera orbits the centre and keeps
  aiming at it, its image frame turned with it.
- **distance** factor relative to the framing distance (uniform in [``distance_min``,
  ``distance_max``], at most 1: closer, so the photo shows a little less than the sample). The
  photo must never see past the sample square (the rectangle ends there): a tilted view's
  footprint is a trapezoid wider on the far side, and since every corner ray keeps its direction
  while the camera slides along its line of sight, the footprint scales linearly with the
  distance. So the drawn factor is **reduced to the largest one whose footprint corners stay
  inside** ``[-s, s]²`` (:func:`max_distance_factor`); ``distance_drawn`` records the draw,
  ``distance_factor`` what was used.
- **flash offset** from the lens: a fraction ``flash_offset`` of the camera distance (phones:
  0.5–2 cm at 20–60 cm ≈ 0.01–0.08), in the image plane at a uniform angle
  ``flash_offset_angle_deg`` (from the image's right towards its up).
- **exposure error** ``exposure_ev`` in stops (uniform) on the auto exposure's scale:
  ``LDR = clip(HDR · scale · 2^ev, 0, 1)`` (:func:`brdfgan.core.exposure.auto_expose`), so the
  flash hotspot is sometimes clipped hard and sometimes not at all.

Every draw takes the same seven uniforms from the generator whatever the ranges, so widening one
range does not shift the others' values. Photos are square (the dataset's ``resolution``²).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from brdfgan.core.render import (
    CameraPose,
    Vector3,
    camera_frame,
    capture_camera_height,
    maps_in_view,
    project_to_image,
    view_footprint,
)
from brdfgan.data.storage.shards import Sample
from brdfgan.data.storage.spec_checks import in_range, ordered

FOV_RANGE_DEG = (1.0, 120.0)
# With the widest field of view the corner rays are 67.8° off the axis; 20° of tilt keeps them
# below the horizon (they must meet the plane).
MAX_TILT_DEG = 20.0
MAX_FLASH_OFFSET = 0.5
DISTANCE_RANGE = (0.5, 1.0)
EV_RANGE = (-4.0, 4.0)
_UNIFORMS_PER_DRAW = 7


def _rotate(vector: np.ndarray, axis: np.ndarray, angle_rad: float) -> np.ndarray:
    # Rodrigues. At angle 0 the result is the vector itself, bit for bit (cos = 1, sin = 0).
    cos, sin = math.cos(angle_rad), math.sin(angle_rad)
    return vector * cos + np.cross(axis, vector) * sin + axis * (axis @ vector) * (1.0 - cos)


def _vector(array: np.ndarray) -> Vector3:
    return (float(array[0]), float(array[1]), float(array[2]))


def tilted_camera(
    fov_deg: float,
    tilt_deg: float,
    tilt_axis_deg: float,
    distance_factor: float,
    plane_half_size: float = 1.0,
) -> CameraPose:
    """The nominal camera (above the centre at the framing height, +Y up) at ``distance_factor``
    times that height, orbited by ``tilt_deg`` about the horizontal axis through the origin at
    azimuth ``tilt_axis_deg`` (from +X towards +Y); it still aims at the sample centre.

    Units: degrees, world units (the sample is ``[-s, s]²``).
    """
    distance = distance_factor * capture_camera_height(fov_deg, plane_half_size)
    azimuth = math.radians(tilt_axis_deg)
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    angle = math.radians(tilt_deg)
    origin = _rotate(np.array([0.0, 0.0, distance]), axis, angle)
    up = _rotate(np.array([0.0, 1.0, 0.0]), axis, angle)
    return CameraPose(_vector(origin), (0.0, 0.0, 0.0), _vector(up), fov_deg)


def max_distance_factor(
    fov_deg: float, tilt_deg: float, tilt_axis_deg: float, plane_half_size: float = 1.0
) -> float:
    """The largest distance factor of :func:`tilted_camera` whose square photo sees only the
    sample square: the footprint scales linearly with the distance, so it is ``s`` over the
    footprint's largest |x| or |y| at factor 1. Exactly 1 without tilt (the framing height puts
    the corners on the square's corners; computed, rounding could put it a hair below)."""
    if tilt_deg == 0.0:
        return 1.0
    corners = view_footprint(tilted_camera(fov_deg, tilt_deg, tilt_axis_deg, 1.0, plane_half_size), 1, 1)
    return min(1.0, plane_half_size / float(np.abs(corners[:, :2]).max()))


def flash_mirror_point(camera_origin: Vector3, flash_position: Vector3) -> Vector3:
    """The point p of the plane z = 0 where the half vector of the directions to the camera C and
    to the flash F is +Z: where a flat mirror shows the flash, ``p = (C·F_z + F·C_z) / (C_z + F_z)``
    (the line from C to F mirrored below the plane crosses it there). Both above the plane.

    Units: world units.
    """
    cx, cy, cz = camera_origin
    fx, fy, fz = flash_position
    if not (cz > 0.0 and fz > 0.0):
        raise ValueError(f"camera {camera_origin} and flash {flash_position} must be above the plane")
    return ((cx * fz + fx * cz) / (cz + fz), (cy * fz + fy * cz) / (cz + fz), 0.0)


def flash_hotspot_px(
    camera: CameraPose, flash_position: Vector3, width: int, height: int
) -> tuple[float, float]:
    """Where the mirror reflection of the flash on the flat (unbumped) sample appears in the
    photo: :func:`flash_mirror_point` projected through the camera.

    Shape / units:
        - output: ``(x, y)`` continuous pixels, x along the columns from the left edge, y along
          the rows from the top; the image centre is ``(width/2, height/2)``
    """
    point = np.asarray([flash_mirror_point(camera.origin, flash_position)])
    x, y = project_to_image(point, camera, width, height)[0]
    return float(x), float(y)


@dataclass(frozen=True)
class CaptureDraw:
    """One photo's capture geometry and exposure error; the defaults are today's photo.

    Angles in degrees; ``distance_drawn``/``distance_factor`` relative to the framing height of
    ``fov_deg``; ``flash_offset`` a fraction of the camera distance; ``exposure_ev`` in stops.
    """

    fov_deg: float = 45.0
    tilt_deg: float = 0.0
    tilt_axis_deg: float = 0.0
    distance_drawn: float = 1.0
    distance_factor: float = 1.0
    flash_offset: float = 0.0
    flash_offset_angle_deg: float = 0.0
    exposure_ev: float = 0.0
    plane_half_size: float = 1.0

    @property
    def camera(self) -> CameraPose:
        return tilted_camera(
            self.fov_deg, self.tilt_deg, self.tilt_axis_deg, self.distance_factor, self.plane_half_size
        )

    @property
    def camera_distance(self) -> float:
        """From the lens to the sample centre, world units."""
        return self.distance_factor * capture_camera_height(self.fov_deg, self.plane_half_size)

    @property
    def flash_position(self) -> Vector3:
        """The lens moved by ``flash_offset · camera_distance`` along the image plane at
        ``flash_offset_angle_deg`` from the image's right towards its up. World units."""
        camera = self.camera
        right, up, _ = camera_frame(camera)
        angle = math.radians(self.flash_offset_angle_deg)
        offset = self.flash_offset * self.camera_distance * (math.cos(angle) * right + math.sin(angle) * up)
        return _vector(np.asarray(camera.origin) + offset)

    def hotspot_px(self, resolution: int) -> tuple[float, float]:
        """:func:`flash_hotspot_px` in the ``resolution``² photo."""
        return flash_hotspot_px(self.camera, self.flash_position, resolution, resolution)

    def to_json(self, resolution: int) -> dict[str, Any]:
        """Plain JSON for the sample metadata: every drawn value, the resulting camera pose and
        flash position (world units), and ``hotspot_px`` (``[x, y]``, :func:`flash_hotspot_px`)."""
        camera = self.camera
        return {
            "fov_deg": self.fov_deg,
            "tilt_deg": self.tilt_deg,
            "tilt_axis_deg": self.tilt_axis_deg,
            "distance_drawn": self.distance_drawn,
            "distance_factor": self.distance_factor,
            "camera_distance": self.camera_distance,
            "flash_offset": self.flash_offset,
            "flash_offset_angle_deg": self.flash_offset_angle_deg,
            "exposure_ev": self.exposure_ev,
            "camera_origin": list(camera.origin),
            "camera_target": list(camera.target),
            "camera_up": list(camera.up),
            "flash_position": list(self.flash_position),
            "hotspot_px": list(self.hotspot_px(resolution)),
        }


def _uniform(u: torch.Tensor, low: float, high: float) -> float:
    # low + u·0 is low exactly: a constant range reproduces its value bit for bit.
    return low + float(u) * (high - low)


@dataclass(frozen=True)
class CaptureSampling:
    """Ranges of the capture randomisation (module docstring); every default is off, which
    draws today's photo. Checked on construction, naming the keys under ``dataset_spec.capture``."""

    fov_min_deg: float = 45.0
    fov_max_deg: float = 45.0
    flash_offset_min: float = 0.0
    flash_offset_max: float = 0.0
    tilt_max_deg: float = 0.0
    distance_min: float = 1.0
    distance_max: float = 1.0
    exposure_ev_min: float = 0.0
    exposure_ev_max: float = 0.0

    def __post_init__(self) -> None:
        key = "dataset_spec.capture"
        for low, high, bounds in (
            ("fov_min_deg", "fov_max_deg", FOV_RANGE_DEG),
            ("flash_offset_min", "flash_offset_max", (0.0, MAX_FLASH_OFFSET)),
            ("distance_min", "distance_max", DISTANCE_RANGE),
            ("exposure_ev_min", "exposure_ev_max", EV_RANGE),
        ):
            ordered(key, self, low, high)
            for name in (low, high):
                in_range(f"{key}.{name}", getattr(self, name), *bounds)
        in_range(f"{key}.tilt_max_deg", self.tilt_max_deg, 0.0, MAX_TILT_DEG)

    def sample(self, generator: torch.Generator, plane_half_size: float = 1.0) -> CaptureDraw:
        """One photo's draw (seven uniforms from ``generator``, whatever the ranges)."""
        u = torch.rand(_UNIFORMS_PER_DRAW, generator=generator, dtype=torch.float64)
        fov = _uniform(u[0], self.fov_min_deg, self.fov_max_deg)
        tilt = _uniform(u[1], 0.0, self.tilt_max_deg)
        tilt_axis = _uniform(u[2], 0.0, 360.0)
        drawn = _uniform(u[3], self.distance_min, self.distance_max)
        return CaptureDraw(
            fov_deg=fov,
            tilt_deg=tilt,
            tilt_axis_deg=tilt_axis,
            distance_drawn=drawn,
            distance_factor=min(drawn, max_distance_factor(fov, tilt, tilt_axis, plane_half_size)),
            flash_offset=_uniform(u[4], self.flash_offset_min, self.flash_offset_max),
            flash_offset_angle_deg=_uniform(u[5], 0.0, 360.0),
            exposure_ev=_uniform(u[6], self.exposure_ev_min, self.exposure_ev_max),
            plane_half_size=plane_half_size,
        )


def recorded_camera(meta: Mapping[str, Any]) -> CameraPose | None:
    """The camera pose a sample's ``meta["capture"]`` records (:meth:`CaptureDraw.to_json`), or
    ``None`` for samples of datasets made before the capture randomisation (nominal camera)."""
    capture = meta.get("capture")
    if not isinstance(capture, Mapping) or "camera_origin" not in capture:
        return None
    return CameraPose(
        _vector(np.asarray(capture["camera_origin"], dtype=np.float64)),
        _vector(np.asarray(capture["camera_target"], dtype=np.float64)),
        _vector(np.asarray(capture["camera_up"], dtype=np.float64)),
        float(capture["fov_deg"]),
    )


def maps_as_photographed(maps: torch.Tensor, meta: Mapping[str, Any]) -> torch.Tensor:
    """The sample's texture-space maps resampled into its photo's pixels
    (:func:`~brdfgan.core.render.maps_in_view` of :func:`recorded_camera`), so that pixel (i, j)
    of the maps describes the surface that pixel (i, j) of the photo shows.

    Why: a randomised capture looks at the sample from a few per cent closer and up to a few
    degrees tilted, so in texture space a texel lies up to ~5 px (at 256²) away from where the photo
    shows it. Fine relief then has no fixed relation to the photo, and a network learns only what
    survives that blur (``research/notes/2026-12-default-model-v3.md``, "The maps were not where
    the photos showed them", has the correlations before and after). Unchanged (the same tensor) for samples
    without a recorded camera.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(8, H, W)``
    """
    pose = recorded_camera(meta)
    return maps if pose is None else maps_in_view(maps, pose)


def sample_as_photographed(sample: Sample) -> Sample:
    """The sample with :func:`maps_as_photographed` maps; ``meta["maps_view"] = "photo"`` says so."""
    maps = maps_as_photographed(sample.maps, sample.meta)
    meta = {**sample.meta, "maps_view": "photo"}
    return Sample(sample.key, sample.photo, maps, meta, check=False, no_flash=sample.no_flash)
