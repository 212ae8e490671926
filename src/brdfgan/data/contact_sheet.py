"""Contact sheet of a dataset: a PNG grid, one sample per row — input | base color | normal |
roughness | metallic — so a person can judge the realism of generated data at a glance.

    brdfgan contact-sheet DATA_DIR [--split train] [--rows 16] [--seed 0] [--out PATH]

The input photo is linear LDR and is shown sRGB-encoded, as a phone would display it; base color
is stored sRGB and shown as is; normals as (n+1)/2 (OpenGL, the usual blue-ish look); roughness
and metallic as gray. Samples are a seeded uniform draw (reservoir sampling over all shards).
"""

from __future__ import annotations

import random
from pathlib import Path

import cv2
import numpy as np
import torch

from brdfgan.core.svbrdf import encode_normal, linear_to_srgb, split_maps
from brdfgan.data.shards import Sample, iter_shard, list_shards
from brdfgan.errors import UserError
from brdfgan.io.images import write_image

COLUMNS = ("input", "basecolor", "normal", "roughness", "metallic")
_LABEL_HEIGHT = 22


def pick_samples(data_dir: str | Path, split: str, rows: int, seed: int = 0) -> list[Sample]:
    """``rows`` samples drawn uniformly from the split's shards (reservoir sampling, seeded)."""
    shards = list_shards(data_dir, split)
    rng = random.Random(seed)
    chosen: list[Sample] = []
    seen = 0
    for shard in shards:
        for sample in iter_shard(shard):
            seen += 1
            if len(chosen) < rows:
                chosen.append(sample)
            else:
                slot = rng.randrange(seen)
                if slot < rows:
                    chosen[slot] = sample
    return sorted(chosen, key=lambda s: s.key)


def sample_row(sample: Sample) -> torch.Tensor:
    """One row of the sheet: the five panels side by side, display-ready sRGB in [0, 1].

    Shape: output ``(3, H, 5·W)``.
    """
    parts = split_maps(sample.maps)
    panels = [
        linear_to_srgb(sample.photo.clamp(0.0, 1.0)),
        parts.basecolor,
        encode_normal(parts.normal),
        parts.roughness.expand(3, -1, -1),
        parts.metallic.expand(3, -1, -1),
    ]
    return torch.cat(panels, dim=-1)


def contact_sheet(samples: list[Sample]) -> np.ndarray:
    """The grid with a header naming the columns. Shape: ``(rows·H + label, 5·W, 3)`` in [0, 1]."""
    if not samples:
        raise UserError("no samples to show")
    rows = torch.cat([sample_row(s) for s in samples], dim=-2).permute(1, 2, 0).numpy()
    width = rows.shape[1] // len(COLUMNS)
    header = np.full((_LABEL_HEIGHT, rows.shape[1], 3), 255, dtype=np.uint8)  # putText draws on 8-bit
    for index, name in enumerate(COLUMNS):
        cv2.putText(header, name, (index * width + 4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    return np.concatenate([header.astype(np.float32) / 255.0, rows.astype(np.float32)], axis=0)


def write_contact_sheet(
    data_dir: str | Path,
    split: str = "train",
    *,
    rows: int = 16,
    seed: int = 0,
    out: str | Path | None = None,
) -> Path:
    """Write the contact sheet PNG (default ``DATA_DIR/contact_sheet_<split>.png``)."""
    path = Path(out) if out else Path(data_dir) / f"contact_sheet_{split}.png"
    return write_image(path, contact_sheet(pick_samples(data_dir, split, rows, seed)))
