"""Trivial reference predictors that any real model must beat (issue: "measured quality").

- :class:`ConstantMaps`: the same map set everywhere, the training set's mean — the best constant
  under a per-pixel squared error in the stored encodings (normal: the mean direction).
- :class:`PhotoAsBasecolor`: the input photo (sRGB-encoded) as base colour, a flat normal and
  constant roughness/metallic (the training means) — what "use the photo as the texture" gives.
- :class:`DeLitPhoto`: the de-lit photo (:func:`brdfgan.core.delit.delit_photo`: the photo
  divided by the flash's falloff on a flat surface for the photo's field of view and hotspot, the
  hotspot clipped) times an exposure gain fitted on a training split, as base colour; a flat
  normal; constant roughness and metallic (the training medians). A physics heuristic with no
  learning: what the flash's falloff alone explains of a photo, the bar a network's relighting
  has to clear to show that it learnt more than that.

All three behave like generators (``forward(photo, flash) -> maps``, ``config()``,
``size_multiple``; :class:`brdfgan.runs.GeneratorLike`), so the evaluator, :mod:`brdfgan.runs` and
``brdfgan predict`` take them unchanged. Build their weight files from a dataset with::

    brdfgan references DATA_DIR --out DIR      # DIR/{mean_maps,photo_basecolor,de_lit}.safetensors
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor, nn

from brdfgan.core.delit import delit_photo
from brdfgan.core.exposure import luminance
from brdfgan.core.flash_geometry import DEFAULT_FOV_DEG, centred_flash_frame
from brdfgan.core.svbrdf import (
    BASECOLOR,
    METALLIC,
    NORMAL,
    NUM_CHANNELS,
    ROUGHNESS,
    linear_to_srgb,
    normalize_normal,
    srgb_to_linear,
)
from brdfgan.errors import UserError


class ConstantMaps(nn.Module):
    """Predicts ``values`` (8 channels, stored encodings) at every pixel, whatever the photo."""

    size_multiple = 1
    values: Tensor  # (8,) buffer

    def __init__(self) -> None:
        super().__init__()
        flat = torch.tensor([0.5, 0.5, 0.5, 0.0, 0.0, 1.0, 0.5, 0.0])
        self.register_buffer("values", flat)

    def config(self) -> dict[str, Any]:
        return {}

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        """Shape: photo ``(B, 3, H, W)`` → maps ``(B, 8, H, W)``; ``flash`` (the flash frame) is unused."""
        batch, _, height, width = photo.shape
        values = self.values.to(photo.dtype)
        return values.view(1, NUM_CHANNELS, 1, 1).expand(batch, NUM_CHANNELS, height, width).clone()


class PhotoAsBasecolor(nn.Module):
    """Base colour = the linear photo sRGB-encoded; flat normal; constant roughness and metallic."""

    size_multiple = 1
    roughness: Tensor  # () buffer
    metallic: Tensor  # () buffer

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("roughness", torch.tensor(0.5))
        self.register_buffer("metallic", torch.tensor(0.0))

    def config(self) -> dict[str, Any]:
        return {}

    def basecolor(self, photo: Tensor, flash: Tensor | None) -> Tensor:
        """The linear base colour of the photo. Shape: ``(B, 3, H, W)`` → same."""
        return photo

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        """Shape: photo ``(B, 3, H, W)`` linear LDR, flash ``(B, 3)`` or ``None`` → maps ``(B, 8, H, W)``."""
        batch, _, height, width = photo.shape
        maps = photo.new_zeros(batch, NUM_CHANNELS, height, width)
        maps[:, BASECOLOR] = linear_to_srgb(self.basecolor(photo, flash).clamp(0.0, 1.0))
        maps[:, NORMAL.start + 2] = 1.0
        maps[:, ROUGHNESS] = self.roughness.to(photo.dtype)
        maps[:, METALLIC] = self.metallic.to(photo.dtype)
        return maps


class DeLitPhoto(PhotoAsBasecolor):
    """Base colour = ``gain`` × the de-lit photo, sRGB-encoded; flat normal; constant roughness
    and metallic. The flash frame says where the hotspot is and the field of view; without one
    the photo is taken as centred on its hotspot with the default field of view (as
    ``brdfgan predict`` assumes without EXIF)."""

    gain: Tensor  # () buffer: exposure gain from the de-lit photo to linear base colour

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("gain", torch.tensor(1.0))

    def basecolor(self, photo: Tensor, flash: Tensor | None) -> Tensor:
        batch, _, height, width = photo.shape
        if flash is None:
            flash = centred_flash_frame(
                batch, height, width, DEFAULT_FOV_DEG, device=photo.device, dtype=photo.dtype
            )
        return self.gain.to(photo.dtype) * delit_photo(photo, flash.to(photo.dtype))


def fit_delit_reference(batches: Any, stride: int = 4) -> DeLitPhoto:
    """A :class:`DeLitPhoto` fitted on the batches of a training split: the exposure gain is the
    median over samples of the ratio of the true linear base colour's mean luminance to the de-lit
    photo's (a median of ratios: a few glossy or dark samples do not move it), roughness and
    metallic the medians of every ``stride``-th texel's.

    Shape:
        - each batch: ``"photo"`` ``(B, 3, H, W)``, ``"maps"`` ``(B, 8, H, W)``, ``"flash"`` ``(B, 3)``
    """
    log_ratios: list[Tensor] = []
    roughness: list[Tensor] = []
    metallic: list[Tensor] = []
    for batch in batches:
        photo, maps = batch["photo"].double(), batch["maps"].double()
        delit = delit_photo(photo, batch["flash"].double())
        truth = srgb_to_linear(maps[:, BASECOLOR])
        ratio = luminance(truth).mean(dim=(1, 2, 3)) / luminance(delit).mean(dim=(1, 2, 3)).clamp_min(1e-6)
        log_ratios.append(ratio.clamp_min(1e-6).log())
        roughness.append(maps[:, ROUGHNESS, ::stride, ::stride].flatten())
        metallic.append(maps[:, METALLIC, ::stride, ::stride].flatten())
    if not log_ratios:
        raise UserError("no training samples to fit the de-lit reference on")
    model = DeLitPhoto()
    model.gain.fill_(float(torch.cat(log_ratios).median().exp()))
    model.roughness.fill_(float(torch.cat(roughness).median()))
    model.metallic.fill_(float(torch.cat(metallic).median()))
    return model


def mean_maps(batches: Any) -> Tensor:
    """Per-channel mean of the maps of every batch (stored encodings; the normal renormalised).

    Shape:
        - each batch["maps"]: ``(B, 8, H, W)``
        - output: ``(8,)``
    """
    total = torch.zeros(NUM_CHANNELS, dtype=torch.float64)
    pixels = 0
    for batch in batches:
        maps = batch["maps"].double()
        total += maps.sum(dim=(0, 2, 3))
        pixels += maps.shape[0] * maps.shape[2] * maps.shape[3]
    if pixels == 0:
        raise UserError("no training samples to average")  # an empty train split: `brdfgan references`
    mean = total / pixels
    mean[NORMAL] = normalize_normal(mean[NORMAL].view(3, 1, 1), dim=0).view(3)
    return mean.float()


def reference_models(mean: Tensor) -> dict[str, nn.Module]:
    """Both references, parameterised by the training mean ``(8,)``."""
    constant = ConstantMaps()
    constant.values.copy_(mean)
    photo = PhotoAsBasecolor()
    photo.roughness.fill_(float(mean[ROUGHNESS]))
    photo.metallic.fill_(float(mean[METALLIC]))
    return {"mean_maps": constant, "photo_basecolor": photo}
