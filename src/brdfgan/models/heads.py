"""The ends of the networks: input encodings, the generator's output head, weight init.

Both networks work in centred ranges: the photo (linear LDR in [0, 1]) enters as ``2x - 1``, and the
discriminator sees the maps centred the same way
(:func:`brdfgan.models.discriminator.discriminator_input`).
The generator's last layer produces 8 unconstrained channels; :func:`maps_from_raw` turns them into a
map set that always satisfies :func:`brdfgan.core.svbrdf.validate_maps`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.capture import TRAINING_CAPTURE, CaptureKind
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, NORMAL, ROUGHNESS, join_maps, normalize_normal
from brdfgan.errors import UserError

# The generator's input channels: the photos of the training capture it sees (brdfgan.capture).
PHOTO_CHANNELS = TRAINING_CAPTURE.network_channels
# Lower bound on the normal's z before normalisation: keeps the vector length >= 1e-3, so the
# normalisation never divides by ~0 (finite gradients) and the normal never points into the surface.
NORMAL_Z_MIN = 1e-3
INIT_STD = 0.02
# raw_from_maps: values in [0, 1] are clamped to [RAW_EPS, 1 - RAW_EPS] before the logit (logits
# within ±6.9, where the sigmoid's slope is still 1e-3 of its peak), and a normal's z to at least
# RAW_NORMAL_Z_MIN before the slopes x/z, y/z are taken (tilts up to 87°).
RAW_EPS = 1e-3
RAW_NORMAL_Z_MIN = 0.05

# How the normal's three raw channels become a unit normal (see maps_from_raw).
NormalHead = Literal["softplus_z", "unit_z"]
NORMAL_HEADS: tuple[str, ...] = ("softplus_z", "unit_z")


class GeneratorConfigError(UserError):
    """A generator constructor argument is unusable; the message names the config key."""


def check_choice(key: str, value: str, choices: tuple[str, ...]) -> None:
    """A one-line error naming the config key unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise GeneratorConfigError(f"{key}={value!r}: must be {' or '.join(map(repr, choices))}")


def check_normal_head(normal_head: str) -> NormalHead:
    """``normal_head`` if it is one of :data:`NORMAL_HEADS`, else a one-line error naming the key."""
    check_choice("model.generator.normal_head", normal_head, NORMAL_HEADS)
    return normal_head  # type: ignore[return-value]


def network_photos(batch: Mapping[str, Tensor], capture: CaptureKind = TRAINING_CAPTURE) -> Tensor:
    """The photos of a batch the generator sees, stacked along the channels in the capture's order.

    Shape: each ``batch[photo.batch_key]`` ``(B, 3, H, W)`` → ``(B, capture.network_channels, H, W)``.
    """
    photos = [batch[photo.batch_key] for photo in capture.network_photos]
    return photos[0] if len(photos) == 1 else torch.cat(photos, dim=1)


def encode_photo(photo: Tensor) -> Tensor:
    """Linear LDR photo in [0, 1] → centred range [-1, 1] (``2x - 1``), the networks' input scale.

    Shape: any; output has the input's shape.
    """
    return photo * 2.0 - 1.0


def maps_from_raw(raw: Tensor, normal_head: NormalHead = "softplus_z") -> Tensor:
    """The generator's output head: 8 unconstrained channels → a valid map set.

    - basecolor, roughness, metallic: ``sigmoid`` (range [0, 1]).
    - normal: ``x`` and ``y`` raw, ``z = softplus(z_raw) + 1e-3``, then :func:`normalize_normal`.
      softplus keeps z > 0 (the normal points out of the surface) with a smooth, non-vanishing
      gradient for z_raw around 0; a raw output of 0 gives a flat +Z normal,
      and the tilt is driven linearly by x and y, unlike a ``tanh``/``sqrt(1 - x² - y²)`` head whose
      gradient blows up near the horizon.
      With ``normal_head="unit_z"`` instead ``z = 1`` and the third raw channel is unused:
      ``normalize(x, y, 1)``, the height-gradient form. Why: the softplus head is scale-free —
      the loss only sees the direction, so nothing holds ``|(x, y, z)|`` — and under Adam the raw
      z grows, which divides the tilt's gradient by z and leaves the predicted normals flat. With
      z fixed, a raw (x, y) is the tangent of the tilt and its gradient at flat is 1.

    Shape:
        - raw: ``(*, 8, H, W)``
        - output: ``(*, 8, H, W)`` in the layout of :mod:`brdfgan.core.svbrdf`
    """
    basecolor = torch.sigmoid(raw[..., BASECOLOR, :, :])
    xy = raw[..., NORMAL.start : NORMAL.start + 2, :, :]
    z_raw = raw[..., NORMAL.start + 2 : NORMAL.stop, :, :]
    z = torch.ones_like(z_raw) if normal_head == "unit_z" else F.softplus(z_raw) + NORMAL_Z_MIN
    normal = normalize_normal(torch.cat([xy, z], dim=-3))
    roughness = torch.sigmoid(raw[..., ROUGHNESS, :, :])
    metallic = torch.sigmoid(raw[..., METALLIC, :, :])
    return join_maps(basecolor, normal, roughness, metallic)


def raw_from_maps(maps: Tensor, eps: float = RAW_EPS) -> Tensor:
    """The inverse of :func:`maps_from_raw` with ``normal_head="unit_z"``: raw channels whose head
    output is ``maps`` — logits of base colour, roughness and metallic (clamped to
    ``[eps, 1 − eps]`` first, so a saturated value stays finite), the normal as its slopes
    ``(x / z, y / z)`` with z at least :data:`RAW_NORMAL_Z_MIN`, and 0 in the unused third normal
    channel. Test-time refinement (:mod:`brdfgan.inference.refine`) optimises these: any raw
    value decodes to valid maps.

    Shape:
        - maps: ``(*, 8, H, W)`` in the layout of :mod:`brdfgan.core.svbrdf`
        - output: ``(*, 8, H, W)``
    """
    unit = maps.clamp(eps, 1.0 - eps)  # the logits' inputs; the normal is read from maps itself
    normal = maps[..., NORMAL, :, :]
    z = normal[..., 2:3, :, :].clamp(min=RAW_NORMAL_Z_MIN)
    return join_maps(
        torch.logit(unit[..., BASECOLOR, :, :]),
        torch.cat([normal[..., 0:2, :, :] / z, torch.zeros_like(z)], dim=-3),
        torch.logit(unit[..., ROUGHNESS, :, :]),
        torch.logit(unit[..., METALLIC, :, :]),
    )


def init_weights(module: nn.Module) -> None:
    """pix2pixHD initialisation, shared by generator and discriminators.

    Convolutions ~ N(0, 0.02), biases 0, affine norm scales ~ N(1, 0.02). For the 3×3×512 convs
    that dominate the generator, 0.02 is close to He init (sqrt(2 / 4608) ≈ 0.021); the first
    layers get smaller weights, which the InstanceNorm after them makes harmless.
    """
    for m in module.modules():
        if isinstance(m, nn.Conv2d | nn.ConvTranspose2d):
            nn.init.normal_(m.weight, 0.0, INIT_STD)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.InstanceNorm2d | nn.BatchNorm2d) and m.affine:
            nn.init.normal_(m.weight, 1.0, INIT_STD)
            nn.init.zeros_(m.bias)
