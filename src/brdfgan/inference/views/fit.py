"""Fit one material to several flash photos of a flat surface (issue 47).

Every view arrives already in the reference photo's texture frame (warped by
:mod:`~brdfgan.inference.views.register`'s homography) with a ``seen`` mask, its camera and flash
positions in world units. In that frame the renderer's texture-space image *is* the forward model
of each view (:func:`~brdfgan.core.render.render_point_lights`: exact view and light directions
per texel; radiance does not depend on where it lands in the photo), so all views render in one
call per step.

:func:`fit_views` starts from the network's prediction of the reference and runs three stages:

0. **Gains alone.** Each view's RGB exposure gain on the prediction (the median ratio,
   :func:`~brdfgan.inference.refine.initial_log_gain`), and its residual (masked
   :func:`~brdfgan.inference.refine.photo_loss`). A view whose residual stands out
   (:func:`outlier_views`) — another surface, a bad registration — is dropped with its reason.
1. **Per-pixel fit, coarse to fine.** Every texel's parameters
   (:func:`~brdfgan.inference.refine.maps_to_parameters`: base-colour logits, normal slopes,
   roughness and metallic logits), one global logit offset per map (base colour, roughness,
   metallic, as :func:`~brdfgan.inference.refine.refine_maps` fits them) and each view's gain, by
   Adam at each working level (a short warm-up, then
   :func:`~brdfgan.inference.refine.cosine_decay`). The loss is the photo loss summed over views
   (unseen pixels masked out, clipped ones lower bounds), plus an L1 prior pulling the per-texel
   correction toward zero, weighted per texel by ``1 / (1 + views seeing it)`` (where views are
   few the prediction holds), plus the total variation of the slopes' and roughness's per-texel
   correction (a few views leave per-texel noise otherwise). The offsets are not held by the
   prior: a map's level is what every texel of every view measures. Texels no view sees keep the
   prediction exactly.
2. **Guard.** The best state of each level is kept; a non-finite loss or gradient, or a loss above
   ``spike_factor`` × the best, restores the best state and halves the learning rate. At the end,
   when the fitted views' photo loss is not below stage 0's, the prediction is returned
   (``kept="prediction"``).

The correction (in the fit's parameters) is carried to the prediction's own size with
:func:`~brdfgan.inference.refine.transfer_correction`. Settings:
:class:`~brdfgan.inference.views.config.ViewFitConfig`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.render import PointLights, render_point_lights
from brdfgan.core.svbrdf import check_map_shape, resize_maps
from brdfgan.inference.refine import (
    cosine_decay,
    initial_log_gain,
    maps_to_parameters,
    offset_parameters,
    parameters_to_maps,
    photo_loss,
    transfer_correction,
)
from brdfgan.inference.views.config import ViewFitConfig

Kept = Literal["fit", "prediction"]

# A working texel counts as seen when at least this share of its photo pixels is seen: a texel
# half outside a view would average the photo with whatever lies outside it.
SEEN_FRACTION = 0.999
# MAD → standard deviation for normal data; the spread floor, as a fraction of the median
# residual, keeps views that agree closely (a tiny MAD) from being dropped for noise.
MAD_TO_SIGMA = 1.4826
MIN_SPREAD_FRACTION = 0.1
# Adam's first steps move every parameter by about the full learning rate, whatever its gradient:
# on a level that starts near its optimum (the previous level's result, upsampled) that throws
# every texel off at once, so each level warms up over this share of its steps.
WARMUP_FRACTION = 0.1
# Parameter channels (refine.maps_to_parameters): base colour (3), slopes (2), roughness, metallic.
_SLOPES_AND_ROUGHNESS = slice(3, 6)


@dataclass(frozen=True)
class ViewRecord:
    """What the fit did with one view."""

    index: int
    coverage: float  # share of the reference's texels the view measures (finest working level)
    gain: tuple[float, float, float]  # the exposure gain, stage 0's for a dropped view
    residual_before: float  # photo loss of the prediction with stage 0's gain
    residual_after: float | None  # of the returned maps with the fitted gain; None when dropped
    dropped: str | None  # why the view was left out, None when fitted


@dataclass(frozen=True)
class ViewFitResult:
    """The fitted maps and the record of the fit (``material.json``'s ``view_fit`` entry)."""

    maps: Tensor  # (8, M, M), the prediction's size
    kept: Kept
    views: tuple[ViewRecord, ...]
    levels: tuple[int, ...]  # the working sizes actually used
    loss_curve: tuple[float, ...]  # total loss per step, all levels in turn
    loss_start: float  # the fitted views' summed photo loss, stage 0 (prediction)
    loss_end: float  # … and at the end of the fit (before the guard's choice)
    restores: int  # times the guard restored the best state
    seconds: float

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values; a non-finite number (a diverged step, a view that sees nothing) is ``null``."""
        out = {k: _json_number(v) for k, v in self.__dict__.items() if k not in ("maps", "views")}
        out["views"] = [{k: _json_number(v) for k, v in record.__dict__.items()} for record in self.views]
        out["levels"] = list(self.levels)
        out["loss_curve"] = [_json_number(v) for v in self.loss_curve]
        return out


def _json_number(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return list(value) if isinstance(value, tuple) else value


def _rgb(values: Tensor) -> tuple[float, float, float]:
    r, g, b = (float(v) for v in values.flatten())
    return r, g, b


# --- pure pieces ---------------------------------------------------------------------------------


def render_views(
    maps: Tensor, camera_position: Tensor, light_position: Tensor, plane_half_size: float
) -> Tensor:
    """The texture-space render of one map set for each view: its camera, one white point light of
    unit intensity (the per-view gain carries the flash's power and the exposure).

    Shape: maps ``(1, 8, H, W)``; camera_position, light_position ``(V, 3)`` → ``(V, 3, H, W)``."""
    views = camera_position.shape[0]
    lights = PointLights(
        position=light_position.to(maps).view(1, views, 1, 3),
        intensity=maps.new_ones(1, views, 1),
        color=maps.new_ones(1, views, 1, 3),
    )
    return render_point_lights(maps, camera_position.to(maps)[None], lights, plane_half_size)[0]


def view_residuals(render: Tensor, photos: Tensor, mask: Tensor, clip_level: float) -> Tensor:
    """Each view's :func:`~brdfgan.inference.refine.photo_loss` over its seen pixels.

    Shape: render, photos ``(V, 3, H, W)``; mask ``(V, 1, H, W)`` → ``(V,)``."""
    return torch.stack(
        [
            photo_loss(render[v : v + 1], photos[v : v + 1], clip_level, mask[v : v + 1])
            for v in range(render.shape[0])
        ]
    )


def outlier_views(residuals: Tensor, outlier_mads: float) -> Tensor:
    """Views whose residual exceeds ``median + outlier_mads · max(1.4826 · MAD, 0.1 · median)``
    (robust to the outliers themselves), and views whose residual is not finite. With two views
    or fewer nothing stands out: which one is wrong cannot be told.

    Shape: residuals ``(V,)`` → ``(V,)`` bool."""
    finite = torch.isfinite(residuals)
    if int(finite.sum()) <= 2:
        return ~finite
    values = residuals[finite]
    median = values.median()
    spread = torch.maximum(MAD_TO_SIGMA * (values - median).abs().median(), MIN_SPREAD_FRACTION * median)
    return ~finite | (residuals > median + outlier_mads * spread)


def total_variation(image: Tensor) -> Tensor:
    """Mean absolute difference between horizontally and vertically adjacent pixels, per channel,
    summed over channels.

    Shape: ``(B, C, H, W)`` → scalar."""
    across = (image[..., :, 1:] - image[..., :, :-1]).abs().mean(dim=(0, 2, 3))
    down = (image[..., 1:, :] - image[..., :-1, :]).abs().mean(dim=(0, 2, 3))
    return (across + down).sum()


def learning_rate_factor(step: int, steps: int) -> float:
    """A level's learning-rate factor at ``step``: a linear warm-up over its first
    :data:`WARMUP_FRACTION` of steps, times :func:`~brdfgan.inference.refine.cosine_decay`."""
    warmup = max(1.0, WARMUP_FRACTION * steps)
    return min(1.0, (step + 1) / warmup) * cosine_decay(step, steps)


def views_at_size(photos: Tensor, seen: Tensor, size: int, clip_level: float) -> tuple[Tensor, Tensor]:
    """The photos area-averaged to ``size`` and their masks: a texel is kept when (almost) all its
    pixels are seen and, if any of them is clipped, the average is still clipped (a mixed texel's
    average is neither a measurement nor a valid lower bound). Non-finite pixels count as unseen.

    Shape: photos ``(V, 3, R, R)``, seen ``(V, 1, R, R)`` → ``(V, 3, size, size)``, ``(V, 1, size, size)``."""
    usable = seen.to(photos.dtype) * torch.isfinite(photos).all(dim=1, keepdim=True)
    clean = torch.where(usable > 0, photos, torch.zeros((), dtype=photos.dtype, device=photos.device))
    clipped = (clean >= clip_level).any(dim=1, keepdim=True).to(photos.dtype)
    if photos.shape[-1] != size:
        clean = F.adaptive_avg_pool2d(clean, size)
        usable = F.adaptive_avg_pool2d(usable, size)
        clipped = F.adaptive_max_pool2d(clipped, size)
    still_clipped = (clean >= clip_level).any(dim=1, keepdim=True)
    mask = (usable >= SEEN_FRACTION) & ((clipped == 0) | still_clipped)
    return clean, mask.to(photos.dtype)


def coverage_prior_weight(mask: Tensor, config: ViewFitConfig) -> Tensor:
    """Per texel and parameter channel, the prior's weight: the map's weight over ``1 + the
    number of views that see the texel``.

    Shape: mask ``(V, 1, H, W)`` → ``(1, 7, H, W)``."""
    per_channel = mask.new_tensor(
        [config.prior_basecolor] * 3
        + [config.prior_slopes] * 2
        + [config.prior_roughness, config.prior_metallic]
    ).view(1, 7, 1, 1)
    return per_channel / (1.0 + mask.sum(dim=0, keepdim=True))


def working_levels(config: ViewFitConfig, largest: int) -> list[tuple[int, int]]:
    """``(size, steps)`` per level, sizes capped at ``largest``; levels that the cap makes equal
    are merged (their steps added)."""
    merged: list[tuple[int, int]] = []
    for size, steps in zip(config.levels, config.steps, strict=True):
        size = min(size, largest)
        if merged and merged[-1][0] == size:
            merged[-1] = (size, merged[-1][1] + steps)
        else:
            merged.append((size, steps))
    return merged


# --- the fit -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Scene:
    """The fixed inputs of one fit."""

    camera_position: Tensor  # (V, 3) of the fitted views
    light_position: Tensor  # (V, 3)
    plane_half_size: float
    clip_level: float


@dataclass(frozen=True)
class _Level:
    """One working size's data: the fitted views' photos and masks, the prediction's parameters,
    the prior's weights, and the texels some view sees."""

    photos: Tensor  # (V, 3, L, L)
    mask: Tensor  # (V, 1, L, L)
    prior: Tensor  # (1, 7, L, L)
    prior_weight: Tensor  # (1, 7, L, L)
    covered: Tensor  # (1, 1, L, L), 1 where a view sees the texel


def _level(prediction: Tensor, photos: Tensor, seen: Tensor, size: int, config: ViewFitConfig) -> _Level:
    small_photos, mask = views_at_size(photos, seen, size, config.clip_level)
    maps = resize_maps(prediction, size)[None] if prediction.shape[-1] != size else prediction[None]
    return _Level(
        photos=small_photos,
        mask=mask,
        prior=maps_to_parameters(maps),
        prior_weight=coverage_prior_weight(mask, config),
        covered=(mask.sum(dim=0, keepdim=True) > 0).to(mask.dtype),
    )


@dataclass(frozen=True)
class _FitState:
    """The unknowns of stage 1, as leaf tensors for the optimiser.

    Shape:
        - delta: ``(1, 7, L, L)``, the per-texel correction of the prediction's parameters
        - offsets: ``(1, 3, 1, 1)``, logits added everywhere to roughness, metallic and base colour
          (:func:`~brdfgan.inference.refine.offset_parameters`): the maps' levels, which the prior
          does not hold back (a wrong level is the prediction's commonest error, and every texel
          of every view measures it)
        - log_gain: ``(V, 3, 1, 1)``
    """

    delta: Tensor
    offsets: Tensor
    log_gain: Tensor

    def variables(self) -> list[Tensor]:
        return [self.delta, self.offsets, self.log_gain]

    def detached(self, requires_grad: bool = False) -> _FitState:
        return _FitState(*(t.detach().clone().requires_grad_(requires_grad) for t in self.variables()))

    def correction(self, covered: Tensor) -> Tensor:
        """The parameters' correction, zero where no view sees.

        Shape: covered ``(1, 1, L, L)`` → ``(1, 7, L, L)``."""
        return offset_parameters(self.delta, self.offsets, torch.ones_like(self.offsets)) * covered

    def at_size(self, size: int) -> _FitState:
        """The same state with ``delta`` resized (bilinearly) to ``size``²."""
        if self.delta.shape[-1] == size:
            return self
        delta = F.interpolate(self.delta, size=(size, size), mode="bilinear", align_corners=False)
        return _FitState(delta, self.offsets, self.log_gain)


def _objective(
    level: _Level, scene: _Scene, state: _FitState, config: ViewFitConfig
) -> tuple[Tensor, Tensor]:
    """The total loss and each view's photo loss (module docstring). The prior and the smoothness
    act on the per-texel correction only, not on the global offsets."""
    maps = parameters_to_maps(level.prior + state.correction(level.covered))
    render = render_views(maps, scene.camera_position, scene.light_position, scene.plane_half_size)
    residuals = view_residuals(render * state.log_gain.exp(), level.photos, level.mask, scene.clip_level)
    delta = state.delta * level.covered
    prior = (level.prior_weight * delta.abs()).sum(dim=1).mean()
    smoothness = config.tv_weight * total_variation(delta[:, _SLOPES_AND_ROUGHNESS])
    return residuals.sum() + prior + smoothness, residuals


@dataclass
class _Progress:
    """What the levels accumulate: the loss curve and the guard's restores."""

    curve: list[float]
    restores: int = 0


def _fit_level(
    level: _Level,
    scene: _Scene,
    start: _FitState,
    steps: int,
    config: ViewFitConfig,
    progress: _Progress,
    on_step: Callable[[int, float], None] | None,
) -> _FitState:
    """Adam on one level from ``start`` with the guard (module docstring); returns the best state
    seen."""
    state = start.detached(requires_grad=True)
    learning_rate = config.learning_rate
    optimizer = torch.optim.Adam(state.variables(), lr=learning_rate)
    best_loss, best = math.inf, state.detached()
    restores = 0
    for step in range(steps):
        for group in optimizer.param_groups:
            group["lr"] = learning_rate * learning_rate_factor(step, steps)
        loss, _ = _objective(level, scene, state, config)
        value = float(loss.detach())
        healthy = math.isfinite(value) and value <= config.spike_factor * best_loss
        if healthy:
            if value < best_loss:
                best_loss, best = value, state.detached()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            healthy = all(t.grad is None or bool(torch.isfinite(t.grad).all()) for t in state.variables())
        if not healthy:
            # Back to the best state, with fresh moments (a NaN may sit in Adam's) and half the rate.
            restores += 1
            progress.restores += 1
            with torch.no_grad():
                for variable, saved in zip(state.variables(), best.variables(), strict=True):
                    variable.copy_(saved)
            if restores > config.max_restores:
                break
            learning_rate /= 2
            optimizer = torch.optim.Adam(state.variables(), lr=learning_rate)
        else:
            optimizer.step()
        progress.curve.append(value)
        if on_step is not None:
            on_step(len(progress.curve), value)
    with torch.no_grad():  # the last update has not been scored yet
        value = float(_objective(level, scene, state, config)[0])
    return state.detached() if math.isfinite(value) and value < best_loss else best


def fit_views(
    photos: Tensor,
    seen: Tensor,
    camera_position: Tensor,
    light_position: Tensor,
    maps: Tensor,
    plane_half_size: float,
    config: ViewFitConfig | None = None,
    on_step: Callable[[int, float], None] | None = None,
) -> ViewFitResult:
    """Fit ``maps`` (the network's prediction of the reference view) to every view (module docstring).

    Args:
        photos: the views, linear, each warped into the reference's texture frame; any exposure
            and white balance (each view gets its own gain). Values outside ``seen`` are ignored.
            The first is the reference, the photo ``maps`` were predicted from.
        seen: 1 where the view sees the texel (0/1 or bool).
        camera_position, light_position: each view's camera and flash in world units, in the
            renderer's frame (the texture square is ``[-s, s]²`` of z = 0, row 0 at +Y).
        maps: the prediction.
        plane_half_size: ``s``.
        config: the fit's settings (default: ``ViewFitConfig()``).
        on_step: called after each step with ``(step, loss)``, steps counted over all levels.

    Shape:
        - photos: ``(V, 3, R, R)``; seen: ``(V, 1, R, R)``
        - camera_position, light_position: ``(V, 3)``
        - maps: ``(8, M, M)``; output maps: ``(8, M, M)``
    """
    _check_fit_inputs(photos, seen, camera_position, light_position, maps, plane_half_size)
    config = config or ViewFitConfig()
    # Lengths in half-sides of the square: the renders then have the level the start gain's
    # black-pixel floor and the photo loss's log floor are set for (a unit flash 20-50 cm from a
    # 10 cm sample renders below them). Scaling every length by 1/s scales every render by s²,
    # which each view's gain absorbs; the gains reported are those of this unit scene.
    camera_position = camera_position / plane_half_size
    light_position = light_position / plane_half_size
    started = time.perf_counter()
    device = maps.device
    prediction = maps.detach().float()
    photos = photos.detach().float().to(device)
    seen = seen.detach().float().to(device)
    schedule = working_levels(config, min(prediction.shape[-1], photos.shape[-1]))
    views = photos.shape[0]

    with torch.no_grad():  # no graph from the caller's positions into the fit's backward passes
        all_views = _Scene(camera_position.float(), light_position.float(), 1.0, config.clip_level)
    screening = _screen_views(prediction, photos, seen, all_views, schedule[-1][0], config)
    progress = _Progress(curve=[])
    if screening.fitted:
        outcome = _fit_coarse_to_fine(
            prediction, photos, seen, all_views, screening, schedule, config, progress, on_step
        )
    else:
        outcome = _FitOutcome(prediction.clone(), "prediction", math.nan, {}, screening.log_gain)

    records = tuple(
        ViewRecord(
            index=v,
            coverage=float(screening.coverage[v]),
            gain=_rgb(outcome.log_gain[v].exp()),
            residual_before=float(screening.residual_before[v]),
            residual_after=outcome.residual_after.get(v),
            dropped=screening.reasons[v],
        )
        for v in range(views)
    )
    return ViewFitResult(
        maps=outcome.maps.to(maps.dtype),
        kept=outcome.kept,
        views=records,
        levels=tuple(size for size, _ in schedule),
        loss_curve=tuple(progress.curve),
        loss_start=screening.loss_start,
        loss_end=outcome.loss_end,
        restores=progress.restores,
        seconds=time.perf_counter() - started,
    )


def _check_fit_inputs(
    photos: Tensor,
    seen: Tensor,
    camera_position: Tensor,
    light_position: Tensor,
    maps: Tensor,
    plane_half_size: float,
) -> None:
    """:func:`fit_views`'s arguments against its Shape section."""
    dims = check_shape(photos, "V 3 R R", name="photos")
    check_shape(seen, "V 1 R R", name="seen", dims=dims)
    check_shape(camera_position, "V 3", name="camera_position", dims=dims)
    check_shape(light_position, "V 3", name="light_position", dims=dims)
    check_map_shape(maps)
    check_shape(maps, "8 M M", name="square maps")
    if not plane_half_size > 0:
        raise ValueError(f"plane_half_size must be positive, got {plane_half_size}")


@dataclass(frozen=True)
class _Screening:
    """Stage 0, per view: its start log gain ``(V, 3, 1, 1)``, the share of the finest level it
    sees ``(V,)``, its residual on the prediction ``(V,)`` (NaN where it sees nothing) and the
    reason it is left out of the fit, or ``None``."""

    log_gain: Tensor
    coverage: Tensor
    residual_before: Tensor
    reasons: list[str | None]

    @property
    def fitted(self) -> list[int]:
        """The views stages 1 and 2 fit: those not left out."""
        return [v for v, reason in enumerate(self.reasons) if reason is None]

    @property
    def loss_start(self) -> float:
        """The fitted views' photo loss on the prediction; NaN when none is fitted."""
        fitted = self.fitted
        return float(self.residual_before[fitted].sum()) if fitted else math.nan


@torch.no_grad()
def _screen_views(
    prediction: Tensor, photos: Tensor, seen: Tensor, scene: _Scene, finest: int, config: ViewFitConfig
) -> _Screening:
    """Stage 0 at the finest level (``finest``²): gains on the prediction, residuals, outliers."""
    level = _level(prediction, photos, seen, finest, config)
    render = render_views(
        parameters_to_maps(level.prior), scene.camera_position, scene.light_position, scene.plane_half_size
    )
    # initial_log_gain skips black render pixels: zeroing the unseen ones leaves them out.
    masked_render = render * level.mask
    log_gain = torch.cat(
        [
            initial_log_gain(level.photos[v : v + 1], masked_render[v : v + 1], config.clip_level)
            for v in range(photos.shape[0])
        ]
    )
    coverage = level.mask.mean(dim=(1, 2, 3))
    residual_before = view_residuals(render * log_gain.exp(), level.photos, level.mask, config.clip_level)
    # A view that sees nothing has no residual (photo_loss would say 0, the best of all).
    residual_before = torch.where(coverage > 0, residual_before, math.nan)
    return _Screening(log_gain, coverage, residual_before, _drop_reasons(residual_before, coverage, config))


@dataclass(frozen=True)
class _FitOutcome:
    """Stages 1 and 2: the maps returned (the fit, or a copy of the prediction), which one, the
    fitted views' photo loss at the end (NaN without a fit), their residuals on the maps returned
    and every view's log gain."""

    maps: Tensor
    kept: Kept
    loss_end: float
    residual_after: dict[int, float]
    log_gain: Tensor


def _fit_coarse_to_fine(
    prediction: Tensor,
    photos: Tensor,
    seen: Tensor,
    all_views: _Scene,
    screening: _Screening,
    schedule: list[tuple[int, int]],
    config: ViewFitConfig,
    progress: _Progress,
    on_step: Callable[[int, float], None] | None,
) -> _FitOutcome:
    """Stages 1 and 2 on the views ``screening`` kept (module docstring): the fit is returned when
    it lowers their photo loss below stage 0's by the share ``config.min_improvement``."""
    fitted = screening.fitted
    index = torch.tensor(fitted, device=prediction.device)
    scene = _Scene(
        all_views.camera_position[index],
        all_views.light_position[index],
        all_views.plane_half_size,
        config.clip_level,
    )
    size = schedule[0][0]
    state = _FitState(
        delta=torch.zeros(1, 7, size, size, device=prediction.device),
        offsets=torch.zeros(1, 3, 1, 1, device=prediction.device),
        log_gain=screening.log_gain[index],
    )
    with torch.enable_grad():
        for size, steps in schedule:
            level = _level(prediction, photos[index], seen[index], size, config)
            state = _fit_level(level, scene, state.at_size(size), steps, config, progress, on_step)
    with torch.no_grad():
        correction = state.correction(level.covered)
        _, residuals = _objective(level, scene, state, config)
        loss_end = float(residuals.sum())
        if math.isfinite(loss_end) and loss_end < screening.loss_start * (1.0 - config.min_improvement):
            log_gain = screening.log_gain.clone()
            log_gain[index] = state.log_gain
            return _FitOutcome(
                _at_prediction_size(prediction, level, correction, seen[index]),
                "fit",
                loss_end,
                {v: float(r) for v, r in zip(fitted, residuals, strict=True)},
                log_gain,
            )
    # The prediction is returned: so are its residuals and gains.
    residual_before = {v: float(screening.residual_before[v]) for v in fitted}
    return _FitOutcome(prediction.clone(), "prediction", loss_end, residual_before, screening.log_gain)


def _drop_reasons(residuals: Tensor, coverage: Tensor, config: ViewFitConfig) -> list[str | None]:
    """Per view, the one-line reason to leave it out of the fit, or ``None``. The first view, the
    reference the prediction was made from, is never an outlier: its residual is the prediction's
    own error, and without it nothing ties the fit to the photo the material is framed on."""
    outliers = outlier_views(residuals, config.outlier_mads)
    finite = residuals[torch.isfinite(residuals)]
    median = float(finite.median()) if finite.numel() else math.nan
    reasons: list[str | None] = []
    for v in range(residuals.shape[0]):
        if float(coverage[v]) == 0.0:
            reasons.append("sees no texel of the reference")
        elif not math.isfinite(float(residuals[v])):
            reasons.append("its residual against the prediction is not finite")
        elif bool(outliers[v]) and v > 0:
            reasons.append(
                f"residual {float(residuals[v]):.3f} against the prediction stands out "
                f"(median {median:.3f}): another surface or a bad registration"
            )
        else:
            reasons.append(None)
    return reasons


def _at_prediction_size(prediction: Tensor, level: _Level, correction: Tensor, seen: Tensor) -> Tensor:
    """The prediction with the fitted correction carried to its size
    (:func:`~brdfgan.inference.refine.transfer_correction`); texels no view sees keep the prediction.

    Shape: prediction ``(8, M, M)``; correction ``(1, 7, L, L)``; seen ``(V, 1, R, R)`` → ``(8, M, M)``."""
    before = parameters_to_maps(level.prior)
    after = parameters_to_maps(level.prior + correction)
    size = prediction.shape[-1]
    same_size = size == level.prior.shape[-1]
    fitted = after if same_size else transfer_correction(prediction[None], before, after)
    coverage = seen.amax(dim=0, keepdim=True)
    if coverage.shape[-1] != size:
        coverage = F.interpolate(coverage, size=(size, size), mode="bilinear", align_corners=False)
    return torch.where(coverage > 0.5, fitted, prediction[None])[0]
