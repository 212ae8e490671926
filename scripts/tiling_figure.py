"""The tiling figure of the README and docs/predict.md (``docs/tileable_2x2.png``): maps tiled 2 × 2,
the previous ``--tileable`` beside today's.

    python -m scripts.tiling_figure [--out docs/tileable_2x2.png] [--weights W.safetensors]
                                    [--samples ceramic_tiles wood_planks] [--panel 208]

One row per sample photo of ``src/brdfgan/samples/``, the network's maps as ``brdfgan predict``
makes them (:func:`~brdfgan.inference.pipeline.predict_reference`). Columns, each a map tiled
2 × 2: the network's base colour as it is (the seams show); the previous ``--tileable`` (the flash
mark repaired where its detail leaked, then rolled and cut along minimum-error paths:
:func:`~brdfgan.core.seamless.make_seamless`), base colour and metallic; today's
(:func:`~brdfgan.inference.pipeline.finish_maps`: the flash taken out of the maps, then whole
lattice cells for a periodic material, whole periods across the stripes for a 1-D one, else the
cut), base colour and metallic. Takes seconds on a CPU.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import Tensor

from brdfgan.core.flash_mark import repair_flash_mark
from brdfgan.core.seamless import make_seamless
from brdfgan.core.svbrdf import split_maps
from brdfgan.figures import caption, with_column_header
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pipeline import (
    PredictOptions,
    Predictor,
    ReferencePrediction,
    StageClock,
    finish_maps,
    predict_reference,
)
from brdfgan.io.images import write_image

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "src" / "brdfgan" / "samples"
DEFAULT_OUT = ROOT / "docs" / "tileable_2x2.png"
DEFAULT_SAMPLES = ("ceramic_tiles", "wood_planks")
COLUMNS = (
    "untiled: base colour",
    "previous --tileable:\nbase colour",
    "previous --tileable:\nmetallic",
    "--tileable:\nbase colour",
    "--tileable:\nmetallic",
)


def _two_by_two(image: Tensor) -> Tensor:
    """``(C, H, W)`` → ``(C, 2H, 2W)``: the image tiled twice in each direction."""
    return image.repeat(1, 2, 2)


def figure_row(reference: ReferencePrediction, panel: int) -> np.ndarray:
    """One row of panels. Shape ``(panel, 5·panel, 3)`` in [0, 1]."""
    maps = reference.maps
    hotspot = (float(reference.flash_frame[0, 0]), float(reference.flash_frame[0, 1]))
    previous = make_seamless(repair_flash_mark(maps, hotspot)[0]).maps
    today, _, _ = finish_maps(maps, reference, tileable=True)
    images = [split_maps(maps).basecolor]
    for tiled in (previous, today):
        parts = split_maps(tiled)
        images += [parts.basecolor, parts.metallic.expand(3, -1, -1)]
    panels = [_two_by_two(image.float()).permute(1, 2, 0).numpy() for image in images]
    resized = [cv2.resize(p, (panel, panel), interpolation=cv2.INTER_AREA) for p in panels]
    return np.concatenate(resized, axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--weights", type=Path, default=None, help="default: the shipped weights")
    parser.add_argument("--samples", nargs="+", default=list(DEFAULT_SAMPLES), help="stems in samples/")
    parser.add_argument("--panel", type=int, default=208, help="side of one 2 × 2 panel in pixels")
    args = parser.parse_args()
    photos = [SAMPLES / f"{name}.jpg" for name in args.samples]
    missing = [str(photo) for photo in photos if not photo.is_file()]
    if missing:
        raise SystemExit(f"error: no such sample photo: {', '.join(missing)}")
    predictor = Predictor.create(load_model(args.weights), PredictOptions(preview=False))
    rows: list[tuple[str, np.ndarray]] = []
    for path in photos:
        with torch.no_grad():
            reference = predict_reference(read_photo(path), predictor, StageClock({}))
        rows.append((path.stem.replace("_", " "), figure_row(reference, args.panel)))
    canvas = np.ascontiguousarray(
        (np.concatenate([row for _, row in rows], axis=0) * 255.0 + 0.5).astype(np.uint8)
    )
    for index, (label, _) in enumerate(rows):  # putText draws on 8-bit
        caption(canvas, label, (3, index * args.panel + 12))
    figure = with_column_header(canvas.astype(np.float32) / 255.0, COLUMNS)
    write_image(args.out, figure)
    print(f"{args.out}: {figure.shape[1]}×{figure.shape[0]}, {len(rows)} rows")


if __name__ == "__main__":
    main()
