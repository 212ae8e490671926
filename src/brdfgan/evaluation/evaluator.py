"""Evaluate generators on a split and write what a paper table needs.

``evaluate_models`` runs every model over the same batches with the same metric definitions
(:mod:`brdfgan.metrics`); ``write_results`` writes ``metrics.json``, ``metrics.csv``,
``metrics.md`` and ``rmse.png`` (models × maps, full vs downscaled, like the paper's comparison
figure); ``comparison_grid`` shows input | ground truth | prediction per map | re-render for a
fixed list of samples (``fixed_samples``), with labelled columns; training logs the same grid
every validation epoch (:class:`~brdfgan.training.prediction_grid.PredictionGrid`).
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torchmetrics import MetricCollection

from brdfgan.capture import FLASH_PHOTO, NO_FLASH_PHOTO
from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import FlashCapture, PointLights, render_point_lights
from brdfgan.core.svbrdf import encode_normal, linear_to_srgb, split_maps
from brdfgan.data.loading.datamodule import flash_frames
from brdfgan.data.phone.conditions import sample_as_photographed
from brdfgan.data.phone.pairs import flash_only_photos
from brdfgan.data.storage.shards import Sample, iter_shard, list_shards
from brdfgan.errors import UserError
from brdfgan.figures import with_column_header
from brdfgan.inference.model.tiling import model_placement
from brdfgan.inference.pair.relief_fit import PairFitConfig, fit_pair
from brdfgan.io.atomic import atomic_replace, write_text_atomic
from brdfgan.io.images import write_image
from brdfgan.metrics import hotspot_centres
from brdfgan.models.heads import network_photos

FLASH_FRAME_SOURCES = ("recorded", "centred")
PAPER_MAPS = ("diffuse", "specular", "normal", "roughness")
ALL_MAPS = (*PAPER_MAPS, "basecolor", "metallic")
# The predicted maps whose hotspot ratio the table shows (metrics.json/.csv hold all of them).
HOTSPOT_COLUMNS = {"basecolor": "basecolor", "normal": "normal", "roughness": "rough", "metallic": "metal"}
# The maps whose checkerboard ratio (predicted / true period-2 power) the table shows.
CHECKERBOARD_COLUMNS = {"basecolor": "base", "normal": "normal", "roughness": "rough", "metallic": "metal"}


@dataclass(frozen=True)
class PairRows:
    """The rows scored on flash + no-flash pairs (issue 59), beside each model's row on the flash
    photo: ``<name>@flash-only``, the model on the flash-only photo (the room light subtracted,
    auto-exposed as predict exposes it), for every name in ``flash_only``; ``<name>+pair-fit``,
    the pair fit (:func:`~brdfgan.inference.pair.relief_fit.fit_pair`, with ``fit_config``) read
    with that prediction and written into the model's prediction from the flash photo, as
    ``brdfgan predict --no-flash`` writes it, for every name in ``fit``. Names are the evaluated
    models'."""

    flash_only: tuple[str, ...] = ()
    fit: tuple[str, ...] = ()
    fit_config: PairFitConfig = field(default_factory=PairFitConfig)

    def names(self) -> list[str]:
        return [f"{name}@flash-only" for name in self.flash_only] + [f"{name}+pair-fit" for name in self.fit]

    def check(self, models: Iterable[str]) -> None:
        """Raises UserError (one line) naming a row whose model is not evaluated."""
        known = set(models)
        for key, names in (("pair_rows.flash_only", self.flash_only), ("pair_rows.fit", self.fit)):
            for name in names:
                if name not in known:
                    choices = ", ".join(sorted(known))
                    raise UserError(f"{key}: {name!r} is not an evaluated model (one of {choices})")


def pair_row_maps(
    models: Mapping[str, nn.Module],
    batch: Mapping[str, Any],
    rows: PairRows,
    flash: Tensor | None,
    recorded: Tensor,
    on_photo: Mapping[str, Tensor],
) -> dict[str, Tensor]:
    """The maps of every :class:`PairRows` row for one batch of pairs (the twins and their
    ``exposure_ratio`` and ``white_balance``, :func:`~brdfgan.data.loading.datamodule
    .collate_samples`): the models are given the frames ``flash`` (as on the flash photo), the fit
    the ``recorded`` ones; ``on_photo``: each model's maps from the flash photo, which the fit's
    relief is written into.

    Raises:
        UserError: the batch holds no no-flash twins (the data was made without ``dataset_spec.pairs``).

    Shape:
        - flash, recorded: ``(B, 3)``; on_photo, output: each ``(B, 8, H, W)``
    """
    if NO_FLASH_PHOTO.batch_key not in batch:
        raise UserError(
            "pair_rows: the test data has no no-flash twins; generate it with dataset_spec.pairs=true"
        )
    photo = batch[FLASH_PHOTO.batch_key].to(recorded.device)
    pair = flash_only_photos(
        photo, batch[NO_FLASH_PHOTO.batch_key].to(photo), batch["exposure_ratio"], batch["white_balance"]
    )
    network_input, _ = auto_expose(pair.flash_only)
    out: dict[str, Tensor] = {}
    from_flash_only = {
        name: models[name](network_input, flash) for name in dict.fromkeys((*rows.flash_only, *rows.fit))
    }
    for name in rows.flash_only:
        out[f"{name}@flash-only"] = from_flash_only[name]
    for name in rows.fit:
        fitted = []
        for i in range(photo.shape[0]):
            with torch.enable_grad():  # evaluate_models runs under no_grad; the fit is an Adam loop
                result = fit_pair(
                    pair.flash_only[i],
                    pair.room[i],
                    pair.valid[i],
                    from_flash_only[name][i],
                    recorded[i : i + 1],
                    rows.fit_config,
                    written=on_photo[name][i],
                )
            fitted.append(result.maps)
        out[f"{name}+pair-fit"] = torch.stack(fitted)
    return out


@torch.no_grad()
def evaluate_models(
    models: Mapping[str, nn.Module],
    batches: Iterable[Mapping[str, Any]],
    make_metrics: Callable[[], MetricCollection],
    device: torch.device | str = "cpu",
    flash_frame: str = "recorded",
    pair_rows: PairRows = PairRows(),
) -> dict[str, dict[str, float]]:
    """Metric values per model name. ``make_metrics()`` builds a fresh metric per model; every
    model sees the same batches in the same order. The flash positions of ``batch["meta"]``
    (:func:`~brdfgan.metrics.hotspot_centres`) go to the metrics as ``hotspot``; a batch without
    ``meta`` has them at the image centres. The recorded flash frames ``batch["flash"]`` go to the
    metrics as ``flash`` whatever ``flash_frame`` says (the geometry of the true relief shading,
    :class:`~brdfgan.metrics.ReliefLeak`; without them, photos centred on their hotspot).
    ``flash_frame``: ``"recorded"`` passes the batches' flash frames to the models, ``"centred"``
    the frame of a photo centred on its hotspot with the default field of view (what ``brdfgan
    predict`` assumes without EXIF). ``pair_rows``: rows of the models on the batches' flash +
    no-flash pairs (:class:`PairRows`, :func:`pair_row_maps`; the fit is given the recorded frames,
    as the refinement rows are), scored against the same truth with the flash photo as the photo."""
    if flash_frame not in FLASH_FRAME_SOURCES:
        raise UserError(f"flash_frame={flash_frame!r}: must be {' or '.join(map(repr, FLASH_FRAME_SOURCES))}")
    pair_rows.check(models)
    metrics = {name: make_metrics().to(device) for name in [*models, *pair_rows.names()]}
    for model in models.values():
        model.to(device).eval()
    for batch in batches:
        photo = network_photos(batch).to(device)
        truth = batch["maps"].to(device)
        meta = batch.get("meta")
        hotspot = None if meta is None else hotspot_centres(meta, *truth.shape[-2:]).to(device)
        recorded = batch.get("flash")
        recorded = None if recorded is None else recorded.to(device)
        # None: each network's own default, the photo centred on its hotspot with the default FOV.
        flash = recorded if flash_frame == "recorded" else None
        predictions = {name: model(photo, flash) for name, model in models.items()}
        if pair_rows.names():
            if recorded is None:
                raise ValueError("pair rows need the batches' recorded flash frames (batch['flash'])")
            predictions |= pair_row_maps(models, batch, pair_rows, flash, recorded, predictions)
        for name, maps in predictions.items():
            metrics[name].update(maps, truth, hotspot=hotspot, flash=recorded, photo=photo)
    return {name: {k: float(v) for k, v in metric.compute().items()} for name, metric in metrics.items()}


def write_results(results: Mapping[str, Mapping[str, float]], out_dir: str | os.PathLike[str]) -> list[Path]:
    """``metrics.json``, ``metrics.csv`` (one row per model), ``metrics.md`` and ``rmse.png``, each
    written atomically (a full disk or a kill leaves the previous file or none, never half a one)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = sorted({key for values in results.values() for key in values})
    write_text_atomic(out / "metrics.json", json.dumps(results, indent=2, sort_keys=True) + "\n")
    table = io.StringIO(newline="")
    writer = csv.writer(table)
    writer.writerow(["model", *names])
    for model, values in results.items():
        writer.writerow([model, *(f"{values[n]:.6f}" if n in values else "" for n in names)])
    write_text_atomic(out / "metrics.csv", table.getvalue())
    write_text_atomic(out / "metrics.md", markdown_table(results))
    bar_chart(results, out / "rmse.png")
    return [out / n for n in ("metrics.json", "metrics.csv", "metrics.md", "rmse.png")]


def markdown_table(results: Mapping[str, Mapping[str, float]]) -> str:
    """Per-map RMSE at full and downscaled resolution, angular and re-render error, the base
    colour's saturation ratio (predicted / true: 1 right, < 1 greyed) and hue error (degrees), the
    checkerboard ratios (predicted / true period-2 power per map: 1 right, ≫ 1 a checkerboard), the
    false metal (mean predicted metallic on dielectric truth: 0 right), the relief leak and its
    slope (the base colour's error against the true relief shading: 0 right, 1 the relief copied
    into it), the normal angle over the texels whose relief the photo shows beside a flat map's
    there, and the hotspot ratios of the predicted maps (RMSE near the flash highlight /
    elsewhere), per model."""
    columns = [(f"rmse/{m}", f"{m}") for m in ALL_MAPS] + [(f"rmse256/{m}", f"{m} ↓256") for m in PAPER_MAPS]
    columns += [("normal_angle_deg", "normal °"), ("rerender_rmse", "re-render")]
    columns += [("basecolor_saturation_ratio", "sat ratio"), ("basecolor_hue_error_deg", "hue °")]
    columns += [(f"checkerboard/{m}", f"chk {label}") for m, label in CHECKERBOARD_COLUMNS.items()]
    columns += [
        ("false_metal", "false metal"),
        ("relief_leak", "relief leak"),
        ("relief_leak/slope", "leak slope"),
        ("normal_angle_deg/observable", "normal ° seen"),
        ("normal_angle_deg/observable_flat", "flat ° seen"),
        ("normal_slope_cosine", "slope cos"),
        ("normal_slope_ratio", "slope ratio"),
    ]
    columns += [(f"hotspot/{m}", f"hot {label}") for m, label in HOTSPOT_COLUMNS.items()]
    present = [(key, label) for key, label in columns if any(key in v for v in results.values())]
    lines = ["| model | " + " | ".join(label for _, label in present) + " |"]
    lines.append("|---|" + "---|" * len(present))
    for model, values in results.items():
        cells = [f"{values[key]:.4f}" if key in values else "–" for key, _ in present]
        lines.append(f"| {model} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def bar_chart(results: Mapping[str, Mapping[str, float]], path: Path) -> Path:
    """Grouped bars: the paper's four maps, one bar per (model, full | downscaled)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    downscaled = [m for m in results if any(k.startswith("rmse256/") for k in results[m])]
    series = [(m, "rmse") for m in results] + [(f"{m} ↓256", "rmse256") for m in downscaled]
    width = 0.8 / max(1, len(series))
    figure, axis = plt.subplots(figsize=(1.8 + 1.6 * len(PAPER_MAPS), 3.6), dpi=120)
    for index, (label, prefix) in enumerate(series):
        model = label.removesuffix(" ↓256")
        values = [results[model].get(f"{prefix}/{m}", np.nan) for m in PAPER_MAPS]
        axis.bar(np.arange(len(PAPER_MAPS)) + index * width, values, width, label=label)
    axis.set_xticks(np.arange(len(PAPER_MAPS)) + width * (len(series) - 1) / 2, PAPER_MAPS)
    axis.set_ylabel("RMSE")
    axis.legend(fontsize=7)
    figure.tight_layout()
    try:
        with atomic_replace(path) as temp:
            figure.savefig(temp, format="png")
    finally:
        plt.close(figure)
    return path


def _novel_light_render(maps: Tensor, capture: FlashCapture) -> Tensor:
    """Render under one fixed light off to the side (not the training flash), display-ready."""
    batch = maps.shape[0]
    camera = maps.new_tensor([0.0, 0.0, capture.camera_height]).expand(batch, 1, 3)
    lights = PointLights(
        position=maps.new_tensor([1.2, 0.8, 1.6]).view(1, 1, 1, 3).expand(batch, 1, 1, 3),
        intensity=maps.new_full((batch, 1, 1), 3.0),
        color=maps.new_ones(batch, 1, 1, 3),
    )
    image = render_point_lights(maps, camera, lights, capture.plane_half_size)[:, 0]
    return linear_to_srgb(image.clamp(0.0, 1.0))


def _panels(maps: Tensor) -> list[Tensor]:
    parts = split_maps(maps)
    return [parts.basecolor, encode_normal(parts.normal), parts.roughness.expand(3, -1, -1),
            parts.metallic.expand(3, -1, -1)]  # fmt: skip


# The grids' columns: the input, then ground truth and prediction of each map and of a re-render
# under a light the network never saw (a fixed point light off to the side).
GRID_COLUMNS = (
    "input",
    *(f"{name}\n{side}" for name in ("basecolor", "normal", "roughness", "metallic", "relit")
      for side in ("GT", "pred")),
)  # fmt: skip


def fixed_samples(
    data_dir: Path, split: str, count: int, keys: Sequence[str] | None = None, *, align_maps: bool = True
) -> list[Sample]:
    """The first ``count`` samples of a split in shard and key order, or the samples named by
    ``keys`` (in that order) — a list fixed before training, not cherry-picked afterwards. With
    ``align_maps`` their maps are resampled into the photos' pixels, as the DataModule reads them
    (:func:`~brdfgan.data.phone.conditions.sample_as_photographed`)."""
    wanted = list(keys) if keys else None
    found: dict[str, Sample] = {}
    samples: list[Sample] = []
    for shard in list_shards(data_dir, split):
        for stored in iter_shard(shard):
            sample = sample_as_photographed(stored) if align_maps else stored
            if wanted is None:
                if len(samples) == count:
                    return samples
                samples.append(sample)
            elif sample.key in wanted:
                found[sample.key] = sample
    if wanted is None:
        return samples
    missing = [key for key in wanted if key not in found]
    if missing:
        raise UserError(f"grid_keys: no sample {missing[0]!r} in the {split} split of {data_dir}")
    return [found[key] for key in wanted]


@torch.no_grad()
def comparison_grid(generator: nn.Module, samples: Sequence[Sample]) -> np.ndarray:
    """One row per sample under a header naming the columns (:data:`GRID_COLUMNS`): input |
    (GT, prediction) per map | (GT, prediction) re-render. The generator runs on the device of
    its parameters or buffers (:func:`~brdfgan.inference.model.tiling.model_placement`).

    Shape: output ``(HEADER_HEIGHT + N·H, 11·W, 3)`` display-ready in [0, 1].
    """
    photos = torch.stack([s.photo for s in samples])
    device, _ = model_placement(generator, photos)
    truth = torch.stack([s.maps for s in samples])
    flash = flash_frames([s.meta for s in samples], *photos.shape[-2:])
    pred = generator.eval()(photos.to(device), flash.to(device)).float().cpu()
    capture = FlashCapture()
    renders = _novel_light_render(torch.cat([truth, pred]), capture)
    rows = []
    for i in range(len(samples)):
        panels = [linear_to_srgb(photos[i].clamp(0.0, 1.0))]
        for t, p in zip(_panels(truth[i]), _panels(pred[i]), strict=True):
            panels += [t, p]
        panels += [renders[i], renders[len(samples) + i]]
        rows.append(torch.cat(panels, dim=-1))
    grid = torch.cat(rows, dim=-2).permute(1, 2, 0).numpy()
    return with_column_header(grid, GRID_COLUMNS)


def write_grid(generator: nn.Module, samples: Sequence[Sample], path: str | os.PathLike[str]) -> Path:
    return write_image(path, comparison_grid(generator, samples))
