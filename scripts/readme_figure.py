"""The README's before/after figure: sample flash photos through ``brdfgan predict``, in-process.

    python scripts/readme_figure.py [--out docs/readme_before_after.png] [--weights W.safetensors]
                                    [--samples wood_planks ceramic_tiles rusted_metal] [--panel 192]

One row per photo of ``src/brdfgan/samples/``; columns: the photo as the network sees it (the
crop, auto-exposed, sRGB) | base colour | normal | roughness | metallic | the maps relit under a
novel point light. Every panel is a file that ``brdfgan predict`` writes — the pipeline runs
whole (:func:`brdfgan.inference.pipeline.predict_photo`, at the model's 256²) into a temporary
folder, and the figure is cut from its ``basecolor.png``, ``normal.png``, ``roughness.png``,
``metallic.png`` and ``preview.png`` (its input tile and its first light: azimuth 45°, elevation
45°) — so the figure shows what an artist gets from the shipped weights (default) or
``--weights``. Rerun it when the shipped model changes; it takes seconds on a CPU.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

from brdfgan.figures import caption, with_column_header
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.outputs.preview import LABEL_HEIGHT, SEPARATOR, preview_size
from brdfgan.inference.pipeline import PredictOptions, Predictor, predict_photo
from brdfgan.io.images import read_image, write_image

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "src" / "brdfgan" / "samples"
DEFAULT_OUT = ROOT / "docs" / "readme_before_after.png"
DEFAULT_SAMPLES = ("wood_planks", "ceramic_tiles", "rusted_metal")
COLUMNS = ("photo", "base colour", "normal", "roughness", "metallic", "relit\n(novel light)")
MAP_FILES = ("basecolor.png", "normal.png", "roughness.png", "metallic.png")
PREVIEW_TILE = 256  # preview.png's tile side (write_preview's default)


def _rgb(image: np.ndarray) -> np.ndarray:
    """``(H, W, C)`` in [0, 1], gray or RGB(A) → ``(H, W, 3)``."""
    return np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[..., :3]


def preview_tiles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The input tile and the first novel-light tile of a ``preview.png``."""
    preview = read_image(path)
    rows, cols = preview_size(PREVIEW_TILE)
    if preview.shape[:2] != (rows, cols):
        raise SystemExit(f"error: {path}: {preview.shape[1]}×{preview.shape[0]}, expected {cols}×{rows}")
    tiles = preview[LABEL_HEIGHT:, :, :3]
    step = PREVIEW_TILE + SEPARATOR
    return tiles[:, :PREVIEW_TILE], tiles[:, step : step + PREVIEW_TILE]


def figure_row(photo: Path, predictor: Predictor, workdir: Path, panel: int) -> np.ndarray:
    """One row: ``brdfgan predict`` on ``photo``, its files side by side. Shape ``(panel, 6·panel, 3)``."""
    result = predict_photo(photo, workdir / photo.stem, predictor)
    photo_tile, relit_tile = preview_tiles(result.output / "preview.png")
    panels = [photo_tile, *(_rgb(read_image(result.output / name)) for name in MAP_FILES), relit_tile]
    resized = [cv2.resize(p, (panel, panel), interpolation=cv2.INTER_AREA) for p in panels]
    return np.concatenate(resized, axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--weights", type=Path, default=None, help="default: the shipped weights")
    parser.add_argument("--samples", nargs="+", default=list(DEFAULT_SAMPLES), help="stems in samples/")
    parser.add_argument("--panel", type=int, default=192, help="side of one panel in pixels")
    args = parser.parse_args()
    model = load_model(args.weights)
    predictor = Predictor.create(model, PredictOptions(resolution=model.resolution))
    photos = [SAMPLES / f"{name}.jpg" for name in args.samples]
    with tempfile.TemporaryDirectory(prefix="readme_figure_") as workdir:
        rows = [figure_row(photo, predictor, Path(workdir), args.panel) for photo in photos]
    canvas = np.ascontiguousarray((np.concatenate(rows, axis=0) * 255.0 + 0.5).astype(np.uint8))
    for index, photo in enumerate(photos):  # putText draws on 8-bit
        caption(canvas, photo.stem.replace("_", " "), (3, index * args.panel + 12))
    figure = with_column_header(canvas.astype(np.float32) / 255.0, COLUMNS)
    write_image(args.out, figure)
    print(f"{args.out}: {figure.shape[1]}×{figure.shape[0]}, model {model.model_id}")


if __name__ == "__main__":
    main()
