"""Relief statistics of normal maps and what a photo shows of them (issue 46, item 1).

Three questions, one group of pure functions each (definitions in each docstring; the measured
tables are in research/notes/2026-12-relief-investigation.md):

- **Realism: what relief the maps hold.** :func:`tilt_deg` (a texel's angle from +Z; its mean is
  the angle a flat map scores), :func:`flat_share`, :func:`flat_window_share`,
  :func:`steep_angle_share` and :func:`slope_band_energy` (how the slope field's power spreads
  over octaves of spatial frequency); :func:`dark_is_low_cosine` (whether the base colour's dark
  lines are the relief's grooves or its ridges).
- **Observability: what a photo can show of it.** :func:`scene_relief_shading` (the photo with its
  relief over the same photo with flat normals, in log luminance, rendered as a training photo is
  rendered), :func:`delivered_noise_log` and :func:`srgb8_rounding_log` (the photo's noise in the
  same units), :func:`observable_mask` and :func:`observable_angle`.
- **The sensor: how much of a photo's detail is relief.** :func:`relief_share`.
- **Shape from shading with the rest known: what the shading can give at most.**
  :func:`photo_relief_residual` (a photo over the flat render of its true maps) and
  :func:`fit_height_to_shading` (the height whose relief shading matches it);
  :func:`radial_slope` (the one slope component a flash at the lens shades).

Everything is in photo pixels (a photo of ``(B, 3, H, W)``), or texels of a map, and takes
``(B, …)`` batches; nothing here draws random numbers.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.delit import flash_render, flat_flash_render
from brdfgan.core.exposure import auto_exposure_scale, log_luminance, luminance
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.flash_geometry import flash_offset_channels
from brdfgan.core.height import height_slope_channels, slope_field
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, NORMAL, ROUGHNESS, srgb_to_linear
from brdfgan.data.loading.rendered import render_scenes
from brdfgan.metrics import (  # their home: the evaluator grades with them
    RELIEF_LOG_FLOOR,
    observable_mask,
    srgb8_rounding_log,
)

__all__ = [
    "CLIP_LEVEL",
    "FLAT_DEG",
    "FLAT_WINDOW",
    "FLAT_WINDOW_DEG",
    "HIGH_PASS_FRACTION",
    "LOG_FLOOR",
    "SLOPE_BANDS",
    "STEEP_DEG",
    "dark_is_low_cosine",
    "delivered_noise_log",
    "fit_height_to_shading",
    "flat_share",
    "flat_window_share",
    "high_pass",
    "observable_angle",
    "observable_mask",
    "photo_relief_residual",
    "radial_slope",
    "relief_share",
    "scene_relief_shading",
    "slope_band_energy",
    "srgb8_rounding_log",
    "steep_angle_share",
    "tilt_deg",
]

# A texel is flat below this tilt: a slope of 0.9 %, under a tenth of an 8-bit step of shading
# change for a flash at the lens (1 − cos 0.5° = 4e-5).
FLAT_DEG = 0.5
# A window (side in texels, of a 256² crop: a quarter of its side) is nearly flat when its mean
# tilt is below FLAT_WINDOW_DEG: a patch a network sees no relief in at all.
FLAT_WINDOW = 64
FLAT_WINDOW_DEG = 1.0
# Steep: tan 17° ≈ 0.31, a slope that turns the diffuse shading of a flash 30° off the
# normal by about a sixth: grout edges, cracks, tile bevels.
STEEP_DEG = 17.0
# Octave band edges of the slope spectrum in cycles per pixel: periods of > 32, 16–32, 8–16, 4–8
# and < 4 pixels (the last reaches 1.4 px in the spectrum's corners).
SLOPE_BANDS = (0.0, 1.0 / 32.0, 1.0 / 16.0, 1.0 / 8.0, 1.0 / 4.0, math.inf)
# Linear luminance floor before a log, in units of the exposed photo (1 = white): about three
# 8-bit sRGB codes above black, so black pixels and shadows stay finite.
LOG_FLOOR = 1e-3
# The high-pass of relief_share: Gaussian σ as a fraction of the photo's shorter side. A flash's
# falloff and its specular lobe vary over a quarter of the side or more; 1/16 removes them and
# keeps the relief's grout lines, cracks and grain.
HIGH_PASS_FRACTION = 1.0 / 16.0
# A photo's pixel is clipped (a hotspot shows no shading) when a channel is at this linear level or
# above: predict's refinement and the views' fit default (RefineConfig.clip_level, ViewsConfig.clip_level).
CLIP_LEVEL = 0.98


# ----------------------------------------------------------------------------- realism


def tilt_deg(normal: Tensor) -> Tensor:
    """Each texel's tilt: the angle in degrees between its normal and +Z,
    ``atan2(sqrt(n_x² + n_y²), n_z)`` (any positive length: the angle of the direction). The
    mean over a map is the angle a flat map scores against it (:class:`~brdfgan.metrics.
    svbrdf_metrics.NormalAngularError` with a flat prediction), "the flat map's angle".

    Shape:
        - normal: ``(*, 3, H, W)``, z ≥ 0
        - output: ``(*, H, W)`` in [0, 90]

    Example:
        >>> normal = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, -2.0, 0.0]]).T.reshape(3, 1, 3)
        >>> [round(v, 3) for v in tilt_deg(normal).flatten().tolist()]
        [0.0, 45.0, 90.0]
    """
    check_shape(normal, "* 3 H W", name="normal")
    x, y, z = normal.unbind(dim=-3)
    return torch.rad2deg(torch.atan2(torch.hypot(x, y), z))


def _check_threshold(name: str, value: float) -> None:
    if not 0.0 < value < 90.0:
        raise ValueError(f"{name} must lie in (0, 90) degrees, got {value}")


def flat_share(normal: Tensor, threshold_deg: float = FLAT_DEG) -> Tensor:
    """The share of texels whose :func:`tilt_deg` is below ``threshold_deg``.

    Shape:
        - normal: ``(*, 3, H, W)``
        - output: ``(*)`` in [0, 1]

    Example:
        A flat map is all flat; a map tilted 1° in its left half is half flat:

        >>> normal = torch.zeros(3, 4, 4)
        >>> normal[2] = 1.0
        >>> flat_share(normal).item()
        1.0
        >>> normal[0, :, :2] = math.tan(math.radians(1.0))
        >>> flat_share(normal).item()
        0.5
    """
    _check_threshold("threshold_deg", threshold_deg)
    return (tilt_deg(normal) < threshold_deg).to(normal.dtype).mean(dim=(-2, -1))


def steep_angle_share(normal: Tensor, threshold_deg: float = STEEP_DEG) -> Tensor:
    """The share of the flat map's angle (the summed :func:`tilt_deg`) carried by texels steeper
    than ``threshold_deg``: ``Σ θ·[θ > threshold] / Σ θ``; 0 for a flat map (no angle to carry).

    Shape:
        - normal: ``(*, 3, H, W)``
        - output: ``(*)`` in [0, 1]

    Example:
        One texel of 30° among fifteen of 2°: it is a sixteenth of the texels and half the angle:

        >>> normal = torch.zeros(3, 4, 4)
        >>> normal[2] = 1.0
        >>> normal[0] = math.tan(math.radians(2.0))
        >>> normal[0, 0, 0] = math.tan(math.radians(30.0))
        >>> round(steep_angle_share(normal).item(), 4)
        0.5
        >>> normal[0] = 0.0
        >>> steep_angle_share(normal).item()
        0.0
    """
    _check_threshold("threshold_deg", threshold_deg)
    tilt = tilt_deg(normal)
    total = tilt.sum(dim=(-2, -1))
    steep = (tilt * (tilt > threshold_deg)).sum(dim=(-2, -1))
    return torch.where(
        total > 0, steep / total.clamp_min(torch.finfo(tilt.dtype).tiny), torch.zeros_like(total)
    )


def flat_window_share(
    normal: Tensor, window: int = FLAT_WINDOW, threshold_deg: float = FLAT_WINDOW_DEG
) -> Tensor:
    """The share of ``window × window`` windows whose mean :func:`tilt_deg` is below
    ``threshold_deg``. The windows tile the map from its top-left corner without overlap; a
    remainder narrower than a window at the right or bottom is left out.

    Shape:
        - normal: ``(*, 3, H, W)``, H and W ≥ ``window``
        - output: ``(*)`` in [0, 1]

    Example:
        A 4 × 8 map in two 4² windows, the right one holding a 10° texel (mean 0.6°) — flat at
        1°, not at 0.5°:

        >>> normal = torch.zeros(3, 4, 8)
        >>> normal[2] = 1.0
        >>> normal[0, 0, 7] = math.tan(math.radians(10.0))
        >>> flat_window_share(normal, window=4).item()
        1.0
        >>> flat_window_share(normal, window=4, threshold_deg=0.5).item()
        0.5
    """
    dims = check_shape(normal, "* 3 H W", name="normal")
    _check_threshold("threshold_deg", threshold_deg)
    if not 1 <= window <= min(dims["H"], dims["W"]):
        raise ValueError(
            f"window must lie in [1, {min(dims['H'], dims['W'])}] (the map's side), got {window}"
        )
    tilt = tilt_deg(normal)
    flat = tilt.reshape(-1, 1, dims["H"], dims["W"])
    means = torch.nn.functional.avg_pool2d(flat, window, stride=window)
    share = (means < threshold_deg).to(normal.dtype).mean(dim=(-3, -2, -1))
    return share.reshape(tilt.shape[:-2])


def slope_band_energy(normal: Tensor, bands: Sequence[float] = SLOPE_BANDS) -> Tensor:
    """How the slope field's power spreads over spatial frequency: per band ``[f_k, f_{k+1})`` of
    radial frequency ``f = sqrt(f_x² + f_y²)`` (cycles per pixel, ``bands`` the edges, increasing),
    the share of the power of :func:`slope_field` (both components summed) that lies in it.

    The spectrum is that of each slope component minus its mean (the map's mean slope is a tilt of
    the whole sample, not relief), times a 2-D Hann window (a map need not tile: the window keeps
    the jump at its borders from leaking power into every band), summed over the FFT bins of each
    band, divided by the sum over all bins but the zero frequency. The shares of bands that cover
    all frequencies (the default: 0 to ∞) sum to 1; a map without slope variation has all 0.

    Shape:
        - normal: ``(*, 3, H, W)``
        - output: ``(*, len(bands) − 1)``

    Example:
        Five ripples across a 64² map (12.8 pixels long) put their power in the 8–16-pixel band
        (the third of the default edges: 1/16 to 1/8 cycles per pixel):

        >>> x = torch.arange(64.0)
        >>> normal = torch.zeros(3, 64, 64)
        >>> normal[0], normal[2] = 0.1 * torch.sin(2 * math.pi * 5 * x / 64), 1.0
        >>> [round(v, 2) for v in slope_band_energy(normal).tolist()]
        [0.0, 0.0, 1.0, 0.0, 0.0]
    """
    dims = check_shape(normal, "* 3 H W", name="normal")
    edges = [float(edge) for edge in bands]
    if len(edges) < 2 or edges[0] < 0 or any(high <= low for low, high in itertools.pairwise(edges)):
        raise ValueError(f"bands must be at least two increasing, non-negative edges, got {list(bands)}")
    height, width = dims["H"], dims["W"]
    slopes = slope_field(normal.to(torch.float64))
    slopes = slopes - slopes.mean(dim=(-2, -1), keepdim=True)
    hann = torch.outer(
        torch.hann_window(height, periodic=False, dtype=torch.float64),
        torch.hann_window(width, periodic=False, dtype=torch.float64),
    )
    power = torch.fft.fft2(slopes * hann).abs().square().sum(dim=-3)  # (*, H, W)
    fy = torch.fft.fftfreq(height, dtype=torch.float64).view(height, 1)
    fx = torch.fft.fftfreq(width, dtype=torch.float64).view(1, width)
    radius = torch.hypot(fx, fy)
    power[..., 0, 0] = 0.0
    total = power.sum(dim=(-2, -1))
    shares = []
    for low, high in itertools.pairwise(edges):
        inside = (radius >= low) & (radius < high)
        band = (power * inside).sum(dim=(-2, -1))
        shares.append(torch.where(total > 0, band / total.clamp_min(1e-300), torch.zeros_like(total)))
    return torch.stack(shares, dim=-1).to(normal.dtype)


def dark_is_low_cosine(maps: Tensor, blur_px: float = 1.0) -> Tensor:
    """How far "dark is low" holds on a material: the cosine, per slope component, between the
    slopes of its base colour's log luminance taken as a height (blurred by ``blur_px``, borders
    reflected) and its normal map's :func:`slope_field`, summed over the map. +1: every dark line
    is a groove; −1: every dark line is a ridge; 0: the base colour says nothing of the relief's
    sign. A network that reads relief from the base colour rather than from the shading learns
    the sign its training materials agree on.

    Shape:
        - maps: ``(*, 8, H, W)`` (the base colour sRGB-encoded, as stored)
        - output: ``(*, 2)``, the x and y components; 0 where either field is constant

    Example:
        A bright square raised above a dark ground (its base colour outlines the relief the right
        way), then the same relief inverted:

        >>> height = torch.zeros(1, 1, 32, 32)
        >>> height[..., 8:24, 8:24] = 4.0
        >>> maps = torch.zeros(8, 32, 32)
        >>> maps[:3] = 0.2 + 0.6 * (height[0] > 0)
        >>> maps[3:6] = torch.cat([height_slope_channels(height)[0], torch.ones(1, 32, 32)])
        >>> [round(v, 2) for v in dark_is_low_cosine(maps).tolist()]
        [0.89, 0.89]
        >>> maps[3:5] *= -1
        >>> [round(v, 2) for v in dark_is_low_cosine(maps).tolist()]
        [-0.89, -0.89]
    """
    dims = check_shape(maps, "* 8 H W", name="maps")
    flat = maps.reshape(-1, 8, dims["H"], dims["W"]).to(torch.float64)
    height = gaussian_blur(_log_luminance(srgb_to_linear(flat[:, BASECOLOR])), blur_px, border="reflect")
    texture = -height_slope_channels(height)  # the height's gradient, as slope_field's slopes are
    relief = slope_field(flat[:, NORMAL])
    dot = (texture * relief).sum(dim=(-2, -1))
    norms = texture.square().sum(dim=(-2, -1)).mul(relief.square().sum(dim=(-2, -1))).sqrt()
    cosine = torch.where(norms > 0, dot / norms.clamp_min(1e-300), torch.zeros_like(dot))
    return cosine.reshape(*maps.shape[:-3], 2).to(maps.dtype)


# ----------------------------------------------------------------------------- observability


def _log_luminance(rgb: Tensor) -> Tensor:
    return log_luminance(rgb, LOG_FLOOR)


def scene_relief_shading(
    maps: Tensor,
    camera_position: Tensor,
    light_position: Tensor,
    light_rgb: Tensor,
    grids: Tensor,
    exposure_ev: Tensor,
) -> Tensor:
    """What the relief does to a training photo: ``log Y(P_n) − log Y(P_flat)``, ``P_n`` the photo
    of the scene as :func:`~brdfgan.data.loading.rendered.photograph_scenes` takes it (the flash at its
    offset and the environment's distant lights, :func:`~brdfgan.core.render.render_point_lights`,
    resampled into the photo's pixels, auto-exposed off by the drawn error and clipped to [0, 1])
    and ``P_flat`` the same photo of the maps with flat normals **at ``P_n``'s exposure**; ``Y`` the
    luminance floored at :data:`LOG_FLOOR` (:func:`log_luminance`).

    Exactly 0 for flat normals, and where both photos clip or sink below the floor (a photo shows no
    relief there); negative where the relief turns the surface from the light. Independent of the
    lights' overall intensity (the auto exposure).

    Shape:
        - maps: ``(B, 8, R, R)`` texture space; camera_position: ``(B, 3)``
        - light_position, light_rgb: ``(B, K, 3)``; grids: ``(B, R', R', 2)``; exposure_ev: ``(B,)``
        - output: ``(B, 1, R', R')``

    Example:
        A white plane with a ridge (normals tilted 20° left and right) under a light straight above
        the camera: the ridge's texels are darker than flat (``cos 20°`` less light, and less
        specular), the rest unchanged:

        >>> from brdfgan.core.render import nominal_camera, view_grid
        >>> from brdfgan.core.svbrdf import flat_maps
        >>> maps = flat_maps(8, 8, basecolor=(0.8, 0.8, 0.8), roughness=0.5, batch=(1,))
        >>> maps[0, 3, :, 3], maps[0, 3, :, 4] = -math.sin(math.radians(20)), math.sin(math.radians(20))
        >>> maps[0, 5, :, 3:5] = math.cos(math.radians(20))
        >>> camera = torch.tensor([[0.0, 0.0, 2.4142]])
        >>> grid = view_grid(nominal_camera(45.0), 8, 8).float()[None]
        >>> lights = (camera[:, None], torch.ones(1, 1, 3))
        >>> shading = scene_relief_shading(maps, camera, *lights, grid, torch.zeros(1))
        >>> bool((shading[0, 0, :, 3:5] < -0.06).all()), shading[0, 0, :, :3].abs().max().item()
        (True, 0.0)
    """
    dims = check_shape(maps, "B 8 R R", name="maps")
    check_shape(camera_position, "B 3", name="camera_position", dims=dims)
    dims = check_shape(light_position, "B K 3", name="light_position", dims=dims)
    check_shape(light_rgb, "B K 3", name="light_rgb", dims=dims)
    check_shape(grids, "B S S 2", name="grids", dims=dims)
    check_shape(exposure_ev, "B", name="exposure_ev", dims=dims)
    flat = maps.clone()
    flat[:, NORMAL] = 0.0
    flat[:, NORMAL.start + 2] = 1.0
    relief_hdr = render_scenes(maps, camera_position, light_position, light_rgb, grids)
    flat_hdr = render_scenes(flat, camera_position, light_position, light_rgb, grids)
    scale = (auto_exposure_scale(relief_hdr) * torch.pow(2.0, exposure_ev.to(relief_hdr)))[
        :, None, None, None
    ]
    return _log_luminance((relief_hdr * scale).clamp(0.0, 1.0)) - _log_luminance(
        (flat_hdr * scale).clamp(0.0, 1.0)
    )


def high_pass(image: Tensor, sigma_px: float) -> Tensor:
    """``image − gaussian_blur(image, sigma_px)``, mirrored at the border
    (:func:`~brdfgan.core.filtering.gaussian_blur`): the detail finer than about ``sigma_px``.

    Shape:
        - image: ``(B, C, H, W)``
        - output: same

    Example:
        A constant has no detail:

        >>> bool(high_pass(torch.full((1, 1, 8, 8), 3.0), 2.0).abs().max() < 1e-6)
        True
    """
    check_shape(image, "B C H W", name="image")
    return image - gaussian_blur(image, sigma_px, "reflect")


def relief_share(photo: Tensor, relief_log_ratio: Tensor, sigma_px: float | None = None) -> Tensor:
    """The share of a photo's detail variation that is relief: per photo, the squared Pearson
    correlation over its pixels between the high-passed log luminance of the photo
    (:func:`log_luminance`, :func:`high_pass`) and the high-passed relief log ratio
    (:func:`scene_relief_shading`), ``sigma_px`` the high-pass's σ (default: :data:`HIGH_PASS_FRACTION`
    of the shorter side, which removes the flash's falloff and lobe).

    1: the photo's detail is the relief's shading up to scale (a uniform albedo photographed
    clean); it falls as albedo texture, noise, JPEG or processing add detail that is not relief,
    or remove the relief's. 0 where the relief ratio or the photo has no detail. The high-passes
    are taken in the inputs' precision, the correlation in float64.

    Shape:
        - photo: ``(B, 3, H, W)`` linear
        - relief_log_ratio: ``(B, 1, H, W)``, or ``(1, 1, H, W)`` for deliveries of one photo
        - output: ``(B,)`` in [0, 1]

    Example:
        A photo that is a smooth falloff times the relief's shading is nearly all relief (the
        mirrored border leaves a trace of the ramp); a second, unrelated texture as strong as the
        relief makes it about half:

        >>> g = torch.Generator().manual_seed(0)
        >>> relief = 0.1 * torch.randn(1, 1, 32, 32, generator=g)
        >>> falloff = torch.linspace(-1.0, 0.0, 32).view(1, 1, 1, 32)
        >>> photo = (falloff + relief).exp().expand(1, 3, 32, 32)
        >>> round(relief_share(photo, relief).item(), 2)
        0.98
        >>> texture = 0.1 * torch.randn(1, 1, 32, 32, generator=g)
        >>> round(relief_share((falloff + relief + texture).exp().expand(1, 3, 32, 32), relief).item(), 1)
        0.5
    """
    dims = check_shape(photo, "B 3 H W", name="photo")
    ratio_dims = check_shape(
        relief_log_ratio, "N 1 H W", name="relief_log_ratio", dims={"H": dims["H"], "W": dims["W"]}
    )
    if ratio_dims["N"] not in (1, dims["B"]):
        raise ValueError(
            f"relief_log_ratio must hold 1 or {dims['B']} (the photos') ratios, got {ratio_dims['N']}"
        )
    sigma = HIGH_PASS_FRACTION * min(dims["H"], dims["W"]) if sigma_px is None else sigma_px
    x = high_pass(_log_luminance(photo), sigma).flatten(1).to(torch.float64)
    y = high_pass(relief_log_ratio, sigma).flatten(1).to(torch.float64)
    x = x - x.mean(dim=1, keepdim=True)
    y = y - y.mean(dim=1, keepdim=True)
    power = x.square().sum(dim=1) * y.square().sum(dim=1)
    share = (x * y).sum(dim=1).square() / power.clamp_min(1e-300)
    return torch.where(power > 0, share, torch.zeros_like(share)).to(photo.dtype)


def delivered_noise_log(delivered: Tensor, reference: Tensor, sigma_px: float = 2.0) -> Tensor:
    """The noise a delivery added, per pixel, in log luminance: the local RMS (a Gaussian window
    of ``sigma_px``) of ``d − mean(d)``, ``d = log Y(delivered) − log Y(reference)``
    (:func:`log_luminance`), the reference being the same photo delivered without the noisy steps
    (e.g. a sensor's shot/read noise and JPEG switched off, every other draw equal). The mean is
    removed because the auto exposure of the two differs by a constant.

    Shape:
        - delivered, reference: ``(B, 3, H, W)`` linear
        - output: ``(B, 1, H, W)`` ≥ 0

    Example:
        Multiplicative noise of 5 % is 0.05 in log units:

        >>> g = torch.Generator().manual_seed(0)
        >>> reference = torch.full((1, 3, 64, 64), 0.2)
        >>> delivered = reference * (1 + 0.05 * torch.randn(1, 1, 64, 64, generator=g))
        >>> round(delivered_noise_log(delivered, reference, 4.0).mean().item(), 2)
        0.05
    """
    dims = check_shape(delivered, "B 3 H W", name="delivered")
    check_shape(reference, "B 3 H W", name="reference", dims=dims)
    difference = _log_luminance(delivered) - _log_luminance(reference)
    difference = difference - difference.mean(dim=(-2, -1), keepdim=True)
    return gaussian_blur(difference.square(), sigma_px, "reflect").clamp_min(0.0).sqrt()


def observable_angle(normal: Tensor, mask: Tensor) -> Tensor:
    """The part of the flat map's angle a photo can show: the mean :func:`tilt_deg` over the
    observable texels (``mask``) times their share, i.e. ``Σ θ·mask / N`` over all N texels. Beside
    the total (``tilt_deg(normal).mean()``, the flat map's angle) it says how much of the angle a
    model could recover from the photo pixel by pixel.

    Shape:
        - normal: ``(*, 3, H, W)``
        - mask: ``(*, H, W)`` bool (or ``(*, 1, H, W)``)
        - output: ``(*)`` degrees

    Example:
        Two texels of 10° and two flat, the first 10° texel observable: 2.5° of the 5° total:

        >>> normal = torch.zeros(3, 1, 4)
        >>> normal[2], normal[0, 0, :2] = 1.0, math.tan(math.radians(10.0))
        >>> mask = torch.tensor([[True, False, True, False]])
        >>> round(observable_angle(normal, mask).item(), 3), round(tilt_deg(normal).mean().item(), 3)
        (2.5, 5.0)
    """
    tilt = tilt_deg(normal)
    if mask.shape != tilt.shape:
        mask = mask.squeeze(-3) if mask.ndim == tilt.ndim + 1 and mask.shape[-3] == 1 else mask
    if mask.shape != tilt.shape:
        raise ValueError(
            f"mask must have shape {tuple(tilt.shape)} (the normals' texels), got {tuple(mask.shape)}"
        )
    return (tilt * mask.to(tilt.dtype)).mean(dim=(-2, -1))


# ----------------------------------------------------------------------------- shape from shading


def photo_relief_residual(
    photo: Tensor, maps: Tensor, frame: Tensor, clip_level: float = CLIP_LEVEL
) -> tuple[Tensor, Tensor]:
    """What a photo shows of its relief when everything else is known: ``(r, valid)``, ``r`` the
    photo's log luminance less an affine fit ``a·x + c`` of ``x``, the log luminance of the
    flash render of its **true** maps with flat normals (:func:`~brdfgan.core.delit.flat_flash_render`),
    divided by ``a``, so it is in the units of :func:`~brdfgan.metrics.relief_shading`. The fit (per
    photo, least squares over the valid pixels) absorbs the exposure and, through ``a``, a tone
    curve's slope; room light, the phone's processing, noise, JPEG and the renderers' differences
    stay in ``r``, which has mean 0 over the valid pixels (the true shading's mean went with ``c``:
    fit it with ``free_offset``). ``a`` is clamped at 0.1 (a photo unrelated to its render).
    ``valid``: the pixels with no channel at ``clip_level`` or above (a clipped hotspot shows no
    shading) and a luminance above the floor of :func:`~brdfgan.metrics.relief_shading`.

    Shape:
        - photo: ``(B, 3, H, W)`` linear, the maps' size; maps: ``(B, 8, H, W)``; frame: ``(B, 3)``
        - output: ``(B, 1, H, W)`` float, ``(B, 1, H, W)`` bool

    Example:
        A grey surface's photo that is the flat render squared and exposed (a tone curve of slope 2
        in log units) holds no relief:

        >>> from brdfgan.core.svbrdf import flat_maps
        >>> maps = flat_maps(8, 8, basecolor=(0.5, 0.5, 0.5), roughness=0.6, batch=(1,))
        >>> frame = torch.tensor([[4.0, 4.0, 0.1]])
        >>> linear = srgb_to_linear(maps[:, BASECOLOR])
        >>> flat = flat_flash_render(linear, maps[:, ROUGHNESS], maps[:, METALLIC], frame)
        >>> residual, valid = photo_relief_residual(0.9 * flat.square() / flat.max() ** 2, maps, frame)
        >>> bool(residual.abs().max() < 1e-4), bool(valid.all())
        (True, True)
    """
    dims = check_shape(photo, "B 3 H W", name="photo")
    check_shape(maps, "B 8 H W", name="maps", dims=dims)
    flat = flat_flash_render(srgb_to_linear(maps[:, BASECOLOR]), maps[:, ROUGHNESS], maps[:, METALLIC], frame)
    x = log_luminance(flat, RELIEF_LOG_FLOOR).double()
    y = log_luminance(photo, RELIEF_LOG_FLOOR).double()
    # Clipped where any channel is (as predict's refinement and the views' fit take it).
    valid = (photo < clip_level).all(dim=1, keepdim=True) & (luminance(photo) > RELIEF_LOG_FLOOR)
    weight = valid.double()
    count = weight.sum(dim=(-2, -1), keepdim=True).clamp_min(1.0)
    mean_x = (x * weight).sum(dim=(-2, -1), keepdim=True) / count
    mean_y = (y * weight).sum(dim=(-2, -1), keepdim=True) / count
    covariance = ((x - mean_x) * (y - mean_y) * weight).sum(dim=(-2, -1), keepdim=True)
    variance = ((x - mean_x).square() * weight).sum(dim=(-2, -1), keepdim=True)
    # A photo of constant flat render (no falloff to fit a slope on) keeps a = 1.
    gain = torch.where(variance > 1e-9, covariance / variance.clamp_min(1e-9), torch.ones_like(variance))
    gain = gain.clamp_min(0.1)
    residual = (y - mean_y - gain * (x - mean_x)) / gain
    return (residual * weight).to(photo.dtype), valid


def radial_slope(normal: Tensor, frame: Tensor) -> Tensor:
    """The slope along the direction away from the flash hotspot, ``s · ô`` (``s`` the
    :func:`~brdfgan.core.height.slope_field`, ``ô`` the unit offset of each pixel from the hotspot,
    :func:`~brdfgan.core.flash_geometry.flash_offset_channels`; 0 at the hotspot itself): the one
    component of a slope that a flash at the lens shades to first order (``n·l = (1 + s·o) /
    √((1 + |s|²)(1 + |o|²))``, ``o`` the offset); the slope across it changes the shading only
    through ``|s|²``.

    Shape:
        - normal: ``(B, 3, H, W)``; frame: ``(B, 3)``
        - output: ``(B, 1, H, W)``

    Example:
        A surface tilted towards +x (falling along +x, slope −0.75): in line with the hotspot
        along x its radial slope is −0.75; straight below it 0, and a pixel further right part of
        −0.75 (its offset is mostly downward):

        >>> normal = torch.tensor([0.6, 0.0, 0.8]).view(1, 3, 1, 1).expand(1, 3, 1, 2)
        >>> [round(v, 2) for v in radial_slope(normal, torch.tensor([[0.0, 0.5, 1.0]])).flatten().tolist()]
        [-0.75, -0.75]
        >>> below = radial_slope(normal, torch.tensor([[0.5, -3.0, 1.0]]))
        >>> [round(v, 2) + 0.0 for v in below.flatten().tolist()]
        [0.0, -0.21]
    """
    dims = check_shape(normal, "B 3 H W", name="normal")
    offsets = flash_offset_channels(frame.to(normal.dtype), dims["H"], dims["W"])
    length = offsets.norm(dim=1, keepdim=True)
    away = torch.where(length > 0, offsets / length.clamp_min(1e-12), torch.zeros_like(offsets))
    return (slope_field(normal) * away).sum(dim=1, keepdim=True)


def fit_height_to_shading(
    maps: Tensor,
    frame: Tensor,
    observed: Tensor,
    valid: Tensor,
    *,
    ridge: float = 0.0,
    free_offset: bool = False,
    steps: int = 400,
    learning_rate: float = 1.0,
    levels: int = 6,
) -> Tensor:
    """Shape from shading with the rest of the surface known: per photo, the normals of the height
    ``h`` that minimise ``mean_valid (S(h) − observed − c)² + ridge · mean |∇h|²``, ``S`` the flash
    relief shading (:func:`~brdfgan.metrics.relief_shading`) of ``maps`` with ``h``'s normals
    (:func:`~brdfgan.core.height.height_slope_channels`) in place of theirs, ``observed`` e.g. the
    true maps' own shading or :func:`photo_relief_residual`, and ``c`` 0 or, ``free_offset``, the
    mean difference over the valid pixels (an observation known up to a constant, as a residual
    whose mean was fitted away). L-BFGS (at most ``steps`` iterations, ``2 · steps`` evaluations)
    from a flat ``h`` made of ``levels`` grids of halving resolution enlarged bilinearly and summed
    (a broad rise moves as fast as a fine groove); each photo on its own, so the result does not
    depend on the batch.

    An oracle without a learned prior: it is given the base colour, roughness and metallic a model
    must find, and reads the relief by least squares alone. One flash at the lens shades a pixel
    by ``n·l`` only (``l = v``), one number for two slopes; the height's integrability and the
    ridge's pull to flat decide the rest (:func:`radial_slope`). Runs with gradients on even under
    ``torch.no_grad``.

    Shape:
        - maps: ``(B, 8, H, W)``; frame: ``(B, 3)``
        - observed: ``(B, 1, H, W)``; valid: ``(B, 1, H, W)`` bool
        - output: ``(B, 3, H, W)`` unit normals
    """
    dims = check_shape(maps, "B 8 H W", name="maps")
    check_shape(observed, "B 1 H W", name="observed", dims=dims)
    check_shape(valid, "B 1 H W", name="valid", dims=dims)
    if ridge < 0 or steps < 0 or not learning_rate > 0 or levels < 1:
        raise ValueError(f"need ridge ≥ 0, steps ≥ 0, learning_rate > 0, levels ≥ 1; got {ridge=}, "
                         f"{steps=}, {learning_rate=}, {levels=}")  # fmt: skip
    fitted = [
        _fit_one_height(
            maps[k : k + 1],
            frame[k : k + 1],
            observed[k : k + 1],
            valid[k : k + 1],
            ridge=ridge,
            free_offset=free_offset,
            steps=steps,
            learning_rate=learning_rate,
            levels=levels,
        )
        for k in range(dims["B"])
    ]
    return torch.cat(fitted) if fitted else maps[:, NORMAL].detach().clone()


def _fit_one_height(
    maps: Tensor,
    frame: Tensor,
    observed: Tensor,
    valid: Tensor,
    *,
    ridge: float,
    free_offset: bool,
    steps: int,
    learning_rate: float,
    levels: int,
) -> Tensor:
    """:func:`fit_height_to_shading` of one photo (``B = 1``)."""
    height, width = maps.shape[-2:]
    maps, observed = maps.detach().float(), observed.detach().float()
    # relief_shading's two renders and floor, the flat render made once: log Y(R_n) − log Y(R_flat).
    basecolor, roughness, metallic = srgb_to_linear(maps[:, BASECOLOR]), maps[:, ROUGHNESS], maps[:, METALLIC]
    plain = log_luminance(flat_flash_render(basecolor, roughness, metallic, frame), RELIEF_LOG_FLOOR)
    weight = valid.float() / valid.float().sum().clamp_min(1.0)
    grids = [
        torch.zeros(
            1, 1, max(1, height >> level), max(1, width >> level), device=maps.device, requires_grad=True
        )
        for level in range(levels)
    ]
    # L-BFGS, not Adam: Adam's steps are ~learning_rate whatever the gradient's scale, which
    # draws noise over a near-flat surface; the problem is a smooth least squares.
    optimizer = torch.optim.LBFGS(
        grids, lr=learning_rate, max_iter=steps, max_eval=2 * steps, history_size=20,
        tolerance_grad=1e-12, tolerance_change=1e-15, line_search_fn="strong_wolfe",
    )  # fmt: skip

    def unnormalised_normals() -> tuple[Tensor, Tensor]:  # (−∇h, 1) and −∇h
        surface = sum(
            torch.nn.functional.interpolate(grid, size=(height, width), mode="bilinear", align_corners=False)
            for grid in grids
        )
        normal_xy = height_slope_channels(surface)  # type: ignore[arg-type]
        return torch.cat([normal_xy, torch.ones_like(normal_xy[:, :1])], dim=1), normal_xy

    def closure() -> Tensor:
        normal, normal_xy = unnormalised_normals()
        photo = flash_render(basecolor, normal, roughness, metallic, frame)
        difference = log_luminance(photo, RELIEF_LOG_FLOOR) - plain - observed
        if free_offset:
            difference = difference - (difference * weight).sum()
        loss = (difference.square() * weight).sum() + ridge * normal_xy.square().sum(dim=1).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        return loss

    with torch.enable_grad():
        if steps > 0:
            optimizer.step(closure)
        normal, _ = unnormalised_normals()
    return (normal / normal.norm(dim=1, keepdim=True)).detach()
