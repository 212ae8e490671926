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

**Level** (:func:`level_scores`). A clipped hotspot more often leaves a *smooth* disc: the base
colour greyed and lightened, the metallic raised, the roughness lowered, with the texture still
visible through it (the wood-plank sample: detail scores 0.35-1.21, a disc every viewer sees). Per
map, the median of each of :data:`LEVEL_BINS` equal-area rings inside the disc's radius (the
highlight's reach or the mark's radius, whichever is larger:
:func:`~brdfgan.core.clipped_fill.remove_flash`) minus
the median of the reference ring outside it (:data:`LEVEL_REFERENCE` radii) is the disc's *bias
profile*; its largest step over the reference's spread (1.4826 × its median absolute deviation,
plus one 8-bit level) is the map's level score. Ring medians ignore the texture, so a stationary
texture scores ~1-2 and a visible disc well above :data:`LEVEL_THRESHOLD` (3: over-exposed
renders of held-out materials did not separate 2-5, and the wood-plank sample's disc scores 4.6
once its clipped pixels are filled; research/notes/2026-12-flash-leak.md). A map whose
score is above it gets the bias profile subtracted (interpolated over the radius, 0 at its edge):
the disc's level goes, the texture in it stays. Normals are left to the detail repair. Metals are
levelled too: their highlight belongs in the render, not in the base colour map (standing down
where the surroundings read as metal left a disc a viewer sees on 12 of 76 over-exposed renders,
levelling them on 6, with the disc's base-colour error and the metal kept unchanged;
research/notes/2026-12-flash-leak.md).

**Lost texture.** Where the photo clipped half the disk or more (:data:`CLIPPED_DISK_SHARE`), the
maps there hold no evidence, and once the clipped pixels are brought into their surroundings'
range (:func:`~brdfgan.core.clipped_fill.fill_clipped`) they are smooth: a disc of plain colour in a
textured surface, which a tile repeats (the wood-plank sample's base colour scores 0.14). A
textured map (:data:`TEXTURED_MAPS`) whose detail score is below ``1 / threshold`` there has lost
its texture to the clipping and gets the same patch (asked for by ``--tileable`` only:
:func:`~brdfgan.core.clipped_fill.remove_flash`). Without clipping, a low score is no mark: the
hotspot may fall on a plain tile with grout around it (the ceramic sample scores 0.19, its bricks
0.32).

**Repair** (:func:`repair_flash_mark`). The leaked maps get the disk (to :data:`REPAIR_INNER`
radii, fading out by :data:`REPAIR_OUTER`) replaced by a patch of their own texture from nearby:
the displacement among :data:`PATCH_DIRECTIONS` directions at :data:`PATCH_DISTANCES` radii whose
surroundings best match the disk's surroundings (the ring out to :data:`MATCH_OUTER` radii, all
maps together, normalised per map as the seam cuts do), added with the mean level difference
between the two surroundings so that the patch joins at the right brightness. Displacements whose
patch would leave the image are skipped, so a hotspot near an edge takes its patch from inside.
One displacement serves every leaked map, which stay aligned. Where the level is checked, a patch
that would itself read as a disc (a terrazzo chip as large as the disc: a level score of 40 after
the patch on a validation render where the smooth fill scored 2.8) gives way to the next best
(:func:`patch_disk`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.filtering import gaussian_blur, smoothstep
from brdfgan.core.flash_geometry import hotspot_distance
from brdfgan.core.seamless import MAP_GROUPS, MAP_NAMES, copy_error, local_contrast, map_scales
from brdfgan.core.svbrdf import CHANNELS, check_single_maps, normalize_normal

# The disk whose detail is compared with its surroundings, as a fraction of the shorter side: the
# marks of the shipped model span up to ~0.11 of the side (wood planks at 256²).
FLASH_MARK_RADIUS_FRACTION = 0.1
# A score above it is a leak. On the shipped samples the marked maps score 2.3–19 and the clean
# ones at most 1.8 (docs/predict.md#tileable-maps---tileable); on over-exposed renders of held-out
# materials 2, 4 and no detail repair at all scored within 0.002 (research/notes/2026-12-flash-leak.md):
# a clipped hotspot's disc is smooth, the level check's to find.
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
# The level check (module docstring): equal-area rings inside the radius, the reference ring in
# radii (widened to LEVEL_REFERENCE_WIDE when the image cuts it to fewer than LEVEL_MIN_PIXELS),
# and the threshold on the score.
LEVEL_BINS = 12
LEVEL_REFERENCE = (1.0, 1.5)
LEVEL_REFERENCE_WIDE = 2.0
LEVEL_MIN_PIXELS = 16
LEVEL_WORKING_SIDE = 256
LEVEL_THRESHOLD = 3.0  # module docstring
LEVELLED_MAPS = ("basecolor", "roughness", "metallic")
PATCH_DISTANCES = (2.6, 3.2, 3.8, 4.4)
# The best patches tried where the chosen one would read as a disc itself (patch_disk).
PATCH_TRIES = 8
# The share of the scoring disk the photo must clip before a smooth disk counts as lost texture,
# and the maps whose texture can be lost: a metallic map is mostly plain (0 or 1), and a patch of it
# from elsewhere brings metal into a dielectric disc (measured: the OOD renders' disc metal 0.07 →
# 0.12 with it).
CLIPPED_DISK_SHARE = 0.5
TEXTURED_MAPS = ("basecolor", "normal", "roughness")
BUSY_WEIGHT = 1.0


@dataclass(frozen=True)
class FlashMark:
    """What :func:`repair_flash_mark` found and did: the hotspot ``centre`` ``(x, y)`` and disk
    ``radius`` in pixels, each map's leak score (:data:`MAP_NAMES`), the maps repaired and the
    displacement ``(dy, dx)`` of the patch copied into them (``None``: nothing repaired, or no
    patch fitted inside the image); the level check's radius, each levelled map's score
    (:data:`LEVELLED_MAPS`), the maps levelled, and the two thresholds used. A record written
    before the level check existed reads back with none levelled."""

    centre: tuple[float, float]
    radius: float
    scores: dict[str, float]
    repaired: tuple[str, ...]
    patch_offset: tuple[int, int] | None
    level_radius: float = 0.0
    level_scores: dict[str, float] = field(default_factory=dict)
    levelled: tuple[str, ...] = ()
    threshold: float = LEAK_THRESHOLD
    level_threshold: float = LEVEL_THRESHOLD
    clipped_share: float = 0.0  # of the scoring disk, clipped in the photo (module docstring)

    def to_json(self) -> dict[str, Any]:
        return {
            "centre": list(self.centre),
            "radius": self.radius,
            "threshold": self.threshold,
            "leak_scores": dict(self.scores),
            "repaired": list(self.repaired),
            "patch_offset": list(self.patch_offset) if self.patch_offset is not None else None,
            "level_radius": self.level_radius,
            "level_threshold": self.level_threshold,
            "level_scores": dict(self.level_scores),
            "levelled": list(self.levelled),
            "clipped_share": self.clipped_share,
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
            level_radius=float(record.get("level_radius", 0.0)),
            level_scores={str(name): float(v) for name, v in record.get("level_scores", {}).items()},
            levelled=tuple(str(name) for name in record.get("levelled", ())),
            threshold=float(record.get("threshold", LEAK_THRESHOLD)),
            level_threshold=float(record.get("level_threshold", LEVEL_THRESHOLD)),
            clipped_share=float(record.get("clipped_share", 0.0)),
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


def patch_candidates(maps: Tensor, centre: tuple[float, float]) -> list[tuple[int, int]]:
    """The displacements ``(dy, dx)`` of the patches that could replace the hotspot disk (module
    docstring), best first: their repaired disk's sources inside the image; ranked by the mismatch
    between their surroundings and the disk's, plus how much busier their inside is than the disk's
    surroundings (a patch must not bring a grout line or a plank edge into a plain area). Empty when
    no candidate fits inside the image.

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
    scored: list[tuple[float, tuple[int, int]]] = []
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
            scored.append((mismatch + BUSY_WEIGHT * busier, (dy, dx)))
    return [offset for _, offset in sorted(scored, key=lambda candidate: candidate[0])]


def patch_disk(
    maps: Tensor,
    centre: tuple[float, float],
    names: tuple[str, ...],
    level_radius: float,
    level_threshold: float,
) -> tuple[Tensor, tuple[int, int] | None]:
    """The maps ``names`` with the hotspot disk replaced by the best patch (:func:`patch_candidates`,
    :func:`fill_disk`) that does not itself read as a disc: where the disc's level is checked
    (``level_radius`` > 0), a patch whose ring medians step above ``level_threshold`` in a map the
    check reads (a terrazzo chip as large as the disc, copied onto the hotspot) gives way to the next of
    the :data:`PATCH_TRIES` best, and where every one does, the one that steps least is taken;
    with the displacement used (``None``: no candidate fits, the maps unchanged).

    Shape: ``(8, H, W)`` → ``(8, H, W)``.
    """
    candidates = patch_candidates(maps, centre)
    if not candidates:
        return maps, None
    checked = tuple(name for name in names if name in LEVELLED_MAPS) if level_radius > 0 else ()
    tried: list[tuple[float, Tensor, tuple[int, int]]] = []
    for offset in candidates[:PATCH_TRIES] if checked else candidates[:1]:
        patched = fill_disk(maps, centre, offset, names)
        scores = level_scores(patched, centre, level_radius) if checked else {}
        step = max((scores[name] for name in checked), default=0.0)
        if step <= level_threshold:
            return patched, offset
        tried.append((step, patched, offset))
    _, patched, offset = min(tried, key=lambda trial: trial[0])
    return patched, offset


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
    weight = 1.0 - smoothstep(REPAIR_INNER * radius, REPAIR_OUTER * radius, window.distance)
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


@dataclass(frozen=True)
class LevelBias:
    """The disc's bias profile (module docstring): the hotspot ``centre`` and ``radius`` in the
    maps' pixels, each channel's ``steps`` over the :data:`LEVEL_BINS` rings (map units),
    and ``scores`` per map of :data:`LEVELLED_MAPS`."""

    centre: tuple[float, float]
    radius: float
    steps: Tensor  # (8, LEVEL_BINS)
    scores: dict[str, float]

    def field(self, maps: Tensor) -> tuple[_Window, Tensor]:
        """The window around the disc and the bias of every channel at its pixels: the steps
        interpolated linearly over each ring's middle radius (by area), flat inside the first ring,
        0 at the radius and beyond. Shape: maps ``(8, H, W)`` → field ``(8, h, w)``."""
        window = _Window.around(maps, self.centre, self.radius + 1.0)
        middles = [self.radius * math.sqrt((k + 0.5) / LEVEL_BINS) for k in range(LEVEL_BINS)]
        knots = torch.tensor([0.0, *middles, self.radius], dtype=torch.float64, device=maps.device)
        steps = self.steps.to(maps.device)
        values = torch.cat([steps[:, :1], steps, torch.zeros_like(steps[:, :1])], dim=-1)  # (8, K + 2)
        at = window.distance.clamp(max=self.radius).flatten().contiguous()
        upper = torch.searchsorted(knots, at, right=True).clamp(1, len(knots) - 1)
        lower = upper - 1
        share = ((at - knots[lower]) / (knots[upper] - knots[lower])).clamp(0.0, 1.0)
        bias = values[:, lower] + share * (values[:, upper] - values[:, lower])
        bias = torch.where((window.distance < self.radius).flatten(), bias, torch.zeros_like(bias))
        return window, bias.view(-1, window.height, window.width).to(maps.dtype)


def level_bias(maps: Tensor, centre: tuple[float, float], radius: float) -> LevelBias | None:
    """The bias profile of the disc of ``radius`` pixels around ``centre`` (module docstring),
    measured on a copy area-averaged to at most :data:`LEVEL_WORKING_SIDE` (the scores were
    calibrated at 256²; ring medians need no more); ``None`` when the image holds too little of the
    disc or of its reference ring.

    Shape: maps ``(8, H, W)``.
    """
    check_single_maps(maps)
    height, width = maps.shape[-2:]
    factor = max(1, math.ceil(min(height, width) / LEVEL_WORKING_SIDE))
    work = maps.detach().double()
    if factor > 1:
        work = F.interpolate(work[None], size=(height // factor, width // factor), mode="area")[0]
    scale = work.shape[-1] / width
    small_centre, small_radius = (centre[0] * scale, centre[1] * scale), radius * scale
    window = _Window.around(work, small_centre, LEVEL_REFERENCE_WIDE * small_radius + 1.0)
    distance = window.distance / small_radius  # in radii
    reference = (distance > LEVEL_REFERENCE[0]) & (distance <= LEVEL_REFERENCE[1])
    if int(reference.sum()) < LEVEL_MIN_PIXELS:
        reference = (distance > 1.0) & (distance <= LEVEL_REFERENCE_WIDE)
    edges = [math.sqrt(k / LEVEL_BINS) for k in range(LEVEL_BINS + 1)]
    rings = [(distance >= lo) & (distance < hi) for lo, hi in itertools.pairwise(edges)]
    if int(reference.sum()) < LEVEL_MIN_PIXELS or any(int(ring.sum()) < LEVEL_MIN_PIXELS for ring in rings):
        return None
    pixels = window.read(work)
    level = pixels[:, reference].median(dim=-1).values  # (8,)
    spread = 1.4826 * (pixels[:, reference] - level[:, None]).abs().median(dim=-1).values + 1.0 / 255.0
    steps = torch.stack([pixels[:, ring].median(dim=-1).values - level for ring in rings], dim=-1)  # (8, K)
    relative = (steps.abs() / spread[:, None]).amax(dim=-1)  # (8,)
    scores = {name: float(relative[CHANNELS[name]].max()) for name in LEVELLED_MAPS}
    return LevelBias((float(centre[0]), float(centre[1])), float(radius), steps, scores)


def level_scores(maps: Tensor, centre: tuple[float, float], radius: float) -> dict[str, float]:
    """Per map of :data:`LEVELLED_MAPS`, the level score of the disc of ``radius`` pixels around
    ``centre`` (module docstring); 0.0 for each when the image holds too little of it.

    Shape: maps ``(8, H, W)``.
    """
    bias = level_bias(maps, centre, radius)
    return bias.scores if bias is not None else dict.fromkeys(LEVELLED_MAPS, 0.0)


def level_disc(maps: Tensor, bias: LevelBias, names: tuple[str, ...]) -> Tensor:
    """The maps ``names`` with the bias profile subtracted (module docstring), the others
    unchanged; values kept in [0, 1].

    Shape: ``(8, H, W)`` → ``(8, H, W)``.
    """
    window, field = bias.field(maps)
    rows = slice(window.top, window.top + window.height)
    columns = slice(window.left, window.left + window.width)
    result = maps.clone()
    for name in names:
        part = CHANNELS[name]
        inside = result[part, rows, columns]
        result[part, rows, columns] = torch.where(
            field[part] != 0, (inside - field[part]).clamp(0.0, 1.0), inside
        )
    return result


def repair_flash_mark(
    maps: Tensor,
    centre: tuple[float, float],
    threshold: float = LEAK_THRESHOLD,
    *,
    radius: float | None = None,
    level_threshold: float = LEVEL_THRESHOLD,
    clipped: Tensor | None = None,
) -> tuple[Tensor, FlashMark]:
    """The maps with the flash mark removed (module docstring), and what was found and done: first,
    given the highlight's ``radius`` in pixels (:func:`~brdfgan.core.clipped_fill.highlight_radius`
    of the photo), the disc's level taken out of the maps whose level score is above
    ``level_threshold`` (``None`` or 0: no level check, as without a photo); then the patch copied
    into the maps whose detail score is above ``threshold``, or, where ``clipped`` (the photo's
    clipped pixels) covers :data:`CLIPPED_DISK_SHARE` of the disk, below ``1 / threshold`` (lost
    texture).

    Shape: ``(8, H, W)`` → ``(8, H, W)``; centre ``(x, y)`` in pixels; clipped ``(H, W)`` bool.
    """
    check_single_maps(maps)
    if not all(math.isfinite(v) for v in centre):
        raise ValueError(f"the hotspot centre must be two finite numbers, got {centre}")
    height, width = maps.shape[-2:]
    radius = 0.0 if radius is None else float(radius)
    if not (math.isfinite(radius) and radius >= 0):
        raise ValueError(f"the level radius must be a finite number >= 0, got {radius}")
    bias = level_bias(maps, centre, radius) if radius > 0 else None
    levelled: tuple[str, ...] = ()
    if bias is not None:
        levelled = tuple(name for name in LEVELLED_MAPS if bias.scores[name] > level_threshold)
    levelled_maps = level_disc(maps, bias, levelled) if bias is not None and levelled else maps
    scores = leak_scores(levelled_maps, centre)
    share = clipped_disk_share(clipped, centre) if clipped is not None else 0.0
    leaked = tuple(
        name
        for name in MAP_NAMES
        if scores[name] > threshold
        or (share >= CLIPPED_DISK_SHARE and name in TEXTURED_MAPS and scores[name] < 1.0 / threshold)
    )
    repaired, offset = (
        patch_disk(levelled_maps, centre, leaked, radius, level_threshold)
        if leaked
        else (levelled_maps, None)
    )
    record = FlashMark(
        centre=(float(centre[0]), float(centre[1])),
        radius=mark_radius(height, width),
        scores=scores,
        repaired=leaked if offset is not None else (),
        patch_offset=offset,
        level_radius=radius,
        level_scores=bias.scores if bias is not None else dict.fromkeys(LEVELLED_MAPS, 0.0),
        levelled=levelled,
        threshold=threshold,
        level_threshold=level_threshold,
        clipped_share=share,
    )
    return repaired, record


def clipped_disk_share(clipped: Tensor, centre: tuple[float, float]) -> float:
    """The share of the scoring disk (:func:`mark_radius` around ``centre``) that ``clipped`` covers;
    0 when the disk holds no pixel of the image.

    Shape: ``(H, W)`` bool.

    Example:
        >>> clipped = torch.zeros(100, 100, dtype=torch.bool)
        >>> clipped[40:60, 40:60] = True  # a 20-pixel square in the 10-pixel-radius disk
        >>> clipped_disk_share(clipped, (50.0, 50.0))
        1.0
        >>> clipped_disk_share(clipped, (10.0, 10.0))
        0.0
    """
    check_shape(clipped, "H W", name="clipped")
    window = _Window.around(clipped[None], centre, mark_radius(*clipped.shape) + 1.0)
    inside = window.distance <= mark_radius(*clipped.shape)
    if not inside.any():
        return 0.0
    return float(window.read(clipped[None])[0][inside].float().mean())
