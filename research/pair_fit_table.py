"""The pair fit on held-out flash + no-flash pairs (issue 59, items 3-4): normals, base colour and
the other maps of the pair fit beside its references, on photos rendered by the project's renderer.

Held-out materials: the validation split's procedural materials and scan sets of
``dataset_spec=procedural_and_scans`` (the shipped model's data) and the out-of-distribution scans
(``../shared/ood/ambientcg`` or ``BRDFGAN_OOD_DIR``). Each crop is photographed as
:func:`~brdfgan.data.loading.rendered.draw_scene` draws a training photo — the capture, the flash,
a *test* environment as the room light at 0.05-1 × the flash — twice: flash and room light, and
the room light alone, each auto-exposed on its own (the exposure ratio known, as EXIF gives it).
No phone effects unless ``--sensor`` (the evaluation sensor on each shot, its own draws).

Rows:
- ``flat``: the true maps with flat normals (the angle every row is compared with);
- ``v4 flash``: the shipped network on the flash photo (today's predict);
- ``v4 flash-only``: on the flash-only image (the room light subtracted, re-exposed);
- ``de-lit flash-only``: the de-lit reference on the flash-only image;
- ``pair fit``: :func:`~brdfgan.inference.pair.relief_fit.fit_pair` read with ``v4 flash-only``
  and written into ``v4 flash``, as ``brdfgan predict --no-flash`` runs it (before 2026-12-07,
  later: written into ``v4 flash-only``);
- ``v4 flash, as written`` and ``pair fit, as written``: the two as ``brdfgan predict`` writes them,
  through :func:`~brdfgan.core.clipped_fill.remove_flash` (what every prediction goes through)
  with the flash photo, whose reading they carry.

``--shards DIR`` scores a generated dataset's Mitsuba pairs instead (``dataset_spec.pairs``: each
test sample's no-flash twin, undone with its ``meta["pair"]``), e.g. the OOD benchmark's:
``generate.py dataset_spec=ood out_dir=data/ood_pairs``, then ``--shards data/ood_pairs``.

    python -m research.pair_fit_table --crops 4 --out outputs/pair_fit/table.md
"""

from __future__ import annotations

import argparse
import itertools
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import hydra
import numpy as np
import torch
from torch import Tensor, nn

from brdfgan.core.clipped_fill import CLIP_LEVEL as CLIP
from brdfgan.core.clipped_fill import remove_flash
from brdfgan.core.exposure import auto_exposure_scale
from brdfgan.core.render import warp_maps_to_view
from brdfgan.core.svbrdf import NORMAL, encode_normal, linear_to_srgb
from brdfgan.data.loading.datamodule import collate_samples, flash_frames
from brdfgan.data.loading.rendered import collate_scenes, draw_scene, render_scenes, scene_tensors
from brdfgan.data.materials.scanned import read_scanned_material, scanned_material_folders
from brdfgan.data.materials.source import PaintedMaterial
from brdfgan.data.phone.conditions import sample_as_photographed
from brdfgan.data.phone.environments import build_environment_pools
from brdfgan.data.phone.pairs import flash_only_photos
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.data.spec.dataset_spec import (
    DatasetSpec,
    paint_material,
    scan_materials,
    split_materials,
    split_scan_sets,
)
from brdfgan.data.spec.determinism import derive_seed, material_seed
from brdfgan.data.storage.shards import Sample, iter_shard, list_shards
from brdfgan.figures import caption, with_column_header
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pair.relief_fit import PairFitConfig, fit_pair
from brdfgan.io.atomic import write_text_atomic
from brdfgan.io.images import write_image
from brdfgan.losses.parameter import angular_distance
from brdfgan.metrics import SVBRDFMetrics
from research.relief_tables import OOD_SCANS, HandfulBank, compose_config, log

ROOT = Path(__file__).resolve().parents[1]
DE_LIT = ROOT / "src" / "brdfgan" / "weights" / "references" / "de_lit.safetensors"
ROWS = (
    "flat",
    "v4 flash",
    "v4 flash-only",
    "de-lit flash-only",
    "pair fit",
    "v4 flash, as written",
    "pair fit, as written",
)
COLUMNS = (
    ("angle / flat", "normal_angle_deg"),
    ("observable / flat", "normal_angle_deg/observable"),
    ("slope cos", "normal_slope_cosine"),
    ("slope ratio", "normal_slope_ratio"),
    ("base colour RMSE", "rmse/basecolor"),
    ("roughness RMSE", "rmse/roughness"),
    ("re-render", "rerender_rmse"),
    ("false metal", "false_metal"),
    ("relief leak", "relief_leak"),
)


@dataclass(frozen=True)
class Pair:
    """One held-out pair as the fit and the networks get it (all at the crop's size R)."""

    flash: Tensor  # (3, R, R) the flash photo, linear LDR
    flash_only: Tensor  # (3, R, R) flash − ratio · no-flash, re-exposed
    room: Tensor  # (3, R, R) the room light's share, in flash_only's units
    valid: Tensor  # (1, R, R) neither shot clipped
    frame: Tensor  # (1, 3)
    truth: Tensor  # (8, R, R) the maps as the photo shows them


def held_out_sets(spec: DatasetSpec) -> dict[str, list[PaintedMaterial]]:
    """The validation split's procedural materials and scan sets, and the OOD scans."""
    scans = scan_materials(spec)
    procedural = [
        paint_material(spec, "val", index, torch.Generator().manual_seed(material_seed(spec.seed, index)))
        for index in split_materials(spec)["val"]
        if index not in scans
    ]
    folders = scanned_material_folders(str(spec.scans.folder), key="dataset_spec.scans.folder")

    def scanned(folder: Path) -> PaintedMaterial:
        maps = read_scanned_material(folder, spec.scans.resolution)
        return PaintedMaterial(maps, f"scanned/{folder.name}", {}, {}, spec.scans.crop)

    return {
        "val procedural": procedural,
        "val scans": [scanned(folders[i]) for i in split_scan_sets(spec)["val"]],
        "OOD scans": [scanned(folder) for folder in scanned_material_folders(str(OOD_SCANS))],
    }


def photograph_pair(
    bank: HandfulBank, key: str, seed: int, lights: int, sensor: SensorEffects | None
) -> Pair:
    """The pair of one drawn scene (module docstring)."""
    scene = draw_scene(bank, key, seed, lights)
    maps, camera, position, rgb, grid, exposure_ev = scene_tensors(collate_scenes([scene]))
    room_rgb = rgb.clone()
    room_rgb[:, 0] = 0.0  # light 0 is the flash
    shots = []
    for index, light in enumerate((rgb, room_rgb)):
        hdr = render_scenes(maps, camera, position, light, grid)
        scale = auto_exposure_scale(hdr) * (torch.pow(2.0, exposure_ev) if index == 0 else 1.0)
        photo = (hdr * scale[:, None, None, None]).clamp(0.0, 1.0)[0]
        if sensor is not None:
            generator = torch.Generator().manual_seed(
                derive_seed(seed, "pair sensor", index) & 0x7FFFFFFFFFFFFFFF
            )
            illuminant = SensorEffects.flash_illuminant(scene.meta) if index == 0 else None
            photo, record = sensor.apply(photo, generator, illuminant_rgb=illuminant)
            scale = scale * (record["exposure_scale"] or 1.0)
        shots.append((photo, float(scale)))
    (flash, flash_scale), (no_flash, room_scale) = shots
    ratio = flash_scale / room_scale  # the exposure ratio EXIF would give
    hdr_flash_only = (flash - ratio * no_flash).clamp_min(0.0) / flash_scale
    exposure = float(auto_exposure_scale(hdr_flash_only[None]))
    valid = ((flash.amax(0) < CLIP) & (no_flash.amax(0) < CLIP)).float()[None]
    return Pair(
        flash=flash,
        flash_only=(hdr_flash_only * exposure).clamp(0.0, 1.0),
        room=no_flash * ratio / flash_scale * exposure,
        valid=valid,
        frame=flash_frames([scene.meta], flash.shape[-2], flash.shape[-1]),
        truth=warp_maps_to_view(maps, grid)[0],
    )


def shard_pairs(root: Path, scanned: bool, split: str = "test") -> Iterator[Pair]:
    """The Mitsuba pairs of a generated dataset (module docstring), maps aligned as the evaluator
    does: its scanned materials' (``meta["family"]`` ``scanned/…``) or its procedural ones'."""
    for shard in list_shards(root, split):
        for stored in iter_shard(shard):
            if stored.no_flash is None:
                raise SystemExit(f"{shard}: sample {stored.key} has no no-flash twin (dataset_spec.pairs)")
            if str(stored.meta.get("family", "")).startswith("scanned/") != scanned:
                continue
            sample = sample_as_photographed(stored)
            batch = collate_samples([Sample(stored.key, sample.photo, sample.maps, sample.meta,
                                            check=False, no_flash=stored.no_flash)])  # fmt: skip
            pair = flash_only_photos(batch["photo"], batch["photo_noflash"], batch["exposure_ratio"],
                                     batch["white_balance"], CLIP)  # fmt: skip
            exposure = float(auto_exposure_scale(pair.flash_only))
            yield Pair(
                flash=sample.photo,
                flash_only=(pair.flash_only[0] * exposure).clamp(0.0, 1.0),
                room=pair.room[0] * exposure,
                valid=pair.valid[0],
                frame=batch["flash"],
                truth=sample.maps,
            )


def score(
    pairs: Iterator[Pair], v4: nn.Module, de_lit: nn.Module, config: PairFitConfig
) -> tuple[dict[str, dict[str, float]], int]:
    """Every row's metrics over ``pairs``, and how many there were."""
    metrics = {row: SVBRDFMetrics(downscale_to=None) for row in ROWS}
    count = 0
    for pair in pairs:
        for row, maps in predictions(pair, v4, de_lit, config):
            metrics[row].update(maps[None], pair.truth[None], flash=pair.frame, photo=pair.flash[None])
        count += 1
    return {row: {k: float(v) for k, v in metric.compute().items()} for row, metric in metrics.items()}, count


def predictions(
    pair: Pair, v4: nn.Module, de_lit: nn.Module, config: PairFitConfig
) -> Iterator[tuple[str, Tensor]]:
    flat = pair.truth.clone()
    flat[NORMAL] = 0.0
    flat[NORMAL.start + 2] = 1.0
    yield "flat", flat
    with torch.no_grad():
        single = v4(pair.flash[None], pair.frame)[0]
        yield "v4 flash", single
        from_flash_only = v4(pair.flash_only[None], pair.frame)[0]
        yield "v4 flash-only", from_flash_only
        yield "de-lit flash-only", de_lit(pair.flash_only[None], pair.frame)[0]
    fitted = fit_pair(
        pair.flash_only, pair.room, pair.valid, from_flash_only, pair.frame, config, written=single
    ).maps
    yield "pair fit", fitted
    yield "v4 flash, as written", remove_flash(single, pair.flash, pair.frame)[0]
    yield "pair fit, as written", remove_flash(fitted, pair.flash, pair.frame)[0]


FIGURE_COLUMNS = ("flash photo", "no-flash photo", "normal: truth", "v4, flash photo", "pair fit")


def figure_row(pair: Pair, v4: nn.Module, config: PairFitConfig, label: str, panel: int) -> np.ndarray:
    """One row of the before/after figure: the two photos (the no-flash one scaled to its own
    range), the true normals, v4's from the flash photo and the pair fit's, each normal panel
    captioned with its mean angle to the truth. Shape ``(panel, 5·panel, 3)`` uint8."""
    with torch.no_grad():
        single = v4(pair.flash[None], pair.frame)[0]
        from_flash_only = v4(pair.flash_only[None], pair.frame)[0]
    fitted = fit_pair(pair.flash_only, pair.room, pair.valid, from_flash_only, pair.frame, config).maps
    room = pair.room / pair.room.amax().clamp_min(1e-6)
    tiles = [linear_to_srgb(pair.flash.clamp(0, 1)), linear_to_srgb(room.clamp(0, 1))]
    tiles += [encode_normal(maps[NORMAL]) for maps in (pair.truth, single, fitted)]
    images = [
        cv2.resize(t.permute(1, 2, 0).numpy(), (panel, panel), interpolation=cv2.INTER_AREA) for t in tiles
    ]
    row = np.ascontiguousarray((np.concatenate(images, axis=1) * 255.0 + 0.5).astype(np.uint8))
    caption(row, label, (3, 12))
    flat = torch.zeros_like(pair.truth[NORMAL])
    flat[2] = 1.0
    for column, maps in ((2, None), (3, single), (4, fitted)):
        normal = flat if maps is None else maps[NORMAL]
        angle = float(angular_distance(normal, pair.truth[NORMAL], dim=0).mean()) * 180.0
        text = f"flat {angle:.1f} deg" if maps is None else f"{angle:.1f} deg"
        caption(row, text, (column * panel + 3, panel - 6))
    return row


def write_figure(path: Path, rows: list[np.ndarray]) -> None:
    canvas = np.concatenate(rows, axis=0).astype(np.float32) / 255.0
    write_image(path, with_column_header(canvas, FIGURE_COLUMNS))


def figure_pairs(root: Path, count: int) -> list[tuple[str, Pair]]:
    """The figure's pairs, chosen by a rule that does not look at any prediction: of each of the
    first ``count`` scanned sets in key order, the crop with the most relief (the flat map's mean
    angle to its true normals)."""
    best: dict[str, tuple[float, Pair]] = {}
    for pair, family in zip(shard_pairs(root, scanned=True), shard_families(root, scanned=True), strict=True):
        if family not in best and len(best) == count:
            continue
        normal = pair.truth[NORMAL]
        relief = float(torch.acos(normal[2].clamp(-1.0, 1.0)).mean())
        if family not in best or relief > best[family][0]:
            best[family] = (relief, pair)
    return [(family.removeprefix("scanned/"), pair) for family, (_, pair) in best.items()]


def shard_families(root: Path, scanned: bool, split: str = "test") -> Iterator[str]:
    """The ``meta["family"]`` of :func:`shard_pairs`'s pairs, in its order."""
    for shard in list_shards(root, split):
        for stored in iter_shard(shard):
            family = str(stored.meta.get("family", ""))
            if family.startswith("scanned/") == scanned:
                yield family


def table(name: str, scores: dict[str, dict[str, float]], photos: int) -> str:
    flat = scores["flat"]
    lines = [f"**{name}** ({photos} pairs)\n", "| row | " + " | ".join(c for c, _ in COLUMNS) + " |"]
    lines.append("|---" * (len(COLUMNS) + 1) + "|")
    for row in ROWS:
        values = scores[row]
        cells = []
        for column, key in COLUMNS:
            value = values.get(key, float("nan"))
            if column == "angle / flat":
                value /= flat["normal_angle_deg"]
            elif column == "observable / flat":
                value = value / values.get("normal_angle_deg/observable_flat", float("nan"))
            cells.append(f"{value:.3f}")
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    lines.append(f"\nflat map's angle {flat['normal_angle_deg']:.2f}°")
    return "\n".join(lines) + "\n"


def score_shards(args: argparse.Namespace, v4: nn.Module, de_lit: nn.Module, config: PairFitConfig,
                 started: float) -> None:  # fmt: skip
    """``--shards``: the table of a generated dataset's Mitsuba pairs, or with ``--figure`` its figure."""
    if args.figure is not None:
        chosen = figure_pairs(args.shards, args.figure_rows)
        write_figure(args.figure, [figure_row(pair, v4, config, label, 128) for label, pair in chosen])
        print(f"wrote {args.figure}")
        return
    shard_report = [f"# The pair fit on Mitsuba pairs: {args.shards} (no sensor)\n"]
    for name, scanned in (("test split, scans", True), ("test split, procedural", False)):
        pairs = itertools.islice(shard_pairs(args.shards, scanned), args.max_pairs or None)
        scores, count = score(pairs, v4, de_lit, config)
        if count:
            shard_report.append(table(name, scores, count))
        write_text_atomic(args.out, "\n".join(shard_report))
        log(f"{name}: {count} pairs ({time.time() - started:.0f} s)")
    print("\n".join(shard_report))


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--crops", type=int, default=3, help="pairs per held-out material")
    parser.add_argument("--limit", type=int, default=0, help="materials per set (0: all)")
    parser.add_argument("--sensor", action="store_true", help="the evaluation sensor on each shot")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--sets", default="val procedural,val scans,OOD scans", help="comma-separated held-out sets to score"
    )
    parser.add_argument("--flat-prior", type=float, default=PairFitConfig.flat_prior)
    parser.add_argument("--min-roughness", type=float, default=PairFitConfig.min_roughness)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--shards", type=Path, default=None, help="a generated dataset with pairs (its test split)"
    )
    parser.add_argument(
        "--figure", type=Path, default=None, help="with --shards: the before/after figure of its scans' pairs"
    )
    parser.add_argument("--figure-rows", type=int, default=7)
    parser.add_argument(
        "--max-pairs", type=int, default=0, help="with --shards: the first N pairs of each group (0: all)"
    )
    args = parser.parse_args(argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    started = time.time()
    cfg = compose_config()
    spec: DatasetSpec = hydra.utils.instantiate(cfg.data.prepare.spec, _convert_="all")
    sensor = hydra.utils.instantiate(cfg.data.eval_sensor) if args.sensor else None
    lights = int(cfg.data.environment_lights)
    test_environments = build_environment_pools(spec.lighting, derive_seed(spec.seed, "lighting")).test
    v4, de_lit = (load_model(path).generator.eval() for path in (None, DE_LIT))
    config = PairFitConfig(flat_prior=args.flat_prior, min_roughness=args.min_roughness)
    if args.shards is not None:
        score_shards(args, v4, de_lit, config, started)
        return
    report = [f"# The pair fit on held-out pairs ({'evaluation sensor' if args.sensor else 'no sensor'})\n"]
    chosen = args.sets.split(",")
    for name, materials in held_out_sets(spec).items():
        if name not in chosen:
            continue
        materials = materials[: args.limit] if args.limit else materials

        def rendered(name: str = name, materials: list[PaintedMaterial] = materials) -> Iterator[Pair]:
            for m, material in enumerate(materials):
                bank = HandfulBank(spec, [material], int(cfg.data.bank.environment_resolution))
                bank.scan_folders = ()
                bank.environments = test_environments
                for crop in range(args.crops):
                    seed = derive_seed(args.seed, "pair table", name, m, crop) & 0x7FFFFFFFFFFFFFFF
                    yield photograph_pair(bank, f"pair-{m}-{crop}", seed, lights, sensor)
                log(f"{name}: {m + 1}/{len(materials)} materials ({time.time() - started:.0f} s)")

        scores, photos = score(rendered(), v4, de_lit, config)
        report.append(table(name, scores, photos))
        write_text_atomic(args.out, "\n".join(report))
    report.append(f"{time.time() - started:.0f} s in all")
    write_text_atomic(args.out, "\n".join(report))
    print("\n".join(report))


if __name__ == "__main__":
    main()
