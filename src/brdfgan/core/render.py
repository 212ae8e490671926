"""Differentiable point-light renderer for a planar SVBRDF sample (pure torch).

Scene (docs/conventions.md#scene-and-orientation): the sample is the square ``[-s, s]²`` of the
plane z = 0 (``s`` = ``plane_half_size``), texel (i, j) sits at ``x = -s + (j + ½)·2s/W``,
``y = s − (i + ½)·2s/H`` (row 0 is +Y), the tangent frame is the world frame. Every output pixel
is one texel, shaded with the exact view direction towards the camera position and lit by point
lights with inverse square falloff:

    L_o(p) = Σ_k f(l_k, v) · max(n·l_k, 0) · I_k / |x_k − p|²

where ``I_k`` is the RGB radiant intensity (W/sr) of light k. For the capture camera — above the
sample centre, looking down −Z, framing the square exactly (:func:`capture_camera_height`) — this
texture-space image *is* the perspective photograph (cross-checked against Mitsuba); for other
camera positions it is the usual rendering-loss image of the sample seen from there.

Batched over samples ``B`` and light/view configurations ``V`` (each with its own camera and
``K`` lights that add up), on any device, differentiable w.r.t. every map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.brdf import (
    EPS,
    VECTOR_DIM,
    burley_diffuse_factor,
    ggx_specular_factor,
    schlick_weight,
)
from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import (
    NORMAL,
    NUM_CHANNELS,
    check_map_shape,
    diffuse_albedo,
    normalize_normal,
    roughness_to_alpha,
    specular_albedo,
    split_maps,
    srgb_to_linear,
)


@dataclass(frozen=True)
class PointLights:
    """Point lights: ``position`` ``(B, V, K, 3)``, scalar ``intensity`` ``(B, V, K)`` in W/sr,
    and ``color`` ``(B, V, K, 3)`` (linear RGB multipliers)."""

    position: Tensor
    intensity: Tensor
    color: Tensor

    def radiant_intensity(self) -> Tensor:
        """RGB radiant intensity ``(B, V, K, 3)``."""
        return self.intensity.unsqueeze(-1) * self.color


def capture_camera_height(fov_deg: float, plane_half_size: float = 1.0) -> float:
    """Height above z = 0 at which a camera with horizontal field of view ``fov_deg`` looking
    down −Z frames exactly the square ``[-s, s]²``.

    Example:
        ``s / tan(fov / 2)``: a 90° lens frames the unit square from height 1, the default 45°
        from 1 / tan 22.5° = 1 + √2:

        >>> round(capture_camera_height(90.0), 4), round(capture_camera_height(45.0), 4)
        (1.0, 2.4142)
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must lie in (0, 180), got {fov_deg}")
    return plane_half_size / math.tan(math.radians(fov_deg) / 2.0)


Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class CameraPose:
    """A pinhole camera in world units: its position ``origin``, the point it aims at, the
    world direction that is up in the image (orthogonal to the view direction) and the
    horizontal field of view. :func:`nominal_camera` builds the capture camera of today's
    photos; :mod:`brdfgan.data.phone.conditions` draws randomised ones."""

    origin: Vector3
    target: Vector3 = (0.0, 0.0, 0.0)
    up: Vector3 = (0.0, 1.0, 0.0)
    fov_deg: float = 45.0


def nominal_camera(fov_deg: float, plane_half_size: float = 1.0) -> CameraPose:
    """The capture camera of docs/conventions.md#scene-and-orientation: above the sample centre at
    :func:`capture_camera_height`, looking down −Z with +Y up, framing ``[-s, s]²`` exactly."""
    height = capture_camera_height(fov_deg, plane_half_size)
    return CameraPose((0.0, 0.0, height), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_deg)


def camera_frame(pose: CameraPose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit ``(right, up, forward)`` of the image: columns grow along ``right``, rows along
    ``−up``, ``forward`` points from the camera to its target (Mitsuba's ``look_at`` frame).

    Shape:
        - output: three ``(3,)`` float64 arrays
    """
    origin = np.asarray(pose.origin, dtype=np.float64)
    forward = np.asarray(pose.target, dtype=np.float64) - origin
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(pose.up, dtype=np.float64))
    norm = np.linalg.norm(right)
    if not norm > 1e-9:
        raise ValueError(f"camera up {pose.up} is parallel to the view direction")
    right /= norm
    return right, np.cross(right, forward), forward


def project_to_image(points: np.ndarray, pose: CameraPose, width: int, height: int) -> np.ndarray:
    """Continuous pixel coordinates of world points in the photo of ``pose`` (horizontal field of
    view, square pixels): x along the columns from the left edge, y along the rows from the top,
    so pixel (row i, column j) spans ``[j, j+1] × [i, i+1]`` and the image centre is (W/2, H/2).

    Shape:
        - points: ``(N, 3)`` world units, in front of the camera
        - output: ``(N, 2)`` pixels, ``(x, y)``
    """
    right, up, forward = camera_frame(pose)
    local = np.asarray(points, dtype=np.float64) - np.asarray(pose.origin, dtype=np.float64)
    depth = local @ forward
    if not (depth > 0).all():
        raise ValueError("points must lie in front of the camera")
    tan_half = math.tan(math.radians(pose.fov_deg) / 2.0)
    x = (local @ right) / (depth * tan_half)  # −1 … 1 across the width
    y = (local @ up) / (depth * tan_half * height / width)  # −1 … 1 across the height
    return np.stack([(x + 1.0) / 2.0 * width, (1.0 - y) / 2.0 * height], axis=-1)


def view_footprint(pose: CameraPose, width: int, height: int) -> np.ndarray:
    """Where the rays through the four image corners meet the plane z = 0, in the order
    top-left, top-right, bottom-right, bottom-left. The photo shows exactly the quadrilateral
    they span (a pinhole view of a plane is a projective map).

    Shape:
        - output: ``(4, 3)`` world units
    """
    right, up, forward = camera_frame(pose)
    tan_x = math.tan(math.radians(pose.fov_deg) / 2.0)
    tan_y = tan_x * height / width
    origin = np.asarray(pose.origin, dtype=np.float64)
    corners = []
    for sx, sy in ((-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)):
        ray = forward + sx * tan_x * right + sy * tan_y * up
        if not ray[2] < 0.0:
            raise ValueError(f"the image corner ray {ray.tolist()} does not reach the plane z = 0")
        corners.append(origin - origin[2] / ray[2] * ray)
    return np.stack(corners)


def view_plane_points(pose: CameraPose, height: int, width: int) -> np.ndarray:
    """Where the ray through each pixel centre of the photo of ``pose`` meets the plane z = 0
    (the pixel convention of :func:`project_to_image`; :func:`view_footprint` gives the corners).

    Shape:
        - output: ``(height, width, 2)`` world ``(x, y)``, float64
    """
    if height < 1 or width < 1:
        raise ValueError(f"need a positive image size, got {height}x{width}")
    right, up, forward = camera_frame(pose)
    tan_x = math.tan(math.radians(pose.fov_deg) / 2.0)
    tan_y = tan_x * height / width
    sx = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    sy = 1.0 - (np.arange(height) + 0.5) / height * 2.0
    rays = forward + sx[None, :, None] * tan_x * right + sy[:, None, None] * tan_y * up
    if not (rays[..., 2] < 0.0).all():
        raise ValueError("some pixel rays do not reach the plane z = 0")
    origin = np.asarray(pose.origin, dtype=np.float64)
    points = origin - (origin[2] / rays[..., 2])[..., None] * rays
    return points[..., :2]


def maps_in_view(maps: Tensor, pose: CameraPose, plane_half_size: float = 1.0) -> Tensor:
    """The texture-space maps of the sample as the photo taken from ``pose`` sees them, pixel for
    pixel: each map is sampled (bilinearly) where the ray through the pixel centre meets the
    plane, and the normals are renormalised. For the nominal camera (centred, framing the square)
    this is the identity up to rounding; for a tilted, closer or farther camera it is the warp that
    puts every texel under the pixel that photographs it. Normals stay in the sample's tangent frame
    (+X, +Y of the plane), which a camera tilted by a few degrees sees almost unrotated.

    Points off the sample square take the nearest border texel.

    Shape:
        - maps: ``(8, H, W)`` in the layout of :mod:`brdfgan.core.svbrdf`
        - output: ``(8, H, W)``
    """
    check_shape(maps, f"{NUM_CHANNELS} H W", name="maps")
    height, width = maps.shape[-2:]
    grid = view_grid(pose, height, width, plane_half_size).to(maps.dtype)
    return warp_maps_to_view(maps[None], grid[None])[0]


def view_grid(pose: CameraPose, height: int, width: int, plane_half_size: float = 1.0) -> Tensor:
    """Where each pixel of the photo taken from ``pose`` samples the texture-space square, as a
    ``grid_sample`` grid (:func:`view_plane_points` in its coordinates).

    Shape:
        - output: ``(height, width, 2)`` float64
    """
    points = torch.from_numpy(view_plane_points(pose, height, width) / plane_half_size)
    # grid_sample's (x, y) in [-1, 1] with align_corners=False are the outer texel edges: x = -1 is
    # the left edge (world -s), y = -1 the top edge (world +s, row 0 is +Y).
    return torch.stack([points[..., 0], -points[..., 1]], dim=-1)


def warp_to_view(images: Tensor, grids: Tensor) -> Tensor:
    """Texture-space images resampled (bilinearly) into the photos' pixels through their
    :func:`view_grid`; points off the square take the nearest border texel.

    Shape:
        - images: ``(B, C, H, W)``; grids: ``(B, H', W', 2)``
        - output: ``(B, C, H', W')``
    """
    return F.grid_sample(
        images, grids.to(images), mode="bilinear", padding_mode="border", align_corners=False
    )


def warp_maps_to_view(maps: Tensor, grids: Tensor) -> Tensor:
    """:func:`warp_to_view` for map sets: the normals renormalised after the interpolation.

    Shape:
        - maps: ``(B, 8, H, W)``; grids: ``(B, H', W', 2)``
        - output: ``(B, 8, H', W')``
    """
    warped = warp_to_view(maps, grids)
    warped[:, NORMAL] = normalize_normal(warped[:, NORMAL], dim=1)
    return warped


def texel_centres(
    height: int,
    width: int,
    plane_half_size: float = 1.0,
    *,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> tuple[Tensor, Tensor]:
    """World x of each texel column and y of each texel row on the sample square, row 0 at +Y
    (the separable form of :func:`plane_positions`).

    Shape:
        - output: ``(width,)``, ``(height,)``
    """
    s = plane_half_size
    xs = -s + (torch.arange(width, dtype=dtype, device=device) + 0.5) * (2.0 * s / width)
    ys = s - (torch.arange(height, dtype=dtype, device=device) + 0.5) * (2.0 * s / height)
    return xs, ys


def plane_positions(
    height: int,
    width: int,
    plane_half_size: float = 1.0,
    *,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> Tensor:
    """World positions of the texel centres on z = 0, row 0 at +Y.

    Shape:
        - output: ``(3, height, width)``
    """
    xs, ys = texel_centres(height, width, plane_half_size, dtype=dtype, device=device)
    grid_y, grid_x = torch.meshgrid(ys, xs, indexing="ij")
    return torch.stack([grid_x, grid_y, torch.zeros_like(grid_x)], dim=0)


def check_scene_shapes(maps: Tensor, camera_position: Tensor, lights: PointLights) -> None:
    """Raise ``ValueError`` unless maps ``(B, 8, H, W)``, camera ``(B, V, 3)`` and lights
    ``(B, V, K, ·)`` fit together."""
    check_map_shape(maps)
    scene = check_shape(maps, f"B {NUM_CHANNELS} H W", name="maps")
    scene = check_shape(camera_position, "B V 3", name="camera_position", dims=scene)
    scene = check_shape(lights.position, "B V K 3", name="light position", dims=scene)
    check_shape(lights.intensity, "B V K", name="light intensity", dims=scene)
    check_shape(lights.color, "B V K 3", name="light color", dims=scene)


Components = tuple[Tensor, Tensor, Tensor]


def _unit(x: Tensor, y: Tensor, z: Tensor) -> tuple[Components, Tensor]:
    """Unit vector components of ``(x, y, z)`` (broadcast to a common shape) and the squared norm.

    Components are separate tensors, not one tensor with a vector axis: a reduction over a
    middle axis of length 3 is a strided loop that costs more than the whole shading on CPU.
    """
    norm_sq = torch.addcmul(torch.addcmul(z * z, y, y), x, x)
    inverse = norm_sq.sqrt().clamp_(min=EPS).reciprocal_()
    return (x * inverse, y * inverse, z * inverse), norm_sq


def _dot(a: Components, b: Components) -> Tensor:
    return torch.addcmul(torch.addcmul(a[2] * b[2], a[1], b[1]), a[0], b[0])


@dataclass(frozen=True)
class ShadingInputs:
    """What the shading needs of a map set, per texel (broadcast over configurations): linear
    diffuse albedo and F0 ``(B, 1, 3, H, W)``, roughness and GGX α ``(B, 1, 1, H, W)``, and the
    unit normal's components, each ``(B, 1, 1, H, W)``. Built once by :func:`shading_inputs`, so
    that eager code does not recompute them for every configuration."""

    diffuse: Tensor
    f0: Tensor
    roughness: Tensor
    alpha: Tensor
    normal: Components

    @property
    def shape(self) -> tuple[int, int, int, int]:
        """``(B, 8, H, W)`` of the maps these came from."""
        batch, _, _, height, width = self.roughness.shape
        return batch, 8, height, width


def linear_basecolor_maps(maps: Tensor) -> Tensor:
    """``maps`` with the base colour decoded from sRGB to linear (the form
    ``shading_inputs(..., basecolor_linear=True)`` takes). Decoding before a compiled shading
    matters: fused into the per-configuration loop, the sRGB decoding's ``pow`` ran once per
    configuration and was 40 % of a compiled render.

    Shape: ``(B, 8, H, W)`` → same.
    """
    return torch.cat([srgb_to_linear(maps[:, 0:3]), maps[:, 3:]], dim=1)


def shading_inputs(maps: Tensor, *, basecolor_linear: bool = False) -> ShadingInputs:
    """The per-texel terms of :func:`shade_point_lights` (differentiable).

    Args:
        maps: map sets, base colour sRGB-encoded (or linear with ``basecolor_linear``).
        basecolor_linear: the base colour is already linear (:func:`linear_basecolor_maps`).

    Shape:
        - maps: ``(B, 8, H, W)``
        - output: see :class:`ShadingInputs`
    """
    parts = split_maps(maps.unsqueeze(1))  # (B, 1, C, H, W): broadcast over configurations
    basecolor = parts.basecolor if basecolor_linear else srgb_to_linear(parts.basecolor)
    normal = normalize_normal(parts.normal, dim=VECTOR_DIM)
    return ShadingInputs(
        diffuse=diffuse_albedo(basecolor, parts.metallic),
        f0=specular_albedo(basecolor, parts.metallic),
        roughness=parts.roughness,
        alpha=roughness_to_alpha(parts.roughness),
        normal=(normal[:, :, 0:1], normal[:, :, 1:2], normal[:, :, 2:3]),
    )


def render_point_lights(
    maps: Tensor, camera_position: Tensor, lights: PointLights, plane_half_size: float = 1.0
) -> Tensor:
    """Render map sets under point lights, one image per light/view configuration:
    :func:`shade_point_lights` of :func:`shading_inputs`.

    Args:
        maps: map sets in the layout of :mod:`brdfgan.core.svbrdf` (base color sRGB-encoded,
            normals unit — they are renormalised here so gradients stay tangent).
        camera_position: world position of the camera of each configuration.
        lights: ``K`` point lights per configuration; their contributions add up.
        plane_half_size: half the side length of the sample square in world units.

    Returns:
        Linear HDR radiance.

    Shape:
        - maps: ``(B, 8, H, W)``
        - camera_position: ``(B, V, 3)``
        - lights: position ``(B, V, K, 3)``, intensity ``(B, V, K)``, color ``(B, V, K, 3)``
        - output: ``(B, V, 3, H, W)``

    Example:
        One texel at the centre, camera and light 2 above it with intensity ``π·2²``: the
        radiance is ``π f`` with f the head-on BRDF, ``(1 + F0/4)/π`` for a white dielectric of
        roughness 1 (Lambertian ``1/π`` plus ``F0 D G/4`` with ``D = 1/π``, F0 = 0.04):

        >>> from brdfgan.core.svbrdf import flat_maps
        >>> maps = flat_maps(1, 1, basecolor=(1.0, 1.0, 1.0), roughness=1.0, batch=(1,))
        >>> camera = torch.tensor([[[0.0, 0.0, 2.0]]])
        >>> lights = PointLights(
        ...     position=camera[:, :, None],
        ...     intensity=torch.full((1, 1, 1), 4 * math.pi),
        ...     color=torch.ones(1, 1, 1, 3),
        ... )
        >>> image = render_point_lights(maps, camera, lights)
        >>> tuple(image.shape), round(image[0, 0, 0, 0, 0].item(), 4)
        ((1, 1, 3, 1, 1), 1.01)
    """
    check_scene_shapes(maps, camera_position, lights)
    return shade_point_lights(shading_inputs(maps), camera_position, lights, plane_half_size)


def shade_point_lights(
    inputs: ShadingInputs, camera_position: Tensor, lights: PointLights, plane_half_size: float = 1.0
) -> Tensor:
    """The radiance of :func:`render_point_lights` from the maps' :func:`shading_inputs`.

    Evaluates :func:`~brdfgan.core.brdf.evaluate_brdf` at every texel, factored for speed (tests
    hold it to the direct evaluation, values and gradients): everything that depends only on the
    scene (view, light and half vectors, h·l, Schlick's weight, falloff) is computed without
    autograd, vectors are kept as separate component tensors, and per light the shading is
    reduced to three colourless fields ``A, B, C`` so that the colour enters once,

        L_k = I_k · (d · A + F0 · B + C),   A = w f_d/d,  B = w (1 − s) f_s/F,  C = w s f_s/F,

    with w = cos θ_l / r² where l and v are above the shading normal (else 0) and s = (1 − h·l)^5.
    Only ``(B, V, 1, H, W)`` fields are materialised until the last step.

    Shape:
        - inputs: from maps ``(B, 8, H, W)``
        - camera_position: ``(B, V, 3)``
        - lights: position ``(B, V, K, 3)``, intensity ``(B, V, K)``, color ``(B, V, K, 3)``
        - output: ``(B, V, 3, H, W)``
    """
    n = inputs.normal
    batch, _, height, width = inputs.shape
    dtype, device = inputs.roughness.dtype, inputs.roughness.device

    with torch.no_grad():  # the scene: no map enters here
        xs, ys = texel_centres(height, width, plane_half_size, dtype=dtype, device=device)
        xs, ys = xs.view(1, 1, 1, 1, width), ys.view(1, 1, 1, height, 1)

        def towards(points: Tensor) -> Components:  # (B, V, 3) → separable offsets from the texels
            p = points.to(dtype)[..., None, None, None]  # (B, V, 3, 1, 1, 1)
            return (p[:, :, 0] - xs, p[:, :, 1] - ys, p[:, :, 2])

        view, _ = _unit(*towards(camera_position))
        scene = []
        for k in range(lights.position.shape[2]):
            light, distance_sq = _unit(*towards(lights.position[:, :, k]))
            half, _ = _unit(light[0] + view[0], light[1] + view[1], light[2] + view[2])
            h_dot_l = _dot(half, light).clamp_(min=0.0, max=1.0)
            falloff = distance_sq.clamp_(min=1e-12).reciprocal_()
            scene.append((light, half, h_dot_l, schlick_weight(h_dot_l), falloff))
        intensity = lights.radiant_intensity().to(dtype)[..., None, None]  # (B, V, K, 3, 1, 1)

    n_dot_v_raw = _dot(n, view)
    n_dot_v = n_dot_v_raw.clamp(min=EPS, max=1.0)
    radiance: Tensor | None = None
    for k, (light, half, h_dot_l, schlick, falloff) in enumerate(scene):
        n_dot_l_raw = _dot(n, light)
        n_dot_l = n_dot_l_raw.clamp(min=EPS, max=1.0)
        n_dot_h = _dot(n, half).clamp(min=0.0, max=1.0)
        visible = (n_dot_l_raw > 0) & (n_dot_v_raw > 0)
        # cos θ_l / r², zero where either direction is below the shading normal.
        weight = torch.where(visible, n_dot_l_raw * falloff, torch.zeros((), dtype=dtype, device=device))
        colourless_diffuse = weight * burley_diffuse_factor(inputs.roughness, n_dot_l, n_dot_v, h_dot_l)
        colourless_specular = weight * ggx_specular_factor(inputs.alpha, n_dot_l, n_dot_v, n_dot_h)
        schlick_specular = schlick * colourless_specular
        light_k = torch.addcmul(schlick_specular, inputs.diffuse, colourless_diffuse)
        light_k = torch.addcmul(light_k, inputs.f0, colourless_specular - schlick_specular)
        light_k = light_k * intensity[:, :, k]
        radiance = light_k if radiance is None else radiance + light_k
    if radiance is None:  # no lights
        return torch.zeros(batch, camera_position.shape[1], 3, height, width, dtype=dtype, device=device)
    return radiance


class PointLightRenderer(nn.Module):
    """Thin module around :func:`render_point_lights` holding the scene scale.

    Args:
        plane_half_size: half the side of the sample square.
        compile: run the renderer through ``torch.compile``. Eager mode materialises every
            intermediate of the ~40 elementwise steps at full size; the compiled kernel fuses
            them, several times faster after a one-off compile (docs/benchmarks.md#renderer-speed),
            so training turns it on and short scripts leave it off.

    Shape: as :func:`render_point_lights`.
    """

    def __init__(self, plane_half_size: float = 1.0, compile: bool = False) -> None:
        super().__init__()
        self.plane_half_size = plane_half_size
        self.compiled = compile
        self._render = torch.compile(render_point_lights) if compile else render_point_lights

    def forward(self, maps: Tensor, camera_position: Tensor, lights: PointLights) -> Tensor:
        return self._render(maps, camera_position, lights, self.plane_half_size)

    def extra_repr(self) -> str:
        return f"plane_half_size={self.plane_half_size}, compile={self.compiled}"


@dataclass(frozen=True)
class FlashCapture:
    """The capture set-up: a camera above the sample centre looking down −Z and framing the
    square exactly, with a point-light flash at the camera (docs/conventions.md#scene-and-orientation)."""

    fov_deg: float = 45.0
    intensity: float = 1.0
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    plane_half_size: float = 1.0

    @property
    def camera_height(self) -> float:
        return capture_camera_height(self.fov_deg, self.plane_half_size)

    @property
    def camera_pose(self) -> CameraPose:
        return nominal_camera(self.fov_deg, self.plane_half_size)

    @property
    def radiant_intensity(self) -> tuple[float, float, float]:
        """RGB radiant intensity of the flash in W/sr."""
        r, g, b = self.color
        return (self.intensity * r, self.intensity * g, self.intensity * b)


def render_flash(
    maps: Tensor,
    capture: FlashCapture = FlashCapture(),
    supersample: int = 1,
    flash_offset: Tensor | None = None,
    camera_xy: Tensor | None = None,
) -> Tensor:
    """Render the flash photograph of the capture set-up.

    Args:
        maps: map sets.
        capture: camera and flash.
        supersample: shade ``supersample²`` points per pixel (maps repeated nearest-neighbour, as a
            texture lookup does) and average them: a box-filtered pixel footprint, like a
            camera's, instead of the texel centre. Matters for highlights a few pixels wide.
        flash_offset: the flash moved from the lens, parallel to the sample (world units; a
            phone's flash beside its lens); ``None``: at the lens.
        camera_xy: the camera (and the flash with it) moved parallel to the sample from above its
            centre, still looking straight down and at the same height (world units): the photo
            is then a window of a wider view centred elsewhere — a crop whose hotspot is off its
            centre (:func:`~brdfgan.core.flash_geometry.hotspot_position`); ``None``: centred.

    Shape:
        - maps: ``(B, 8, H, W)``; flash_offset, camera_xy: ``(B, 2)``
        - output: ``(B, 3, H, W)``

    Example:
        A uniform flat sample photographed with the flash at the lens: the hotspot is the centre
        and the photo is symmetric (mirrored left–right and top–bottom):

        >>> from brdfgan.core.svbrdf import flat_maps
        >>> photo = render_flash(flat_maps(5, 5, batch=(1,)))
        >>> tuple(photo.shape)
        (1, 3, 5, 5)
        >>> divmod(int(photo[0, 0].argmax()), 5)
        (2, 2)
        >>> torch.allclose(photo, photo.flip(-1)) and torch.allclose(photo, photo.flip(-2))
        True
    """
    batch = maps.shape[0]
    camera = maps.new_tensor([0.0, 0.0, capture.camera_height]).expand(batch, 1, 3)
    if camera_xy is not None:
        camera = camera + F.pad(camera_xy, (0, 1)).unsqueeze(1)
    flash = camera if flash_offset is None else camera + F.pad(flash_offset, (0, 1)).unsqueeze(1)
    lights = PointLights(
        position=flash.unsqueeze(2),
        intensity=maps.new_full((batch, 1, 1), capture.intensity),
        color=maps.new_tensor(capture.color).expand(batch, 1, 1, 3),
    )
    if supersample > 1:
        maps = maps.repeat_interleave(supersample, -1).repeat_interleave(supersample, -2)
    image = render_point_lights(maps, camera, lights, capture.plane_half_size)[:, 0]
    return F.avg_pool2d(image, supersample) if supersample > 1 else image
