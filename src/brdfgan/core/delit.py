"""The de-lit photo: a flash photo divided by the flash's falloff on a flat surface.

Under a point flash at the lens, a flat Lambertian surface of albedo ``ρ`` photographed from
distance ``d`` along the axis returns, at a pixel whose offset from the hotspot is ``o`` (in units
of the camera distance, :func:`~brdfgan.core.flash_geometry.flash_offset_channels`), the radiance
``ρ/π · I cos θ / r²`` with ``r² = d² (1 + |o|²)`` and ``cos θ = 1 / √(1 + |o|²)``. Relative to the
hotspot that is the **flat-surface falloff**

    ``falloff(o) = (1 + |o|²)^(−3/2)``

so ``photo / falloff`` is the photo with the flash's geometric light distribution removed: a
uniform matte material comes out uniform whatever the field of view (the field of view sets how
far ``|o|`` reaches at the photo's edges: ±0.18 at 20°, ±0.77 at 75°). What remains in it is the
material's albedo times the exposure, plus what the flat-diffuse model does not explain: the
specular highlight (clipped here), relief shading and environment light.

It is the photo-anchored starting point of a base-colour estimate (``brdfgan.models.reference
.DeLitPhoto`` and the next default model), and a physics heuristic that real phone captures
showed to relight better than the v3 network (docs: issue 31).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from brdfgan.core.brdf import evaluate_brdf
from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import luminance
from brdfgan.core.flash_geometry import check_flash_frame, flash_offset_channels
from brdfgan.core.svbrdf import normalize_normal

# The hotspot is clipped at this multiple of the de-lit luminance's upper quartile: a glossy
# highlight is several times brighter than the albedo around it, a matte one's peak is not
# clipped (measured on real phone captures: docs/ood.md, the de_lit reference).
HOTSPOT_CLIP_FACTOR = 1.5
HOTSPOT_CLIP_QUANTILE = 0.75


def flat_flash_falloff(frame: Tensor, height: int, width: int) -> Tensor:
    """The flash's irradiance on a flat surface relative to its hotspot, ``(1 + |o|²)^(−3/2)``,
    with ``o`` each pixel's offset from the hotspot in camera distances (module docstring).

    Shape:
        - frame: ``(B, 3)`` flash frame ``(x, y, s)``
        - output: ``(B, 1, height, width)`` in ``(0, 1]``, 1 at the hotspot

    Example:
        A 3 × 3 photo with a 90° field of view: ``s = 2 tan 45° / 3 = 2/3`` per pixel, so a corner
        pixel is offset by ``(±2/3, ±2/3)`` and receives ``(1 + 8/9)^(−3/2)`` of the hotspot's light:

        >>> from brdfgan.core.flash_geometry import centred_flash_frame
        >>> falloff = flat_flash_falloff(centred_flash_frame(1, 3, 3, fov_deg=90.0), 3, 3)
        >>> round(falloff[0, 0, 1, 1].item(), 4), round(falloff[0, 0, 0, 0].item(), 4)
        (1.0, 0.3852)
        >>> round((1 + 8 / 9) ** -1.5, 4)
        0.3852
    """
    offsets = flash_offset_channels(frame, height, width)
    return (1.0 + offsets.square().sum(dim=1, keepdim=True)).pow(-1.5)


def flash_directions(frame: Tensor, height: int, width: int) -> tuple[Tensor, Tensor]:
    """Each pixel's unit direction towards the flash at the lens, ``(−o, 1)/√(1 + |o|²)``, and its
    squared distance ``1 + |o|²`` in camera distances (``o`` its offset from the hotspot,
    :func:`~brdfgan.core.flash_geometry.flash_offset_channels`): the head-on flash's geometry.

    Shape:
        - frame: ``(B, 3)``
        - output: ``(B, 3, height, width)`` and ``(B, 1, height, width)``
    """
    offsets = flash_offset_channels(frame, height, width)
    distance_squared = 1.0 + offsets.square().sum(dim=1, keepdim=True)  # camera distances²
    towards_flash = torch.cat([-offsets, torch.ones_like(offsets[:, :1])], dim=1) / distance_squared.sqrt()
    return towards_flash, distance_squared


def flash_render(
    basecolor_linear: Tensor, normal: Tensor, roughness: Tensor, metallic: Tensor, frame: Tensor
) -> Tensor:
    """The flash photo of a surface with these maps, relative to the flash's irradiance at the
    hotspot: ``π f(l, v) max(n·l, 0) / (1 + |o|²)`` with the flash at the lens (``l = v =
    (−o, 1)/√(1 + |o|²)`` from each pixel towards the flash, ``o`` its offset from the hotspot in
    camera distances, :func:`~brdfgan.core.flash_geometry.flash_offset_channels`) and ``n`` the
    renormalised normal. With flat normals it is :func:`flat_flash_render`.

    Shape:
        - basecolor_linear, normal: ``(B, 3, H, W)``; roughness, metallic: ``(B, 1, H, W)``
        - frame: ``(B, 3)`` flash frame ``(x, y, s)``
        - output: ``(B, 3, H, W)``, non-negative
    """
    dims = check_shape(basecolor_linear, "B 3 H W", name="basecolor_linear")
    check_shape(normal, "B 3 H W", name="normal", dims=dims)
    check_flash_frame(frame, dims["B"])
    towards_flash, distance_squared = flash_directions(frame.to(basecolor_linear.dtype), dims["H"], dims["W"])
    unit = normalize_normal(normal)
    cosine = (unit * towards_flash).sum(dim=1, keepdim=True).clamp_min(0.0)
    brdf = evaluate_brdf(basecolor_linear, unit, roughness, metallic, towards_flash, towards_flash)
    return math.pi * brdf * cosine / distance_squared


def flat_flash_render(basecolor_linear: Tensor, roughness: Tensor, metallic: Tensor, frame: Tensor) -> Tensor:
    """The flash photo of a *flat* surface with these maps (:func:`flash_render` with normals
    +Z): ``π f(l, v) (1 + |o|²)^(−3/2)``, so a white Lambertian surface gives the falloff itself
    and 1 at the hotspot. The photo divided by it is the **shading image**: what the surface's
    relief (and light the flash model does not explain) did to the photo.

    Shape:
        - basecolor_linear: ``(B, 3, H, W)``; roughness, metallic: ``(B, 1, H, W)``
        - frame: ``(B, 3)``
        - output: ``(B, 3, H, W)``
    """
    flat = torch.zeros_like(basecolor_linear)
    flat[:, 2] = 1.0
    return flash_render(basecolor_linear, flat, roughness, metallic, frame)


def hotspot_cap(
    image: Tensor, factor: float = HOTSPOT_CLIP_FACTOR, quantile: float = HOTSPOT_CLIP_QUANTILE
) -> Tensor:
    """``factor`` × the image's ``quantile`` of luminance: the level :func:`clip_hotspot` caps at.

    Shape:
        - image: ``(B, 3, H, W)`` linear RGB, non-negative
        - output: ``(B,)``
    """
    check_shape(image, "B 3 H W", name="image")
    if not factor > 0 or not 0.0 < quantile <= 1.0:
        raise ValueError(f"need factor > 0 and 0 < quantile <= 1, got {factor=}, {quantile=}")
    return factor * torch.quantile(luminance(image).flatten(1).float(), quantile, dim=1).to(image.dtype)


def clip_hotspot(
    image: Tensor,
    factor: float = HOTSPOT_CLIP_FACTOR,
    quantile: float = HOTSPOT_CLIP_QUANTILE,
    *,
    cap: Tensor | None = None,
) -> Tensor:
    """Scale down every pixel whose luminance exceeds ``factor`` × the image's ``quantile`` of
    luminance (or a given ``cap``: a tile of a photo uses the whole photo's) to that level,
    keeping its chromaticity (a clipped highlight stays the albedo's hue rather than turning white).

    Shape:
        - image: ``(B, 3, H, W)`` linear RGB, non-negative
        - cap: ``(B,)`` or ``(B, 1)``, optional
        - output: same as image
    """
    if cap is None:
        cap = hotspot_cap(image, factor, quantile)
    lum = luminance(image)  # (B, 1, H, W)
    cap = cap.to(image.dtype).reshape(-1, 1, 1, 1)
    scale = torch.where(lum > cap, cap / lum.clamp_min(torch.finfo(image.dtype).tiny), torch.ones_like(lum))
    return image * scale


def delit_photo(photo: Tensor, frame: Tensor, *, clip: bool = True) -> Tensor:
    """The linear photo divided by the flat-surface flash falloff for its flash frame (its field
    of view and hotspot), the hotspot then clipped (:func:`clip_hotspot`) unless ``clip=False``.
    No exposure gain: multiply by one to get an albedo estimate.

    Shape:
        - photo: ``(B, 3, H, W)`` linear LDR
        - frame: ``(B, 3)``
        - output: ``(B, 3, H, W)`` linear, non-negative (not bounded above)

    Example:
        The flash photo of a flat matte surface of albedo 0.3 (the falloff times 0.3) comes out
        de-lit as a uniform 0.3:

        >>> from brdfgan.core.flash_geometry import centred_flash_frame
        >>> frame = centred_flash_frame(1, 5, 5, fov_deg=60.0)
        >>> photo = 0.3 * flat_flash_falloff(frame, 5, 5).expand(1, 3, 5, 5)
        >>> torch.allclose(delit_photo(photo, frame), torch.full((1, 3, 5, 5), 0.3))
        True
    """
    check_shape(photo, "B 3 H W", name="photo")
    check_flash_frame(frame, photo.shape[0])
    falloff = flat_flash_falloff(frame.to(photo.dtype), photo.shape[-2], photo.shape[-1])
    delit = photo.clamp_min(0.0) / falloff
    return clip_hotspot(delit) if clip else delit


__all__ = [
    "HOTSPOT_CLIP_FACTOR",
    "HOTSPOT_CLIP_QUANTILE",
    "clip_hotspot",
    "delit_photo",
    "flat_flash_falloff",
    "flat_flash_render",
    "hotspot_cap",
]
