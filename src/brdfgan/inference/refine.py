"""Test-time refinement: fit the network's maps to the photo with the differentiable renderer.

A forward pass uses the photo only through what the network learnt; re-rendered under the
capture's own flash, its maps often reproduce the photo poorly. :func:`refine_maps` moves the
maps so that their render matches the photo, starting from the prediction (MaterialGAN, Guo et
al. 2020; Deschaintre et al. 2020; Gao et al. 2019).

The capture model is the training captures' (:class:`~brdfgan.core.render.FlashCapture`): a
camera looking straight down from above the photo's flash hotspot (the flash frame the network
read; a crop is a window of a view centred on its hotspot), at the height the frame's field of
view gives (from the EXIF, :mod:`brdfgan.inference.intake.lens`), the flash at the lens.

What is fitted (:class:`CaptureFit`; settings in
:class:`~brdfgan.inference.refine_config.RefineConfig`):

- **one logit offset per map** — base colour (all channels alike: its level against the specular
  highlight, which the gain cannot set), roughness, metallic — so the network's normals and the
  maps' spatial detail stay as predicted; ``fit_roughness=False`` keeps the roughness,
  ``fit_basecolor=False`` the base colour, and ``roughness_nuisance`` fits the roughness's offset
  but returns the predicted roughness;
- a per-channel **gain** (log-parametrised): the photo's unknown exposure and white balance;
- optionally a low-frequency **ambient irradiance** (a ``g × g`` grid per channel, bilinearly
  upsampled, times the diffuse albedo): light the flash model cannot explain — a room or the sky —
  which would otherwise be fitted into the base colour;
- optionally a **flash offset** (a 2-vector in the plane, world units): a flash beside the lens.

The objective (:func:`photo_loss`) is the L1 between log(render + ε) and log(photo + ε) over the
unclipped pixels; a clipped pixel (any channel ≥ ``clip_level``) says only that the truth is at
least that bright, so it costs only where the render falls below it.

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


def photo_loss(render: Tensor, photo: Tensor, clip_level: float, mask: Tensor | None = None) -> Tensor:
    """L1 of log(x + ε) over unclipped pixels; clipped ones (any channel ≥ ``clip_level``) as
    lower bounds. Mean over all pixels and channels, or with ``mask`` (a view's seen pixels) the
    mean weighted by it, 0 when it is all 0; the photo must be finite where the mask is 0 too.

    Shape: render, photo ``(B, 3, H, W)``; mask ``(B, 1, H, W)`` → scalar."""
    log_render = torch.log(render.clamp_min(0.0) + LOG_EPSILON)
    log_photo = torch.log(photo + LOG_EPSILON)
    clipped = (photo >= clip_level).any(dim=1, keepdim=True)
    error = torch.where(clipped, (log_photo - log_render).clamp_min(0.0), (log_render - log_photo).abs())
    if mask is None:
        return error.mean()
    return (error * mask).sum() / mask.expand_as(error).sum().clamp_min(1e-12)


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


# The offsets' channels in CaptureFit.offsets, and the parameter channels each one shifts.
_OFFSET_TARGETS = (_ROUGHNESS, _METALLIC, _BASECOLOR)


@dataclass(frozen=True)
class CaptureFit:
    """The unknowns of one refinement (module docstring), as leaf tensors for the optimiser.

    Shape:
        - offsets: ``(1, 3, 1, 1)``, logits added to roughness, metallic and base colour
        - log_gain: ``(1, 3, 1, 1)``; log_ambient: ``(1, 3, g, g)``; flash_offset: ``(1, 2)``
    """

    offsets: Tensor
    log_gain: Tensor
    log_ambient: Tensor | None
    flash_offset: Tensor | None

    def variables(self) -> list[Tensor]:
        optional = (self.log_ambient, self.flash_offset)
        return [self.offsets, self.log_gain, *(t for t in optional if t is not None)]


def offset_parameters(prior: Tensor, offsets: Tensor, mask: Tensor) -> Tensor:
    """``prior``'s parameters (:func:`maps_to_parameters`) with ``offsets · mask`` added: each
    offset to every pixel of its map (the base colour's to all three channels alike).

    Shape: prior ``(B, 7, H, W)``; offsets, mask ``(B | 1, 3, 1, 1)`` → ``(B, 7, H, W)``."""
    shifted = offsets * mask
    parameters = prior.clone()
    for channel, target in enumerate(_OFFSET_TARGETS):
        parameters[:, target] = parameters[:, target] + shifted[:, channel : channel + 1]
    return parameters


def render_capture(maps: Tensor, capture: FlashCapture, camera_xy: Tensor, fit: CaptureFit) -> Tensor:
    """What the camera records of ``maps`` under the fitted capture: the flash render (with the
    fitted flash offset), plus the ambient light's diffuse reflection, times the gain.

    Shape: maps ``(1, 8, H, W)``, camera_xy ``(1, 2)`` → ``(1, 3, H, W)``."""
    render = render_flash(maps, capture, flash_offset=fit.flash_offset, camera_xy=camera_xy)
    if fit.log_ambient is not None:
        render = add_ambient(render, maps, fit.log_ambient)
    return render * fit.log_gain.exp()


def _at_working_size(photo: Tensor, maps: Tensor, size: int) -> tuple[Tensor, Tensor]:
    """The photo and the maps (batches of one, float) at the fit's size."""
    maps_small = resize_maps(maps[0], size)[None] if maps.shape[-1] != size else maps
    target = photo.detach().float().unsqueeze(0).to(maps.device)
    if target.shape[-1] != size:
        mode = "area" if target.shape[-1] > size else "bilinear"
        target = F.interpolate(target, size=(size, size), mode=mode)
    return target, maps_small


def _start(prior_maps: Tensor, target: Tensor, capture: FlashCapture, camera_xy: Tensor,
           config: RefineConfig) -> CaptureFit:  # fmt: skip
    """Offsets at zero, the gain at the photo's median ratio to the prediction's render, the
    ambient light at 1 % of the flash's irradiance at the centre (small, but with a gradient)."""
    device = prior_maps.device
    with torch.no_grad():
        render = render_flash(prior_maps, capture, camera_xy=camera_xy)
    ambient = torch.full((1, 3, config.ambient_grid, config.ambient_grid), math.log(1e-2), device=device)
    return CaptureFit(
        offsets=torch.zeros(1, 3, 1, 1, device=device).requires_grad_(True),
        log_gain=initial_log_gain(target, render, config.clip_level).clone().requires_grad_(True),
        log_ambient=ambient.requires_grad_(True) if config.ambient else None,
        flash_offset=torch.zeros(1, 2, device=device).requires_grad_(True)
        if config.fit_flash_offset
        else None,
    )


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
    maps_full = maps.detach().float().unsqueeze(0)
    target, prior_maps = _at_working_size(photo, maps_full, min(config.working_size, maps_full.shape[-1]))
    camera_xy = hotspot_position(frame, photo.shape[-2], photo.shape[-1]).to(maps_full.device)
    prior = maps_to_parameters(prior_maps)
    # Which offsets move (roughness, metallic, base colour), and which the returned maps keep.
    fitted = torch.tensor(
        [float(config.fit_roughness), 1.0, float(config.fit_basecolor)], device=prior.device
    ).view(1, 3, 1, 1)
    returned = fitted * torch.tensor(
        [float(not config.roughness_nuisance), 1.0, 1.0], device=prior.device
    ).view(1, 3, 1, 1)

    with torch.enable_grad():
        fit = _start(prior_maps, target, capture, camera_xy, config)

        def objective() -> tuple[Tensor, Tensor]:
            render = render_capture(
                parameters_to_maps(offset_parameters(prior, fit.offsets, fitted)), capture, camera_xy, fit
            )
            return photo_loss(render, target, config.clip_level), render

        optimizer = torch.optim.Adam(fit.variables(), lr=config.learning_rate)
        schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: cosine_decay(step, config.steps))
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
        refined = parameters_to_maps(offset_parameters(prior, fit.offsets, returned))
        same_size = maps_full.shape[-1] == prior_maps.shape[-1]
        out = refined if same_size else transfer_correction(maps_full, parameters_to_maps(prior), refined)

    def srgb_rmse(render: Tensor) -> float:
        return float((linear_to_srgb(render.clamp(0, 1)) - linear_to_srgb(target)).square().mean().sqrt())

    ambient = None
    if fit.log_ambient is not None:
        irradiance = _ambient_irradiance(fit.log_ambient.detach(), target.shape[-1]).mean(dim=(0, 2, 3))
        ambient = tuple(float(v) for v in irradiance)
    return RefineResult(
        maps=out[0].to(maps.dtype),
        steps=config.steps,
        seconds=time.perf_counter() - started,
        gain=tuple(float(v) for v in fit.log_gain.detach().exp().flatten()),  # type: ignore[arg-type]
        flash_offset=None
        if fit.flash_offset is None
        else tuple(float(v) for v in fit.flash_offset.detach()[0]),  # type: ignore[arg-type]
        ambient_mean=ambient,  # type: ignore[arg-type]
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
