"""Test-time refinement: fit the network's maps to the photo with the differentiable renderer.

A forward pass uses the photo only through what the network learnt; re-rendered under the
capture's own flash, its maps often reproduce the photo poorly. :func:`refine_maps` optimises the
maps so that their render matches the photo, starting from the prediction and held near it
(MaterialGAN, Guo et al. 2020; Deschaintre et al. 2020; Gao et al. 2019).

The capture model is the training captures' (:class:`~brdfgan.core.render.FlashCapture`): a
camera looking straight down from above the photo's flash hotspot (the flash frame the network
read; a crop is a window of a view centred on its hotspot), at the height the frame's field of
view gives (from the EXIF, :mod:`brdfgan.inference.intake.lens`), the flash at the lens. What is
corrected (:class:`~brdfgan.inference.refine_config.RefineConfig`): by default one logit offset per
map — base colour, roughness, metallic — keeping the network's normals and spatial detail;
optionally the roughness kept (``fit_roughness=False``) or fitted but not returned
(``roughness_nuisance``), a scale of the normals' slopes (``fit_normal_strength``), the gradient
of a fitted height field added to them (``fit_relief``) and per-pixel corrections (``pixel_maps``).
Fitted beside the maps:

- a per-channel **gain** (log-parametrised): the photo's unknown exposure and white balance;
- optionally a low-frequency **ambient irradiance** (a ``g × g`` grid per channel, bilinearly
  upsampled, times the diffuse albedo): light the flash model cannot explain — a room or the sky —
  which would otherwise be fitted into the base colour;
- optionally a **flash offset** (a 2-vector in the plane, world units): a flash beside the lens.

The objective, per term (weights in :class:`RefineConfig`):

- *photo*: L1 between log(render + ε) and log(photo + ε) over the unclipped pixels; a clipped
  pixel (any channel ≥ ``clip_level``) says only that the truth is at least that bright, so it
  costs only where the render falls below it;
- *prior*: L1 of every map to the network's prediction (base colour, roughness, metallic values
  and the normals' slopes) — the photo shows one view and cannot tell everything apart; needed
  by per-pixel corrections, off by default (on one offset per map it is a dead zone);
- *low-frequency prior*: L1 of the base colour blurred, to the prediction blurred — the
  photo's large-scale shading (vignetting, falloff the model misjudges) belongs to light, not
  to the albedo;
- *total variation* of roughness and metallic: they change at edges, not per pixel.

Parametrisation keeps every map valid: logits for base colour, roughness and metallic, slopes
``(s_x, s_y)`` for the normal ``normalize(s_x, s_y, 1)`` (unit and facing up). Large maps are
refined at ``working_size`` and the correction (in these parameters) is upsampled and added to the
full-resolution prediction (:func:`transfer_correction`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.flash_geometry import (
    centred_flash_frame,
    check_flash_frame,
    field_of_view,
    hotspot_position,
)
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import (
    check_map_shape,
    diffuse_albedo,
    join_maps,
    linear_to_srgb,
    normalize_normal,
    resize_maps,
    split_maps,
    srgb_to_linear,
)
from brdfgan.inference.refine_config import RefineConfig

# Values kept away from 0 and 1 before the logit, so a saturated prediction stays movable.
LOGIT_MARGIN = 1e-3
# Normals are kept within ~84° of the vertical (slope 10).
MAX_SLOPE = 10.0
# ε of the log in the photo term: below ~1 % of the auto-exposed range, noise dominates.
LOG_EPSILON = 1e-2
# Parameter channels: base colour logits (3), normal slopes (2), roughness and metallic logits.
_BASECOLOR, _SLOPES, _ROUGHNESS, _METALLIC = slice(0, 3), slice(3, 5), slice(5, 6), slice(6, 7)


@dataclass(frozen=True)
class RefineResult:
    """The refined maps and what the fit found (``material.json``'s ``refinement`` entry)."""

    maps: Tensor  # (8, H, W), the resolution of the maps given
    steps: int
    seconds: float
    gain: tuple[float, float, float]
    flash_offset: tuple[float, float] | None
    ambient_mean: tuple[float, float, float] | None  # irradiance relative to the flash's at the centre
    normal_strength: float | None  # the fitted scale of the normals' slopes (fit_normal_strength)
    loss_start: float
    loss_end: float
    photo_rmse_start: float  # sRGB RMSE of the re-rendered input view, before and after
    photo_rmse_end: float

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k != "maps"}


def maps_to_parameters(maps: Tensor) -> Tensor:
    """The unconstrained parameters of :func:`parameters_to_maps` for ``maps``.

    Shape: ``(B, 8, H, W)`` → ``(B, 7, H, W)``."""
    check_map_shape(maps)
    parts = split_maps(maps)
    normal = normalize_normal(parts.normal)
    z = normal[:, 2:3].clamp_min(1.0 / MAX_SLOPE)
    return torch.cat(
        [
            torch.logit(parts.basecolor.clamp(LOGIT_MARGIN, 1 - LOGIT_MARGIN)),
            (normal[:, 0:2] / z).clamp(-MAX_SLOPE, MAX_SLOPE),
            torch.logit(parts.roughness.clamp(LOGIT_MARGIN, 1 - LOGIT_MARGIN)),
            torch.logit(parts.metallic.clamp(LOGIT_MARGIN, 1 - LOGIT_MARGIN)),
        ],
        dim=1,
    )


def parameters_to_maps(parameters: Tensor) -> Tensor:
    """Valid maps of unconstrained parameters: sigmoid of the logits, ``normalize(s_x, s_y, 1)``.

    Shape: ``(B, 7, H, W)`` → ``(B, 8, H, W)``."""
    slopes = parameters[:, _SLOPES].clamp(-MAX_SLOPE, MAX_SLOPE)
    normal = normalize_normal(torch.cat([slopes, torch.ones_like(slopes[:, :1])], dim=1))
    return join_maps(
        torch.sigmoid(parameters[:, _BASECOLOR]),
        normal,
        torch.sigmoid(parameters[:, _ROUGHNESS]),
        torch.sigmoid(parameters[:, _METALLIC]),
    )


def photo_loss(render: Tensor, photo: Tensor, clip_level: float) -> Tensor:
    """L1 of log(x + ε) over unclipped pixels; clipped ones (any channel ≥ ``clip_level``) as
    lower bounds. Mean over all pixels and channels.

    Shape: render, photo ``(B, 3, H, W)`` → scalar."""
    log_render = torch.log(render.clamp_min(0.0) + LOG_EPSILON)
    log_photo = torch.log(photo + LOG_EPSILON)
    clipped = (photo >= clip_level).any(dim=1, keepdim=True)
    error = torch.where(clipped, (log_photo - log_render).clamp_min(0.0), (log_render - log_photo).abs())
    return error.mean()


def total_variation(image: Tensor) -> Tensor:
    """Mean absolute difference of neighbouring pixels. Shape: ``(B, C, H, W)`` → scalar."""
    return (image[..., 1:, :] - image[..., :-1, :]).abs().mean() + (
        image[..., :, 1:] - image[..., :, :-1]
    ).abs().mean()


def transfer_correction(maps: Tensor, before: Tensor, after: Tensor) -> Tensor:
    """Add the refinement's correction ``after − before`` (maps at the working size) to ``maps``
    at their own size, in the parameters of :func:`maps_to_parameters` (bilinear upsampling).

    Shape: maps ``(B, 8, H, W)``; before, after ``(B, 8, h, w)`` → ``(B, 8, H, W)``."""
    delta = maps_to_parameters(after) - maps_to_parameters(before)
    if delta.shape[-2:] != maps.shape[-2:]:
        delta = F.interpolate(delta, size=maps.shape[-2:], mode="bilinear", align_corners=False)
    return parameters_to_maps(maps_to_parameters(maps) + delta)


def _ambient_irradiance(grid: Tensor, size: int) -> Tensor:
    return F.interpolate(grid.exp(), size=(size, size), mode="bilinear", align_corners=False)


def add_ambient(render: Tensor, maps: Tensor, log_irradiance: Tensor) -> Tensor:
    """The flash render plus the diffuse reflection of a low-frequency ambient irradiance
    (``exp`` of a ``g × g`` grid per channel, bilinearly upsampled), relative to the flash's.

    Shape: render ``(B, 3, H, W)``, maps ``(B, 8, H, W)``, log_irradiance ``(B, 3, g, g)`` →
    ``(B, 3, H, W)``."""
    parts = split_maps(maps)
    albedo = diffuse_albedo(srgb_to_linear(parts.basecolor), parts.metallic)
    return render + albedo * _ambient_irradiance(log_irradiance, render.shape[-1])


def initial_log_gain(photo: Tensor, render: Tensor, clip_level: float) -> Tensor:
    """Per channel, the log of the median ratio photo / render over the pixels neither clipped
    nor black in the render (0 when there are none): where the fitted gain starts.

    Shape: photo, render ``(1, 3, H, W)`` → ``(1, 3, 1, 1)``."""
    valid = (photo < clip_level).all(dim=1, keepdim=True) & (render > 1e-4).all(1, keepdim=True)
    ratio = (photo / render.clamp_min(1e-6)).permute(1, 0, 2, 3)[:, valid[:, 0]]
    gain = ratio.median(dim=1).values if ratio.shape[1] > 0 else photo.new_ones(3)
    return gain.clamp_min(1e-6).log().view(1, 3, 1, 1)


def cosine_decay(step: int, steps: int) -> float:
    """The learning-rate factor of a fit of ``steps`` steps at ``step``: 1 → 0 along half a cosine."""
    return 0.5 * (1 + math.cos(math.pi * min(step, steps) / max(steps, 1)))


def refine_maps(
    photo: Tensor,
    maps: Tensor,
    flash_frame: Tensor,
    config: RefineConfig | None = None,
    on_step: Callable[[int, float], None] | None = None,
) -> RefineResult:
    """Fit ``maps`` (the network's prediction) to ``photo`` (module docstring).

    Args:
        photo: the network's input, linear, auto-exposed (what :func:`preprocess
            <brdfgan.inference.intake.preprocess.preprocess>` gives), at the maps' size or any
            other square size (it is resized to the working size).
        maps: the prediction.
        flash_frame: the photo's :mod:`flash frame <brdfgan.core.flash_geometry>` (what the
            network read): the field of view across the photo and the hotspot, below the
            camera and flash of the capture model (the photo is a crop, its hotspot anywhere).
        config: the refinement's settings (default: ``RefineConfig()``).
        on_step: called after each step with ``(step, loss)`` (progress).

    Shape:
        - photo: ``(3, N, N)``; maps: ``(8, M, M)``; flash_frame: ``(1, 3)`` or ``(3,)``
        - output maps: ``(8, M, M)``
    """
    check_shape(photo, "3 N N", name="square photo")
    check_map_shape(maps)
    check_shape(maps, "8 M M", name="square maps")
    config = config or RefineConfig()
    frame = flash_frame.detach().float().reshape(1, -1)
    check_flash_frame(frame, 1)
    started = time.perf_counter()
    capture = FlashCapture(fov_deg=field_of_view(float(frame[0, 2]), photo.shape[-1]))
    with torch.enable_grad():
        maps_full = maps.detach().float().unsqueeze(0)
        size = min(config.working_size, maps_full.shape[-1])
        prior_maps = resize_maps(maps_full[0], size)[None] if maps_full.shape[-1] != size else maps_full
        target = photo.detach().float().unsqueeze(0).to(maps_full.device)
        if target.shape[-1] != size:
            target = F.interpolate(
                target, size=(size, size), mode="area" if target.shape[-1] > size else "bilinear"
            )
        camera_xy = hotspot_position(frame, photo.shape[-2], photo.shape[-1]).to(maps_full.device)
        prior = maps_to_parameters(prior_maps)
        prior_values = parameters_to_maps(prior)
        prior_slopes = prior[:, _SLOPES]
        prior_low = gaussian_blur(prior_values[:, 0:3], config.low_frequency_sigma, "reflect")

        # Corrections of the prior's parameters: per pixel for base colour and slopes, and for
        # roughness and metallic a coarse grid (the photo shows them only where it has a highlight)
        pixel_delta = torch.zeros_like(prior[:, :5]).requires_grad_(config.pixel_maps)
        grid = config.material_grid or size
        # Without per-pixel maps, the grid also shifts the base colour's logits (all channels
        # alike): the albedo's level against the specular highlight, which the gain cannot set.
        material_delta = torch.zeros(1, 2 if config.pixel_maps else 3, grid, grid, device=prior.device)
        material_delta.requires_grad_(True)
        # A map left out of the fit keeps its offset at zero (channels: roughness, metallic, base).
        fitted = torch.tensor([float(config.fit_roughness), 1.0, 1.0], device=prior.device)
        fitted = fitted[: material_delta.shape[1]].view(1, -1, 1, 1)
        # The normals' strength: one log-scale of the predicted slopes (as --normal-strength).
        log_strength = torch.zeros(1, 1, 1, 1, device=prior.device, requires_grad=config.fit_normal_strength)

        # fit_relief: a height field on a relief_grid² lattice whose gradient adds to the predicted
        # slopes — an integrable correction, the relief the network's flat normals lack.
        relief = torch.zeros(1, 1, config.relief_grid, config.relief_grid, device=prior.device)
        relief.requires_grad_(config.fit_relief)

        def relief_slopes() -> Tensor | None:
            if not config.fit_relief:
                return None
            height = F.interpolate(relief, size=(size, size), mode="bilinear", align_corners=False)
            padded = F.pad(height, (1, 1, 1, 1), mode="replicate")
            dh_dx = (padded[..., 1:-1, 2:] - padded[..., 1:-1, :-2]) / 2
            dh_drow = (padded[..., 2:, 1:-1] - padded[..., :-2, 1:-1]) / 2
            return torch.cat([-dh_dx, dh_drow], dim=1)  # +y up the rows (core.height)

        # roughness_nuisance: the roughness offset is fitted but not returned (the maps keep the
        # predicted roughness): it soaks up the highlight's spread the flat normals cannot give.
        returned = fitted.clone()
        returned[:, :1] *= float(not config.roughness_nuisance)

        def current_parameters(mask: Tensor, added_slopes: Tensor | None) -> Tensor:
            upsampled = material_delta * mask
            if grid != size:
                upsampled = F.interpolate(upsampled, size=(size, size), mode="bilinear", align_corners=False)
            base_shift = upsampled[:, 2:3] if not config.pixel_maps else 0.0
            slopes = prior_slopes * log_strength.exp() + pixel_delta[:, _SLOPES]
            if added_slopes is not None:
                slopes = slopes + added_slopes
            return torch.cat(
                [
                    prior[:, _BASECOLOR] + pixel_delta[:, _BASECOLOR] + base_shift,
                    slopes,
                    prior[:, 5:7] + upsampled[:, :2],
                ],
                dim=1,
            )

        with torch.no_grad():
            start_render = render_flash(prior_values, capture, camera_xy=camera_xy)
        log_gain = initial_log_gain(target, start_render, config.clip_level).clone().requires_grad_(True)
        variables: list[Tensor] = (
            [pixel_delta, material_delta, log_gain] if config.pixel_maps else [material_delta, log_gain]
        )
        if config.fit_normal_strength:
            variables.append(log_strength)
        if config.fit_relief:
            variables.append(relief)
        ambient = None
        if config.ambient:
            # Start at 1 % of the flash's irradiance at the centre: small but with a gradient.
            ambient = torch.full(
                (1, 3, config.ambient_grid, config.ambient_grid),
                math.log(1e-2),
                device=prior.device,
                requires_grad=True,
            )
            variables.append(ambient)
        offset = None
        if config.fit_flash_offset:
            offset = torch.zeros(1, 2, device=prior.device, requires_grad=True)
            variables.append(offset)
        optimizer = torch.optim.Adam(variables, lr=config.learning_rate)
        schedule = torch.optim.lr_scheduler.LambdaLR(
            optimizer,
            lambda step: cosine_decay(step, config.steps),
        )

        def objective() -> tuple[Tensor, Tensor]:
            added_slopes = relief_slopes()  # once per step: the photo term and the relief prior
            parameters = current_parameters(fitted, added_slopes)
            current = parameters_to_maps(parameters)
            render = render_flash(current, capture, flash_offset=offset, camera_xy=camera_xy)
            if ambient is not None:
                render = add_ambient(render, current, ambient)
            render = render * log_gain.exp()
            loss = photo_loss(render, target, config.clip_level)
            loss = loss + config.prior_weight * (current[:, 0:3] - prior_values[:, 0:3]).abs().mean()
            loss = loss + config.material_prior_weight * (current[:, 6:8] - prior_values[:, 6:8]).abs().mean()
            if config.pixel_maps:
                slope_change = (parameters[:, _SLOPES] - prior_slopes).abs().mean()
                loss = loss + config.normal_prior_weight * slope_change
            if config.low_frequency_weight > 0:
                low = gaussian_blur(current[:, 0:3], config.low_frequency_sigma, "reflect")
                loss = loss + config.low_frequency_weight * (low - prior_low).abs().mean()
            if config.tv_weight > 0:
                loss = loss + config.tv_weight * total_variation(current[:, 6:8])
            if added_slopes is not None and config.relief_weight > 0:
                loss = loss + config.relief_weight * added_slopes.square().mean()
            return loss, render

        with torch.no_grad():
            loss_start, render_start = objective()
        for step in range(config.steps):
            loss, _ = objective()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            schedule.step()
            if on_step is not None:
                on_step(step + 1, float(loss.detach()))
        with torch.no_grad():
            loss_end, render_end = objective()
            refined = parameters_to_maps(current_parameters(returned, relief_slopes()))
            out = (
                refined
                if maps_full.shape[-1] == size
                else transfer_correction(maps_full, prior_values, refined)
            )

    def srgb_rmse(render: Tensor) -> float:
        return float((linear_to_srgb(render.clamp(0, 1)) - linear_to_srgb(target)).square().mean().sqrt())

    irradiance = None
    if ambient is not None:
        irradiance = tuple(float(v) for v in _ambient_irradiance(ambient.detach(), size).mean(dim=(0, 2, 3)))
    return RefineResult(
        maps=out[0].to(maps.dtype),
        steps=config.steps,
        seconds=time.perf_counter() - started,
        gain=tuple(float(v) for v in log_gain.detach().exp().flatten()),  # type: ignore[arg-type]
        flash_offset=None if offset is None else tuple(float(v) for v in offset.detach()[0]),  # type: ignore[arg-type]
        ambient_mean=irradiance,  # type: ignore[arg-type]
        normal_strength=float(log_strength.detach().exp()) if config.fit_normal_strength else None,
        loss_start=float(loss_start),
        loss_end=float(loss_end),
        photo_rmse_start=srgb_rmse(render_start),
        photo_rmse_end=srgb_rmse(render_end),
    )


class RefinedGenerator(nn.Module):
    """A generator followed by :func:`refine_maps` of each photo: what ``brdfgan predict --refine``
    does, as a model the evaluator can score. The capture geometry comes from the flash frames
    (field of view and hotspot); without frames, centred hotspots and the default field of view."""

    def __init__(self, generator: nn.Module, config: RefineConfig) -> None:
        super().__init__()
        self.generator = generator
        self.config = config

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        maps = self.generator(photo, flash)
        if flash is None:
            flash = centred_flash_frame(photo.shape[0], photo.shape[-2], photo.shape[-1], device=photo.device)
        refined = [
            refine_maps(photo[index], maps[index], flash[index], self.config).maps
            for index in range(photo.shape[0])
        ]
        return torch.stack(refined)
