"""The capture renderer of dataset generation: a map set under an HDR environment plus the flash.

Scene: the textured plane of :func:`brdfgan.mitsuba_render.scene.plane_scene_dict` (principled +
normalmap, nearest-filtered raw bitmaps, rows flipped), a camera (the nominal one of
:class:`~brdfgan.core.render.FlashCapture` or any :class:`~brdfgan.core.render.CameraPose`, as
:mod:`brdfgan.data.phone.conditions` draws them), a point-light flash (at the lens or next to
it), an ``envmap`` emitter holding an equirect array of :mod:`brdfgan.core.lighting` (its +Y-up
frame turned to our +Z-up by :data:`~brdfgan.mitsuba_render.environment.ENVMAP_TO_WORLD`) and, for sun/sky
environments, the sun as a ``directional`` emitter.

Integrator: ``direct``. Per pixel sample it takes one emitter sample (envmap importance sampling
by luminance, the point light or the sun) and one BSDF sample, combined with the power
heuristic, which is what glossy surfaces under a bright, structured environment need. A single
plane cannot see itself, so there is no indirect light and ``direct`` is exact — ``path`` with
``max_depth = 2`` estimates the same thing at the same cost.

Sampler: ``stratified`` (so ``spp`` must be a square: 64 = 8², the paper's 196 = 14²). With several
emitters, each emitter sample picks one of them at random; with an independent sampler that
choice alone puts ~1/√spp relative noise on the flash term (a delta light that is otherwise
noise-free). Stratifying the choice over a pixel's samples removes most of it
(docs/conventions.md#capture-rendering).

Scene reuse: the scene is loaded once per emitter set (environment yes/no, sun yes/no) and then
updated per sample through ``mi.traverse`` + ``params.update()`` (textures, envmap data, flash
intensity and position, sun, the sensor's ``x_fov`` and ``to_world``); a change of map or
environment shape reloads it. A new camera pose per sample costs no kernel recompile. Reuse is the
default (``reuse_scene=True``) though ``mi.render`` dominates a call, so it gains only a few
percent (docs/conventions.md#capture-rendering); results are identical either way (tested).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import auto_expose
from brdfgan.core.lighting import Environment, SunLight, check_equirect, orthonormal_frame
from brdfgan.core.render import CameraPose, FlashCapture, Vector3
from brdfgan.core.svbrdf import encode_normal, split_maps, srgb_to_linear, validate_maps
from brdfgan.mitsuba_render.environment import ENVMAP_TO_WORLD
from brdfgan.mitsuba_render.scene import MitsubaPointLight, camera_to_world, plane_scene_dict
from brdfgan.mitsuba_render.variant import mitsuba

log = logging.getLogger(__name__)

# Parameter keys of the scene built by :func:`capture_scene_dict` (see ``mi.traverse``).
_BSDF = "sample.bsdf.nested_bsdf"
_TEXTURE_KEYS = {
    "base_color": f"{_BSDF}.base_color.data",
    "roughness": f"{_BSDF}.roughness.data",
    "metallic": f"{_BSDF}.metallic.data",
    "normal": "sample.bsdf.normalmap.data",
}
_FLASH_KEY = "point_light_0.intensity.value"
_FLASH_POSITION_KEY = "point_light_0.position"
_FOV_KEY = "sensor.x_fov"
_CAMERA_TO_WORLD_KEY = "sensor.to_world"
_ENV_KEY = "environment.data"
_SUN_IRRADIANCE_KEY = "sun.irradiance.value"
_SUN_TO_WORLD_KEY = "sun.to_world"


@dataclass(frozen=True)
class CaptureTiming:
    """Wall-clock seconds of the last :meth:`CaptureRenderer.render`: the whole call, the part
    inside ``mi.render`` (kernel launch and evaluation), and whether it loaded a scene."""

    total_s: float
    mi_render_s: float
    loaded_scene: bool


def _texture_array(image: Tensor) -> np.ndarray:
    # Same layout as scene._bitmap_texture: (C, H, W) ours → (H, W, C) with rows flipped, since
    # Mitsuba's rectangle puts bitmap row 0 at y = −s (docs/conventions.md#mitsuba-row-flip).
    return np.ascontiguousarray(image.detach().to("cpu", torch.float32).flip(-2).permute(1, 2, 0).numpy())


def _texture_arrays(maps: Tensor) -> dict[str, np.ndarray]:
    parts = split_maps(maps)
    return {
        "base_color": _texture_array(srgb_to_linear(parts.basecolor)),
        "roughness": _texture_array(parts.roughness),
        "metallic": _texture_array(parts.metallic),
        "normal": _texture_array(encode_normal(parts.normal)),
    }


def _padded_envmap(environment: np.ndarray) -> np.ndarray:
    # Mitsuba 3.9 stores an envmap with one wrap-around column on each side (W + 2 columns:
    # last, 0 … W−1, first); ``data`` updates must keep that layout.
    return np.ascontiguousarray(
        np.concatenate([environment[:, -1:], environment, environment[:, :1]], axis=1), dtype=np.float32
    )


def _sun_to_world(mi: Any, direction: tuple[float, float, float]) -> Any:
    # A directional emitter shines along its local +Z; it must travel away from the sun. Only that
    # axis matters to it, so look_at may take any up vector off the axis: a tangent of its frame.
    towards = np.asarray(direction, dtype=np.float64)
    towards /= np.linalg.norm(towards)
    up, _ = orthonormal_frame(towards)
    return mi.ScalarTransform4f().look_at(origin=[0.0, 0.0, 0.0], target=list(-towards), up=list(up))


def _check_environment(environment: np.ndarray) -> None:
    check_equirect(environment)
    if not np.isfinite(environment).all() or (environment < 0).any():
        raise ValueError("environment must be finite and non-negative")


def capture_scene_dict(
    maps: Tensor,
    environment: np.ndarray | None,
    flash_rgb_intensity: tuple[float, float, float],
    *,
    sun: SunLight | None = None,
    capture: FlashCapture = FlashCapture(),
    resolution: int | None = None,
    spp: int = 64,
    seed: int = 0,
    camera: CameraPose | None = None,
    flash_position: Vector3 | None = None,
) -> dict[str, Any]:
    """Scene dict of one capture: plane, camera, flash, environment (optional) and sun (optional).
    ``camera`` defaults to the nominal camera of ``capture``, ``flash_position`` to the lens.

    Shape:
        - maps: ``(8, H, W)``
        - environment: ``(He, 2He, 3)`` equirect radiance, Mitsuba envmap convention
    """
    mi = mitsuba()
    extra: dict[str, dict[str, Any]] = {}
    if environment is not None:
        extra["environment"] = {
            "type": "envmap",
            # A writable copy: cached environments are read-only and nanobind refuses those.
            "bitmap": mi.Bitmap(np.array(environment, dtype=np.float32, order="C", copy=True)),
            "to_world": mi.ScalarTransform4f(np.array(ENVMAP_TO_WORLD)),
            "scale": 1.0,
        }
    if sun is not None:
        extra["sun"] = {
            "type": "directional",
            "to_world": _sun_to_world(mi, sun.direction),
            "irradiance": {"type": "rgb", "value": [float(e) for e in sun.irradiance]},
        }
    pose = camera if camera is not None else capture.camera_pose
    flash = MitsubaPointLight(
        flash_position if flash_position is not None else pose.origin, flash_rgb_intensity
    )
    scene = plane_scene_dict(
        maps,
        lights=[flash],
        fov_deg=capture.fov_deg,
        plane_half_size=capture.plane_half_size,
        spp=spp,
        seed=seed,
        resolution=resolution,
        integrator={"type": "direct", "hide_emitters": True},
        extra_emitters=extra,
        camera=pose,
    )
    scene["sensor"]["sampler"] = {"type": "stratified", "sample_count": int(spp), "seed": int(seed)}
    return scene


@dataclass
class _LoadedScene:
    scene: Any
    params: Any
    map_shape: tuple[int, ...]
    env_shape: tuple[int, ...] | None


class CaptureRenderer:
    """Renders captures (environment + sun + flash) of map sets, reusing loaded Mitsuba scenes.

    Args:
        resolution: film size (square); the maps are usually this size too (one texel a pixel).
        spp: samples per pixel, a perfect square (stratified sampler), e.g. 64 or 196.
        capture: the nominal camera geometry (field of view, sample size), used when
            :meth:`render` gets no camera pose; its flash settings are not used, :meth:`render`
            takes the flash intensity (and position) per sample.
        environment_resolution: expected equirect height (a different one reloads the scene).
        reuse_scene: update the loaded scene through ``mi.traverse`` instead of reloading it
            for every sample (faster, see the module docstring; results are identical).

    Shape (:meth:`render`):
        - maps: ``(8, H, W)``
        - environment: ``(He, 2He, 3)``
        - output: ``(3, resolution, resolution)`` linear HDR, row 0 = +Y
    """

    def __init__(
        self,
        resolution: int = 256,
        spp: int = 64,
        capture: FlashCapture = FlashCapture(),
        environment_resolution: int = 256,
        *,
        reuse_scene: bool = True,
    ) -> None:
        if resolution < 1:
            raise ValueError(f"resolution must be >= 1, got {resolution}")
        if spp < 1 or math.isqrt(spp) ** 2 != spp:
            raise ValueError(f"spp must be a perfect square for the stratified sampler, got {spp}")
        if environment_resolution < 3:
            raise ValueError(f"environment_resolution must be >= 3, got {environment_resolution}")
        self.resolution = resolution
        self.spp = spp
        self.capture = capture
        self.environment_resolution = environment_resolution
        self.reuse_scene = reuse_scene
        self._scenes: dict[tuple[bool, bool], _LoadedScene] = {}
        self.last_timing: CaptureTiming | None = None
        mi = mitsuba()
        self.variant: str = mi.variant()
        log.info(
            "CaptureRenderer: Mitsuba %s variant %s, %d² at %d spp, environment %d×%d, %s",
            mi.__version__,
            self.variant,
            resolution,
            spp,
            environment_resolution,
            2 * environment_resolution,
            "traverse-update" if reuse_scene else "reload per sample",
        )

    def render(
        self,
        maps: Tensor,
        environment: np.ndarray | None,
        flash_rgb_intensity: tuple[float, float, float],
        seed: int = 0,
        sun: SunLight | None = None,
        *,
        camera: CameraPose | None = None,
        flash_position: Vector3 | None = None,
    ) -> Tensor:
        """Linear HDR capture of ``maps`` under ``environment`` (already rotated and scaled),
        ``sun`` and the flash (RGB radiant intensity, W/sr) at ``flash_position`` (default: the
        lens), seen by ``camera`` (default: the nominal camera of ``self.capture``). ``None``
        or an all-zero environment leaves the envmap out of the scene (no emitter samples
        wasted on it)."""
        start = time.perf_counter()
        mi = mitsuba()
        validate_maps(maps)
        check_shape(maps, "8 H W", name="maps")
        if len(flash_rgb_intensity) != 3 or any(not c >= 0 for c in flash_rgb_intensity):
            raise ValueError(f"flash_rgb_intensity must be 3 non-negative values, got {flash_rgb_intensity}")
        flash = (float(flash_rgb_intensity[0]), float(flash_rgb_intensity[1]), float(flash_rgb_intensity[2]))
        if environment is not None:
            _check_environment(environment)
            if not environment.any():
                environment = None
        pose = camera if camera is not None else self.capture.camera_pose
        light_position = flash_position if flash_position is not None else pose.origin
        key = (environment is not None, sun is not None)
        map_shape = tuple(maps.shape)
        env_shape = None if environment is None else environment.shape

        entry = self._scenes.get(key) if self.reuse_scene else None
        loaded = entry is None or entry.map_shape != map_shape or entry.env_shape != env_shape
        if loaded:
            scene = mi.load_dict(
                capture_scene_dict(
                    maps,
                    environment,
                    flash,
                    sun=sun,
                    capture=self.capture,
                    camera=pose,
                    flash_position=light_position,
                    resolution=self.resolution,
                    spp=self.spp,
                    # The sampler's load-time seed also enters the samples (stratified sampler,
                    # docs/conventions.md#capture-rendering): keep it fixed so a reused scene and
                    # a fresh one agree, and vary only the seed of mi.render.
                    seed=0,
                )
            )
            if self.reuse_scene:
                self._scenes[key] = _LoadedScene(scene, mi.traverse(scene), map_shape, env_shape)
        else:
            assert entry is not None
            scene = entry.scene
            self._update(entry.params, maps, environment, flash, sun, pose, light_position)

        render_start = time.perf_counter()
        image = mi.render(scene, spp=self.spp, seed=seed)
        array = np.array(image, dtype=np.float32)  # forces evaluation of the kernel
        render_s = time.perf_counter() - render_start
        output = torch.from_numpy(array).permute(2, 0, 1)[:3].contiguous()
        self.last_timing = CaptureTiming(time.perf_counter() - start, render_s, loaded)
        return output

    def _update(
        self,
        params: Any,
        maps: Tensor,
        environment: np.ndarray | None,
        flash: tuple[float, float, float],
        sun: SunLight | None,
        camera: CameraPose,
        flash_position: Vector3,
    ) -> None:
        mi = mitsuba()
        for name, array in _texture_arrays(maps).items():
            params[_TEXTURE_KEYS[name]] = mi.TensorXf(array)
        params[_FLASH_KEY] = mi.Color3f(*flash)
        params[_FLASH_POSITION_KEY] = mi.Point3f(*(float(c) for c in flash_position))
        params[_FOV_KEY] = float(camera.fov_deg)
        params[_CAMERA_TO_WORLD_KEY] = mi.Transform4f(camera_to_world(camera).matrix)
        if environment is not None:
            params[_ENV_KEY] = mi.TensorXf(_padded_envmap(environment))
        if sun is not None:
            params[_SUN_IRRADIANCE_KEY] = mi.Color3f(*(float(e) for e in sun.irradiance))
            params[_SUN_TO_WORLD_KEY] = mi.Transform4f(_sun_to_world(mi, sun.direction).matrix)
        params.update()


@dataclass(frozen=True, eq=False)
class CaptureResult:
    """One simulated photo: linear HDR, its auto-exposed linear LDR in [0, 1] and the exposure
    multiplier applied, exposure error included (``ldr = clip(hdr · exposure_scale, 0, 1)``)."""

    hdr: Tensor
    ldr: Tensor
    exposure_scale: float


def render_capture(
    renderer: CaptureRenderer,
    maps: Tensor,
    environment: Environment | None,
    flash_rgb_intensity: tuple[float, float, float],
    seed: int = 0,
    *,
    camera: CameraPose | None = None,
    flash_position: Vector3 | None = None,
    exposure_ev: float = 0.0,
) -> CaptureResult:
    """Render a capture and auto-expose it to linear LDR (paper appendix, docs/conventions.md#auto-exposure),
    off by ``exposure_ev`` stops: ``ldr = clip(hdr · auto_scale · 2^exposure_ev, 0, 1)``.
    ``camera`` and ``flash_position`` as :meth:`CaptureRenderer.render`.

    Shape:
        - maps: ``(8, H, W)``
        - output: hdr and ldr ``(3, R, R)``
    """
    hdr = renderer.render(
        maps,
        None if environment is None else environment.radiance,
        flash_rgb_intensity,
        seed=seed,
        sun=None if environment is None else environment.sun,
        camera=camera,
        flash_position=flash_position,
    )
    ldr, scale = auto_expose(hdr, exposure_ev)
    return CaptureResult(hdr, ldr, float(scale))
