"""Paper §5 augmentation: random crops with rotation and scale from large maps to training size.

A crop is a square of side ``2·scale`` (plane units; the source covers ``[-1, 1]²``) centred at
``center``, rotated by ``angle`` and optionally mirrored: the feature at source position ``q``
lands at output position ``M·R(angle)·(q − center)/scale``, with ``M`` the mirror ``x → −x`` or
the identity. Procedural materials tile, so sampling wraps around; scanned sets need not tile, so
their crops can be drawn to stay inside the source (``CropSampling.inside``).

Per map:
- base color is resampled in linear space (filtering sRGB values darkens edges) and re-encoded;
- normals are resampled, their XY components rotated by the same angle as the content (a slope
  facing +X rotated by 90° faces +Y) and mirrored with it (a mirrored slope facing +X faces −X),
  then renormalised;
- roughness and metallic are resampled as they are.

Downscaling pre-filters with an antialiased resize so a 2048² material reduced to 256² does not
alias; the rotation then samples bilinearly at about one source texel per output texel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.sampling import log_uniform
from brdfgan.core.svbrdf import (
    BASECOLOR,
    METALLIC,
    NORMAL,
    ROUGHNESS,
    check_map_shape,
    linear_to_srgb,
    normalize_normal,
    srgb_to_linear,
)
from brdfgan.data.storage.spec_checks import in_range, ordered


@dataclass(frozen=True)
class CropTransform:
    """Where a crop comes from: centre in ``[-1, 1]²``, half side ``scale`` (1 = whole source),
    rotation ``angle`` in radians (counter-clockwise, +Y up), then ``mirror`` (x → −x)."""

    center: tuple[float, float]
    scale: float
    angle: float
    mirror: bool = False

    def to_json(self) -> dict[str, Any]:
        """The record of a sample's metadata; ``mirror`` only when set, so that the records of
        crops without it are the bytes they were before mirroring existed."""
        record: dict[str, Any] = {"center": list(self.center), "scale": self.scale, "angle": self.angle}
        return record | {"mirror": True} if self.mirror else record


@dataclass(frozen=True)
class CropSampling:
    """Ranges of the random crops: crop side as a fraction of the source side, rotation.

    ``mirror``: mirror half of the crops (x → −x). ``inside``: draw the centre so that the
    rotated crop lies inside the source (for sources that do not tile, such as scans; a crop
    too large for that is centred). Both off by default, and then a draw takes the same four
    uniforms it always took, so a spec without them paints the crops it painted before.
    """

    scale_min: float = 0.125
    scale_max: float = 0.5
    rotate: bool = True
    mirror: bool = False
    inside: bool = False

    def __post_init__(self) -> None:
        key = "dataset_spec.crop"  # where a crop spec is configured; messages name the key as typed
        ordered(key, self, "scale_min", "scale_max")
        in_range(f"{key}.scale_min", self.scale_min, 0.0, 1.0, low_open=True)  # log-uniform
        in_range(f"{key}.scale_max", self.scale_max, 0.0, 1.0, low_open=True)

    def sample(self, generator: torch.Generator) -> CropTransform:
        u = torch.rand(5 if self.mirror else 4, generator=generator, dtype=torch.float64).tolist()
        # Log-uniform scale: each octave of zoom is equally likely.
        scale = log_uniform(u[0], self.scale_min, self.scale_max)
        angle = 2.0 * math.pi * u[1] if self.rotate else 0.0
        # The rotated square's half extent along x and y is scale·(|cos| + |sin|).
        reach = 1.0 - scale * (abs(math.cos(angle)) + abs(math.sin(angle))) if self.inside else 1.0
        reach = max(reach, 0.0)
        center = (reach * (2.0 * u[2] - 1.0), reach * (2.0 * u[3] - 1.0))
        return CropTransform(center=center, scale=scale, angle=angle, mirror=self.mirror and u[4] < 0.5)


def _prefilter(maps: Tensor, size: int) -> Tensor:
    """Antialiased resize of a (C, S, S) stack to (C, size, size) when that shrinks it."""
    if size >= maps.shape[-1]:
        return maps
    return F.interpolate(maps[None], size=(size, size), mode="bilinear", antialias=True, align_corners=False)[
        0
    ]


def _sampling_grid(transform: CropTransform, out_size: int, source_size: int, pad: int) -> Tensor:
    """grid_sample coordinates ``(1, N, N, 2)`` into a source circularly padded by ``pad`` texels."""
    c = (torch.arange(out_size, dtype=torch.float64) + 0.5) * (2.0 / out_size) - 1.0
    y_out, x_out = torch.meshgrid(-c, c, indexing="ij")  # row 0 is +Y
    if transform.mirror:  # the output's x comes from the mirrored source: q = c + s R(−θ) M p
        x_out = -x_out
    cos, sin = math.cos(transform.angle), math.sin(transform.angle)
    # Inverse rotation takes an output position back to the source.
    x = transform.center[0] + transform.scale * (cos * x_out + sin * y_out)
    y = transform.center[1] + transform.scale * (-sin * x_out + cos * y_out)
    x, y = torch.remainder(x + 1.0, 2.0) - 1.0, torch.remainder(y + 1.0, 2.0) - 1.0
    shrink = source_size / (source_size + 2 * pad)
    return torch.stack([x * shrink, -y * shrink], dim=-1)[None].float()


def crop_maps(maps: Tensor, transform: CropTransform, out_size: int) -> Tensor:
    """Resample one map set through a crop transform.

    Shape:
        - maps: ``(8, S, S)``
        - output: ``(8, out_size, out_size)``
    """
    check_map_shape(maps)
    check_shape(maps, "8 S S", name="square maps")
    return _crop_linear(_linear_basecolor(maps), transform, out_size)


def _linear_basecolor(maps: Tensor) -> Tensor:
    """A copy of the maps with the base colour decoded to linear, for resampling."""
    work = maps.clone()
    work[BASECOLOR] = srgb_to_linear(maps[BASECOLOR])
    return work


def _crop_linear(work: Tensor, transform: CropTransform, out_size: int) -> Tensor:
    """:func:`crop_maps` of maps whose base colour is already linear (:func:`_linear_basecolor`)."""
    # Source texels per output texel; pre-filter so the rotation samples ~1:1.
    texels_per_output = transform.scale * work.shape[-1] / out_size
    source = _prefilter(work, max(out_size, round(work.shape[-1] / max(texels_per_output, 1.0))))
    pad = 2
    padded = F.pad(source[None], (pad, pad, pad, pad), mode="circular")
    grid = _sampling_grid(transform, out_size, source.shape[-1], pad).to(work.dtype)
    out = F.grid_sample(padded, grid, mode="bilinear", padding_mode="border", align_corners=False)[0]

    cos, sin = math.cos(transform.angle), math.sin(transform.angle)
    nx, ny, nz = out[NORMAL][0], out[NORMAL][1], out[NORMAL][2]
    turned_x = cos * nx - sin * ny
    if transform.mirror:  # M R(θ) n: the slopes turn with the content, then mirror with it
        turned_x = -turned_x
    out[NORMAL] = normalize_normal(torch.stack([turned_x, sin * nx + cos * ny, nz]))
    out[BASECOLOR] = linear_to_srgb(out[BASECOLOR].clamp(0.0, 1.0))
    # Resampling weights sum to 1 only up to rounding: keep the scalar maps inside [0, 1].
    out[ROUGHNESS] = out[ROUGHNESS].clamp(0.0, 1.0)
    out[METALLIC] = out[METALLIC].clamp(0.0, 1.0)
    return out


def random_crops(
    maps: Tensor,
    count: int,
    out_size: int,
    generator: torch.Generator,
    sampling: CropSampling = CropSampling(),
) -> tuple[Tensor, list[CropTransform]]:
    """``count`` random crops of one material (paper: 7) and the transforms that made them.

    Shape:
        - maps: ``(8, S, S)``
        - output: ``(count, 8, out_size, out_size)``
    """
    check_map_shape(maps)
    check_shape(maps, "8 S S", name="square maps")
    transforms = [sampling.sample(generator) for _ in range(count)]
    work = _linear_basecolor(maps)  # once per material, not per crop
    return torch.stack([_crop_linear(work, t, out_size) for t in transforms]), transforms
