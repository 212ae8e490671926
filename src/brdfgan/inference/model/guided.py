"""``brdfgan predict``'s guided fast path: a photo-anchored network runs at a capped side and its
outputs are carried up to the output side, guided by the full-resolution photo.

Why it can: the anchored network's base colour is the de-lit photo times per-pixel corrections
(:func:`~brdfgan.models.anchored.compose_basecolor`), so its detail comes from the photo, not from
the network — and the network's cost grows with the pixel count. So for an output side above the
cap the network reads the photo shrunk to the cap (area average); then, at the output side:

1. the anchor (the de-lit photo, its hotspot clipped at the level the network's pass measured,
   times its gain) is recomputed from the full-resolution photo
   (:meth:`~brdfgan.models.anchored.AnchoredUNet.anchor`);
2. the corrections (log-gain, residual, metal colour, metallic), the normals and the roughness are
   carried up with :func:`~brdfgan.core.filtering.guided_upsample`, guided by the log of that
   anchor averaged over its channels (the network's own input channel, in which the log-gain acts
   additively);
3. the base colour is composed from the full-resolution anchor and the carried corrections, the
   model's own composition.

What it costs in fidelity against running the network at the output side, and the measure that
the maps keep the photo's detail: docs/predict.md ("Output resolution"). An explicit
``--resolution`` always runs the network at that side (the exact path).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.filtering import guided_upsample, split_bands
from brdfgan.core.flash_geometry import check_flash_frame
from brdfgan.core.svbrdf import NORMAL, NUM_CHANNELS, ROUGHNESS, join_maps, linear_to_srgb, normalize_normal
from brdfgan.models.anchored import CORRECTION_CHANNELS, LOG_EPS, AnchoredUNet, compose_basecolor

# The largest side the anchored network runs at when the user did not ask for a resolution
# (docs/predict.md#output-resolution: the measurements that chose it).
DEFAULT_NETWORK_CAP = 1024
# guided_upsample's window radius (network pixels) and ridge (log-anchor units squared).
GUIDE_RADIUS = 1
GUIDE_EPS = 1e-3
METHOD = "guided_upsample (a guided filter's slopes, He & Sun 2015), guide: mean log anchor"
CARRIED = ("log-gain", "residual", "metal colour", "metallic", "normal", "roughness")


def anchored_network(generator: nn.Module) -> AnchoredUNet | None:
    """``generator`` when it is a photo-anchored :class:`AnchoredUNet` (the only kind the fast path
    suits: others draw their base colour's detail from the network), else ``None``."""
    return generator if isinstance(generator, AnchoredUNet) and generator.anchored else None


# MapsAndCorrections' output: the maps, the corrections, the anchor's hotspot cap (one channel).
OUTPUT_CHANNELS = NUM_CHANNELS + CORRECTION_CHANNELS + 1


class MapsAndCorrections(nn.Module):
    """An anchored network whose forward returns its maps, its base colour's corrections and the
    level its anchor's hotspot was clipped at (constant over the image),
    ``(B, OUTPUT_CHANNELS, H, W)``: a generator the tiling runs like any other (frozen
    statistics, blended tiles) when the capped side is still above the tile, and all
    :func:`carry_up` needs of the network."""

    def __init__(self, network: AnchoredUNet) -> None:
        super().__init__()
        self.network = network

    @property
    def size_multiple(self) -> int:
        return self.network.size_multiple

    def check_input(self, photo: Tensor) -> None:
        self.network.check_input(photo)

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        caps: list[Tensor] = []  # the cap module's output (in tiles: the whole photo's, replayed)
        hook = self.network.hotspot_cap.register_forward_hook(lambda _module, _args, cap: caps.append(cap))
        try:
            maps, corrections = self.network.maps_and_corrections(photo, flash)
        finally:
            hook.remove()
        assert corrections is not None  # anchored_network admits anchored networks only
        cap = caps[0].to(maps.dtype)[:, :, None, None].expand(-1, 1, *maps.shape[-2:])
        return torch.cat([maps, corrections, cap], dim=1)


def shrink_photo(photo: Tensor, side: int) -> Tensor:
    """The photo the network reads on the fast path: area-averaged to ``side`` (each network pixel
    the mean of the photo's pixels it covers, as predict's own resize does for whole factors).

    Shape: ``(B, 3, N, N)`` → ``(B, 3, side, side)``.
    """
    check_shape(photo, "B 3 N N", name="photo")
    if not 1 <= side <= photo.shape[-1]:
        raise ValueError(f"side must be in [1, {photo.shape[-1]}], got {side}")
    return F.interpolate(photo, size=(side, side), mode="area")


def carry_up(network: AnchoredUNet, outputs: Tensor, photo: Tensor, flash: Tensor) -> Tensor:
    """The maps at the photo's side from the network's outputs at a smaller side (module docstring).

    Args:
        network: the anchored network that produced ``outputs``.
        outputs: :class:`MapsAndCorrections`' output on :func:`shrink_photo` of ``photo``.
        photo: the full-resolution photo, linear LDR in [0, 1].
        flash: the full-resolution photo's flash frame.

    Shape:
        - outputs: ``(1, OUTPUT_CHANNELS, n, n)``
        - photo: ``(1, 3, N, N)``, N >= n; flash: ``(1, 3)``
        - output: ``(1, 8, N, N)`` maps
    """
    check_shape(outputs, f"1 {OUTPUT_CHANNELS} n n", name="outputs")
    check_shape(photo, "1 3 N N", name="photo")
    check_flash_frame(flash, 1)
    if outputs.shape[-1] > photo.shape[-1]:
        raise ValueError(f"outputs ({outputs.shape[-1]}²) are larger than the photo ({photo.shape[-1]}²)")
    maps, corrections = outputs[:, :NUM_CHANNELS], outputs[:, NUM_CHANNELS:-1]
    # The hotspot is clipped where the network's own anchor was: at the cap of the photo it read.
    anchor = network.anchor(photo, flash, cap=outputs[:, -1, 0, :1])
    source = torch.cat([corrections, maps[:, NORMAL], maps[:, ROUGHNESS]], dim=1)
    # One grey guide: measured as good as the three channels, at a third of the regressions.
    guide = (anchor + LOG_EPS).log().mean(dim=1, keepdim=True)
    carried = guided_upsample(source, guide, GUIDE_RADIUS, GUIDE_EPS)
    corrections = carried[:, :CORRECTION_CHANNELS]
    normal, roughness = carried[:, CORRECTION_CHANNELS : CORRECTION_CHANNELS + 3], carried[:, -1:]
    return join_maps(
        linear_to_srgb(compose_basecolor(anchor, corrections)),
        normalize_normal(normal),
        roughness.clamp(0.0, 1.0),
        corrections[:, -1:].clamp(0.0, 1.0),  # the metallic the base colour was blended with
    )


@dataclass(frozen=True)
class BandDetail:
    """How much of a reference's detail above a resolution an image has (:func:`band_detail`)."""

    correlation: float  # of the two detail bands, over all pixels and channels
    energy_ratio: float  # the image's detail energy over the reference's


def band_detail(image: Tensor, reference: Tensor, side: int) -> BandDetail:
    """The detail measure of the fast path: the band of two linear images above the resolution
    ``side`` (:func:`~brdfgan.core.filtering.split_bands`), in log (relative detail, whatever gain
    separates them), their correlation and energy ratio. With ``side`` the network's and the
    de-lit photo as the reference, it says whether a base colour has the photo's detail that the
    network could not see: 1 and 1 when it has all of it unchanged, a ratio ~0 for a plain
    enlargement of the network's maps.

    Shape:
        - image, reference: ``(B, C, H, W)`` linear, ``side <= H, W``
    """
    if image.shape != reference.shape:
        raise ValueError(f"image {tuple(image.shape)} and reference {tuple(reference.shape)} differ")
    band = split_bands((image.float().clamp_min(0.0) + LOG_EPS).log(), side, side)[1]
    reference_band = split_bands((reference.float().clamp_min(0.0) + LOG_EPS).log(), side, side)[1]
    energy, reference_energy = band.square().sum(), reference_band.square().sum()
    correlation = (band * reference_band).sum() / (energy * reference_energy).sqrt().clamp_min(1e-30)
    return BandDetail(float(correlation), float(energy / reference_energy.clamp_min(1e-30)))


def upsampling_record(network_side: int, side: int) -> dict[str, Any]:
    """``material.json``'s record of which path ran: the network's side, the output side and, on
    the fast path, how the outputs were carried up (``None`` on the exact path)."""
    upsampling = None
    if network_side != side:
        upsampling = {"method": METHOD, "radius": GUIDE_RADIUS, "eps": GUIDE_EPS, "carried": list(CARRIED)}
    return {"network_resolution": network_side, "output_resolution": side, "upsampling": upsampling}


__all__ = [
    "DEFAULT_NETWORK_CAP",
    "OUTPUT_CHANNELS",
    "BandDetail",
    "MapsAndCorrections",
    "anchored_network",
    "band_detail",
    "carry_up",
    "shrink_photo",
    "upsampling_record",
]
