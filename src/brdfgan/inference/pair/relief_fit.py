"""A flash + no-flash pair → the surface's relief, by a fit that needs no training (issue 59).

The two photos of one surface differ only in their light. Where the surface is diffuse, each
photo is the albedo times a shading: the flash-only image (the flash photo less the room light,
:mod:`brdfgan.inference.pair.intake`) ``F = g · A · S_f(n)`` with the head-on flash's shading
``S_f(n) = max(n·l, 0) / d²`` (``l`` towards the flash at the lens, ``d`` the distance in camera
distances, :func:`~brdfgan.core.delit.flash_render`'s geometry), and the room light's share of the
flash photo ``R = A · E(n)`` with ``E`` the room's irradiance, a low-order function of the normal
(real spherical harmonics to order 2: a sky, a window, a lamp to the side). Their ratio cancels
the albedo:

    log R − log F = log E(n) − log S_f(n) − log g,

one equation per pixel and channel in the surface normal, in which the room light's side-lit
shading is first order in the slope where the flash's, at its hotspot, is second order. The fit
(:func:`fit_pair`) finds the height ``h`` whose normals ``n ∝ (−∂h/∂x, −∂h/∂y, 1)`` (+y up the rows,
:func:`~brdfgan.core.height.height_slope_channels`) and the harmonics' 9 × 3 coefficients (``g``
folded in) that explain the ratio, by Adam on a robust (Charbonnier) loss, coarse to fine, with

- a height, not two free slopes per pixel: integrable normals, and masked pixels filled smoothly;
- a prior toward flat (the slopes' squares) where the ratio constrains little;
- glints and metal masked: where the network's maps make the flash's specular lobe a large share
  of the flat render, or the metallic map is metal, the photo is not ``A · S_f``;
- a guard on pixels the fit never saw: a fifth of the finest level's pixels are held out, and three
  reliefs are scored on them, each with the room light refitted for it: a flat surface, the
  network's normals and the fitted relief. The one with the lowest residual is kept when it lowers
  the flat surface's by :attr:`PairFitConfig.min_improvement` (``kept="fit"`` or
  ``"prediction"``); otherwise the normals are flat (``kept="flat"``), as they are when no pixel
  could be held out (all masked). On the fitted pixels alone, a relief fitted to noise would
  pass; and the network's own normals are not a safe default: on the near-flat scan test set v4
  draws relief turned against the truth (slope cosine −0.6), which the pair's ratio refutes.
- a check of the fit's sign: with one room-light direction dominant, a relief and its mirror image
  (height negated) under the light turned 180° (:func:`turned_light`) have the same first-order
  shading, and only the flash's oblique and second-order shading tells them apart. The guard
  scores the fitted relief turned over too, and keeps the fit only where that leaves
  :attr:`PairFitConfig.min_sign_margin` more of the held-out residual: a wood floor's grain was
  fitted turned over (normals' slopes correlating with the truth's at −0.6) with its negation
  explaining the held-out pixels within 0.5 %.
- the material's own share of the ratio given to every relief the guard scores
  (:attr:`PairFitConfig.guard_with_maps`): the ratio also varies with what the diffuse model
  lacks, the room's reflections and the flash's residual specular, and those follow the material
  (brighter where the surface is darker, stronger where it is glossier), not the relief. A relief
  fitted to them lowers the held-out residual of a flat surface that has no such terms, so each
  relief is scored with the room light *and* a per-channel linear term in the network's roughness
  and log base-colour luminance (:func:`material_confounds`) refitted for it: a relief is kept for
  what it explains beyond the material's maps. On the validation procedural pairs this turned
  away a fit that lowered the plain residual by 40 % on a surface 0.6° from flat (drawing 1.4°).

The kept relief is then written into a network's maps (``written``; by default the maps the fit
read, those of the flash-only image): their normals replaced, their base colour divided by the
relief's shading ratio ``S_f(n)/S_f(flat)`` when the fitted relief is kept (the flash shading taken
out, as the fit found it), roughness and metallic as they are. ``brdfgan predict --no-flash``
writes it into the network's reading of the flash photo, whose base colour, roughness and metallic
were better on validation pairs than the flash-only image's, while the fit itself reads the
flash-only image's maps (its masks, guard terms and the ``"prediction"`` candidate), with which
validation chose the fit's settings. The fit runs at the levels' sizes (at most the maps'), and
its height is carried up to the maps' size.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Literal, TypeVar

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.brdf import evaluate_brdf
from brdfgan.core.checks import check_shape
from brdfgan.core.delit import flash_directions
from brdfgan.core.exposure import luminance
from brdfgan.core.flash_geometry import check_flash_frame, resize_flash_frame
from brdfgan.core.height import height_slope_channels
from brdfgan.core.render import linear_basecolor_maps
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, NORMAL, ROUGHNESS, check_map_shape, linear_to_srgb
from brdfgan.inference.refine import cosine_decay

Kept = Literal["fit", "prediction", "flat"]
# The reliefs the guard scores: the ones it may keep, and the fitted relief turned over.
Scored = Literal["fit", "prediction", "flat", "turned"]
ReliefName = TypeVar("ReliefName", bound=str)  # a relief's name in held_out_residuals

# Real spherical harmonics to order 2, the constants of Ramamoorthi & Hanrahan 2001: irradiance
# from any distant light is within a few per cent of its projection on these nine.
_SH_CONSTANTS = (0.282095, 0.488603, 0.488603, 0.488603, 1.092548, 1.092548, 0.315392, 1.092548, 0.546274)
SH_TERMS = len(_SH_CONSTANTS)
# Below this (linear, of the flash photo's range) a photo's value is noise: left out of the ratio.
VALUE_FLOOR = 2e-3
# The share of the finest level's pixels the guard holds out (module docstring), drawn from a fixed
# seed so that a fit is repeatable.
HOLDOUT_FRACTION = 0.2
HOLDOUT_SEED = 59
# Charbonnier's ε, in log units: residuals beyond ~0.05 count linearly (glints, shadows the model
# lacks), below quadratically.
ROBUST_EPSILON = 0.05


@dataclass(frozen=True)
class PairFitConfig:
    """The pair fit's settings (module docstring)."""

    levels: tuple[int, ...] = (64, 128, 256)
    steps: tuple[int, ...] = (200, 150, 100)
    learning_rate: float = 0.02
    # Weight of the slopes' mean square (tan² of the tilt). This and min_roughness were chosen on
    # the validation split's pairs (research/pair_fit_table.py; docs/predict.md has the table): at
    # 0.02-0.2 the fit drew relief on the near-flat glossy procedural materials.
    flat_prior: float = 1.0
    specular_share: float = 0.3  # a pixel whose flat flash render is more than this specular is masked
    metal_level: float = 0.5  # … as is one the network calls metal
    # … and one glossier than this: a glossy surface mirrors the room's lamps and windows into the
    # no-flash photo, which the diffuse model would read as relief
    min_roughness: float = 0.5
    # The relative drop of the held-out residual a relief must bring to be kept, chosen on the
    # validation split's Mitsuba pairs with research/pair_guard.py (procedural 1.001×, scans 0.997×
    # a flat map's angle; at 0.02 the fits and the network's relief kept put them at 1.035×, 0.983×).
    min_improvement: float = 0.15
    # The share of the held-out residual by which the fitted relief must beat itself turned over
    # to be kept (choose_relief): the largest that keeps every fit the guard passes on the
    # validation and training splits' Mitsuba pairs (research/pair_guard.py; their margins were
    # 0.047-0.52; at 0.05 validation loses a good fit).
    min_sign_margin: float = 0.02
    # Score the guard's reliefs with the material's own share of the ratio (module docstring).
    guard_with_maps: bool = True

    def __post_init__(self) -> None:
        if len(self.levels) != len(self.steps) or not self.levels:
            raise ValueError(f"levels {self.levels} and steps {self.steps}: one count per level")
        if list(self.levels) != sorted(set(self.levels)) or self.levels[0] < 8:
            raise ValueError(f"levels {self.levels}: increasing sizes of at least 8")


@dataclass(frozen=True)
class PairFitResult:
    """The maps with the fitted relief, and the record of the fit (``material.json``'s ``pair_fit``)."""

    maps: Tensor  # (8, N, N)
    kept: Kept
    height: Tensor  # (1, 1, n, n) the fitted relief in the finest level's pixel units, kept or not
    residual_flat: float  # the ratio's robust residual of a flat surface on the held-out pixels
    residual_fit: float  # … of the fitted relief
    residual_prediction: float  # … of the network's normals
    residual_turned: float  # … of the fitted relief turned over (its height negated)
    masked_fraction: float  # share of pixels the ratio could not use (invalid, glint, metal, dark)
    room_light: tuple[tuple[float, ...], ...]  # 3 × 9 harmonic coefficients (relative to the flash)
    levels: tuple[int, ...]
    seconds: float
    settings: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = {k: v for k, v in asdict(self).items() if k not in ("maps", "height", "room_light", "levels")}
        out["room_light"] = [list(row) for row in self.room_light]
        out["levels"] = list(self.levels)
        return out


# --- pure pieces -----------------------------------------------------------------------------------


def sh_basis(normal: Tensor) -> Tensor:
    """The nine real harmonics of order ≤ 2 at each unit normal.

    Shape: ``(B, 3, H, W)`` → ``(B, 9, H, W)``.

    Example:
        Straight up, only the constant, ``z`` and ``3z² − 1`` terms are non-zero:

        >>> up = torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1)
        >>> [round(v, 4) for v in sh_basis(up).flatten().tolist()]
        [0.2821, 0.0, 0.4886, 0.0, 0.0, 0.0, 0.6308, 0.0, 0.0]
    """
    check_shape(normal, "B 3 H W", name="normal")
    x, y, z = normal.unbind(1)
    terms = (torch.ones_like(x), y, z, x, x * y, y * z, 3 * z * z - 1, x * z, x * x - y * y)
    return torch.stack([c * t for c, t in zip(_SH_CONSTANTS, terms, strict=True)], dim=1)


def normals_of_height(height: Tensor) -> Tensor:
    """Unit normals of a height in pixel units (a rise of 1 over one pixel is 45°).

    Shape: ``(B, 1, n, n)`` → ``(B, 3, n, n)``."""
    normal = torch.cat([height_slope_channels(height), torch.ones_like(height)], dim=1)
    return normal / normal.norm(dim=1, keepdim=True)


def flash_shading(normal: Tensor, frame: Tensor) -> Tensor:
    """The head-on flash's diffuse shading ``max(n·l, 0) / d²`` (module docstring).

    Shape: normal ``(B, 3, H, W)``, frame ``(B, 3)`` → ``(B, 1, H, W)``."""
    towards_flash, distance_squared = flash_directions(
        frame.to(normal.dtype), normal.shape[-2], normal.shape[-1]
    )
    return (normal * towards_flash).sum(dim=1, keepdim=True).clamp_min(1e-4) / distance_squared


def usable_ratio_mask(
    flash_only: Tensor, room: Tensor, valid: Tensor, maps: Tensor, frame: Tensor, config: PairFitConfig
) -> Tensor:
    """Where the ratio of the room light to the flash is the diffuse model's: valid, above the
    noise floor in both, not a glint of the flash's specular lobe, not metal.

    Shape: ``(3, N, N)``, ``(3, N, N)``, ``(1, N, N)``, ``(8, N, N)``, ``(1, 3)`` → ``(1, N, N)`` float."""
    flat = torch.zeros_like(maps[NORMAL])
    flat[2] = 1.0
    towards = flash_directions(frame, maps.shape[-2], maps.shape[-1])[0][0]
    basecolor = linear_basecolor_maps(maps[None])[0][BASECOLOR]
    lobes = [
        evaluate_brdf(
            basecolor,
            flat,
            maps[ROUGHNESS],
            maps[METALLIC],
            towards,
            towards,
            diffuse_lobe=diffuse,
            specular_lobe=not diffuse,
        ).mean(0)
        for diffuse in (True, False)
    ]
    specular = lobes[1] / (lobes[0] + lobes[1]).clamp_min(1e-8)
    bright = (flash_only.min(0).values > VALUE_FLOOR) & (room.min(0).values > VALUE_FLOOR)
    usable = (
        (valid[0] > 0.5)
        & bright
        & (specular < config.specular_share)
        & (maps[METALLIC][0] < config.metal_level)
        & (maps[ROUGHNESS][0] >= config.min_roughness)
    )
    return usable.float()[None]


def pair_log_ratio(flash_only: Tensor, room: Tensor) -> Tensor:
    """``log R − log F``, the ratio the fit explains (module docstring), each photo floored at
    :data:`VALUE_FLOOR`. Shape: ``(3, N, N)``, ``(3, N, N)`` → ``(3, N, N)``."""
    return room.clamp_min(VALUE_FLOOR).log() - flash_only.clamp_min(VALUE_FLOOR).log()


# Adam steps of each guard refit (the room light and the material terms for one relief): as many as
# the default's finest level, whatever the fit's own steps (a refit of a few steps moves a light
# that was already fitted away from it).
GUARD_STEPS = 100


def material_confounds(maps: Tensor, usable: Tensor) -> Tensor:
    """The guard's material terms (module docstring): the network's roughness and the log of its
    linear base colour's luminance, each standardised over the ``usable`` pixels (all where none
    is), so that their coefficients are on one scale and apart from the room light's constant.

    Shape: maps ``(8, N, N)``, usable ``(1, N, N)`` → ``(2, N, N)``.

    Example:
        >>> maps = torch.zeros(8, 2, 2)
        >>> maps[ROUGHNESS] = torch.tensor([[0.2, 0.4], [0.6, 0.8]])
        >>> material_confounds(maps, torch.ones(1, 2, 2))[0].mean().abs() < 1e-6
        tensor(True)
    """
    check_map_shape(maps)
    linear = linear_basecolor_maps(maps[None])[0][BASECOLOR]
    channels = torch.stack([maps[ROUGHNESS][0], luminance(linear)[0].clamp_min(VALUE_FLOOR).log()])
    used = usable[0] > 0.5
    if not bool(used.any()):
        used = torch.ones_like(used)
    values = channels[:, used]
    mean, spread = values.mean(dim=1), values.std(dim=1).nan_to_num(0.0).clamp_min(1e-6)
    return (channels - mean.view(-1, 1, 1)) / spread.view(-1, 1, 1)


def _robust(residual: Tensor) -> Tensor:
    return (residual.square() + ROBUST_EPSILON**2).sqrt() - ROBUST_EPSILON


def _downsample(image: Tensor, size: int) -> Tensor:
    return image if image.shape[-1] == size else F.interpolate(image, size=(size, size), mode="area")


@dataclass
class _Level:
    """One working size's fixed inputs."""

    log_ratio: Tensor  # (1, 3, n, n)
    weight: Tensor  # (1, 1, n, n), 1 where the ratio is used
    frame: Tensor  # (1, 3)
    # (1, K, n, n) material terms (material_confounds) whose per-channel coefficients follow the
    # light's SH_TERMS columns; None: the light has the harmonics alone
    confounds: Tensor | None = None

    @classmethod
    def of(
        cls, log_ratio: Tensor, usable: Tensor, frame: Tensor, size: int, confounds: Tensor | None = None
    ) -> _Level:
        weight = _downsample(usable[None], size)

        def average(image: Tensor) -> Tensor:
            return _downsample(image[None] * usable[None], size) / weight.clamp_min(1e-6)

        return cls(
            average(log_ratio),
            (weight > 0.999).float(),
            resize_flash_frame(frame, size / log_ratio.shape[-1]),
            None if confounds is None else average(confounds),
        )

    def split(self) -> tuple[_Level, _Level]:
        """This level's pixels as the ones fitted and the ones held out (:data:`HOLDOUT_FRACTION`)."""
        generator = torch.Generator().manual_seed(HOLDOUT_SEED)
        held = (torch.rand(self.weight.shape, generator=generator) < HOLDOUT_FRACTION).float()
        return replace(self, weight=self.weight * (1 - held)), replace(self, weight=self.weight * held)

    def residual(self, height: Tensor, light: Tensor) -> Tensor:
        """The mean robust residual of the ratio model over the used pixels."""
        return self.residual_of_normals(normals_of_height(height), light)

    def residual_of_normals(self, normal: Tensor, light: Tensor) -> Tensor:
        """:meth:`residual` for unit normals ``(1, 3, n, n)`` at this level's size; ``light`` is
        ``(3, SH_TERMS)``, or ``(3, SH_TERMS + K)`` with the material terms' coefficients."""
        irradiance = torch.einsum("ck,bkhw->bchw", light[:, :SH_TERMS], sh_basis(normal)).clamp_min(1e-4)
        model = irradiance.log() - flash_shading(normal, self.frame).log()
        if self.confounds is not None:
            model = model + torch.einsum("ck,bkhw->bchw", light[:, SH_TERMS:], self.confounds)
        return (_robust(model - self.log_ratio) * self.weight).sum() / (3 * self.weight.sum().clamp_min(1))


# The height's correction at a level is a pyramid of grids this many octaves deep, summed after
# enlarging: Adam moves every grid's values alike, so broad relief converges as fast as fine.
PYRAMID_OCTAVES = 5


def _pyramid_height(start: Tensor, grids: list[Tensor]) -> Tensor:
    size = start.shape[-1]
    enlarged = [F.interpolate(g, size=(size, size), mode="bilinear", align_corners=False) for g in grids]
    return start + torch.stack(enlarged).sum(0)


def _fit_level(
    level: _Level,
    start: Tensor,
    light: Tensor,
    steps: int,
    config: PairFitConfig,
) -> tuple[Tensor, Tensor]:
    """Adam on the room light and a pyramid correction of the height ``start`` (pixel units) at
    one working size; the height is returned with its mean (a ramp-free sample's) removed."""
    size = start.shape[-1]
    grids = [
        torch.zeros(1, 1, max(size >> octave, 2), max(size >> octave, 2), requires_grad=True)
        for octave in range(PYRAMID_OCTAVES)
    ]
    light = light.detach().clone().requires_grad_(True)
    optimizer = torch.optim.Adam([light, *grids], lr=config.learning_rate)
    for step in range(steps):
        for group in optimizer.param_groups:
            group["lr"] = config.learning_rate * cosine_decay(step, steps)
        optimizer.zero_grad()
        height = _pyramid_height(start, grids)
        slopes = height_slope_channels(height)
        loss = level.residual(height, light) + config.flat_prior * slopes.square().mean()
        loss.backward()
        optimizer.step()
    with torch.no_grad():
        height = _pyramid_height(start, grids)
    return height - height.mean(), light.detach()


def _fit_light(level: _Level, normal: Tensor, light: Tensor, steps: int, config: PairFitConfig) -> Tensor:
    """Adam on the room light alone, for fixed unit normals ``(1, 3, n, n)`` at the level's size."""
    light = light.detach().clone().requires_grad_(True)
    optimizer = torch.optim.Adam([light], lr=config.learning_rate)
    for step in range(steps):
        for group in optimizer.param_groups:
            group["lr"] = config.learning_rate * cosine_decay(step, steps)
        optimizer.zero_grad()
        level.residual_of_normals(normal, light).backward()
        optimizer.step()
    return light.detach()


def _working_normals(normal: Tensor, size: int) -> Tensor:
    """A normal map ``(3, N, N)`` area-averaged to ``size`` and made unit again: ``(1, 3, n, n)``."""
    small = _downsample(normal[None].float(), size)
    return small / small.norm(dim=1, keepdim=True).clamp_min(1e-8)


def _initial_light(level: _Level, height: Tensor) -> Tensor:
    """The constant harmonic that explains the median ratio over a flat surface."""
    with torch.no_grad():
        shading = flash_shading(normals_of_height(height), level.frame)
        used = level.weight[0, 0] > 0
        light = torch.zeros(3, SH_TERMS)
        for channel in range(3):
            ratio = (level.log_ratio[0, channel] + shading[0, 0].log())[used]
            light[channel, 0] = (
                ratio.median().exp() if ratio.numel() else torch.tensor(1.0)
            ) / _SH_CONSTANTS[0]
    return light


def fit_pair(
    flash_only: Tensor,
    room: Tensor,
    valid: Tensor,
    maps: Tensor,
    frame: Tensor,
    config: PairFitConfig | None = None,
    on_step: Callable[[int, int], None] | None = None,
    *,
    written: Tensor | None = None,
) -> PairFitResult:
    """The relief that explains a pair's ratio (module docstring), written into ``written``.

    Args:
        flash_only: the flash photo less the room light, linear (any exposure).
        room: the room light's share of the flash photo (the registered no-flash photo times the
            exposure ratio and white-balance gains), linear, in ``flash_only``'s units.
        valid: 1 where both photos are usable (seen, unclipped).
        maps: the network's maps from the flash-only image: the glint and metal masks, the
            guard's material terms and its ``"prediction"`` candidate (their normals) come from them.
        frame: the flash frame of these pixels.
        config: the settings (default ``PairFitConfig()``).
        on_step: called with ``(step, of steps)`` over all levels.
        written: the maps the kept relief is written into (default ``maps``), e.g. the network's
            reading of the flash photo (module docstring).

    Shape:
        - flash_only, room: ``(3, N, N)``; valid: ``(1, N, N)``; maps, written: ``(8, N, N)``
          (or both larger); frame: ``(1, 3)``
        - output maps: ``(8, N, N)``
    """
    started = time.perf_counter()
    config = config or PairFitConfig()
    size = check_shape(flash_only, "3 N N", name="flash_only")["N"]
    check_shape(room, "3 N N", name="room", dims={"N": size})
    check_shape(valid, "1 N N", name="valid", dims={"N": size})
    check_map_shape(maps)
    if written is not None:
        check_shape(written, "8 H W", name="written", dims={"H": maps.shape[-2], "W": maps.shape[-1]})
    check_flash_frame(frame, 1)
    flash_only, room, valid, maps, frame = (
        t.detach().float() for t in (flash_only, room, valid, maps, frame)
    )
    written = maps if written is None else written.detach().float()
    usable = usable_ratio_mask(flash_only, room, valid, maps, frame, config)
    log_ratio = pair_log_ratio(flash_only, room)
    sizes = [min(level, size) for level in config.levels]
    total, done = sum(config.steps), 0
    height = torch.zeros(1, 1, sizes[0], sizes[0])  # pixel units of the working size
    light = _initial_light(_Level.of(log_ratio, usable, frame, sizes[0]), height)
    flat_light = light
    fitted, held_out = _Level.of(log_ratio, usable, frame, sizes[-1]).split()
    for level_size, steps in zip(sizes, config.steps, strict=True):
        # The finest level fits its pixels less the held-out ones; coarser levels average them in.
        level = fitted if level_size == sizes[-1] else _Level.of(log_ratio, usable, frame, level_size)
        # Twice the pixels across: the same rise is twice as many (smaller) pixels high.
        height = _enlarge(height, level_size)
        flat = normals_of_height(torch.zeros_like(height))
        flat_light = _fit_light(level, flat, flat_light, steps, config)
        height, light = _fit_level(level, height, light, steps, config)
        done += steps
        if on_step is not None:
            on_step(done, total)
    network_normals = _working_normals(maps[NORMAL], sizes[-1])
    network_light = _fit_light(fitted, network_normals, flat_light, config.steps[-1], config)
    candidates: dict[Scored, tuple[Tensor, Tensor]] = {
        "flat": (normals_of_height(torch.zeros_like(height)), flat_light),
        "fit": (normals_of_height(height), light),
        "prediction": (network_normals, network_light),
        "turned": (normals_of_height(-height), turned_light(light)),
    }
    if config.guard_with_maps:
        # Every relief scored with the material's own share of the ratio refitted for it.
        confounds = material_confounds(maps, usable)
        fitted, held_out = _Level.of(log_ratio, usable, frame, sizes[-1], confounds).split()
        residuals = held_out_residuals(fitted, held_out, candidates, GUARD_STEPS, config)
    else:
        residuals = held_out_residuals(fitted, held_out, candidates, 0, config)
    kept = choose_relief(residuals, config.min_improvement, config.min_sign_margin)
    if kept == "fit":
        result = with_relief(written, height, frame)
    else:
        result = written.clone()
        result[NORMAL] = maps[NORMAL] if kept == "prediction" else torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1)
    return PairFitResult(
        maps=result,
        kept=kept,
        height=height,
        residual_flat=residuals["flat"],
        residual_fit=residuals["fit"],
        residual_prediction=residuals["prediction"],
        residual_turned=residuals["turned"],
        masked_fraction=float(1 - usable.mean()),
        room_light=tuple(tuple(round(float(v), 6) for v in row) for row in light),
        levels=tuple(dict.fromkeys(sizes)),
        seconds=time.perf_counter() - started,
        settings=asdict(config),
    )


def held_out_residuals(
    fitted: _Level,
    held_out: _Level,
    reliefs: Mapping[ReliefName, tuple[Tensor, Tensor]],
    steps: int,
    config: PairFitConfig,
) -> dict[ReliefName, float]:
    """The guard's score of each relief (module docstring): its unit normals ``(1, 3, n, n)`` and
    starting room light ``(3, SH_TERMS)``; the light — and the material terms from 0, where the
    levels carry them — refitted on ``fitted`` for ``steps`` (0: as given), then the robust
    residual on ``held_out``."""
    out: dict[ReliefName, float] = {}
    for name, (normal, start) in reliefs.items():
        if fitted.confounds is not None:
            start = torch.cat([start, torch.zeros(3, fitted.confounds.shape[1])], 1)
        light = _fit_light(fitted, normal, start, steps, config)
        with torch.no_grad():
            out[name] = float(held_out.residual_of_normals(normal, light))
    return out


def choose_relief(
    residuals: Mapping[Scored, float], min_improvement: float, min_sign_margin: float = 0.0
) -> Kept:
    """The relief the held-out residuals support (module docstring): the lowest of the fit's and
    the network's when it lowers the flat surface's by ``min_improvement``, else ``"flat"`` (also
    when the flat residual is 0: nothing was held out). The fit is a candidate only where its
    relief turned over (``"turned"``) leaves at least ``min_sign_margin`` more of the residual:
    else the ratio does not tell the relief from its mirror image, and its sign is a guess.

    Example:
        >>> choose_relief({"flat": 1.0, "fit": 0.5, "prediction": 0.9, "turned": 0.8}, 0.02, 0.05)
        'fit'
        >>> choose_relief({"flat": 1.0, "fit": 0.5, "prediction": 0.9, "turned": 0.51}, 0.02, 0.05)
        'prediction'
        >>> choose_relief({"flat": 1.0, "fit": 1.2, "prediction": 0.99, "turned": 1.5}, 0.02)
        'flat'
    """
    candidates: tuple[Kept, ...] = ("prediction",)
    if residuals["turned"] >= (1 + min_sign_margin) * residuals["fit"]:
        candidates = ("fit", "prediction")
    best = min(candidates, key=lambda name: residuals[name])
    if residuals["flat"] > 0 and residuals[best] < (1 - min_improvement) * residuals["flat"]:
        return best
    return "flat"


def turned_light(light: Tensor) -> Tensor:
    """The room light that lights a relief turned over (height negated, slopes ``(x, y) → (−x, −y)``)
    as ``light`` lights the relief: the light turned 180° about the normal's axis, i.e. the
    harmonics odd in ``(x, y)`` (``y``, ``x``, ``yz``, ``xz``) negated. Its first-order shading is
    the relief's; the flash's, second order and centred, is not, and tells the two apart.

    Shape: ``(3, SH_TERMS + K)`` → same (material terms, if any, kept).

    Example:
        >>> turned_light(torch.arange(9.0).view(1, 9))[0].tolist()
        [0.0, -1.0, 2.0, -3.0, 4.0, -5.0, 6.0, -7.0, 8.0]
    """
    out = light.clone()
    out[:, [1, 3, 5, 7]] *= -1
    return out


def _enlarge(height: Tensor, size: int) -> Tensor:
    """A height in pixel units at another size, in that size's pixel units."""
    if height.shape[-1] == size:
        return height
    scale = size / height.shape[-1]
    return F.interpolate(height, size=(size, size), mode="bicubic", align_corners=False) * scale


def with_relief(maps: Tensor, height: Tensor, frame: Tensor) -> Tensor:
    """``maps`` with the normals of ``height`` (pixel units, carried up to the maps' size) and the
    base colour divided by the relief's flash shading over a flat surface's (module docstring).

    Shape: ``(8, N, N)``, ``(1, 1, n, n)``, ``(1, 3)`` → ``(8, N, N)``."""
    normal = normals_of_height(_enlarge(height, maps.shape[-1]))
    flat = torch.zeros_like(normal)
    flat[:, 2] = 1.0
    relief_shading = flash_shading(normal, frame) / flash_shading(flat, frame)
    out = maps.clone()
    out[NORMAL] = normal[0]
    linear = linear_basecolor_maps(maps[None])[0][BASECOLOR] / relief_shading[0].clamp(0.25, 4.0)
    out[BASECOLOR] = linear_to_srgb(linear.clamp(0.0, 1.0))
    return out
