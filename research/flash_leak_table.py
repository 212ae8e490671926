"""The flash left in the maps (issue 60, item 2): the hotspot disc's base colour and metallic, and
false metal on thin dark features, before and after :mod:`brdfgan.core.clipped_fill`.

Held-out materials, photographed by the project's renderer with the flash at the lens
(:func:`~brdfgan.core.delit.flash_render`, the hotspot at the photo's centre, the field of view drawn
in 40-75°) and over-exposed: the auto exposure (:func:`~brdfgan.core.exposure.auto_exposure_scale`)
times ``2^ev`` for the smallest ``ev`` of +1, +1.25, ... +2 that clips 1 % of the pixels, clipped
at 1. A render that clips under 1 % even at +2 EV (a matte material) or over 10 % at +1 EV is
still scored for false metal but left out of the hotspot rows.

Sets (procedural materials as the shipped model's data spec paints them, 512² cut to 256² crops):

- ``val``: the validation split's procedural materials, and ``tune``: one fresh draw of every
  family (a seed stream no split uses): the thresholds are chosen on these two;
- ``test``: the test split's procedural materials (the regular families first): reported only;
- ``ood``: the out-of-distribution scans (``../shared/ood/ambientcg``): reported only.

Measures per render (the disc: pixels within 0.1 × the side of the hotspot; the rest: beyond 2 ×
that):

- ``disc/rest``: the base colour's mean absolute error (sRGB) in the disc over the rest's; goal ≤ 1.2;
- ``disc metal``: the mean predicted metallic in the disc where the truth is dielectric (< 0.1);
  goal ≤ 0.05;
- ``disc seen``: the renders whose disc a viewer sees: a level score
  (:func:`~brdfgan.core.flash_mark.level_scores`, out to the highlight's reach) above
  :data:`~brdfgan.core.flash_mark.LEVEL_THRESHOLD` in base colour, roughness or metallic, where
  the true maps' own is not (a mortar line or a large chip across the hotspot steps the ring
  medians of the material itself: the truth scores above it on 17 of the 38 val renders);
- ``thin dark metal``: the mean predicted metallic on the truth's thin dark features (texels darker
  than their 9 × 9 neighbourhood's closing by 25 %, dielectric);
- ``false metal``: the mean predicted metallic where the truth is dielectric;
- ``metal kept``: the mean predicted metallic where the truth is metal (> 0.5); should not drop.

    python -m research.flash_leak_table --out outputs/flash_leak/table.md
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import hydra
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from brdfgan.core.clipped_fill import (
    CLIP_LEVEL,
    RANGE_SPREAD,
    clipped_mask,
    fill_clipped,
    highlight_radius,
    remove_flash,
    suppress_false_metal,
    thin_dark_weight,
)
from brdfgan.core.delit import flash_render
from brdfgan.core.exposure import auto_exposure_scale, luminance
from brdfgan.core.flash_geometry import DEFAULT_FOV_DEG, centred_flash_frame, hotspot_distance
from brdfgan.core.flash_mark import (
    LEAK_THRESHOLD,
    LEVEL_THRESHOLD,
    level_scores,
    mark_radius,
    repair_flash_mark,
)
from brdfgan.core.svbrdf import resize_maps, split_maps, srgb_to_linear
from brdfgan.data.materials.families import FAMILIES
from brdfgan.data.materials.scanned import read_scanned_material, scanned_material_folders
from brdfgan.data.spec.dataset_spec import DatasetSpec, paint_material, scan_materials, split_materials
from brdfgan.data.spec.determinism import derive_seed, material_seed
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.intake.preprocess import preprocess
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pipeline import tile_pattern
from brdfgan.io.atomic import write_text_atomic
from research.relief_tables import OOD_SCANS, compose_config

ROOT = Path(__file__).resolve().parents[1]
SIDE = 256
EVS = (1.0, 1.25, 1.5, 1.75, 2.0)
CLIPPED_RANGE = (0.01, 0.10)
FOV_RANGE = (40.0, 75.0)
REGULAR = ("mosaic", "relief_tiles", "pavers", "tread_plate", "wood_planks", "bricks")
DIELECTRIC = 0.1  # the evaluator's DIELECTRIC_THRESHOLD
METAL = 0.5
THIN_WINDOW = 9  # px: the closing that finds thin dark features in the truth
THIN_DARKER = 0.25  # a texel this much darker than its closing is on a thin dark feature


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


@dataclass(frozen=True)
class Render:
    """One photographed crop and the shipped model's maps of it (all at ``SIDE``²)."""

    name: str
    family: str
    photo: Tensor  # (3, S, S) linear LDR
    frame: Tensor  # (1, 3)
    ev: float
    clipped_fraction: float
    truth: Tensor  # (8, S, S)
    predicted: Tensor  # (8, S, S)

    @property
    def hotspot(self) -> tuple[float, float]:
        return float(self.frame[0, 0]), float(self.frame[0, 1])

    @property
    def in_range(self) -> bool:
        return CLIPPED_RANGE[0] <= self.clipped_fraction <= CLIPPED_RANGE[1]


def crop_material(maps: Tensor, generator: torch.Generator) -> Tensor:
    """A square of half to all of the material's side, resized to ``SIDE``² (as the bank's crops)."""
    side = maps.shape[-1]
    size = int(side * (0.5 + 0.5 * float(torch.rand((), generator=generator))))
    top, left = (int(torch.randint(side - size + 1, (), generator=generator)) for _ in range(2))
    return resize_maps(maps[:, top : top + size, left : left + size], SIDE)


def photograph(maps: Tensor, generator: torch.Generator) -> tuple[Tensor, Tensor, float, float]:
    """The over-exposed flash photo of ``maps`` (module docstring), its flash frame, its ``ev`` and
    its clipped fraction. Shape: ``(8, S, S)`` → ``(3, S, S)``, ``(1, 3)``."""
    fov = FOV_RANGE[0] + (FOV_RANGE[1] - FOV_RANGE[0]) * float(torch.rand((), generator=generator))
    frame = centred_flash_frame(1, SIDE, SIDE, fov, dtype=torch.float64)
    parts = split_maps(maps.double()[None])
    hdr = flash_render(srgb_to_linear(parts.basecolor), parts.normal, parts.roughness, parts.metallic, frame)
    base = auto_exposure_scale(hdr)
    chosen = None
    for ev in EVS:
        photo = (hdr * base * 2.0**ev).clamp(0.0, 1.0)[0]
        fraction = float((photo >= CLIP_LEVEL).any(dim=0).float().mean())
        chosen = (photo, ev, fraction)
        if fraction >= CLIPPED_RANGE[0]:
            break
    assert chosen is not None
    photo, ev, fraction = chosen
    return photo.float(), frame.float(), ev, fraction


def held_out(spec: DatasetSpec, split: str, limit: int) -> list[tuple[str, Tensor]]:
    """The split's procedural materials ``(family, maps)``, the regular families first."""
    families = list(FAMILIES)
    scans = scan_materials(spec)
    indices = [i for i in split_materials(spec)[split] if i not in scans]
    indices.sort(key=lambda i: (families[i % len(families)] not in REGULAR, i))
    chosen = indices[:limit] if limit else indices
    painted = []
    for index in chosen:
        material = paint_material(
            spec, split, index, torch.Generator().manual_seed(material_seed(spec.seed, index))
        )
        painted.append((material.family, material.maps))
    return painted


def fresh_materials(spec: DatasetSpec, seed: int) -> list[tuple[str, Tensor]]:
    """One new draw of every family at the spec's material resolution, from a seed stream of its
    own: materials no split holds, so the model never saw them (tuning, beside ``val``)."""
    painted = []
    for name, family in FAMILIES.items():
        generator = torch.Generator().manual_seed(
            derive_seed(seed, "flash leak tune", name) & 0x7FFFFFFFFFFFFFFF
        )
        params = family.sample_parameters(generator)
        painted.append((name, family.make_maps(params, spec.material_resolution, generator)))
    return painted


def ood_materials() -> list[tuple[str, Tensor]]:
    return [
        (f"ood/{folder.name}", read_scanned_material(folder, 512))
        for folder in scanned_material_folders(str(OOD_SCANS))
    ]


def render_set(
    name: str, materials: Sequence[tuple[str, Tensor]], crops: int, generator_model: nn.Module, seed: int
) -> list[Render]:
    renders = []
    for m, (family, maps) in enumerate(materials):
        for crop in range(crops):
            generator = torch.Generator().manual_seed(
                derive_seed(seed, "flash leak", name, m, crop) & 0x7FFFFFFFFFFFFFFF
            )
            truth = crop_material(maps.float(), generator)
            photo, frame, ev, fraction = photograph(truth, generator)
            with torch.no_grad():
                predicted = generator_model(photo[None], frame)[0]
            renders.append(Render(f"{name}-{m}-{crop}", family, photo, frame, ev, fraction, truth, predicted))
    return renders


# ----------------------------------------------------------------------------- measures


def thin_dark(truth: Tensor) -> Tensor:
    """The truth's thin dark dielectric features (module docstring). Shape: ``(8, S, S)`` → ``(S, S)``."""
    lum = luminance(srgb_to_linear(truth[0:3])[None])[0, 0]
    pad = THIN_WINDOW // 2
    closed = -F.max_pool2d(-F.max_pool2d(lum[None, None], THIN_WINDOW, 1, pad), THIN_WINDOW, 1, pad)[0, 0]
    return (lum < (1.0 - THIN_DARKER) * closed) & (truth[7] < DIELECTRIC)


def _mean(values: Tensor, where: Tensor) -> float:
    return float(values[where].mean()) if bool(where.any()) else float("nan")


def measures(render: Render, maps: Tensor) -> dict[str, float]:
    """The module docstring's measures of ``maps`` against the render's truth."""
    truth = render.truth
    radius = mark_radius(SIDE, SIDE)
    distance = hotspot_distance(render.frame[:, :2].double(), SIDE, SIDE)[0]
    disc, rest = distance <= radius, distance > 2.0 * radius
    error = (maps[0:3] - truth[0:3]).abs().mean(dim=0)
    dielectric, metal = truth[7] < DIELECTRIC, truth[7] > METAL
    reach = max(highlight_radius(render.photo, render.frame), radius)
    return {
        "disc/rest": _mean(error, disc) / _mean(error, rest),
        "disc level": max(level_scores(maps, render.hotspot, reach).values()),
        "true disc level": max(level_scores(truth, render.hotspot, reach).values()),
        "disc metal": _mean(maps[7], disc & dielectric),
        "disc metal excess": _mean(maps[7], disc & dielectric) - _mean(maps[7], rest & dielectric),
        "thin dark metal": _mean(maps[7], thin_dark(truth)),
        "false metal": _mean(maps[7], dielectric),
        "metal kept": _mean(maps[7], metal),
    }


Variant = Callable[[Render], Tensor]


def filled(render: Render, spread: float = RANGE_SPREAD) -> Tensor:
    return fill_clipped(render.predicted, clipped_mask(render.photo), spread=spread).maps


def levelled(
    render: Render,
    spread: float = RANGE_SPREAD,
    level: float = LEVEL_THRESHOLD,
    detail: float = LEAK_THRESHOLD,
    fill: Callable[[Render, float], Tensor] = filled,
) -> Tensor:
    """``fill``: where the filled maps come from (the calibration passes a cached :func:`filled`)."""
    radius = highlight_radius(render.photo, render.frame)
    maps = fill(render, spread)
    return repair_flash_mark(maps, render.hotspot, detail, radius=radius, level_threshold=level)[0]


VARIANTS: dict[str, Variant] = {
    "network": lambda render: render.predicted,
    "+ clipped fill": filled,
    "+ disc levelled": levelled,
    "+ thin-dark metal rule (remove_flash)": lambda r: remove_flash(r.predicted, r.photo, r.frame)[0],
    "--tileable: + pattern disc, lost texture patched": (
        lambda r: tileable_removal(r.predicted, r.photo, r.frame)
    ),
}


def tileable_removal(maps: Tensor, photo: Tensor, frame: Tensor) -> Tensor:
    """:func:`remove_flash` as ``--tileable`` runs it (``inference.pipeline.finish_maps``): the
    maps' lattice or stripes found first, the lost texture patched."""
    lattice, stripes = tile_pattern(maps).flash_twins()
    return remove_flash(maps, photo, frame, lattice=lattice, stripes=stripes, restore_texture=True)[0]


def _average(values: Sequence[float]) -> float:
    kept = [v for v in values if not math.isnan(v)]
    return sum(kept) / len(kept) if kept else float("nan")


def hotspot_row(renders: Sequence[Render], variant: Variant) -> dict[str, float]:
    """The disc measures of ``variant`` over the renders with 1-10 % clipped; ``both``: how many
    meet both goals (disc/rest ≤ 1.2, disc metal ≤ 0.05 or no dielectric in the disc)."""
    rows = [measures(r, variant(r)) for r in renders if r.in_range]
    ratios = [row["disc/rest"] for row in rows]
    metal = [row["disc metal"] for row in rows]
    return {
        "disc/rest": _average(ratios),
        "worst": max(ratios),
        "≤ 1.2": sum(v <= 1.2 for v in ratios),
        "disc metal": _average(metal),
        "excess": _average([row["disc metal excess"] for row in rows]),
        "≤ 0.05": sum(not v > 0.05 for v in metal),
        "both": sum(r <= 1.2 and not m > 0.05 for r, m in zip(ratios, metal, strict=True)),
        "disc seen": sum(row["disc level"] > LEVEL_THRESHOLD >= row["true disc level"] for row in rows),
        "renders": len(rows),
    }


def _chosen(rows: dict[float, dict[str, float]]) -> float:
    """The setting that meets both goals on the most renders, then the smallest mean disc/rest;
    within 0.005 of it, the first in the grid's order (each grid starts from the shipped value)."""
    most = max(row["both"] for row in rows.values())
    best = min(row["disc/rest"] for row in rows.values() if row["both"] == most)
    return next(key for key, row in rows.items() if row["both"] == most and row["disc/rest"] <= best + 0.005)


def calibration(renders: Sequence[Render]) -> tuple[str, float, float, float]:
    """The grids that chose :data:`~brdfgan.core.clipped_fill.RANGE_SPREAD`,
    :data:`~brdfgan.core.flash_mark.LEVEL_THRESHOLD` and the detail threshold
    (:data:`~brdfgan.core.flash_mark.LEAK_THRESHOLD`) on ``renders`` (the tuning sets), one after
    the other (:func:`_chosen`), as markdown; and the three values chosen."""
    lines = [
        "| setting | disc/rest | worst | ≤ 1.2 | disc metal | ≤ 0.05 | both goals |",
        "|---|---|---|---|---|---|---|",
    ]

    def add(label: str, row: dict[str, float]) -> None:
        count = row["renders"]
        lines.append(
            f"| {label} | {row['disc/rest']:.3f} | {row['worst']:.2f} | {row['≤ 1.2']}/{count} "
            f"| {row['disc metal']:.3f} | {row['≤ 0.05']}/{count} | {row['both']}/{count} |"
        )

    add("network", hotspot_row(renders, VARIANTS["network"]))
    cache: dict[tuple[str, float], Tensor] = {}

    def fill(render: Render, spread: float) -> Tensor:
        if (render.name, spread) not in cache:
            cache[render.name, spread] = filled(render, spread)
        return cache[render.name, spread]

    spreads = {k: hotspot_row(renders, partial(fill, spread=k)) for k in (1.0, 0.0, 0.5, 1.5, 2.0)}
    for k, row in spreads.items():
        add(f"clipped fill, spread {k:g}", row)
    spread = _chosen(spreads)
    levels = {
        t: hotspot_row(renders, partial(levelled, spread=spread, level=t, detail=LEAK_THRESHOLD, fill=fill))
        for t in (3.0, 1.0, 2.0, 5.0, 8.0, math.inf)
    }
    for t, row in levels.items():
        add(f"fill {spread:g} + level threshold {t:g}", row)
    threshold = _chosen(levels)
    details = {LEAK_THRESHOLD: levels[threshold]}
    details |= {
        d: hotspot_row(renders, partial(levelled, spread=spread, level=threshold, detail=d, fill=fill))
        for d in (4.0, math.inf)
    }
    for d in (4.0, math.inf):
        add(f"fill {spread:g} + level {threshold:g} + detail threshold {d:g}", details[d])
    return "\n".join(lines) + "\n", spread, threshold, _chosen(details)


COLUMNS = ("disc/rest", "worst", "≤ 1.2", "disc metal", "excess", "≤ 0.05", "disc seen")


def report(title: str, renders: Sequence[Render]) -> str:
    """Table 2 (disc measures per variant) and table 3 (metal per variant) of one set."""
    hot = sum(r.in_range for r in renders)
    regular = [r for r in renders if r.family in REGULAR]
    lines = [
        f"**{title}**: {len(renders)} renders, {hot} with 1-10 % clipped (the disc columns), "
        f"{len(regular)} of the regular families (thin dark metal)\n",
        "| maps | disc/rest | worst | ≤ 1.2 | disc metal | disc metal − rest's | ≤ 0.05 | disc seen "
        "| thin dark metal | false metal | metal kept |",
        "|---" * 12 + "|",
    ]
    for label, variant in VARIANTS.items():
        row = hotspot_row(renders, variant) if hot else dict.fromkeys(COLUMNS, float("nan")) | {"renders": 0}
        every = {r.name: measures(r, variant(r)) for r in renders}
        thin = _average([every[r.name]["thin dark metal"] for r in regular])
        false_metal = _average([m["false metal"] for m in every.values()])
        kept = _average([m["metal kept"] for m in every.values()])
        count = row["renders"]
        lines.append(
            f"| {label} | {row['disc/rest']:.3f} | {row['worst']:.2f} | {row['≤ 1.2']}/{count} "
            f"| {row['disc metal']:.3f} | {row['excess']:+.3f} | {row['≤ 0.05']}/{count} "
            f"| {row['disc seen']}/{count} | {thin:.4f} "
            f"| {false_metal:.4f} | {kept:.3f} |"
        )
    return "\n".join(lines) + "\n"


def family_table(renders: Sequence[Render]) -> str:
    """Thin-dark metal per regular family, the network against :func:`suppress_false_metal`."""
    lines = [
        "| family | renders | thin dark metal: network | after the rule | false metal: network | after "
        "| metal kept: network | after |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for family in REGULAR:
        chosen = [r for r in renders if r.family == family]
        if not chosen:
            continue
        before = [measures(r, r.predicted) for r in chosen]
        after = [measures(r, suppress_false_metal(r.predicted, r.photo)[0]) for r in chosen]
        cells = []
        for key in ("thin dark metal", "false metal", "metal kept"):
            cells += [f"{_average([m[key] for m in before]):.4f}", f"{_average([m[key] for m in after]):.4f}"]
        lines.append(f"| {family} | {len(chosen)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def samples_table(model: nn.Module) -> str:
    """The shipped sample photos (``src/brdfgan/samples``, real phone photos, no truth) at 256²
    through the model and :func:`remove_flash`: the highlight's reach, the disc's level scores
    (:func:`~brdfgan.core.flash_mark.level_scores` at that reach) before and after (and after
    ``--tileable``'s removal, :func:`tileable_removal`), the mean
    metallic on the photo's thin dark features (:func:`thin_dark_weight` > 0.5) over the mean
    elsewhere, before and after."""
    lines = [
        "| sample | clipped | reach px | level scores before (base colour, metallic) | after "
        "| after --tileable | levelled | metal on thin dark features over elsewhere: before | after |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for path in sorted((ROOT / "src" / "brdfgan" / "samples").glob("*.jpg")):
        prepared = preprocess(read_photo(path, "srgb"), SIDE)
        frame = prepared.flash_frame(DEFAULT_FOV_DEG)
        with torch.no_grad():
            maps = model(prepared.photo[None], frame)[0]
        after, record = remove_flash(maps, prepared.photo, frame)
        hotspot = (float(frame[0, 0]), float(frame[0, 1]))
        radius = record.highlight_radius
        before_scores = level_scores(maps, hotspot, radius) if radius > 0 else {}
        after_scores = level_scores(after, hotspot, radius) if radius > 0 else {}
        tiled = tileable_removal(maps, prepared.photo, frame)
        tiled_scores = level_scores(tiled, hotspot, radius) if radius > 0 else {}
        thin = thin_dark_weight(maps, prepared.photo) > 0.5
        excess = [_mean(m[7], thin) - _mean(m[7], ~thin) for m in (maps, after)]

        def pair(scores: dict[str, float]) -> str:
            return f"{scores['basecolor']:.1f}, {scores['metallic']:.1f}" if scores else "-"

        lines.append(
            f"| {path.stem} | {record.fill.clipped_fraction:.1%} | {radius:.0f} | {pair(before_scores)} "
            f"| {pair(after_scores)} | {pair(tiled_scores)} | {', '.join(record.mark.levelled) or '-'} "
            f"| {excess[0]:+.3f} | {excess[1]:+.3f} |"
        )
    return "\n".join(lines) + "\n"


SETS = {"val": 4, "tune": 2, "test": 2, "ood": 2}  # renders per material


def load_set(name: str, args: argparse.Namespace, spec: DatasetSpec, model: nn.Module) -> list[Render]:
    """The set's renders, from the cache when it holds them."""
    crops = SETS[name]
    limit = args.test if name == "test" else 0
    cache = args.cache / f"{name}-{crops}-{limit}-{args.seed}.pt"
    if cache.is_file():
        return torch.load(cache, weights_only=False)
    if name == "ood":
        materials = ood_materials()
    elif name == "tune":
        materials = fresh_materials(spec, args.seed)
    else:
        materials = held_out(spec, name, limit)
    renders = render_set(name, materials, crops, model, args.seed)
    cache.parent.mkdir(parents=True, exist_ok=True)
    torch.save(renders, cache)
    return renders


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--test", type=int, default=24, help="test materials, the regular families first")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", type=Path, default=ROOT / "outputs" / "flash_leak")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    started = time.time()
    spec: DatasetSpec = hydra.utils.instantiate(compose_config().data.prepare.spec, _convert_="all")
    model = load_model(None).generator.eval()
    sets = {name: load_set(name, args, spec, model) for name in SETS}
    log(f"renders ready ({time.time() - started:.0f} s)")
    tuning = sets["val"] + sets["tune"]
    grid, spread, level, detail = calibration(tuning)
    report_lines = [
        "# The flash in the maps: before and after brdfgan.core.clipped_fill.remove_flash\n",
        f"## Calibration on val + tune ({sum(r.in_range for r in tuning)} renders with 1-10 % clipped)\n",
        grid,
        f"Chosen: spread {spread:g}, level threshold {level:g}, detail threshold {detail:g} "
        f"(shipped: {RANGE_SPREAD:g}, {LEVEL_THRESHOLD:g}, {LEAK_THRESHOLD:g}).\n",
        "## Per set, shipped constants\n",
    ]
    log(f"calibrated ({time.time() - started:.0f} s)")
    for name, renders in sets.items():
        report_lines.append(report(name, renders))
        write_text_atomic(args.out, "\n".join(report_lines))
    report_lines.append("## The shipped sample photos (real, no truth)\n")
    report_lines.append(samples_table(model))
    report_lines.append("## Thin dark metal on the regular families (test)\n")
    report_lines.append(family_table(sets["test"]))
    report_lines.append(f"{time.time() - started:.0f} s in all")
    write_text_atomic(args.out, "\n".join(report_lines))
    print("\n".join(report_lines))


if __name__ == "__main__":
    main()
