"""``brdfgan predict --tileable`` on the network's own maps: how well the tiles wrap, how much of
them is copied pixels (a cut) rather than blends, the flash mark's repair, and the time.

For every photo the maps come from the shipped weights (or ``--weights``) as ``brdfgan predict``
makes them: the package's sample photos by default; with ``SOURCE``, a folder of photo files
(through predict's intake) or a dataset folder of shards (e.g. the OOD benchmark ``data/ood``,
its ``--split``; photos stored as predict's intake leaves them, with their recorded flash frame).
Then :func:`brdfgan.inference.pipeline.make_tileable` (repair → roll → cuts) is timed, and the
previous method (:func:`brdfgan.core.seamless.blend_reference`) runs on the same repaired maps
for the before/after. Per map: the wrap ratio (:func:`~brdfgan.core.seamless.wrap_ratios`, the
worse of columns and rows; ≤ 1.2 is the goal) and the copied fraction
(:func:`~brdfgan.core.seamless.copied_fraction`: pixels within two 8-bit levels of one of the
tile's copies; ≥ 0.85 is the goal). Last, the time of ``make_tileable`` at ``--large``² (2048²: a
phone photo's maps) on up to three inputs, in the same run: the first photo that took today's cut,
a periodic one that takes the whole-cell path (``core.lattice``: detection, resampling, residual
seams), the first such photo (the ceramic tiles among the samples), else a synthetic 45° grid of
tiles, and the first photo tiled by whole stripes (``core.stripes``; the wood planks among the
samples). Each is the photo's maps enlarged (bilinear), so the path at that size is said beside it,
with the CPU seconds of its steps timed again one by one: the flash-mark repair, the lattice
detection, the stripes' detection (which runs wherever no lattice cells are used) and the tile on
that path.

    python -m benchmarks.bench_tiling [SOURCE] [--split test] [--weights W] [--large 2048]
        [--threads N] [--json out.json]

``--threads 1`` gives steady times on a machine shared with other jobs: the tiling's operations
are small, and with two threads each of them can wait for a busy core. The CPU seconds (in
parentheses) are the process's own, what a wall time is on an idle machine with one thread.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

WRAP_GOAL = 1.2
COPIED_GOAL = 0.85


# (name, maps, flash frame (1, 3) of the maps' pixels, the network's input photo (None: synthetic))
Item = tuple[str, Tensor, Tensor, Tensor | None]


def photo_maps(photos: list[Path], weights: Path | None) -> Iterator[Item]:
    """``(name, maps, frame, photo)`` per photo file, as ``brdfgan predict`` makes the maps."""
    from brdfgan.inference.intake.lens import crop_field_of_view
    from brdfgan.inference.intake.photo import read_photo
    from brdfgan.inference.intake.preprocess import preprocess
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import PredictOptions, Predictor

    predictor = Predictor.create(load_model(weights), PredictOptions(preview=False))
    for path in photos:
        photo = read_photo(path)
        prepared = preprocess(photo, predictor.resolution, None)
        fov, _ = crop_field_of_view(
            photo.lens, photo.width, photo.height, prepared.crop.size, predictor.options.field_of_view
        )
        frame = prepared.flash_frame(fov)
        with torch.no_grad():
            maps = predictor.maps(prepared.photo, frame)
        yield path.stem, maps, frame, prepared.photo


def shard_maps(root: Path, split: str, weights: Path | None) -> Iterator[Item]:
    """``(key, maps, frame, photo)`` per sample of a dataset split, the network run on the stored photo
    with the sample's flash frame (what the evaluator does)."""
    from brdfgan.data.loading.datamodule import flash_frames
    from brdfgan.data.storage.shards import iter_shard, list_shards
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import PredictOptions, Predictor

    shards = list_shards(root, split)
    if not shards:
        sys.exit(f"error: {root}: no photos and no {split}/ shards")
    predictor = Predictor.create(load_model(weights), PredictOptions(preview=False))
    for shard in shards:
        for sample in iter_shard(shard):
            height, width = sample.photo.shape[-2:]
            frame = flash_frames([sample.meta], height, width)
            with torch.no_grad():
                maps = predictor.maps(sample.photo.float(), frame)
            yield sample.key, maps, frame, sample.photo.float()


def network_maps(source: Path, split: str = "test", weights: Path | None = None) -> Iterator[Item]:
    """The maps of every sample of the dataset ``split`` when ``source`` is a dataset (it holds
    ``dataset.json``; generation also leaves contact-sheet images there, which are not photos),
    else of every photo file in it (:func:`shard_maps`, :func:`photo_maps`)."""
    from brdfgan.inference.intake.photo import PHOTO_EXTENSIONS

    if (source / "dataset.json").is_file():
        return shard_maps(source, split, weights)
    photos = sorted(p for p in source.iterdir() if p.is_file() and p.suffix.lower() in PHOTO_EXTENSIONS)
    return photo_maps(photos, weights)


def _worst(pairs: dict[str, tuple[float, float]]) -> dict[str, float]:
    return {name: max(pair) for name, pair in pairs.items()}


def measure(name: str, maps: Tensor, hotspot: tuple[float, float]) -> dict[str, Any]:
    """One photo's row: the cut (timed) and the blend on the same repaired maps."""
    from brdfgan.core.flash_mark import repair_flash_mark
    from brdfgan.core.seamless import blend_reference, tiling_measures
    from brdfgan.inference.pipeline import make_tileable

    start, cpu = time.perf_counter(), time.process_time()
    _, record = make_tileable(maps, hotspot)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    repaired, _ = repair_flash_mark(maps, hotspot)
    blended, shifts = blend_reference(repaired)
    blend = tiling_measures(blended, repaired, shifts)
    return {
        "name": name,
        "size": int(maps.shape[-1]),
        "seconds": seconds,
        "cpu_seconds": cpu,
        "whole_cells": record.cells is not None,
        "kind": "stripes"
        if record.stripes is not None
        else "periodic"
        if record.cells is not None
        else "non-periodic",
        "repaired": {map_name: record.flash_mark.scores[map_name] for map_name in record.flash_mark.repaired},
        "leak_scores": record.flash_mark.scores,
        "wrap_before": _worst(record.wrap_ratio_before),
        "cut": {"wrap": _worst(record.after.wrap_ratio), "copied": record.after.copied_fraction},
        "blend": {"wrap": _worst(blend.wrap_ratio), "copied": blend.copied_fraction},
    }


# The paths timed at --large: the first photo on each (a synthetic grid where no photo is periodic).
LARGE_KINDS = ("non-periodic", "periodic", "stripes")


def _large(maps: Tensor, frame: Tensor, photo: Tensor | None, side: int) -> dict[str, Any]:
    """Wall and CPU seconds of ``make_tileable`` on ``maps`` enlarged to ``side``², the path it took
    there (``whole cells`` or ``cut``), and the CPU seconds of its steps timed again one by one (the
    flash-mark repair, the lattice detection, the tile on that path), and of ``brdfgan predict``'s
    flash removal (:func:`~brdfgan.core.clipped_fill.remove_flash`, with the lattice or stripes of
    a repeating material) on the photo enlarged with them (``None`` without a photo)."""
    import torch.nn.functional as F

    from brdfgan.core.clipped_fill import remove_flash
    from brdfgan.core.flash_geometry import resize_flash_frame
    from brdfgan.core.flash_mark import repair_flash_mark
    from brdfgan.core.lattice import find_lattice, tile_whole_cells
    from brdfgan.core.seamless import make_seamless
    from brdfgan.core.stripes import find_stripes
    from brdfgan.core.svbrdf import resize_maps
    from brdfgan.inference.pipeline import make_tileable, tile_pattern

    factor = side / maps.shape[-1]
    large = resize_maps(maps, side)
    large_frame = resize_flash_frame(frame, factor)
    centre = (float(large_frame[0, 0]), float(large_frame[0, 1]))
    start, cpu = time.perf_counter(), time.process_time()
    _, record = make_tileable(large, centre)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    path = f"whole cells ({record.cells.cells})" if record.cells is not None else "cut"
    if record.stripes is not None and record.cells is not None:
        path = f"whole stripes ({record.stripes.period:.1f} px, {record.cells.cells} cells)"
    step = time.process_time()
    repaired, _ = repair_flash_mark(large, centre)
    repair = time.process_time() - step
    step = time.process_time()
    find_lattice(repaired)
    detection = time.process_time() - step
    step = time.process_time()
    find_stripes(repaired)  # run wherever no lattice cells are used
    stripes_detection = time.process_time() - step
    step = time.process_time()
    if record.cells is not None:
        tile_whole_cells(repaired, replace(record.cells, roll=(0, 0)))
    else:
        make_seamless(repaired)
    tile = time.process_time() - step
    flash_removal = None
    if photo is not None:
        large_photo = F.interpolate(photo[None].float(), size=(side, side), mode="bilinear")[0].clamp(0, 1)
        lattice, stripes = tile_pattern(large).flash_twins()
        step = time.process_time()
        remove_flash(large, large_photo, large_frame, lattice=lattice, stripes=stripes)
        flash_removal = time.process_time() - step
    return {
        "seconds": wall,
        "cpu_seconds": cpu,
        "path": path,
        "repair_cpu_seconds": repair,
        "detection_cpu_seconds": detection,
        "stripes_detection_cpu_seconds": stripes_detection,
        "tile_cpu_seconds": tile,
        "flash_removal_cpu_seconds": flash_removal,
    }


def synthetic_grid(side: int = 256) -> tuple[Tensor, Tensor, None]:
    """A 45° grid of glazed tiles in recessed grout (the ceramic sample's layout, five cells a
    side), with a little shading noise: a periodic input when the photos hold none. Shape:
    ``(8, side, side)`` float32, the centred flash frame, and no photo."""
    from brdfgan.core.flash_geometry import centred_flash_frame
    from brdfgan.core.svbrdf import join_maps, normalize_normal

    generator = torch.Generator().manual_seed(0)
    axis = torch.arange(side, dtype=torch.float32) + 0.5
    yy, xx = torch.meshgrid(axis, axis, indexing="ij")
    pitch = side / 5.0
    u, v = (xx + yy) / (pitch * 2**0.5), (xx - yy) / (pitch * 2**0.5)
    to_grout = torch.minimum((u - torch.round(u)).abs(), (v - torch.round(v)).abs()) * pitch
    grout = torch.exp(-((to_grout / 2.0) ** 2))
    shade = 0.05 * torch.rand(side, side, generator=generator)
    luminance = (0.75 - 0.45 * grout + shade).clamp(0, 1)
    basecolor = luminance * torch.tensor([0.9, 0.92, 0.95]).view(3, 1, 1)
    gy, gx = torch.gradient(-grout)
    normal = normalize_normal(torch.stack([-0.6 * gx, 0.6 * gy, torch.ones_like(gx)]))
    roughness = (0.2 + 0.6 * grout)[None]
    maps = join_maps(basecolor, normal, roughness, torch.zeros_like(roughness))
    return maps, centred_flash_frame(1, side, side), None


def _fmt(values: dict[str, float], digits: int = 2) -> str:
    return " / ".join(f"{value:.{digits}f}" for value in values.values())


def print_large(kind: str, side: int, timing: dict[str, Any]) -> None:
    """The large timings' lines (:func:`_large`)."""
    print(
        f"make_tileable at {side}², {kind} ({timing['photo']}, {timing['path']}): "
        f"{timing['seconds']:.1f} s (CPU {timing['cpu_seconds']:.1f} s: flash-mark repair "
        f"{timing['repair_cpu_seconds']:.1f}, lattice detection "
        f"{timing['detection_cpu_seconds']:.1f}, stripes detection "
        f"{timing['stripes_detection_cpu_seconds']:.1f}, tile {timing['tile_cpu_seconds']:.1f}, "
        "each on its own)"
    )
    if timing["flash_removal_cpu_seconds"] is not None:
        print(
            f"remove_flash at {side}², {kind} ({timing['photo']}): "
            f"CPU {timing['flash_removal_cpu_seconds']:.1f} s (every prediction runs it)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "source", nargs="?", type=Path, help="photo files or a dataset folder (default: the samples)"
    )
    parser.add_argument("--split", default="test", help="the dataset split when SOURCE holds shards")
    parser.add_argument("--weights", type=Path, default=None, help="a .safetensors file (default: shipped)")
    parser.add_argument(
        "--large", type=int, default=2048, help="side of the timings on enlarged maps (0: skip)"
    )
    parser.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's)")
    parser.add_argument("--json", type=Path, default=None, help="write every row and the summary here")
    args = parser.parse_args()
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    from importlib import resources

    source = args.source or Path(str(resources.files("brdfgan") / "samples"))
    if not source.is_dir():
        sys.exit(f"error: {source}: not a folder")
    items = network_maps(source, args.split, args.weights)

    threads = torch.get_num_threads()
    print(f"--tileable on {source} ({threads} threads); per map: base colour / normal / roughness / metallic")
    columns = (
        "photo",
        "side",
        "s (CPU s)",
        "wrap before",
        "wrap cut",
        "wrap blend",
        "copied cut",
        "copied blend",
    )
    print("| " + " | ".join(columns) + " | repaired (score) |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows: list[dict[str, Any]] = []
    # The inputs of the large timings: the first photo on each path.
    large_inputs: dict[str, Item] = {}
    for item in items:
        name, maps, frame, _ = item
        row = measure(name, maps, (float(frame[0, 0]), float(frame[0, 1])))
        rows.append(row)
        large_inputs.setdefault(row["kind"], item)
        repaired = ", ".join(f"{key} {score:.2f}" for key, score in row["repaired"].items()) or "—"
        print(
            f"| {name} | {row['size']} | {row['seconds']:.2f} ({row['cpu_seconds']:.2f}) "
            f"| {max(row['wrap_before'].values()):.2f} "
            f"| {_fmt(row['cut']['wrap'])} | {_fmt(row['blend']['wrap'])} | {_fmt(row['cut']['copied'], 3)} "
            f"| {_fmt(row['blend']['copied'], 3)} | {repaired} |",
            flush=True,
        )
    if not rows:
        sys.exit(f"error: {source}: nothing to measure")
    worst_wrap = max(max(row["cut"]["wrap"].values()) for row in rows)
    least_copied = min(min(row["cut"]["copied"].values()) for row in rows)
    summary: dict[str, Any] = {
        "photos": len(rows),
        "worst_wrap_cut": worst_wrap,
        "worst_wrap_blend": max(max(row["blend"]["wrap"].values()) for row in rows),
        "least_copied_cut": least_copied,
        "least_copied_blend": min(min(row["blend"]["copied"].values()) for row in rows),
        "median_copied_blend": statistics.median(v for row in rows for v in row["blend"]["copied"].values()),
        "seconds": [min(row["seconds"] for row in rows), max(row["seconds"] for row in rows)],
        "cpu_seconds": [min(row["cpu_seconds"] for row in rows), max(row["cpu_seconds"] for row in rows)],
        "photos_repaired": sum(bool(row["repaired"]) for row in rows),
        "meets_goals": worst_wrap <= WRAP_GOAL and least_copied >= COPIED_GOAL,
    }
    if args.large:
        if "periodic" not in large_inputs:
            large_inputs["periodic"] = ("synthetic 45° grid", *synthetic_grid())
        for kind in LARGE_KINDS:
            if kind in large_inputs:
                name, maps, frame, photo = large_inputs[kind]
                summary[f"{kind}_at_{args.large}"] = {"photo": name, **_large(maps, frame, photo, args.large)}
    print()
    print(
        f"{len(rows)} photos: worst wrap ratio {worst_wrap:.2f} (blend {summary['worst_wrap_blend']:.2f}; "
        f"goal <= {WRAP_GOAL}), least copied fraction {least_copied:.3f} (blend "
        f"{summary['least_copied_blend']:.3f}, median {summary['median_copied_blend']:.3f}; goal >= "
        f"{COPIED_GOAL}), {summary['seconds'][0]:.2f}-{summary['seconds'][1]:.2f} s per photo (CPU "
        f"{summary['cpu_seconds'][0]:.2f}-{summary['cpu_seconds'][1]:.2f} s), "
        f"flash mark repaired in {summary['photos_repaired']}"
    )
    for kind in LARGE_KINDS:
        timing = summary.get(f"{kind}_at_{args.large}")
        if timing is not None:
            print_large(kind, args.large, timing)
    print("goals met" if summary["meets_goals"] else "GOALS NOT MET")
    if args.json is not None:
        args.json.write_text(json.dumps({"source": str(source), "rows": rows, "summary": summary}, indent=1))


if __name__ == "__main__":
    main()
