"""High-resolution inference with bounded memory: overlapping tiles with frozen InstanceNorm statistics.

The generator is fully convolutional, so any photo whose sides are multiples of its ``size_multiple``
can go through it in one pass; but activations grow with the pixel count (one 64-channel feature map
of the paper generator takes 1 GiB at 2048²). :func:`predict_maps` runs small photos directly and
large ones tile by tile.

**Why tiles need frozen statistics.** Every ``InstanceNorm2d`` normalises with the per-channel mean
and variance of its *whole* input. Run tile by tile, every tile would get its own statistics: a dark
tile would be brightened, a smooth one sharpened, and neighbouring tiles would disagree by far more
than any blending can hide (see ``tests/inference/model/test_tiling.py``: with per-tile statistics
the error near seams is orders of magnitude above the frozen-statistics error). So the photo is
processed in two steps:

1. :func:`norm_statistics`: one pass over the whole photo, downscaled so that its longer side is at
   most ``stats_resolution``, while forward pre-hooks record the per-channel mean and biased
   variance of the input of every ``InstanceNorm2d``.
2. :func:`frozen_instance_norm`: every full-resolution tile runs with each ``InstanceNorm2d``
   normalising with those recorded statistics (then applying its affine, if any), i.e. as the
   untiled network would, up to how well the statistics are estimated.

When the photo's longer side is at most ``stats_resolution`` the statistics are measured on the photo
itself and a tiled run reproduces the untiled network up to the padding effects at tile borders,
which the blending windows discard. Statistics measured on a downscaled photo are an approximation:
feature maps at a lower resolution see the texture at another scale (fine detail averaged out, so
typically a smaller variance), so the whole output shifts slightly, uniformly over the photo —
without seams, because every tile shares the same statistics. Measured on randomly initialised
generators (a 1024² pink-noise photo under a flash falloff, statistics at 512 vs at full resolution,
no tiling): mean |Δ| 9e-3, max 0.31 for ``model=default``; mean 3.9e-2, max 1.7 (normals) for the
paper architecture, whose 26 chained norms compound the deviation; at 256 the means grow to
2.3e-2 / 8.2e-2. For comparison, statistics of a full-resolution 512² *crop* are far worse (mean
0.22 / 0.29: a crop misses the flash falloff), and per-tile statistics give mean 0.10 / 0.17. Hence
the default ``stats_resolution`` of 1024: photos up to 1024 px on their longer side get exact
statistics.

**Image statistics.** An :class:`~brdfgan.models.image_statistics.ImageStatistic` module (a per-image
vector: the de-lit anchor's hotspot cap, a feature map's moments, the flash highlight's profile)
has its output recorded in the same pass and replayed in every tile: every tile gets the whole
photo's values.

**Limitation: other global operations.** Only ``InstanceNorm2d`` and ``ImageStatistic`` are frozen. A
model with other image-wide operations — :class:`brdfgan.models.deschaintre2018.Deschaintre2018`'s
global track reads per-level feature means — sees each tile's own means in tiled mode, so its tiles
can disagree. Tiled inference still runs on it (and its affine instance norms are frozen), but for
seam-free results run such a model directly (raise ``max_direct_pixels``) or at a resolution that fits.

**Blending.** Tiles overlap by ``overlap = 2 * margin + ramp`` pixels. Each tile is weighted by a
separable window (:func:`blend_window`): 0 in a ``margin`` band at every inner tile edge, where the
tile's own border padding (reflection / zero padding instead of the true neighbouring content)
corrupts the output; a raised-cosine ramp of width ``ramp`` across the rest of the overlap; 1 in the
middle and up to the image border, which has no neighbour. Weighted maps are accumulated tile by tile
into one preallocated full-size buffer, so peak memory is the output plus one tile's activations,
independent of the number of tiles. Normals are renormalised after blending.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.flash_geometry import (
    centred_flash_frame,
    check_flash_frame,
    crop_flash_frame,
    resize_flash_frame,
)
from brdfgan.core.svbrdf import NORMAL, normalize_normal
from brdfgan.errors import UserError
from brdfgan.models.heads import PHOTO_CHANNELS
from brdfgan.models.image_statistics import ImageStatistic

ProgressCallback = Callable[[int, int], None]
# Per InstanceNorm2d (by module name): one (mean, biased variance) pair of shape (C,) per call in a
# forward pass, in call order (a module used twice in a forward gets two entries); per
# ImageStatistic: its output (1, K), one 1-tuple per call.
NormStatistics = dict[str, list[tuple[Tensor, ...]]]


class TilingError(UserError):
    """The tile side (``--tile``) does not suit the model; other checks here are contracts (ValueError)."""


@dataclass(frozen=True)
class TilingConfig:
    """How :func:`predict_maps` splits a large photo.

    The defaults keep peak memory at that of an untiled 1024² run (a tile, and the statistics pass,
    are 1024² images) and come from measuring the padding influence of randomly initialised
    generators (no trained weights to measure on; ``tests/inference/model/test_tiling.py`` has the
    method): with frozen statistics a tile's output differs from the untiled output by more than
    1e-3 up to 110 px inside a tile edge for the paper architecture (width 64, 9 residual blocks;
    its receptive field reaches 164 px), 73 px for ``model=default`` (width 16, 4 blocks). A 96 px
    ``margin`` and a 64 px ramp bound the blended error of the paper model by 2e-4 (measured: mean
    2e-6, max 6e-4 over a 1024² photo in 512² tiles); ``model=default`` would do with ``margin=48,
    overlap=160`` (bound 8e-4). A 1024² tile with a 256 px overlap computes each pixel (1024 / 768)²
    ≈ 1.8 times.

    Args:
        tile: tile side in pixels; a multiple of the model's ``size_multiple`` (and at least twice it).
        overlap: total overlap between neighbouring tiles, ``2 * margin + ramp``; less than ``tile``.
        max_direct_pixels: photos with ``H * W`` at most this run untiled.
        stats_resolution: longer side of the downscaled pass that measures the InstanceNorm
            statistics; a photo whose longer side is at most this is measured at its own size.
        margin: band at every inner tile edge whose output gets weight 0 (padding artefacts).
        freeze_statistics: normalise tiles with the whole photo's statistics. ``False`` gives every
            tile its own statistics (visible seams); only useful to demonstrate the problem.
    """

    tile: int = 1024
    overlap: int = 256
    max_direct_pixels: int = 1024 * 1024
    stats_resolution: int = 1024
    margin: int = 96
    freeze_statistics: bool = True

    def __post_init__(self) -> None:
        if self.tile < 1 or self.stats_resolution < 1 or self.max_direct_pixels < 0:
            raise ValueError(
                f"TilingConfig needs tile, stats_resolution >= 1 and max_direct_pixels >= 0, got "
                f"tile={self.tile}, stats_resolution={self.stats_resolution}, "
                f"max_direct_pixels={self.max_direct_pixels}"
            )
        if not 0 <= 2 * self.margin <= self.overlap < self.tile:
            raise ValueError(
                "TilingConfig needs 0 <= 2 * margin <= overlap < tile (overlap = 2 * margin + ramp), "
                f"got margin={self.margin}, overlap={self.overlap}, tile={self.tile}"
            )

    def runs_tiled(self, height: int, width: int) -> bool:
        """Whether :func:`predict_maps` splits an ``height × width`` photo into tiles."""
        return height * width > self.max_direct_pixels

    @classmethod
    def for_tile(cls, tile: int | None) -> TilingConfig:
        """The default tiling, or with another tile side (``--tile``): photos above ``tile``² run
        tiled; overlap and margin shrink for small tiles so the config stays valid."""
        default = cls()
        if tile is None:
            return default
        overlap = min(default.overlap, tile // 2)
        margin = min(default.margin, (3 * overlap) // 8)
        return cls(tile=tile, overlap=overlap, margin=margin, max_direct_pixels=tile * tile)

    @property
    def ramp(self) -> int:
        """Width of the raised-cosine transition inside the overlap: ``overlap - 2 * margin``."""
        return self.overlap - 2 * self.margin

    def to_json(self, tiled: bool) -> dict[str, Any]:
        """The ``inference`` entry of ``material.json`` for a photo that ran ``tiled`` or not."""
        return {
            "tiled": tiled,
            "tile": self.tile if tiled else None,
            "overlap": self.overlap if tiled else None,
        }


# --- statistics ------------------------------------------------------------------------------------


def _uses_input_statistics(module: nn.Module) -> bool:
    # An InstanceNorm with running statistics in eval mode already normalises with fixed numbers.
    return isinstance(module, nn.InstanceNorm2d) and (module.training or not module.track_running_stats)


def norm_statistics(model: nn.Module, photo: Tensor, flash: Tensor | None = None) -> NormStatistics:
    """Run ``model`` once on ``photo`` (with its flash frame ``flash``, when given) and record the
    input statistics of every ``InstanceNorm2d`` and the output of every ``ImageStatistic``.

    The forward runs under ``torch.inference_mode()``; its output is discarded. Hooks are removed
    afterwards, also on exceptions.

    Shape:
        - photo: ``(1, C, H, W)``, a size the model accepts
        - output: per module name, a list with one ``(mean, var)`` pair of shape ``(C_norm,)`` per call
          (biased variance, as the norm uses), or one ``(value,)`` of shape ``(1, K)`` per call
    """
    check_shape(photo, "1 C H W", name="norm_statistics photo")
    stats: NormStatistics = {}
    handles = []

    def record(name: str) -> Callable[[nn.Module, tuple[Tensor, ...]], None]:
        def hook(_module: nn.Module, args: tuple[Tensor, ...]) -> None:
            # float32 at least: a half-precision variance over millions of pixels loses digits.
            x = args[0].float() if args[0].dtype in (torch.float16, torch.bfloat16) else args[0]
            var, mean = torch.var_mean(x, dim=(-2, -1), correction=0)
            stats.setdefault(name, []).append((mean.reshape(-1), var.reshape(-1)))

        return hook

    def record_output(name: str) -> Callable[[nn.Module, tuple[Tensor, ...], Tensor], None]:
        def hook(_module: nn.Module, _args: tuple[Tensor, ...], output: Tensor) -> None:
            stats.setdefault(name, []).append((output.detach().clone(),))

        return hook

    try:
        for name, module in model.named_modules():
            if _uses_input_statistics(module):
                handles.append(module.register_forward_pre_hook(record(name)))
            elif isinstance(module, ImageStatistic):
                handles.append(module.register_forward_hook(record_output(name)))
        with torch.inference_mode():
            model(photo, flash)
    finally:
        for handle in handles:
            handle.remove()
    return stats


def _frozen_forward(module: nn.InstanceNorm2d, entries: list[tuple[Tensor, ...]]) -> Callable:
    calls = 0

    def forward(x: Tensor) -> Tensor:
        nonlocal calls
        # Replay the recorded statistics in call order; modulo so that every forward starts over.
        mean, var = entries[calls % len(entries)]
        calls += 1
        batched = x if x.ndim == 4 else x.unsqueeze(0)  # InstanceNorm2d also accepts (C, H, W)
        out = F.batch_norm(
            batched,
            mean.to(device=x.device, dtype=x.dtype),
            var.to(device=x.device, dtype=x.dtype),
            module.weight,
            module.bias,
            training=False,
            momentum=0.0,
            eps=module.eps,
        )
        return out if x.ndim == 4 else out.squeeze(0)

    return forward


def _replayed_output(entries: list[tuple[Tensor, ...]]) -> Callable:
    calls = 0

    def forward(x: Tensor, *_more: Tensor) -> Tensor:  # a statistic may read more inputs (a photo, a frame)
        nonlocal calls
        (value,) = entries[calls % len(entries)]  # in call order, as for the norms
        calls += 1
        return value.to(device=x.device, dtype=x.dtype).expand(x.shape[0], -1)

    return forward


_MISSING = object()


@contextmanager
def frozen_instance_norm(model: nn.Module, stats: NormStatistics) -> Iterator[None]:
    """Make every ``InstanceNorm2d`` named in ``stats`` normalise with the recorded statistics.

    Inside the context each such module computes ``(x - mean) / sqrt(var + eps)`` (then its affine,
    if any) with the recorded per-channel ``mean`` and ``var`` instead of its input's own, for inputs
    of any size. The modules' ``forward`` is restored on exit, also on exceptions.

    Shape:
        - model input: any the model accepts; the normalised features must have the recorded channels
    """
    modules = dict(model.named_modules())
    unknown = set(stats) - set(modules)
    if unknown:
        raise ValueError(f"statistics name modules the model does not have: {sorted(unknown)}")
    saved: list[tuple[nn.Module, object]] = []
    try:
        for name, entries in stats.items():
            module = modules[name]
            if not entries or not isinstance(module, nn.InstanceNorm2d | ImageStatistic):
                raise ValueError(f"statistics for {name!r} belong to no InstanceNorm2d or ImageStatistic")
            # An instance attribute shadows the class's forward; remember any existing one.
            saved.append((module, module.__dict__.get("forward", _MISSING)))
            replayed = (
                _replayed_output(entries)
                if isinstance(module, ImageStatistic)
                else _frozen_forward(module, entries)
            )
            # Replacing a method on one instance is the point here (and what mypy warns about).
            module.forward = replayed  # type: ignore[method-assign]
        yield
    finally:
        for module, previous in reversed(saved):
            if previous is _MISSING:
                del module.forward
            else:
                # The callable saved above, typed ``object`` because of the _MISSING sentinel.
                module.forward = previous  # type: ignore[assignment]


# --- geometry --------------------------------------------------------------------------------------


def tile_starts(length: int, tile: int, overlap: int, multiple: int = 1) -> list[int]:
    """Start offsets of tiles of side ``tile`` covering ``[0, length)`` with at least ``overlap`` overlap.

    The first tile starts at 0, the last ends flush at ``length``, starts are multiples of
    ``multiple`` (a strided network is shift-equivariant only for such shifts, so tiles then see
    exactly what the untiled network sees) and are spread as evenly as that allows.
    ``length`` and ``tile`` must be multiples of ``multiple``; ``tile >= length`` gives ``[0]``.
    """
    if length % multiple or tile % multiple or min(length, tile, multiple) < 1:
        raise ValueError(f"length {length} and tile {tile} must be positive multiples of {multiple}")
    if tile >= length:
        return [0]
    step = (tile - overlap) // multiple * multiple  # the largest allowed distance between starts
    if step < multiple:
        raise ValueError(f"tile {tile} minus overlap {overlap} must be at least the size multiple {multiple}")
    units = (length - tile) // multiple
    gaps = -(-(length - tile) // step)
    return [i * units // gaps * multiple for i in range(gaps + 1)]


def blend_window(size: int, ramp: int, margin: int, *, taper_start: bool, taper_end: bool) -> Tensor:
    """1-D blending weights of a tile: 0 in ``margin``, raised-cosine ``ramp``, then 1.

    At a tapered end the first ``margin`` pixels get weight 0 and the next ``ramp`` pixels rise as
    ``(1 - cos(pi t)) / 2``, sampled at pixel centres; an untapered end (the image border) keeps
    weight 1. Two neighbours whose overlap is exactly ``2 * margin + ramp`` sum to 1 across it (the
    raised cosine is antisymmetric about its midpoint); a larger overlap sums to at least 1.
    If the two tapers meet, the smaller weight wins.

    Shape:
        - output: ``(size,)``, float32, symmetric when both ends are tapered
    """
    if size < 1 or ramp < 0 or margin < 0:
        raise ValueError(
            f"blend_window needs size >= 1, ramp >= 0, margin >= 0, got {size}, {ramp}, {margin}"
        )
    centres = torch.arange(size, dtype=torch.float64) + 0.5

    def rise(distance: Tensor) -> Tensor:
        # distance: of the pixel centre from the tapered edge.
        if ramp == 0:
            return (distance > margin).to(torch.float64)
        t = ((distance - margin) / ramp).clamp(0.0, 1.0)
        return 0.5 - 0.5 * torch.cos(math.pi * t)

    window = torch.ones(size, dtype=torch.float64)
    if taper_start:
        window = torch.minimum(window, rise(centres))
    if taper_end:
        window = torch.minimum(window, rise(size - centres))
    return window.float()


# --- padding ---------------------------------------------------------------------------------------


def _size_multiple(model: nn.Module) -> int:
    return int(getattr(model, "size_multiple", 1))


def padded_size(model: nn.Module, height: int, width: int) -> tuple[int, int]:
    """The smallest size >= ``(height, width)`` the model accepts: multiples of its ``size_multiple``.

    Models with a ``check_input`` (both of ours) are asked; if the rounded-up size is refused (the
    :class:`~brdfgan.models.generator.Generator` needs at least twice the multiple), each side is
    raised to twice the multiple.
    """
    multiple = _size_multiple(model)
    size = (-(-height // multiple) * multiple, -(-width // multiple) * multiple)
    check = getattr(model, "check_input", None)
    if check is None:
        return size
    channels = int(getattr(model, "in_channels", PHOTO_CHANNELS))
    try:
        check(torch.empty(1, channels, *size, device="meta"))  # looks at the shape only
    except ValueError:
        size = (max(size[0], 2 * multiple), max(size[1], 2 * multiple))
        check(torch.empty(1, channels, *size, device="meta"))
    return size


def reflect_pad(photo: Tensor, height: int, width: int) -> Tensor:
    """Pad ``photo`` at the bottom and right by reflection to ``(height, width)``.

    Reflection repeats when the padding exceeds the image (``F.pad`` reflects at most ``size - 1``).
    Padding only at the end keeps pixel ``(0, 0)`` in place, so cropping back is ``[:H, :W]``.

    Shape:
        - photo: ``(B, C, H, W)`` with H, W >= 2 (or no padding needed)
        - output: ``(B, C, height, width)``
    """
    bottom, right = height - photo.shape[-2], width - photo.shape[-1]
    if bottom < 0 or right < 0:
        raise ValueError(f"cannot pad {tuple(photo.shape[-2:])} to a smaller {(height, width)}")
    while bottom > 0 or right > 0:
        step_b, step_r = min(bottom, photo.shape[-2] - 1), min(right, photo.shape[-1] - 1)
        if step_b <= 0 and step_r <= 0:
            raise ValueError(f"reflection padding needs at least 2×2 pixels, got {tuple(photo.shape[-2:])}")
        photo = F.pad(photo, (0, step_r, 0, step_b), mode="reflect")
        bottom, right = bottom - step_b, right - step_r
    return photo


def _pad_for(model: nn.Module, photo: Tensor) -> Tensor:
    return reflect_pad(photo, *padded_size(model, *photo.shape[-2:]))


def stats_photo(model: nn.Module, padded: Tensor, stats_resolution: int) -> Tensor:
    """The input of the statistics pass: ``padded`` itself, or downscaled to ``stats_resolution``.

    The longer side becomes ``stats_resolution`` (aspect kept, antialiased bilinear), then the result
    is padded to a size the model accepts. ``padded`` is the photo as the untiled network would see
    it (already padded), so at its own size the statistics are exactly the untiled network's.

    Shape:
        - padded: ``(1, C, H, W)``
        - output: ``(1, C, h, w)``; ``(h, w) = (H, W)`` when ``max(H, W) <= stats_resolution``
    """
    height, width = padded.shape[-2:]
    longest = max(height, width)
    if longest <= stats_resolution:
        return padded
    scale = stats_resolution / longest
    size = (max(2, round(height * scale)), max(2, round(width * scale)))
    small = F.interpolate(padded, size=size, mode="bilinear", antialias=True, align_corners=False)
    return _pad_for(model, small.clamp(0.0, 1.0))


# --- memory ----------------------------------------------------------------------------------------

# Full-size float buffers of a tiled run, in values per pixel: the padded photo (3), the blended
# output (8) and the temporaries of renormalising its normals (at most 8).
TILED_BUFFER_CHANNELS = 3 + 8 + 8


def activation_bytes_per_pixel(generator: nn.Module) -> float:
    """Peak memory of one untiled forward pass per input pixel, measured on a small input.

    Forward hooks record the bytes every leaf module reads and writes during one pass over the
    smallest photo of at least 64² the model accepts; the largest sum is doubled for what stays
    alive beside them (the residual stream, reflection-padding copies, convolution workspaces) and
    divided by the pixel count. Every activation of a fully convolutional network scales with the
    pixel count, so the ratio holds at any size. Checked against how the peak resident memory of
    untiled ``brdfgan predict`` runs grows with the pixel count (CPU, float32; the photo and maps
    included): estimated 256 B/px vs 265 measured for the shipped weights (width 16, 1024² →
    2048²), 1024 vs 967 for the paper generator (width 64, 512² → 1024²). (A pass on the ``meta``
    device would cost no compute, but its one-off set-up takes longer than this pass.)
    """
    height, width = padded_size(generator, 64, 64)
    device, dtype = model_placement(generator, torch.empty(0))
    largest = 0

    def hook(_module: nn.Module, args: tuple[object, ...], output: object) -> None:
        nonlocal largest
        tensors = [t for t in (*args, output) if isinstance(t, Tensor)]
        largest = max(largest, sum(t.numel() * t.element_size() for t in tensors))

    leaves = [module for module in generator.modules() if not list(module.children())]
    handles = [module.register_forward_hook(hook) for module in leaves]
    channels = int(getattr(generator, "in_channels", PHOTO_CHANNELS))
    try:
        with _inference(generator):
            generator(torch.full((1, channels, height, width), 0.5, device=device, dtype=dtype))
    finally:
        for handle in handles:
            handle.remove()
    return 2.0 * largest / (height * width)


def predict_memory(
    generator: nn.Module, height: int, width: int, config: TilingConfig, activation_bytes: float
) -> int:
    """Bytes :func:`predict_maps` needs for an ``height × width`` photo (beyond the photo itself).

    Untiled: the activations of the whole padded photo. Tiled: the full-size buffers plus the
    activations of the larger of one tile and the statistics pass. ``activation_bytes`` is
    :func:`activation_bytes_per_pixel` of ``generator``.
    """
    full_h, full_w = padded_size(generator, height, width)
    if not config.runs_tiled(height, width):
        return math.ceil(activation_bytes * full_h * full_w)
    tile_pixels = min(config.tile, full_h) * min(config.tile, full_w)
    scale = min(1.0, config.stats_resolution / max(full_h, full_w))
    stats_pixels = math.ceil(full_h * scale) * math.ceil(full_w * scale)
    buffers = TILED_BUFFER_CHANNELS * 4 * full_h * full_w  # float32, the photo's dtype
    return math.ceil(buffers + activation_bytes * max(tile_pixels, stats_pixels))


# --- prediction ------------------------------------------------------------------------------------


def _check_photo(photo: Tensor, *, single: bool) -> None:
    check_shape(photo, f"{'1' if single else 'B'} {PHOTO_CHANNELS} H W", name="photo")
    if min(photo.shape[-2:]) < 2 or not photo.is_floating_point():
        raise ValueError(f"expected a floating-point photo of at least 2×2 pixels, got {tuple(photo.shape)}")


def model_placement(model: nn.Module, photo: Tensor) -> tuple[torch.device, torch.dtype]:
    """The device and dtype of the model's first floating-point parameter or buffer; the photo's
    for a model with neither (a reference predictor without weights)."""
    # Tiles go to the model's device and dtype; the output buffers stay with the photo (e.g. a CPU
    # photo with a GPU model keeps only one tile on the GPU).
    for tensor in (*model.parameters(), *model.buffers()):
        if tensor.is_floating_point():
            return tensor.device, tensor.dtype
    return photo.device, photo.dtype


@contextmanager
def _inference(model: nn.Module) -> Iterator[None]:
    """Eval mode and ``torch.inference_mode()``; the model's previous mode is restored afterwards."""
    was_training = model.training
    model.eval()
    try:
        with torch.inference_mode():
            yield
    finally:
        model.train(was_training)


def _whole_photo_frame(photo: Tensor, flash: Tensor | None) -> Tensor:
    # Without a frame the photo is centred on its hotspot: the centre of the photo itself, not of
    # the padded photo or of a tile, which is what the network would assume for its own input.
    if flash is None:
        return centred_flash_frame(photo.shape[0], *photo.shape[-2:])
    check_flash_frame(flash, photo.shape[0])
    return flash.float().cpu()


def predict_direct(generator: nn.Module, photo: Tensor, flash: Tensor | None = None) -> Tensor:
    """One untiled pass: pad to a size the model accepts, run, crop back.

    ``flash`` is the photos' :mod:`flash frame <brdfgan.core.flash_geometry>` (default: centred on
    each photo, the default field of view); networks that do not read it (the paper generator) ignore it.
    Padding adds pixels after the last row and column, so the frame needs no shift.

    Shape:
        - photo: ``(B, 3, H, W)``, linear LDR in [0, 1], H, W >= 2
        - flash: ``(B, 3)``
        - output: ``(B, 8, H, W)`` on the photo's device and dtype
    """
    _check_photo(photo, single=False)
    device, dtype = model_placement(generator, photo)
    height, width = photo.shape[-2:]
    frame = _whole_photo_frame(photo, flash).to(device)
    with _inference(generator):
        maps = generator(_pad_for(generator, photo).to(device=device, dtype=dtype), frame)
        return maps[..., :height, :width].to(device=photo.device, dtype=photo.dtype)


def predict_tiled(
    generator: nn.Module,
    photo: Tensor,
    config: TilingConfig = TilingConfig(),
    progress: ProgressCallback | None = None,
    flash: Tensor | None = None,
) -> Tensor:
    """Overlapping tiles with frozen InstanceNorm statistics, blended into one map set.

    Every tile gets the whole photo's flash frame moved to the tile's corner (and the statistics
    pass the frame of the downscaled photo), so a flash-aware network sees the same geometry as
    in one untiled pass; ``flash`` as in :func:`predict_direct`.

    Peak memory: the padded photo, the ``(1, 8, H, W)`` output buffer and one tile's activations
    (plus the statistics pass at ``stats_resolution``). ``progress(done, total)`` is called after
    every tile.

    Shape:
        - photo: ``(1, 3, H, W)``, linear LDR in [0, 1], H, W >= 2
        - flash: ``(1, 3)``
        - output: ``(1, 8, H, W)``, valid maps (normals renormalised after blending), on the photo's
          device and dtype; a generator with more output channels (maps first) gets them all
    """
    _check_photo(photo, single=True)
    frame = _whole_photo_frame(photo, flash)
    multiple = _size_multiple(generator)
    if config.tile % multiple:
        raise TilingError(f"tile {config.tile} must be a multiple of the model's size multiple {multiple}")
    device, dtype = model_placement(generator, photo)
    height, width = photo.shape[-2:]

    with _inference(generator):
        padded = _pad_for(generator, photo)
        full_h, full_w = padded.shape[-2:]
        # A photo smaller than a tile along an axis is one tile along it.
        tile_h, tile_w = min(config.tile, full_h), min(config.tile, full_w)
        if padded_size(generator, tile_h, tile_w) != (tile_h, tile_w):
            raise TilingError(f"tile {config.tile} is too small for the model (size multiple {multiple})")
        ys = tile_starts(full_h, tile_h, config.overlap, multiple)
        xs = tile_starts(full_w, tile_w, config.overlap, multiple)

        def windows(starts: list[int], size: int, length: int) -> list[Tensor]:
            return [
                blend_window(
                    size, config.ramp, config.margin, taper_start=start > 0, taper_end=start + size < length
                ).to(device=photo.device, dtype=photo.dtype)
                for start in starts
            ]

        wy, wx = windows(ys, tile_h, full_h), windows(xs, tile_w, full_w)
        # The tiles form a grid of separable windows, so the total weight is the outer product of the
        # 1-D sums: no full-size weight buffer needed.
        sum_y = torch.zeros(full_h, device=photo.device, dtype=photo.dtype)
        sum_x = torch.zeros(full_w, device=photo.device, dtype=photo.dtype)
        for start, w in zip(ys, wy, strict=True):
            sum_y[start : start + tile_h] += w
        for start, w in zip(xs, wx, strict=True):
            sum_x[start : start + tile_w] += w
        assert sum_y.min() > 0 and sum_x.min() > 0, "blending weights must cover every pixel"

        frozen: AbstractContextManager[None] = nullcontext()
        if config.freeze_statistics:
            small = stats_photo(generator, padded, config.stats_resolution)
            small_frame = resize_flash_frame(frame, small.shape[-1] / full_w).to(device)
            frozen = frozen_instance_norm(
                generator, norm_statistics(generator, small.to(device=device, dtype=dtype), small_frame)
            )

        out: Tensor | None = None  # allocated at the first tile: the generator's channels
        total, done = len(ys) * len(xs), 0
        with frozen:
            for y, window_y in zip(ys, wy, strict=True):
                for x, window_x in zip(xs, wx, strict=True):
                    tile = padded[..., y : y + tile_h, x : x + tile_w].to(device=device, dtype=dtype)
                    tile_frame = crop_flash_frame(frame, x, y).to(device)
                    maps = generator(tile, tile_frame).to(device=photo.device, dtype=photo.dtype)
                    if out is None:
                        out = maps.new_zeros(1, maps.shape[1], full_h, full_w)
                    out[..., y : y + tile_h, x : x + tile_w] += maps * (window_y[:, None] * window_x[None, :])
                    done += 1
                    if progress is not None:
                        progress(done, total)

        assert out is not None  # at least one tile
        out = out[..., :height, :width]
        out /= sum_y[:height, None] * sum_x[None, :width]
        # A weighted mean of unit vectors is shorter than 1 where tiles disagree: renormalise.
        out[:, NORMAL] = normalize_normal(out[:, NORMAL])
        return out


def predict_maps(
    generator: nn.Module,
    photo: Tensor,
    config: TilingConfig = TilingConfig(),
    *,
    progress: ProgressCallback | None = None,
    flash: Tensor | None = None,
) -> Tensor:
    """Estimate the maps of a photo of any size: untiled when it is small, tiled otherwise.
    ``flash``: the photo's flash frame, as in :func:`predict_direct`.

    Photos with ``H * W <= config.max_direct_pixels`` run in one pass (:func:`predict_direct`,
    ``progress(1, 1)`` after it); larger ones with :func:`predict_tiled`. Runs under
    ``torch.inference_mode()`` with the generator in eval mode (its mode is restored afterwards), so
    the result is an inference tensor: ``clone()`` it before updating it in place outside that mode.

    Shape:
        - photo: ``(1, 3, H, W)``, linear LDR in [0, 1], any H, W >= 2 (padded by reflection to the
          model's size multiple internally and cropped back)
        - output: ``(1, 8, H, W)``, valid maps on the photo's device and dtype
    """
    _check_photo(photo, single=True)
    height, width = photo.shape[-2:]
    if not config.runs_tiled(height, width):
        maps = predict_direct(generator, photo, flash)
        if progress is not None:
            progress(1, 1)
        return maps
    return predict_tiled(generator, photo, config, progress, flash)
