"""The tiling figure of docs/predict.md (``docs/tileable_2x2.png``): maps tiled 2 × 2 without and
with ``--tileable``, the previous blend against the cut.

    python -m scripts.tiling_figure [--out docs/tileable_2x2.png] [--weights W.safetensors]
                                    [--samples bricks ceramic_tiles wood_planks] [--panel 208]
                                    [--ood data/ood [--ood-key KEY]]

One row per sample photo of ``src/brdfgan/samples/`` (and, with ``--ood``, one photo of the OOD
benchmark's test split: ``--ood-key``, default its first), the maps as ``brdfgan predict`` makes
them (``benchmarks.bench_tiling.network_maps``). Columns, each the map tiled 2 × 2: the network's
base colour as it is (the seams show); the previous ``--tileable``, a variance-preserving blend
of copies of the network's maps (:func:`brdfgan.core.seamless.blend_reference`), base colour and
height; the current one (:func:`brdfgan.inference.pipeline.make_tileable`: flash mark repaired,
then cut), base colour and height. Heights are integrated from the normals as ``height.png`` is (periodic for
the tiles) and stretched to their 1st-99th percentiles. Takes seconds on a CPU.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import torch
from benchmarks.bench_tiling import network_maps, photo_maps
from torch import Tensor

from brdfgan.core.height import height_from_normals
from brdfgan.core.seamless import blend_reference
from brdfgan.core.svbrdf import split_maps
from brdfgan.figures import caption, with_column_header
from brdfgan.inference.pipeline import make_tileable
from brdfgan.io.images import write_image

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "src" / "brdfgan" / "samples"
DEFAULT_OUT = ROOT / "docs" / "tileable_2x2.png"
DEFAULT_SAMPLES = ("bricks", "ceramic_tiles", "wood_planks")
COLUMNS = (
    "untiled: base colour",
    "before (blend):\nbase colour",
    "before (blend):\nheight",
    "--tileable (cut):\nbase colour",
    "--tileable (cut):\nheight",
)


def _two_by_two(image: Tensor) -> Tensor:
    """``(C, H, W)`` → ``(C, 2H, 2W)``: the image tiled twice in each direction."""
    return image.repeat(1, 2, 2)


def _height(maps: Tensor, periodic: bool) -> Tensor:
    """The maps' height as a grey image, stretched to its 1st-99th percentiles. Shape ``(3, H, W)``."""
    height = height_from_normals(split_maps(maps).normal.double(), periodic=periodic)
    low, high = torch.quantile(height.flatten(), torch.tensor([0.01, 0.99], dtype=height.dtype))
    return ((height - low) / (high - low).clamp_min(1e-12)).clamp(0, 1).expand(3, -1, -1)


def figure_row(maps: Tensor, hotspot: tuple[float, float], panel: int) -> np.ndarray:
    """One row of panels. Shape ``(panel, 5·panel, 3)`` in [0, 1]."""
    blended, _ = blend_reference(maps)  # what --tileable did before: no repair, a blend
    tiled, _ = make_tileable(maps, hotspot)
    images = [
        split_maps(maps).basecolor,
        split_maps(blended).basecolor,
        _height(blended, periodic=True),
        split_maps(tiled).basecolor,
        _height(tiled, periodic=True),
    ]
    panels = [_two_by_two(image.float()).permute(1, 2, 0).numpy() for image in images]
    resized = [cv2.resize(p, (panel, panel), interpolation=cv2.INTER_AREA) for p in panels]
    return np.concatenate(resized, axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--weights", type=Path, default=None, help="default: the shipped weights")
    parser.add_argument("--samples", nargs="+", default=list(DEFAULT_SAMPLES), help="stems in samples/")
    parser.add_argument("--panel", type=int, default=208, help="side of one 2 × 2 panel in pixels")
    parser.add_argument("--ood", type=Path, default=None, help="the OOD benchmark's dataset folder")
    parser.add_argument("--ood-key", default=None, help="the OOD photo's sample key (default: the first)")
    args = parser.parse_args()
    photos = [SAMPLES / f"{name}.jpg" for name in args.samples]
    missing = [str(photo) for photo in photos if not photo.is_file()]
    if missing:
        raise SystemExit(f"error: no such sample photo: {', '.join(missing)}")
    rows: list[tuple[str, np.ndarray]] = []
    for name, maps, hotspot in photo_maps(photos, args.weights):
        rows.append((name.replace("_", " "), figure_row(maps, hotspot, args.panel)))
    if args.ood is not None:
        if not args.ood.is_dir():
            raise SystemExit(f"error: {args.ood}: not a folder")
        found = next(
            (
                item
                for item in network_maps(args.ood, "test", args.weights)
                if args.ood_key in (None, item[0])
            ),
            None,
        )
        if found is None:
            raise SystemExit(f"error: {args.ood}: no test sample {args.ood_key!r}")
        name, maps, hotspot = found
        rows.append((f"OOD scan: {name}", figure_row(maps, hotspot, args.panel)))
    canvas = np.ascontiguousarray(
        (np.concatenate([row for _, row in rows], axis=0) * 255.0 + 0.5).astype(np.uint8)
    )
    for index, (label, _) in enumerate(rows):  # putText draws on 8-bit
        caption(canvas, label, (3, index * args.panel + 12))
    figure = with_column_header(canvas.astype(np.float32) / 255.0, COLUMNS)
    write_image(args.out, figure)
    print(
        f"{args.out}: {figure.shape[1]}×{figure.shape[0]}, {len(rows)} rows"
        + ("" if args.ood else " (no OOD row)")
    )


if __name__ == "__main__":
    main()
