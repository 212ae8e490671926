"""A qualitative figure (docs/default_model_grid.png) from evaluate.py's per-model grids.

    python scripts/grid_figure.py EVAL_DIR OUT.png [--models gan baseline] [--panel 96]

Rows are the evaluation's fixed samples (all of them, in their order); columns: the input, then
for base colour, normal, roughness, metallic and the re-render under a novel light the ground
truth followed by each model's prediction.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from brdfgan.figures import HEADER_HEIGHT

PANEL = 256  # side of one panel in evaluate.py's grids
# Panel columns of a grid: input, then (truth, prediction) for four maps and the re-render.
PAIRS = ((1, 2), (3, 4), (5, 6), (7, 8), (9, 10))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("eval_dir", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--models", nargs="+", default=["gan", "baseline"])
    parser.add_argument("--panel", type=int, default=96)
    args = parser.parse_args()
    grids = {}
    for m in args.models:
        grid = cv2.imread(str(args.eval_dir / f"grid_{m}.png"), cv2.IMREAD_COLOR)
        if grid is None:
            raise SystemExit(f"error: missing grid_<model>.png in {args.eval_dir}")
        grids[m] = grid[HEADER_HEIGHT:]  # panels only, below the column labels
    first = grids[args.models[0]]

    def panel(image: np.ndarray, column: int) -> np.ndarray:
        return image[:, column * PANEL : (column + 1) * PANEL]

    columns = [panel(first, 0)]
    for truth, prediction in PAIRS:
        columns.append(panel(first, truth))
        columns += [panel(grids[m], prediction) for m in args.models]
    figure = np.concatenate(columns, axis=1)
    scale = args.panel / PANEL
    figure = cv2.resize(figure, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(args.out), figure, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"{args.out}: {figure.shape[1]}×{figure.shape[0]}, {args.out.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
