"""The SVBRDF map representation: the one place that defines the 8-channel layout.

A map set is a tensor of shape ``(B, 8, H, W)`` (or ``(8, H, W)``) with channels

====== ========= =========================================================
index  map       encoding
====== ========= =========================================================
0:3    basecolor sRGB-encoded in [0, 1], like a texture file
3:6    normal    unit vector in tangent space, +Z out of the surface,
                 +X right, +Y up in the image (OpenGL); components in [-1, 1]
6      roughness perceptual roughness in [0, 1]; GGX alpha = max(r², 0.001)
7      metallic  in [0, 1]
====== ========= =========================================================

Files encode normals as ``(n + 1) / 2`` (:func:`encode_normal`). Base color is converted to
linear (:func:`srgb_to_linear`) before shading, and the derived albedos of the paper (§3) are
``diffuse = b (1 - m)`` and ``specular = 0.04 (1 - m) + b m`` with ``b`` the *linear* base color.

Everything here is a pure torch function; nothing imports Lightning or Hydra.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape

NUM_CHANNELS = 8
BASECOLOR = slice(0, 3)
NORMAL = slice(3, 6)
ROUGHNESS = slice(6, 7)
METALLIC = slice(7, 8)
CHANNELS: dict[str, slice] = {
    "basecolor": BASECOLOR,
    "normal": NORMAL,
    "roughness": ROUGHNESS,
    "metallic": METALLIC,
}
MAP_NAMES: tuple[str, ...] = tuple(CHANNELS)

DIELECTRIC_F0 = 0.04
MIN_ALPHA = 1e-3
NORMAL_UNIT_TOLERANCE = 1e-2


class SVBRDFMaps(NamedTuple):
    """The four maps of a map set, each ``(*, C, H, W)`` with C = 3, 3, 1, 1."""

    basecolor: Tensor
    normal: Tensor
    roughness: Tensor
    metallic: Tensor


class InvalidMapsError(ValueError):
    """A map tensor or file does not satisfy the representation."""


def split_maps(maps: Tensor) -> SVBRDFMaps:
    """Split an 8-channel map tensor into its named maps (views, no copy).

    Shape:
        - maps: ``(*, 8, H, W)``
        - output: basecolor ``(*, 3, H, W)``, normal ``(*, 3, H, W)``,
          roughness ``(*, 1, H, W)``, metallic ``(*, 1, H, W)``

    Example:
        >>> parts = split_maps(flat_maps(4, 5, roughness=0.25))
        >>> tuple(parts.basecolor.shape), tuple(parts.roughness.shape)
        ((3, 4, 5), (1, 4, 5))
        >>> parts.normal[:, 0, 0].tolist(), parts.roughness[0, 0, 0].item()
        ([0.0, 0.0, 1.0], 0.25)
    """
    check_map_shape(maps)
    return SVBRDFMaps(*(maps[..., channels, :, :] for channels in CHANNELS.values()))


def join_maps(basecolor: Tensor, normal: Tensor, roughness: Tensor, metallic: Tensor) -> Tensor:
    """Concatenate the four maps into the 8-channel layout.

    Shape:
        - basecolor, normal: ``(*, 3, H, W)``; roughness, metallic: ``(*, 1, H, W)``
        - output: ``(*, 8, H, W)``

    Example:
        >>> maps = flat_maps(2, 2, batch=(3,))
        >>> torch.equal(join_maps(*split_maps(maps)), maps)
        True
    """
    maps = torch.cat([basecolor, normal, roughness, metallic], dim=-3)
    check_map_shape(maps)
    return maps


def check_map_shape(maps: Tensor) -> None:
    """Raise :class:`InvalidMapsError` unless ``maps`` is ``(*, 8, H, W)`` floating point."""
    if not isinstance(maps, Tensor):
        raise InvalidMapsError(f"maps must be a torch.Tensor, got {type(maps).__name__}")
    name = "maps [basecolor 3, normal 3, roughness 1, metallic 1]"
    check_shape(maps, f"* {NUM_CHANNELS} H W", name=name, error=InvalidMapsError)
    if not maps.is_floating_point():
        raise InvalidMapsError(f"maps must be floating point, got {maps.dtype}")


def check_single_maps(maps: Tensor) -> None:
    """Raise ``ValueError`` unless ``maps`` is one map set ``(8, H, W)`` (:class:`InvalidMapsError`
    unless it is a map tensor at all, see :func:`check_map_shape`)."""
    check_map_shape(maps)
    check_shape(maps, f"{NUM_CHANNELS} H W", name="maps")


def check_map_pair(pred: Tensor, target: Tensor) -> None:
    """Both are map tensors of the same shape (losses and metrics compare them texel by texel)."""
    check_map_shape(pred)
    check_map_shape(target)
    if pred.shape != target.shape:
        raise ValueError(
            f"pred and target must have the same shape, got {tuple(pred.shape)} and {tuple(target.shape)}"
        )


def validate_maps(maps: Tensor, *, normal_tolerance: float = NORMAL_UNIT_TOLERANCE) -> None:
    """Check shape, finiteness, value ranges and unit normals; raise a one-line error if bad.

    Shape:
        - maps: ``(*, 8, H, W)``
    """
    check_map_shape(maps)
    if not torch.isfinite(maps).all():
        bad = [name for name, ch in CHANNELS.items() if not torch.isfinite(maps[..., ch, :, :]).all()]
        raise InvalidMapsError(f"maps contain NaN or infinite values in: {', '.join(bad)}")
    parts = split_maps(maps)
    for name in ("basecolor", "roughness", "metallic"):
        low_t, high_t = torch.aminmax(getattr(parts, name))
        low, high = low_t.item(), high_t.item()
        if low < 0.0 or high > 1.0:
            raise InvalidMapsError(f"{name} must lie in [0, 1], found values in [{low:.4g}, {high:.4g}]")
    # Summing the three products, not linalg.vector_norm over the strided channel dimension:
    # the same lengths several times faster (a reduction over a middle axis is slow here).
    lengths = (parts.normal * parts.normal).sum(dim=-3).sqrt()
    worst = (lengths - 1.0).abs().max().item()
    if worst > normal_tolerance:
        raise InvalidMapsError(
            f"normal vectors must have unit length (tolerance {normal_tolerance}), "
            f"worst deviation {worst:.4g}; decode file values with decode_normal()"
        )
    if (parts.normal[..., 2:3, :, :] < -normal_tolerance).any():
        raise InvalidMapsError("normal vectors must point out of the surface (z >= 0)")


def srgb_to_linear(srgb: Tensor) -> Tensor:
    """The IEC 61966-2-1 sRGB decoding curve, elementwise, for values in [0, 1].

    Shape: any; output has the input's shape.

    Example:
        The linear segment ends at 0.04045 (= 0.0031308 linear); mid-grey in a file is about
        21 % of the light of white, ``((0.5 + 0.055) / 1.055) ** 2.4``:

        >>> [round(v, 4) for v in srgb_to_linear(torch.tensor([0.0, 0.04045, 0.5, 1.0])).tolist()]
        [0.0, 0.0031, 0.214, 1.0]
    """
    low = srgb / 12.92
    high = ((srgb.clamp(min=0.04045) + 0.055) / 1.055) ** 2.4
    return torch.where(srgb <= 0.04045, low, high)


def srgb_decoding_table(levels: int = 255) -> Tensor:
    """The linear value of every code ``0..levels`` of an sRGB-encoded integer image.

    This is how an 8-bit (``levels=255``) or 16-bit (``65535``) sRGB file is linearised: the code
    ``c`` stands for ``srgb_to_linear(c / levels)``, evaluated in float64 and stored as float32.
    ``brdfgan predict`` decodes JPEG/PNG photos with it and the training sensor simulation
    (:mod:`brdfgan.data.phone.sensor`) decodes its simulated JPEGs with it, so both see the same values.

    Shape:
        - output: ``(levels + 1,)`` float32; index it with the codes (as int64)
    """
    codes = torch.arange(levels + 1, dtype=torch.float64) / levels
    return srgb_to_linear(codes).to(torch.float32)


def linear_to_srgb(linear: Tensor) -> Tensor:
    """The IEC 61966-2-1 sRGB encoding curve, elementwise, for values in [0, 1].

    The clamp inside the power keeps the gradient finite on the linear segment.

    Shape: any; output has the input's shape.

    Example:
        An 18 % grey card encodes to about 0.46, and the curve inverts :func:`srgb_to_linear`:

        >>> round(linear_to_srgb(torch.tensor(0.18)).item(), 4)
        0.4614
        >>> codes = torch.linspace(0.0, 1.0, 11, dtype=torch.float64)
        >>> torch.allclose(linear_to_srgb(srgb_to_linear(codes)), codes)
        True
    """
    low = linear * 12.92
    high = 1.055 * linear.clamp(min=0.0031308) ** (1.0 / 2.4) - 0.055
    return torch.where(linear <= 0.0031308, low, high)


def encode_normal(normal: Tensor) -> Tensor:
    """Unit normal in [-1, 1] → file encoding ``(n + 1) / 2`` in [0, 1]. Shape: any.

    Example:
        A flat normal (+Z) is the familiar normal-map lavender, (128, 128, 255) in 8 bits:

        >>> encode_normal(torch.tensor([0.0, 0.0, 1.0])).tolist()
        [0.5, 0.5, 1.0]
    """
    return (normal + 1.0) * 0.5


def decode_normal(encoded: Tensor, dim: int = -3) -> Tensor:
    """File encoding in [0, 1] → renormalised unit normal (quantisation breaks unit length).

    Shape:
        - encoded: ``(*, 3, H, W)`` (vector axis ``dim``)
        - output: same

    Example:
        >>> normal = normalize_normal(torch.tensor([0.3, -0.4, 0.8]), dim=0)
        >>> torch.allclose(decode_normal(encode_normal(normal), dim=0), normal)
        True
        >>> lavender = torch.tensor([128.0, 128.0, 255.0]) / 255  # 8-bit: not quite (0, 0, 1)
        >>> round(decode_normal(lavender, dim=0).norm().item(), 6)
        1.0
    """
    return normalize_normal(encoded * 2.0 - 1.0, dim=dim)


def normalize_normal(normal: Tensor, dim: int = -3, eps: float = 1e-8) -> Tensor:
    """Rescale vectors to unit length along ``dim``; a zero vector becomes +Z.

    Shape:
        - normal: ``(*, 3, H, W)`` (vector axis ``dim``)
        - output: same

    Example:
        >>> [round(v, 4) for v in normalize_normal(torch.tensor([3.0, 0.0, 4.0]), dim=0).tolist()]
        [0.6, 0.0, 0.8]
        >>> normalize_normal(torch.zeros(3), dim=0).tolist()
        [0.0, 0.0, 1.0]
    """
    # Summed products rather than linalg.vector_norm: a norm over the strided channel axis is
    # several times slower on CPU, and this runs on every normal map the data pipeline touches.
    length = (normal * normal).sum(dim=dim, keepdim=True).sqrt()
    # +Z as a broadcast (1, …, 3, …, 1) tensor, not a full-size one: the fallback is rare.
    shape = [1] * normal.ndim
    shape[dim] = 3
    up = normal.new_zeros(shape)
    up.narrow(dim, 2, 1).fill_(1.0)
    return torch.where(length > eps, normal / length.clamp(min=eps), up)


def scale_normal_strength(normal: Tensor, strength: float) -> Tensor:
    """Normals with their tilt exaggerated (``strength > 1``) or flattened (``< 1``): the tangent
    components scaled by ``strength``, then renormalised — the slopes of the surface scale by
    ``strength``, as glTF's ``normalTexture.scale`` does.

    Shape: ``(*, 3, H, W)`` unit normals → same.
    """
    if not (strength >= 0 and math.isfinite(strength)):
        raise ValueError(f"normal strength must be a finite number >= 0, got {strength}")
    scale = normal.new_tensor([strength, strength, 1.0]).view(3, 1, 1)
    return normalize_normal(normal * scale)


def roughness_to_alpha(roughness: Tensor) -> Tensor:
    """Perceptual roughness → GGX alpha = max(r², 0.001) (Mitsuba principled, Disney). Shape: any.

    Example:
        >>> [round(v, 4) for v in roughness_to_alpha(torch.tensor([0.0, 0.5, 1.0])).tolist()]
        [0.001, 0.25, 1.0]
    """
    return (roughness * roughness).clamp(min=MIN_ALPHA)


def diffuse_albedo(basecolor_linear: Tensor, metallic: Tensor) -> Tensor:
    """Paper §3: d = b (1 - m), with b the linear base color.

    Shape:
        - basecolor_linear: ``(*, 3, H, W)``; metallic: ``(*, 1, H, W)``
        - output: ``(*, 3, H, W)``

    Example:
        A dielectric diffuses its base color, a metal not at all:

        >>> b = torch.full((3, 1, 1), 0.8)
        >>> [round(diffuse_albedo(b, torch.full((1, 1, 1), m)).mean().item(), 4) for m in (0.0, 0.5, 1.0)]
        [0.8, 0.4, 0.0]
    """
    return basecolor_linear * (1.0 - metallic)


def specular_albedo(basecolor_linear: Tensor, metallic: Tensor) -> Tensor:
    """Paper §3: F0 = s = 0.04 (1 - m) + b m, with b the linear base color.

    Shape:
        - basecolor_linear: ``(*, 3, H, W)``; metallic: ``(*, 1, H, W)``
        - output: ``(*, 3, H, W)``

    Example:
        A dielectric reflects 4 % at normal incidence whatever its colour, a metal its base color:

        >>> b = torch.full((3, 1, 1), 0.8)
        >>> [round(specular_albedo(b, torch.full((1, 1, 1), m)).mean().item(), 4) for m in (0.0, 0.5, 1.0)]
        [0.04, 0.42, 0.8]
    """
    return DIELECTRIC_F0 * (1.0 - metallic) + basecolor_linear * metallic


def flat_maps(
    height: int,
    width: int,
    basecolor: tuple[float, float, float] = (0.5, 0.5, 0.5),
    roughness: float = 0.5,
    metallic: float = 0.0,
    batch: tuple[int, ...] = (),
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> Tensor:
    """A uniform map set with a flat (+Z) normal; handy as a default and in tests.

    Shape:
        - output: ``(*batch, 8, height, width)``

    Example:
        >>> maps = flat_maps(2, 3, roughness=0.3, batch=(4,))
        >>> tuple(maps.shape)
        (4, 8, 2, 3)
        >>> [round(v, 4) for v in maps[0, :, 1, 2].tolist()]
        [0.5, 0.5, 0.5, 0.0, 0.0, 1.0, 0.3, 0.0]
    """
    values = torch.tensor([*basecolor, 0.0, 0.0, 1.0, roughness, metallic], dtype=dtype, device=device)
    return (
        values.view(*([1] * len(batch)), NUM_CHANNELS, 1, 1)
        .expand(*batch, NUM_CHANNELS, height, width)
        .clone()
    )


def resize_image(image: Tensor, height: int, width: int) -> Tensor:
    """Area averaging when shrinking (every texel counts, no aliasing), bilinear when enlarging.

    Shape:
        - image: ``(C, H, W)``
        - output: ``(C, height, width)``
    """
    if tuple(image.shape[-2:]) == (height, width):
        return image
    batch = image.unsqueeze(0)
    if height <= image.shape[-2] and width <= image.shape[-1]:
        return F.interpolate(batch, size=(height, width), mode="area")[0]
    return F.interpolate(batch, size=(height, width), mode="bilinear", align_corners=False)[0]


def resize_maps(maps: Tensor, size: int | tuple[int, int]) -> Tensor:
    """Resize one map set (e.g. for rendering a preview at a smaller size).

    Base color is averaged in linear (what light does) and re-encoded; normals are averaged and
    renormalised; roughness and metallic are averaged as stored. Averaging normals and roughness
    separately loses the sub-pixel normal variation a prefiltered roughness would keep — fine
    for a preview, not for training data.

    Shape:
        - maps: ``(8, H, W)``
        - output: ``(8, h, w)`` with ``(h, w) = size`` (an int means square)

    Example:
        A black-and-white checkerboard shrinks to half the *light* of white, which is
        ``linear_to_srgb(0.5)`` ≈ 0.7354 in the file, not 0.5:

        >>> maps = flat_maps(2, 2)
        >>> maps[0:3] = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
        >>> small = resize_maps(maps, 1)
        >>> tuple(small.shape), round(small[0, 0, 0].item(), 4)
        ((8, 1, 1), 0.7354)
        >>> torch.allclose(resize_maps(flat_maps(8, 8), (2, 4)), flat_maps(2, 4))
        True
    """
    check_single_maps(maps)
    height, width = (size, size) if isinstance(size, int) else size
    if height < 1 or width < 1:
        raise ValueError(f"size must be positive, got {size}")
    if tuple(maps.shape[-2:]) == (height, width):
        return maps
    parts = split_maps(maps)
    basecolor = linear_to_srgb(resize_image(srgb_to_linear(parts.basecolor), height, width).clamp(0.0, 1.0))
    normal = normalize_normal(resize_image(parts.normal, height, width))
    roughness = resize_image(parts.roughness, height, width).clamp(0.0, 1.0)
    metallic = resize_image(parts.metallic, height, width).clamp(0.0, 1.0)
    return join_maps(basecolor, normal, roughness, metallic)
