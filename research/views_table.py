"""The multi-view table of docs/views.md: synthetic handheld Mitsuba captures of held-out materials,
the shipped model fitted to the first K views, scored on views it never saw and against the truth.

    python -m research.views_table --out logs/views [--per-set 4] [--fit 1,2,3,5]

Materials: the first ``--per-set`` samples of the procedural test split, the scan test sets and the
OOD benchmark (data/procedural_and_scans_test_procedural, …_test_scans, data/ood; never trained
on). Each is photographed 9 times (research.synthetic_captures, default settings, the
evaluation sensor, exposure and white balance locked) into OUT/captures/<set>_<n>/, which
``brdfgan eval-captures --fit-views K`` reads too. For each K the shipped model predicts from view 0
and is fitted to views 0…K−1 (K = 1: the prediction alone); every K is scored on the same
held-out views 5–8 (sRGB RMSE, one gain fitted on view 0, as eval-captures), beside the references
(photo as base colour, de-lit photo; one view). Maps against the truth: RMSE of base colour (sRGB),
roughness, metallic and the normal angle. Writes OUT/views_table.md and OUT/views_table.json;
``--figure PATH`` also draws the before/after figure of the README (the capture ``--figure-capture``:
the reference photo, then base colour, normal map, roughness and held-out view 6 relit, for one
photo, five photos and the truth, beside the photo of view 6).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import islice
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import Tensor

from brdfgan.core.svbrdf import encode_normal, linear_to_srgb, split_maps
from brdfgan.data.storage.shards import iter_shard, list_shards
from brdfgan.evaluation.real_captures import (
    CalibratedCapture,
    capture_models,
    fit_capture_maps,
    fit_gain,
    predict_capture_maps,
    read_capture,
    read_views,
    relight,
    score_capture,
)
from brdfgan.figures import caption, with_column_header
from brdfgan.inference.intake.photo import Photo
from brdfgan.io.images import write_image
from brdfgan.metrics.svbrdf_metrics import MapRMSE, NormalAngularError
from research.synthetic_captures import (
    HandheldSettings,
    locked_phone,
    render_synthetic_capture,
    write_synthetic_capture,
)

SETS = {  # each folder's shards of split "test"
    "procedural": "data/procedural_and_scans_test_procedural",
    "scans": "data/procedural_and_scans_test_scans",
    "ood": "data/ood",
}
HELD_OUT = (5, 6, 7, 8)


@dataclass
class Row:
    model: str
    views: int
    relit: list[float]  # one gain fitted on view 0 (eval-captures' headline)
    calibrated: list[float]  # at the capture's calibrated flash power and locked exposure
    maps: list[dict[str, float]]


def materials(sets: Sequence[tuple[str, str, int]]) -> list[tuple[str, Tensor]]:
    """The first ``count`` samples' maps of each ``(name, folder, count)`` (shards of split "test"),
    named ``<name>_<n>``; only the shards that hold them are read."""
    found = []
    for name, folder, count in sets:
        samples = (sample for shard in list_shards(folder, "test") for sample in iter_shard(shard))
        found += [(f"{name}_{n}", sample.maps) for n, sample in enumerate(islice(samples, count))]
    return found


def held_out_errors(
    capture: CalibratedCapture, photos: Sequence[Photo], maps: Tensor, model: str
) -> tuple[float, float]:
    """``maps`` relit at the views of :data:`HELD_OUT`: their mean sRGB RMSE with one gain fitted
    on view 0 (eval-captures' headline) and at the calibrated power."""
    scores = [s for s in score_capture(capture, photos, maps, model) if s.view in HELD_OUT]
    return (
        sum(s.rmse_fitted for s in scores) / len(scores),
        sum(s.rmse_calibrated for s in scores) / len(scores),
    )


def map_errors(pred: Tensor, true: Tensor) -> dict[str, float]:
    rmse, angle = MapRMSE(), NormalAngularError()
    rmse.update(pred[None], true[None])
    angle.update(pred[None], true[None])
    values = {f"rmse/{key}": float(value) for key, value in rmse.compute().items()}
    values["normal_angle_deg"] = float(angle.compute())
    return values


FIGURE_VIEW = 6
FIGURE_COLUMNS = ("photo (view 0)", "base colour", "normal", "roughness", f"view {FIGURE_VIEW} relit")


def figure_row(
    capture: CalibratedCapture, photos: list[Photo], maps: Tensor, label: str, panel: int
) -> np.ndarray:
    """One row of the figure: the reference photo, maps, and held-out view relit with the gain of
    view 0 (as scored). Shape ``(panel, 5·panel, 3)`` uint8."""
    parts = split_maps(maps)
    renders = relight(capture, maps)
    gain = fit_gain(renders[0], photos[0].linear)
    tiles = [
        linear_to_srgb(photos[0].linear.clamp(0, 1)),
        parts.basecolor,
        encode_normal(parts.normal),
        parts.roughness.expand(3, -1, -1),
        linear_to_srgb((gain * renders[FIGURE_VIEW]).clamp(0, 1)),
    ]
    images = [
        cv2.resize(t.permute(1, 2, 0).numpy(), (panel, panel), interpolation=cv2.INTER_AREA) for t in tiles
    ]
    row = np.ascontiguousarray((np.concatenate(images, axis=1) * 255.0 + 0.5).astype(np.uint8))
    caption(row, label, (3, 12))
    return row


def write_figure(
    path: Path,
    capture: CalibratedCapture,
    photos: list[Photo],
    rows: list[tuple[str, Tensor]],
    panel: int = 160,
) -> None:
    canvas = np.concatenate([figure_row(capture, photos, maps, label, panel) for label, maps in rows], axis=0)
    truth_photo = linear_to_srgb(photos[FIGURE_VIEW].linear.clamp(0, 1)).permute(1, 2, 0).numpy()
    column = np.zeros((canvas.shape[0], panel, 3), dtype=np.uint8)
    column[:panel] = (
        cv2.resize(truth_photo, (panel, panel), interpolation=cv2.INTER_AREA) * 255.0 + 0.5
    ).astype(np.uint8)
    caption(column, f"photo {FIGURE_VIEW} (held out)", (3, 12))
    canvas = np.concatenate([canvas, column], axis=1)
    write_image(
        path, with_column_header(canvas.astype(np.float32) / 255.0, (*FIGURE_COLUMNS, f"photo {FIGURE_VIEW}"))
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--per-set", type=int, default=4)
    parser.add_argument("--fit", default="1,2,3,5")
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--figure-capture", default="scans_0")
    args = parser.parse_args()
    fits = [int(k) for k in args.fit.split(",")]
    captures = make_captures(args.out / "captures", args.per_set)
    models = capture_models()
    shipped, references = models[0], models[1:]
    rows: dict[str, Row] = {}
    seconds: dict[int, list[float]] = {k: [] for k in fits}
    for capture, truth in captures:
        photos = read_views(capture)
        truth = truth.to(torch.float32)
        prediction = predict_capture_maps(capture, photos[0], shipped)
        fitted: dict[int, Tensor] = {}
        for k in fits:
            start = time.perf_counter()
            maps = prediction if k == 1 else fit_capture_maps(capture, photos, prediction, k)
            seconds[k].append(time.perf_counter() - start)
            fitted[k] = maps
            add_errors(rows, capture, photos, shipped.name, k, maps, truth)
        for reference in references:
            maps = predict_capture_maps(capture, photos[0], reference)
            add_errors(rows, capture, photos, reference.name, 1, maps, truth)
        # The floor: the true maps, relit by the project's renderer against Mitsuba's phone photos.
        add_errors(rows, capture, photos, "true maps", 0, truth, truth)
        if args.figure is not None and capture.name == args.figure_capture:
            rows_shown = [(f"{k} photo{'s' if k > 1 else ''}", fitted[k]) for k in (1, max(fits))]
            write_figure(args.figure, capture, photos, [*rows_shown, ("truth", truth)])
        print(capture.name, {key: round(row.relit[-1], 4) for key, row in rows.items()}, flush=True)

    names = [capture.name for capture, _ in captures]
    table = markdown_table(rows, seconds, names, fits, shipped.name, args.per_set)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "views_table.md").write_text(table, encoding="utf-8")
    (args.out / "views_table.json").write_text(
        json.dumps(
            {
                "captures": names,
                "rows": [row.__dict__ for row in rows.values()],
                "fit_seconds": seconds,
            },
            indent=1,
        ),
        encoding="utf-8",
    )
    print(table)


def make_captures(folder: Path, per_set: int) -> list[tuple[CalibratedCapture, Tensor]]:
    """Each material's capture (module docstring) with its true maps: rendered into
    ``folder/<set>_<n>/`` unless an earlier run left it there."""
    sensor, settings = locked_phone("conf/sensor/phone_eval.yaml"), HandheldSettings()
    captures = []
    for seed, (name, maps) in enumerate(materials([(name, path, per_set) for name, path in SETS.items()])):
        capture_folder = folder / name
        if not (capture_folder / "parameters.json").is_file():
            capture = render_synthetic_capture(maps, settings, sensor, seed=seed)
            write_synthetic_capture(capture, maps, capture_folder, name)
        captures.append((read_capture(capture_folder, name), maps))
    return captures


def add_errors(
    rows: dict[str, Row],
    capture: CalibratedCapture,
    photos: list[Photo],
    model: str,
    views: int,
    maps: Tensor,
    truth: Tensor,
) -> None:
    """``maps``' held-out and map errors on one capture, into the row of ``model`` fitted to ``views``."""
    relit, calibrated = held_out_errors(capture, photos, maps, model)
    row = rows.setdefault(f"{model}|{views}", Row(model, views, [], [], []))
    row.relit.append(relit)
    row.calibrated.append(calibrated)
    row.maps.append(map_errors(maps, truth))


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


def markdown_table(
    rows: dict[str, Row],
    seconds: dict[int, list[float]],
    captures: list[str],
    fits: list[int],
    shipped: str,
    per_set: int,
) -> str:
    """views_table.md: every row's mean errors (relit ones also over the shipped model's one-view
    row), then the shipped model's relit errors per set and number of views fitted."""
    lines = [
        f"{len(captures)} synthetic captures ({', '.join(SETS)}: {per_set} each), held-out views "
        f"{', '.join(map(str, HELD_OUT))}",
        "",
        "| model | views fitted | held-out relit, one gain | × one view | calibrated | × one view "
        "| base colour | normal ° | roughness | metallic | fit time s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    single = _mean(rows[f"{shipped}|1"].relit)
    single_calibrated = _mean(rows[f"{shipped}|1"].calibrated)
    for row in rows.values():
        relit, calibrated = _mean(row.relit), _mean(row.calibrated)
        errors = {key: _mean([m[key] for m in row.maps]) for key in row.maps[0]}
        time_s = _mean(seconds[row.views]) if row.model == shipped and row.views > 1 else float("nan")
        lines.append(
            f"| {row.model} | {row.views} | {relit:.4f} | {relit / single:.2f} "
            f"| {calibrated:.4f} | {calibrated / single_calibrated:.2f} "
            f"| {errors['rmse/basecolor']:.4f} | {errors['normal_angle_deg']:.2f} "
            f"| {errors['rmse/roughness']:.4f} | {errors['rmse/metallic']:.4f} | "
            f"{time_s:.1f} |"
        )
    by_set = ["", "| set | " + " | ".join(f"K = {k}" for k in fits) + " |", "|---|" + "---|" * len(fits)]
    for name in SETS:
        indices = [i for i, capture in enumerate(captures) if capture.startswith(name)]
        cells = [
            f"{_mean([rows[f'{shipped}|{k}'].relit[i] for i in indices]):.4f} / "
            f"{_mean([rows[f'{shipped}|{k}'].calibrated[i] for i in indices]):.4f}"
            for k in fits
        ]
        by_set.append(f"| {name} (one gain / calibrated) | " + " | ".join(cells) + " |")
    return "\n".join(lines + by_set) + "\n"


if __name__ == "__main__":
    main()
