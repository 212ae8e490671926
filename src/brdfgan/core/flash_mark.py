"""The flash mark: where the flash hotspot leaked into the maps, and its repair before tiling.

A network that reads a flash photo can bake the highlight into its maps: a blotch of fine detail
in the base colour, a dimple in the normals, a dark spot in the roughness, all centred on the
hotspot. In one photo it is a small flaw; in a tile (``--tileable``) it repeats with every tile.

**Detection** (:func:`leak_scores`). Per map, the energy of its fine detail (the map minus its
Gaussian blur of :func:`detail_sigma` pixels, squared, mean over channels) inside the disk of
:data:`FLASH_MARK_RADIUS_FRACTION` × the shorter side around the hotspot, over that in the ring
around it (one to two radii): ~1 where the hotspot left nothing (the texture is as busy there as
around it), well above 1 where it did. Both energies get :data:`ENERGY_FLOOR` (one 8-bit level,
squared) added, so that a nearly constant map (metallic 0) does not score with its noise. A map
with a score above :data:`LEAK_THRESHOLD` has leaked.

**Repair** (:func:`repair_flash_mark`). The leaked maps get the disk (to :data:`REPAIR_INNER`
radii, fading out by :data:`REPAIR_OUTER`) replaced by a patch of their own texture from nearby:
the displacement among :data:`PATCH_DIRECTIONS` directions at :data:`PATCH_DISTANCES` radii whose
surroundings best match the disk's surroundings (the ring out to :data:`MATCH_OUTER` radii, all
maps together, normalised per map as the seam cuts do), added with the mean level difference
between the two surroundings so that the patch joins at the right brightness. Displacements whose
patch would leave the image are skipped, so a hotspot near an edge takes its patch from inside.
One displacement serves every leaked map, which stay aligned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.flash_geometry import hotspot_distance
from brdfgan.core.seamless import MAP_GROUPS, MAP_NAMES, copy_error, local_contrast, map_scales
from brdfgan.core.svbrdf import check_single_maps, normalize_normal

# The disk whose detail is compared with its surroundings, as a fraction of the shorter side: the
# marks of the shipped model span up to ~0.11 of the side (wood planks at 256²).
FLASH_MARK_RADIUS_FRACTION = 0.1
# A score above it is a leak. On the shipped samples the marked maps score 2.3–19 and the clean
# ones at most 1.8 (docs/predict.md#tileable-maps---tileable).
LEAK_THRESHOLD = 2.0
# One 8-bit level, squared: fine detail below it does not show.
ENERGY_FLOOR = (1.0 / 255.0) ** 2
# The repaired disk: fully replaced to REPAIR_INNER radii (a mark's fringe reaches a little beyond
# the scoring disk), blended out by REPAIR_OUTER; matched on the ring from there to MATCH_OUTER.
REPAIR_INNER = 1.1
REPAIR_OUTER = 1.4
MATCH_OUTER = 2.0
# Where patches are looked for, in radii: far enough that the patch (REPAIR_OUTER radii around its
# centre) misses the mark (REPAIR_INNER radii), ≥ 2.5, and near enough to be the same surface.
PATCH_DIRECTIONS = 16
PATCH_DISTANCES = (2.6, 3.2, 3.8, 4.4)
BUSY_WEIGHT = 1.0


@dataclass(frozen=True)
class FlashMark:
    """What :func:`repair_flash_mark` found and did: the hotspot ``centre`` ``(x, y)`` and disk
    ``radius`` in pixels, each map's leak score (:data:`MAP_NAMES`), the maps repaired and the
    displacement ``(dy, dx)`` of the patch copied into them (``None``: nothing repaired, or no
    patch fitted inside the image)."""

    centre: tuple[float, float]
    radius: float
    scores: dict[str, float]
    repaired: tuple[str, ...]
    patch_offset: tuple[int, int] | None

    def to_json(self) -> dict[str, Any]:
        return {
            "centre": list(self.centre),
            "radius": self.radius,
            "threshold": LEAK_THRESHOLD,
            "leak_scores": dict(self.scores),
            "repaired": list(self.repaired),
            "patch_offset": list(self.patch_offset) if self.patch_offset is not None else None,
        }

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> FlashMark:
        offset = record["patch_offset"]
        return cls(
            centre=(float(record["centre"][0]), float(record["centre"][1])),
            radius=float(record["radius"]),
            scores={str(name): float(score) for name, score in record["leak_scores"].items()},
            repaired=tuple(str(name) for name in record["repaired"]),
            patch_offset=(int(offset[0]), int(offset[1])) if offset is not None else None,
        )


def mark_radius(height: int, width: int) -> float:
    """The scoring disk's radius in pixels for maps of ``height × width``."""
    return FLASH_MARK_RADIUS_FRACTION * min(height, width)


def detail_sigma(height: int, width: int) -> float:
    """The blur whose residual is "fine detail": 2 pixels at 256², scaled with the maps' size (the
    network's detail scales with the resolution it predicts at)."""
    return max(1.0, min(height, width) / 128.0)


def leak_scores(maps: Tensor, centre: tuple[float, float]) -> dict[str, float]:
    """Per map (:data:`MAP_NAMES`), the fine-detail energy inside the hotspot disk over that of the
    ring around it (module docstring); 1.0 for every map when the disk or the ring holds no pixel
    of the image (a hotspot far outside it).

    Shape: maps ``(8, H, W)``; centre ``(x, y)`` in pixels (pixel ``(i, j)`` centred at
    ``(j + 0.5, i + 0.5)``).
    """
    check_single_maps(maps)
    height, width = maps.shape[-2:]
    radius, sigma = mark_radius(height, width), detail_sigma(height, width)
    # Only the disk and its ring matter: blur a window with room for the kernel around them (its
    # own edges, mirrored, then lie beyond the ring), so the cost does not grow with the image.
    window = _Window.around(maps, centre, 2.0 * radius + 3.0 * sigma + 1.0)
    inside = window.distance <= radius
    ring = (window.distance > radius) & (window.distance <= 2.0 * radius)
    if not inside.any() or not ring.any():
        return dict.fromkeys(MAP_NAMES, 1.0)
    # float32: the blur's precision does not matter here, and float64 convolutions are slow on CPUs.
    work = window.read(maps.detach()).float()[None]
    detail = (work - gaussian_blur(work, sigma, "reflect"))[0].double().square()
    scores: dict[str, float] = {}
    for name, part in zip(MAP_NAMES, detail.split(list(MAP_GROUPS)), strict=True):
        energy = part.mean(dim=0)
        scores[name] = float((energy[inside].mean() + ENERGY_FLOOR) / (energy[ring].mean() + ENERGY_FLOOR))
    return scores


def _smoothstep(edge0: float, edge1: float, x: Tensor) -> Tensor:
    """0 below ``edge0``, 1 above ``edge1``, a smooth cubic between."""
    t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass(frozen=True)
class _Window:
    """The rows ``top : top + height`` and columns ``left : left + width`` of the maps that hold
    the disk and its matching ring (all a repair reads or writes: its cost does not grow with the
    image), and each of its pixels' distance from the hotspot, ``(height, width)``."""

    top: int
    left: int
    height: int
    width: int
    distance: Tensor

    @classmethod
    def around(cls, maps: Tensor, centre: tuple[float, float], reach: float) -> _Window:
        full_height, full_width = maps.shape[-2:]
        x, y = centre
        top = min(max(0, math.floor(y - reach)), full_height - 1)
        left = min(max(0, math.floor(x - reach)), full_width - 1)
        bottom = max(min(full_height, math.ceil(y + reach) + 1), top + 1)
        right = max(min(full_width, math.ceil(x + reach) + 1), left + 1)
        centres = torch.tensor([[x - left, y - top]], dtype=torch.float64, device=maps.device)
        distance = hotspot_distance(centres, bottom - top, right - left)[0]
        return cls(top, left, bottom - top, right - left, distance)

    def read(self, image: Tensor, dy: int = 0, dx: int = 0) -> Tensor:
        """``image[:, i + dy, j + dx]`` for the window's pixels ``(i, j)``, clamped at the image's
        edges (:meth:`inside` says where that was not needed). Shape: ``(C, H, W)`` → ``(C, h, w)``."""
        rows = (torch.arange(self.height, device=image.device) + self.top + dy).clamp(0, image.shape[-2] - 1)
        columns = (torch.arange(self.width, device=image.device) + self.left + dx).clamp(
            0, image.shape[-1] - 1
        )
        return image[:, rows][:, :, columns]

    def inside(self, image: Tensor, dy: int, dx: int) -> Tensor:
        """Window pixels whose source ``(i + dy, j + dx)`` lies inside ``image``. Shape: ``(h, w)``."""
        rows = torch.arange(self.height, device=image.device) + self.top + dy
        columns = torch.arange(self.width, device=image.device) + self.left + dx
        fits_rows = (rows >= 0) & (rows < image.shape[-2])
        fits_columns = (columns >= 0) & (columns < image.shape[-1])
        return fits_rows.view(-1, 1) & fits_columns.view(1, -1)


def find_patch(maps: Tensor, centre: tuple[float, float]) -> tuple[int, int] | None:
    """The displacement ``(dy, dx)`` of the patch that best replaces the hotspot disk (module
    docstring): its repaired disk's sources inside the image; the least mismatch between its
    surroundings and the disk's, plus how much busier its inside is than the disk's surroundings
    (a patch must not bring a grout line or a plank edge into a plain area). ``None`` when no
    candidate fits inside the image.

    Shape: maps ``(8, H, W)``.
    """
    check_single_maps(maps)
    radius = mark_radius(*maps.shape[-2:])
    window = _Window.around(maps, centre, MATCH_OUTER * radius)
    disk = window.distance <= REPAIR_OUTER * radius
    ring = (window.distance > REPAIR_OUTER * radius) & (window.distance <= MATCH_OUTER * radius)
    work = maps.detach().double()
    scales = map_scales(work, MAP_GROUPS)
    contrast = local_contrast(work, scales, MAP_GROUPS)[None]
    around = window.read(work)
    calm = float(window.read(contrast)[0][ring].mean()) if ring.any() else 0.0
    best: tuple[float, tuple[int, int]] | None = None
    for reach in PATCH_DISTANCES:
        for step in range(PATCH_DIRECTIONS):
            angle = 2.0 * math.pi * step / PATCH_DIRECTIONS
            dy, dx = round(reach * radius * math.sin(angle)), round(reach * radius * math.cos(angle))
            inside = window.inside(work, dy, dx)
            matched = ring & inside
            if not bool(inside[disk].all()) or not matched.any():
                continue
            mismatch = float(
                copy_error(window.read(work, dy, dx), around, scales, MAP_GROUPS)[matched].mean()
            )
            busier = max(0.0, float(window.read(contrast, dy, dx)[0][disk].mean()) - calm)
            score = mismatch + BUSY_WEIGHT * busier
            if best is None or score < best[0]:
                best = (score, (dy, dx))
    return best[1] if best is not None else None


def fill_disk(
    maps: Tensor, centre: tuple[float, float], offset: tuple[int, int], names: tuple[str, ...]
) -> Tensor:
    """The maps ``names`` with the hotspot disk replaced by the patch at ``offset`` (module
    docstring), the others unchanged; values kept in range, normals renormalised.

    Shape: ``(8, H, W)`` → ``(8, H, W)``.
    """
    check_single_maps(maps)
    radius = mark_radius(*maps.shape[-2:])
    window = _Window.around(maps, centre, MATCH_OUTER * radius)
    weight = 1.0 - _smoothstep(REPAIR_INNER * radius, REPAIR_OUTER * radius, window.distance)
    ring = (window.distance > REPAIR_OUTER * radius) & (window.distance <= MATCH_OUTER * radius)
    ring &= window.inside(maps, *offset)
    around, patch = window.read(maps), window.read(maps, *offset)
    # The median, not the mean: a grout line in one of the two rings must not shift the level.
    level = (around - patch)[:, ring].median(dim=-1).values if ring.any() else around.new_zeros(len(around))
    filled = around + weight.to(maps.dtype) * (patch + level.view(-1, 1, 1) - around)
    result = maps.clone()
    rows = slice(window.top, window.top + window.height)
    columns = slice(window.left, window.left + window.width)
    start = 0
    for name, channels in zip(MAP_NAMES, MAP_GROUPS, strict=True):
        part = slice(start, start + channels)
        start += channels
        if name in names:
            # Normals stay unit vectors; the other maps in their range; pixels outside the disk as they were.
            repaired = normalize_normal(filled[part]) if name == "normal" else filled[part].clamp(0.0, 1.0)
            result[part, rows, columns] = torch.where(weight > 0, repaired, around[part])
    return result


def repair_flash_mark(
    maps: Tensor, centre: tuple[float, float], threshold: float = LEAK_THRESHOLD
) -> tuple[Tensor, FlashMark]:
    """The maps with the flash mark removed from those that leaked it (score above ``threshold``),
    and what was found and done.

    Shape: ``(8, H, W)`` → ``(8, H, W)``; centre ``(x, y)`` in pixels.
    """
    check_single_maps(maps)
    if not all(math.isfinite(v) for v in centre):
        raise ValueError(f"the hotspot centre must be two finite numbers, got {centre}")
    height, width = maps.shape[-2:]
    scores = leak_scores(maps, centre)
    leaked = tuple(name for name in MAP_NAMES if scores[name] > threshold)
    offset = find_patch(maps, centre) if leaked else None
    repaired = fill_disk(maps, centre, offset, leaked) if offset is not None else maps
    record = FlashMark(
        centre=(float(centre[0]), float(centre[1])),
        radius=mark_radius(height, width),
        scores=scores,
        repaired=leaked if offset is not None else (),
        patch_offset=offset,
    )
    return repaired, record
