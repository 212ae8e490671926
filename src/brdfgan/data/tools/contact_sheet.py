"""Contact sheet of a dataset: a PNG grid, one sample per row — input | base color | normal |
roughness | metallic — so a person can judge the realism of generated data at a glance.

    brdfgan contact-sheet DATA_DIR [--split train] [--rows 16] [--seed 0] [--tile PX] [--out PATH]
                                   [--family PREFIX]

The input photo is linear LDR and is shown sRGB-encoded, as a phone would display it; base color
is stored sRGB and shown as is; normals as (n+1)/2 (OpenGL, the usual blue-ish look); roughness
and metallic as gray. Samples are a seeded uniform draw (reservoir sampling over all shards);
each row's input panel names its family (``+ partner`` when mixed, ``(recol.)`` when recoloured).
"""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import torch

from brdfgan.core.svbrdf import encode_normal, linear_to_srgb, resize_image, split_maps
from brdfgan.data.materials.source import SCANNED_PREFIX
from brdfgan.data.storage.shards import Sample, iter_shard, list_shards
from brdfgan.errors import UserError
from brdfgan.figures import caption, with_column_header
from brdfgan.io.images import write_image

COLUMNS = ("input", "basecolor", "normal", "roughness", "metallic")


def pick_samples(
    data_dir: str | Path, split: str, rows: int, seed: int = 0, family: str | None = None
) -> list[Sample]:
    """``rows`` samples drawn uniformly from the split's shards (reservoir sampling, seeded);
    with ``family``, from the samples whose family starts with it (``scanned/``: the scans)."""
    shards = list_shards(data_dir, split)
    rng = random.Random(seed)
    chosen: list[Sample] = []
    seen = 0
    for shard in shards:
        for sample in iter_shard(shard):
            if family is not None and not str(sample.meta.get("family", "")).startswith(family):
                continue
            seen += 1
            if len(chosen) < rows:
                chosen.append(sample)
            else:
                slot = rng.randrange(seen)
                if slot < rows:
                    chosen[slot] = sample
    return sorted(chosen, key=lambda s: s.key)


def sample_row(sample: Sample, tile: int | None = None) -> torch.Tensor:
    """One row of the sheet: the five panels side by side, display-ready sRGB in [0, 1], each
    area-resized to ``tile``² when given (a small sheet of many samples).

    Shape: output ``(3, H, 5·W)`` (``H = W = tile`` when given).
    """
    parts = split_maps(sample.maps)
    panels = [
        linear_to_srgb(sample.photo.clamp(0.0, 1.0)),
        parts.basecolor,
        encode_normal(parts.normal),
        parts.roughness.expand(3, -1, -1),
        parts.metallic.expand(3, -1, -1),
    ]
    if tile is not None:
        panels = [resize_image(panel, tile, tile).clamp(0.0, 1.0) for panel in panels]
    return torch.cat(panels, dim=-1)


def row_label(sample: Sample) -> str:
    """What a row shows: the family, ``+partner`` for a mixed material, ``recol.`` if recoloured."""
    label = str(sample.meta.get("family", sample.key)).removeprefix(SCANNED_PREFIX)
    mix = sample.meta.get("mix")
    if isinstance(mix, dict):
        label += f" + {mix.get('partner_family', '?')}"
    if "recolor" in sample.meta:
        label += " (recol.)"
    return label


def contact_sheet(samples: list[Sample], tile: int | None = None) -> np.ndarray:
    """The grid with a header naming the columns and each row's family on its input panel.

    Shape: ``(rows·H + label, 5·W, 3)`` in [0, 1].
    """
    if not samples:
        raise UserError("no samples to show")
    rows = torch.cat([sample_row(s, tile) for s in samples], dim=-2).permute(1, 2, 0).numpy()
    height = rows.shape[0] // len(samples)
    canvas = np.ascontiguousarray((rows * 255.0 + 0.5).astype(np.uint8))  # putText draws on 8-bit
    for index, sample in enumerate(samples):
        caption(canvas, row_label(sample), (3, index * height + 12))
    return with_column_header(canvas.astype(np.float32) / 255.0, COLUMNS)


def write_contact_sheet(
    data_dir: str | Path,
    split: str = "train",
    *,
    rows: int = 16,
    seed: int = 0,
    out: str | Path | None = None,
    tile: int | None = None,
    family: str | None = None,
) -> Path:
    """Write the contact sheet PNG (default ``DATA_DIR/contact_sheet_<split>.png``)."""
    path = Path(out) if out else Path(data_dir) / f"contact_sheet_{split}.png"
    samples = pick_samples(data_dir, split, rows, seed, family)
    if family is not None and not samples:
        raise UserError(f"{data_dir}: no {split} samples of a family starting with {family!r}")
    return write_image(path, contact_sheet(samples, tile))
