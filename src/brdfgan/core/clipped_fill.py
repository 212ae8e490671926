"""The flash's own marks in the maps: clipped pixels brought back to their surroundings, the
hotspot's disc levelled, and metal taken off thin dark features (issue 60, item 2).

A clipped pixel of a flash photo (any channel at :data:`CLIP_LEVEL` or more) says only that the
surface sent back at least that much light: it is no evidence of base colour, roughness or
metallic. On a dielectric the network reads the clipped flash as a grey or white base colour and
often as metal (the wood-plank sample's grey disc and bright metallic disc, the white streaks the
glints leave on glossy black tiles). :func:`fill_clipped` changes base colour, roughness and
metallic there only as far as the surroundings contradict them:

- **into the surroundings' range** (:func:`surroundings_range`): each clipped pixel's values are
  clamped into the mean ± :data:`RANGE_SPREAD` standard deviations of the unclipped pixels around
  it. Replacing them outright by a fill from the rim (push-pull) was tried and measured worse: the
  rim of a clipped region is often what stopped the clipping (a dark groove, the binder between an
  asphalt's stones), and the clipped pixels are a texture's brightest and glossiest part, a bare
  metal patch in rust among them; the clamp keeps a reading the neighbourhood allows and removes
  one it does not (a white glint on black tile, metal in wood);
- **from the same place elsewhere in the pattern** (:func:`twin_fill`, :class:`Twins`), for a
  periodic material whose two lattice vectors are known: the median of the unclipped twins one or
  two periods away, which keeps the pattern (a grout line crossing the hole stays a grout line);
  for a 1-D pattern (planks, courses) whose stripes' direction is known: twins along the stripes,
  where grooves and gaps run on. Pixels with no unclipped twin fall back to the clamp. Given a
  pattern, :func:`remove_flash` fills the hotspot's whole disc this way (the larger of the flash
  mark's reach and the highlight's), clipped or not: on a plain tile the network leaves a dot and
  a halo there, and on glossy planks a clipped streak longer than the mark's round patch, that a
  tiled sheet would repeat.

Normals are kept: a clipped hotspot leaves them flat rather than wrong, and the flash-mark repair
patches a dimple.

**The disc** around the hotspot reaches as far as the highlight (:func:`highlight_radius`, from
the photo), well beyond the clipped pixels; :func:`~brdfgan.core.flash_mark.repair_flash_mark`
levels it given that radius.

**Thin dark features are not metal** (:func:`suppress_false_metal`): the network reads the dark
gaps between planks and the grout between tiles as metal lines. On a texel darker than the
closing of the photo's luminance (else the base colour's) over a :data:`THIN_WINDOW_FRACTION` ×
side window by :data:`THIN_DARKNESS` (a gap or groove narrower than the window), the metallic is
lowered to the opening of the metallic over the same window — the metal of the surroundings once
features narrower than the window are removed — so a gap in a metal surface stays metal and a gap
in wood becomes wood. Where the surface around reads as metal on average (:data:`METAL_AROUND`
over :data:`METAL_AROUND_WINDOWS` windows) the rule stands down: a perforated or engraved metal's
holes are thin dark features too, and the network's metallic there is patchy, so the opening
would eat real metal (measured: pavers mixed with perforated anodized metal lost up to 0.08).

:func:`remove_flash` chains the three: what ``brdfgan predict`` runs on every prediction. The
constants were chosen on over-exposed renders of held-out materials
(research/notes/2026-12-flash-leak.md, ``python -m research.flash_leak_table``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.delit import delit_photo
from brdfgan.core.exposure import luminance
from brdfgan.core.filtering import box_mean, gaussian_blur, smoothstep
from brdfgan.core.flash_geometry import check_flash_frame, hotspot_distance, resize_flash_frame
from brdfgan.core.flash_mark import REPAIR_INNER, FlashMark, mark_radius, repair_flash_mark
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, ROUGHNESS, check_single_maps, srgb_to_linear

# A pixel with a channel at or above this is clipped (the refinement's and the pair fit's level).
CLIP_LEVEL = 0.98
# The clipped mask is dilated by this fraction of the shorter side (2 px at 256²): a clipped
# pixel's neighbours are blurred with it by the lens, the demosaic and the resize.
CLIP_DILATION_FRACTION = 1.0 / 128.0
# The smooth measures (the surroundings' range, the highlight's reach) run at most this many pixels
# across, on an area-averaged copy.
WORKING_SIDE = 256
# The surroundings' range (surroundings_range): its Gaussian (fraction of the shorter side), the
# share of known pixels a neighbourhood needs to be trusted, and the range's half-width in
# standard deviations.
RANGE_SIGMA_FRACTION = 1.0 / 32.0
RANGE_MIN_KNOWN = 0.25
RANGE_SPREAD = 1.0
# The lattice fill looks this many periods away along each lattice vector; the stripes' fill this
# many times the hole's radius along the stripes, both ways (Twins).
LATTICE_REACH = 2
STRIPE_TWIN_STEPS = (1.0, 1.25, 1.5, 1.75, 2.0)
# Thin dark features: the window (fraction of the shorter side; 9 px at 256²) and how much darker
# than the window's closing a texel must be (smoothstep from the first to the second value).
THIN_WINDOW_FRACTION = 9.0 / 256.0
THIN_DARKNESS = (0.15, 0.35)
# The surroundings that read as metal (suppress_false_metal): the mean metallic over a box of this
# many thin windows, and the smoothstep edges over which the rule stands down.
METAL_AROUND_WINDOWS = 3
METAL_AROUND = (0.25, 0.45)
# The thin-dark rule runs at most this many pixels across (its window is 18 px there).
THIN_WORKING_SIDE = 512
# The highlight's extent (:func:`highlight_radius`): where the ring median of the de-lit photo
# falls to (1 + HIGHLIGHT_EXCESS) × the far field's; never beyond HIGHLIGHT_MAX_FRACTION × side.
HIGHLIGHT_EXCESS = 0.25
HIGHLIGHT_MAX_FRACTION = 0.3
HIGHLIGHT_FAR = (0.3, 0.5)  # the far field, in fractions of the shorter side
HIGHLIGHT_STEP = 2.0  # ring width, pixels at WORKING_SIDE


def _dilate(mask: Tensor, radius: int) -> Tensor:
    """``mask`` grown by a square of ``radius`` pixels. Shape: ``(H, W)`` bool → same."""
    if radius <= 0:
        return mask
    return _dilate_values(mask.float()[None, None], 2 * radius + 1)[0, 0] > 0


def clipped_mask(photo: Tensor, level: float = CLIP_LEVEL) -> Tensor:
    """The photo's clipped pixels (any channel at ``level`` or more), dilated by
    :data:`CLIP_DILATION_FRACTION` × the shorter side.

    Shape: photo ``(3, H, W)`` linear LDR → ``(H, W)`` bool.
    """
    dims = check_shape(photo, "3 H W", name="photo")
    radius = max(1, round(CLIP_DILATION_FRACTION * min(dims["H"], dims["W"])))
    return _dilate((photo >= level).any(dim=0), radius)


def push_pull_fill(image: Tensor, known: Tensor) -> Tensor:
    """``image`` filled where ``known`` is 0 from where it is 1 (weights between blend): a
    normalised-convolution pyramid. Pull: 2 × 2 sums of the weighted values and the weights (capped
    at 1) down to one pixel; push: each level is its own weighted value plus the coarser level's
    bilinear enlargement times the missing weight. Pixels with weight 1 keep their value exactly;
    a hole gets a smooth blend of its rim, further rims weighing less.

    Shape: image ``(C, H, W)``; known ``(H, W)`` in [0, 1] → ``(C, H, W)``. All zero weights give
    zeros.

    Example:
        >>> image = torch.tensor([[[1.0, 0.0, 3.0]]])
        >>> push_pull_fill(image, torch.tensor([[1.0, 0.0, 1.0]])).tolist()
        [[[1.0, 2.0, 3.0]]]
    """
    dims = check_shape(image, "C H W", name="image")
    check_shape(known, "H W", name="known", dims=dims)
    weight = known.to(image.dtype).clamp(0.0, 1.0)[None, None]
    value = image[None] * weight
    levels: list[tuple[Tensor, Tensor]] = []
    while max(weight.shape[-2:]) > 1:
        levels.append((value, weight))
        pad = (0, weight.shape[-1] % 2, 0, weight.shape[-2] % 2)
        value_sum = F.avg_pool2d(F.pad(value, pad), 2) * 4.0
        weight_sum = F.avg_pool2d(F.pad(weight, pad), 2) * 4.0
        # Normalised, then weighted by the capped weight: a coarse pixel over several known ones
        # counts as one known pixel.
        capped = weight_sum.clamp_max(1.0)
        value = value_sum / weight_sum.clamp_min(1e-12) * capped
        weight = capped
    filled = value / weight.clamp_min(1e-12)
    for value, weight in reversed(levels):
        enlarged = F.interpolate(filled, size=weight.shape[-2:], mode="bilinear", align_corners=False)
        filled = value + (1.0 - weight) * enlarged
    return filled[0]


def surroundings_range(image: Tensor, known: Tensor, spread: float) -> tuple[Tensor, Tensor]:
    """Per pixel, the range ``mean ± spread · sd`` of the known pixels around it: their mean and
    standard deviation under a Gaussian of :data:`RANGE_SIGMA_FRACTION` × the shorter side
    (normalised convolution), carried into holes wider than that by :func:`push_pull_fill` from the
    pixels whose neighbourhood is at least :data:`RANGE_MIN_KNOWN` known. Computed on a copy
    area-averaged to at most :data:`WORKING_SIDE` (the moments are smooth), then enlarged.

    Shape: image ``(C, H, W)``; known ``(H, W)`` in [0, 1] → low and high ``(C, H, W)``.
    """
    dims = check_shape(image, "C H W", name="image")
    check_shape(known, "H W", name="known", dims=dims)
    height, width = dims["H"], dims["W"]
    factor = max(1, math.ceil(min(height, width) / WORKING_SIDE))
    size = (max(1, height // factor), max(1, width // factor))
    weight = known.to(image.dtype)[None, None]
    stack = torch.cat([weight, image[None] * weight, image[None].square() * weight], dim=1)
    small = F.interpolate(stack, size=size, mode="area")
    sigma = max(1.0, RANGE_SIGMA_FRACTION * min(size))
    blurred = gaussian_blur(small, sigma, "reflect")[0]
    share, channels = blurred[:1], image.shape[0]
    mean = blurred[1 : 1 + channels] / share.clamp_min(1e-6)
    square = blurred[1 + channels :] / share.clamp_min(1e-6)
    trusted = (share[0] / RANGE_MIN_KNOWN).clamp(0.0, 1.0)
    moments = push_pull_fill(torch.cat([mean, square]), trusted)
    moments = F.interpolate(moments[None], size=(height, width), mode="bilinear", align_corners=False)[0]
    mean, square = moments[:channels], moments[channels:]
    deviation = (square - mean.square()).clamp_min(0.0).sqrt()
    return mean - spread * deviation, mean + spread * deviation


@dataclass(frozen=True)
class Twins:
    """Where a pattern repeats itself, as seen from a pixel: the ``offsets`` ``(dx, dy)`` in pixels
    that carry it onto the same place in another cell, and the pattern's ``kind``:

    - ``"lattice"`` (:meth:`of_lattice`): ``i·a + j·b`` for ``|i|, |j| ≤`` :data:`LATTICE_REACH`,
      not both 0;
    - ``"stripes"`` (:meth:`along_stripes`): ``±s·d`` along the stripes' direction ``d`` for ``s`` in
      :data:`STRIPE_TWIN_STEPS` × ``reach``. Along its stripes a 1-D pattern (planks, courses) is the
      same at any distance: its grooves and gaps run on. Across them it repeats only roughly (one
      plank's tone is not the next's, and a coarser plank gap falls every few grooves), so twins
      across would fill a groove where the disc holds a gap. The steps start at ``reach`` so that
      a hole of that radius around the hotspot finds its twins beyond it (the nearer ones for the
      pixels near its edge, the farther ones for those across it).
    """

    kind: str
    offsets: tuple[tuple[float, float], ...]

    @classmethod
    def of_lattice(cls, vectors: tuple[tuple[float, float], tuple[float, float]]) -> Twins:
        (ax, ay), (bx, by) = vectors
        if not all(math.isfinite(v) for v in (ax, ay, bx, by)) or abs(ax * by - ay * bx) < 1.0:
            raise ValueError(
                f"the lattice vectors must be finite and span a cell of at least 1 px², got {vectors}"
            )
        steps = range(-LATTICE_REACH, LATTICE_REACH + 1)
        offsets = tuple((i * ax + j * bx, i * ay + j * by) for i in steps for j in steps if (i, j) != (0, 0))
        return cls("lattice", offsets)

    @classmethod
    def along_stripes(cls, along: tuple[float, float], reach: float) -> Twins:
        length = math.hypot(*along)
        if not (math.isfinite(length) and length > 0 and math.isfinite(reach) and reach > 0):
            raise ValueError(
                f"the stripes' direction must be finite and non-zero and the reach > 0, got {along}, {reach}"
            )
        dx, dy = along[0] / length, along[1] / length
        steps = [sign * step * reach for step in STRIPE_TWIN_STEPS for sign in (1, -1)]
        offsets = tuple((step * dx, step * dy) for step in steps)
        return cls("stripes", offsets)


def twin_fill(
    image: Tensor, hole: Tensor, twins: Twins, avoid: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """The hole's pixels taken from the same place elsewhere in a repeating pattern: per hole pixel
    the median of its twins ``p + offset`` (:class:`Twins`; bilinear samples) that lie inside the
    image and away from the hole and from ``avoid`` (pixels that are no evidence, clipped ones); and
    where a pixel found at least one twin.

    Shape: image ``(C, H, W)``; hole, avoid ``(H, W)`` bool → ``(C, H, W)`` (the image outside the
    hole, and where no twin was found) and ``(H, W)`` bool.
    """
    dims = check_shape(image, "C H W", name="image")
    check_shape(hole, "H W", name="hole", dims=dims)
    if avoid is not None:
        check_shape(avoid, "H W", name="avoid", dims=dims)
    rows, columns = torch.nonzero(hole, as_tuple=True)
    result, found = image.clone(), torch.zeros_like(hole)
    if rows.numel() == 0:
        return result, found
    offsets = torch.tensor(twins.offsets, dtype=torch.float64)
    height, width = dims["H"], dims["W"]
    x = columns.double()[:, None] + offsets[None, :, 0]  # (N, K)
    y = rows.double()[:, None] + offsets[None, :, 1]
    # grid_sample's normalised coordinates, pixel centres at (2i + 1)/size − 1.
    grid = torch.stack([(2 * x + 1) / width - 1, (2 * y + 1) / height - 1], dim=-1)[None].to(image.dtype)
    unusable = hole if avoid is None else hole | avoid
    sources = torch.cat([image, unusable[None].to(image.dtype)])[None]
    sampled = F.grid_sample(sources, grid, mode="bilinear", padding_mode="zeros", align_corners=False)[0]
    inside = (x >= 0) & (x <= width - 1) & (y >= 0) & (y <= height - 1)
    usable = inside & (sampled[-1] <= 0)  # no unusable pixel in the bilinear footprint
    values = torch.where(usable[None], sampled[:-1], torch.full_like(sampled[:-1], float("nan")))
    median = values.nanmedian(dim=-1).values  # (C, N)
    any_twin = usable.any(dim=-1)
    result[:, rows[any_twin], columns[any_twin]] = median[:, any_twin]
    found[rows[any_twin], columns[any_twin]] = True
    return result, found


# What a fill changes: normals are kept (module docstring).
FILLED_MAPS = (BASECOLOR, ROUGHNESS, METALLIC)
# The pattern disc blends into the maps over this many times its reach; the ring there sets its level.
DISC_BLEND = 1.3


def pattern_disc(
    maps: Tensor, distance: Tensor, reach: float, twins: Twins, clipped: Tensor | None = None
) -> Tensor:
    """Base colour, roughness and metallic within ``reach`` of the hotspot (``distance`` in pixels)
    taken from the same place elsewhere in the pattern (:func:`twin_fill`, never from a
    ``clipped`` pixel: a streak reaches beyond the disc along glossy planks), shifted by the median
    difference between the maps and their twins on the ring out to :data:`DISC_BLEND` × ``reach``
    (the network's maps drift in level across the photo: the twins are farther from the flash) and
    blended out over that ring. Pixels with no twin, and beyond the ring, are unchanged.

    Shape: maps ``(8, H, W)``; distance, clipped ``(H, W)`` → ``(8, H, W)``.
    """
    check_single_maps(maps)
    check_shape(distance, "H W", name="distance", dims={"H": maps.shape[-2], "W": maps.shape[-1]})
    outer = DISC_BLEND * reach
    area = distance <= outer
    if not bool(area.any()):
        return maps
    channels = _filled_channels(maps)
    twins_found, found = twin_fill(channels, area, twins, avoid=clipped)
    ring = found & (distance > reach) & area
    if not bool(ring.any()):
        return maps
    level = (channels - twins_found)[:, ring].median(dim=-1).values.view(-1, 1, 1)
    weight = (1.0 - smoothstep(reach, outer, distance)).to(maps.dtype) * found.to(maps.dtype)
    blended = (channels + weight * (twins_found + level - channels)).clamp(0.0, 1.0)
    return _with_filled_maps(maps, torch.where(area[None], blended, channels))


def _filled_channels(maps: Tensor) -> Tensor:
    """The channels of :data:`FILLED_MAPS`, stacked. Shape: ``(8, H, W)`` → ``(5, H, W)``."""
    return torch.cat([maps[part] for part in FILLED_MAPS])


def _with_filled_maps(maps: Tensor, channels: Tensor) -> Tensor:
    """``maps`` with :data:`FILLED_MAPS` replaced by ``channels``. Shape: ``(8, H, W)``, ``(5, H, W)``."""
    result = maps.clone()
    start = 0
    for part in FILLED_MAPS:
        count = part.stop - part.start
        result[part] = channels[start : start + count]
        start += count
    return result


@dataclass(frozen=True)
class ClippedFill:
    """What :func:`fill_clipped` did: the ``maps``; the share of pixels clipped (the mask given), of
    pixels changed, and of pixels taken from a twin elsewhere in the pattern; the ``method``
    (``"surroundings"``, the twins' kind (``"lattice"``, ``"stripes"``), or ``"none"`` when nothing
    was clipped)."""

    maps: Tensor
    clipped_fraction: float
    changed_fraction: float
    twin_fraction: float
    method: str

    def to_json(self) -> dict[str, Any]:
        return {
            "clip_level": CLIP_LEVEL,
            "range_spread": RANGE_SPREAD,
            "clipped_fraction": self.clipped_fraction,
            "changed_fraction": self.changed_fraction,
            "twin_fraction": self.twin_fraction,
            "method": self.method,
        }


def fill_clipped(
    maps: Tensor,
    clipped: Tensor,
    *,
    twins: Twins | None = None,
    spread: float = RANGE_SPREAD,
) -> ClippedFill:
    """The maps with base colour, roughness and metallic of the clipped pixels brought back to what
    their surroundings say (module docstring): from their ``twins`` elsewhere in a repeating pattern
    where given and found, else clamped into the range of the unclipped pixels around them
    (:func:`surroundings_range`, ``spread`` standard deviations). Normals and every unclipped pixel
    are unchanged, bit for bit; with no clipped pixel (or no unclipped one) the maps themselves are
    returned.

    Shape: maps ``(8, H, W)``; clipped ``(H, W)`` bool (:func:`clipped_mask` of the photo the maps
    were predicted from, at the maps' size) → :class:`ClippedFill` with maps ``(8, H, W)``.
    """
    check_single_maps(maps)
    check_shape(clipped, "H W", name="clipped", dims={"H": maps.shape[-2], "W": maps.shape[-1]})
    pixels = clipped.numel()
    if not bool(clipped.any()) or bool(clipped.all()):
        return ClippedFill(maps, float(clipped.float().mean()), 0.0, 0.0, "none")
    channels = _filled_channels(maps)
    low, high = surroundings_range(channels, (~clipped).to(maps.dtype), spread)
    filled = torch.minimum(torch.maximum(channels, low), high)
    found = torch.zeros_like(clipped)
    if twins is not None:
        from_twins, found = twin_fill(channels, clipped, twins)
        filled = torch.where(found[None], from_twins, filled)
    filled = torch.where(clipped[None], filled.clamp(0.0, 1.0), channels)
    return ClippedFill(
        maps=_with_filled_maps(maps, filled),
        clipped_fraction=float(clipped.sum()) / pixels,
        changed_fraction=float((filled != channels).any(dim=0).sum()) / pixels,
        twin_fraction=float((found & clipped).sum()) / pixels,
        method=twins.kind if twins is not None else "surroundings",
    )


def highlight_radius(photo: Tensor, frame: Tensor) -> float:
    """How far the flash's highlight reaches from the hotspot, in pixels: the first ring (of
    :data:`HIGHLIGHT_STEP` px) whose median de-lit luminance (the photo over the flat-surface
    falloff, :func:`~brdfgan.core.delit.delit_photo`) is at most (1 + :data:`HIGHLIGHT_EXCESS`) ×
    the median of the far field (:data:`HIGHLIGHT_FAR` × side from the hotspot, else the whole
    photo); at most :data:`HIGHLIGHT_MAX_FRACTION` × the shorter side; rings and far field at most
    :data:`WORKING_SIDE` pixels across. Ring medians ignore texture: a matte surface's reach is 0, a
    glossy one's its specular lobe.

    Shape: photo ``(3, H, W)`` linear LDR; frame ``(1, 3)`` its flash frame.
    """
    dims = check_shape(photo, "3 H W", name="photo")
    check_flash_frame(frame, 1)
    # Measured on a copy area-averaged to at most WORKING_SIDE (ring medians need no more), the
    # radius scaled back.
    factor = max(1, math.ceil(min(dims["H"], dims["W"]) / WORKING_SIDE))
    if factor > 1:
        size = (dims["H"] // factor, dims["W"] // factor)
        small = F.interpolate(photo[None].double(), size=size, mode="area")[0]
        scale = size[1] / dims["W"]
        return highlight_radius(small, resize_flash_frame(frame.double(), scale)) / scale
    side = min(dims["H"], dims["W"])
    delit = delit_photo(photo[None].double(), frame.double(), clip=False)
    level = luminance(delit)[0, 0]
    distance = hotspot_distance(frame[:, :2].double(), dims["H"], dims["W"])[0]
    far = (distance > HIGHLIGHT_FAR[0] * side) & (distance <= HIGHLIGHT_FAR[1] * side)
    baseline = level[far].median() if int(far.sum()) >= 16 else level.median()
    reach = HIGHLIGHT_MAX_FRACTION * side
    bins = torch.div(distance, HIGHLIGHT_STEP, rounding_mode="floor").long()
    for index in range(math.ceil(reach / HIGHLIGHT_STEP)):
        ring = bins == index
        if bool(ring.any()) and level[ring].median() <= (1.0 + HIGHLIGHT_EXCESS) * baseline:
            return index * HIGHLIGHT_STEP
    return reach


def thin_dark_weight(maps: Tensor, photo: Tensor | None = None) -> Tensor:
    """How much each texel is a thin dark feature (module docstring): a smoothstep over
    :data:`THIN_DARKNESS` of ``1 − luminance / closing``, the closing over a square of
    :data:`THIN_WINDOW_FRACTION` × the shorter side, of the photo's luminance when given (a gap is
    dark in the photo even where the network painted it grey-blue: the wood-plank sample), else of
    the linear base colour's; grown by a quarter window. The ratio to a local closing ignores the
    flash's smooth falloff.

    Shape: maps ``(8, H, W)``; photo ``(3, H, W)`` linear, optional → ``(H, W)`` in [0, 1].
    """
    check_single_maps(maps)
    if photo is not None:
        check_shape(photo, "3 H W", name="photo", dims={"H": maps.shape[-2], "W": maps.shape[-1]})
    guide = srgb_to_linear(maps[BASECOLOR]) if photo is None else photo.to(maps.dtype)
    window = _odd_window(maps)
    lum = luminance(guide[None])  # (1, 1, H, W)
    closed = _erode(_dilate_values(lum, window), window)
    darkness = smoothstep(*THIN_DARKNESS, 1.0 - lum / closed.clamp_min(1e-6))
    # Grown by a quarter window: the network's metal line is a little wider than the gap it read.
    return _dilate_values(darkness, window // 4 * 2 + 1)[0, 0]


def _odd_window(maps: Tensor) -> int:
    return 2 * max(1, round(THIN_WINDOW_FRACTION * min(maps.shape[-2:]) / 2.0)) + 1


def _dilate_values(image: Tensor, window: int) -> Tensor:
    """Grey dilation (the max over a ``window`` square), the edges repeated; separable (rows, then
    columns: the same max in 2·window comparisons a pixel instead of window²).

    Shape: ``(1, 1, H, W)``."""
    pad = window // 2
    rows = F.max_pool2d(F.pad(image, (pad, pad, 0, 0), mode="replicate"), (1, window), stride=1)
    return F.max_pool2d(F.pad(rows, (0, 0, pad, pad), mode="replicate"), (window, 1), stride=1)


def _erode(image: Tensor, window: int) -> Tensor:
    return -_dilate_values(-image, window)


def suppress_false_metal(maps: Tensor, photo: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """The maps with the metallic of thin dark features lowered to their surroundings' (module
    docstring): ``m − w · max(0, m − opening(m))`` with ``w`` :func:`thin_dark_weight` (of the
    ``photo`` when given) where the surface around does not read as metal; and that weight. Only
    the metallic changes, and only downwards. Above :data:`THIN_WORKING_SIDE` the lowering is
    found on an area-averaged copy and enlarged (a gap spans several pixels there).

    Shape: maps ``(8, H, W)``; photo ``(3, H, W)`` linear, optional → ``(8, H, W)``, ``(H, W)``.
    """
    check_single_maps(maps)
    if photo is not None:
        check_shape(photo, "3 H W", name="photo", dims={"H": maps.shape[-2], "W": maps.shape[-1]})
    height, width = maps.shape[-2:]
    factor = max(1, math.ceil(min(height, width) / THIN_WORKING_SIDE))
    work, guide = maps, photo
    if factor > 1:
        size = (height // factor, width // factor)
        work = F.interpolate(maps[None], size=size, mode="area")[0]
        guide = (
            None if photo is None else F.interpolate(photo[None].to(maps.dtype), size=size, mode="area")[0]
        )
    window = _odd_window(work)
    metallic = work[METALLIC][None]  # (1, 1, h, w)
    # A surface that reads as metal around the feature keeps its metal (perforated or engraved
    # metal: its holes and grooves are thin dark features whose rims the network reads as metal).
    around = box_mean(metallic, METAL_AROUND_WINDOWS * (window // 2))
    weight = thin_dark_weight(work, guide) * (1.0 - smoothstep(*METAL_AROUND, around))[0, 0]
    opened = _dilate_values(_erode(metallic, window), window)
    lowering = (weight * (metallic - opened).clamp_min(0.0))[0]  # (1, h, w)
    if factor > 1:
        lowering = F.interpolate(lowering[None], size=(height, width), mode="bilinear", align_corners=False)[
            0
        ]
        weight = F.interpolate(
            weight[None, None], size=(height, width), mode="bilinear", align_corners=False
        )[0, 0]
    result = maps.clone()
    result[METALLIC] = (maps[METALLIC] - lowering).clamp_min(0.0)
    return result, weight


@dataclass(frozen=True)
class FlashRemoval:
    """What :func:`remove_flash` did: the clipped fill, the highlight's radius, the flash mark
    found and repaired, and the share of texels whose metallic the thin-dark rule lowered by more
    than one 8-bit level."""

    fill: ClippedFill
    highlight_radius: float
    mark: FlashMark
    false_metal_fraction: float

    def to_json(self) -> dict[str, Any]:
        return {
            "clipped_fill": self.fill.to_json(),
            "highlight_radius": self.highlight_radius,
            "flash_mark": self.mark.to_json(),
            "false_metal_lowered_fraction": self.false_metal_fraction,
        }


def remove_flash(
    maps: Tensor,
    photo: Tensor,
    frame: Tensor,
    *,
    clipped: Tensor | None = None,
    lattice: tuple[tuple[float, float], tuple[float, float]] | None = None,
    stripes: tuple[float, float] | None = None,
    restore_texture: bool = False,
) -> tuple[Tensor, FlashRemoval]:
    """The flash taken out of maps predicted from ``photo`` (module docstring): the clipped pixels
    filled (:func:`fill_clipped`, ``clipped`` defaulting to :func:`clipped_mask` of the photo; with
    a ``lattice`` (two vectors ``(dx, dy)``) or ``stripes`` (their direction ``(dx, dy)``), the
    hotspot's disc too, from its twins elsewhere in the pattern, :class:`Twins`), the
    thin dark features' metal lowered (:func:`suppress_false_metal`), then the hotspot's disc
    levelled within the flash mark's radius or the highlight's, whichever is larger, and a leaked
    blotch patched (:func:`~brdfgan.core.flash_mark.repair_flash_mark`). Maps of a photo with nothing
    clipped and no thin dark feature under metal, with no disc or blotch around the hotspot, come
    back unchanged, bit for bit.

    ``restore_texture`` (``--tileable``): a disc whose texture the clipping took gets a patch of
    the maps' own texture (:func:`~brdfgan.core.flash_mark.repair_flash_mark`'s lost texture). A
    patch is a plausible texture, not the surface's: it raises the disc's base-colour error over
    the smooth fill's (research/notes/2026-12-flash-leak.md), so only a tile, where a smooth disc
    would repeat, asks for it.

    Shape: maps ``(8, H, W)``; photo ``(3, H, W)`` linear LDR at the maps' size (the network's
    input, preprocessed); frame ``(1, 3)`` its flash frame; clipped ``(H, W)`` bool, optional →
    ``(8, H, W)`` and :class:`FlashRemoval`.
    """
    check_single_maps(maps)
    check_shape(photo, "3 H W", name="photo", dims={"H": maps.shape[-2], "W": maps.shape[-1]})
    check_flash_frame(frame, 1)
    if lattice is not None and stripes is not None:
        raise ValueError("remove_flash takes a lattice or stripes, not both")
    clipped = clipped_mask(photo) if clipped is None else clipped
    radius = highlight_radius(photo, frame)
    # A repeating material's hotspot disc comes from the same place elsewhere in its pattern: the
    # mark's reach or the highlight's, whichever is larger (a dot and its halo on a plain tile; the
    # clipped streak a glossy plank stretches along its grooves).
    reach = max(REPAIR_INNER * mark_radius(*maps.shape[-2:]), radius)
    twins = (
        Twins.of_lattice(lattice)
        if lattice is not None
        else Twins.along_stripes(stripes, DISC_BLEND * reach)
        if stripes is not None
        else None
    )
    if twins is not None:
        distance = hotspot_distance(frame[:, :2].double(), *maps.shape[-2:])[0]
        maps = pattern_disc(maps, distance, reach, twins, clipped)
        clipped = clipped & (distance > reach)
    fill = fill_clipped(maps, clipped, twins=twins)
    hotspot = (float(frame[0, 0]), float(frame[0, 1]))
    # The disc's level is read over the mark's radius or the highlight's, whichever is larger: the
    # network's marks span up to a tenth of the side whatever the highlight's reach (a metallic disc
    # past a glossy paint's narrow highlight; a darker disc around a glossy tile's pinpoint glint,
    # whose highlight reaches no ring at all).
    level_radius = max(mark_radius(*maps.shape[-2:]), radius)
    # Thin dark features' metal first: lowered in the ring around the disc, it would leave the
    # disc's own metal standing out of a level that was read before.
    lowered_maps, _ = suppress_false_metal(fill.maps, photo)
    lowered = float(((fill.maps[METALLIC] - lowered_maps[METALLIC]) > 1.0 / 255.0).float().mean())
    result, mark = repair_flash_mark(
        lowered_maps, hotspot, radius=level_radius, clipped=clipped if restore_texture else None
    )
    return result, FlashRemoval(fill, radius, mark, lowered)
