"""Text on figure PNGs: a header row naming a grid's columns, outlined captions on panels.

The grids of ``evaluate.py``, of training's dashboards and of ``brdfgan contact-sheet`` are read
by people who did not write them, so every column says what it shows.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from brdfgan.core.checks import check_shape

# Height of the header row in pixels: room for two lines (scripts that cut panels out of a grid
# skip it).
HEADER_HEIGHT = 34
_LINE_HEIGHT = 14
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_MAX_SCALE = 0.45


def with_column_header(grid: np.ndarray, labels: Sequence[str]) -> np.ndarray:
    """``grid`` with a white header row above it naming its equally wide columns; a label may
    hold two lines (``"normal\\nGT"``) and is shrunk to fit its column.

    Shape: ``grid`` ``(H, W, 3)`` in ``[0, 1]``, ``W`` divisible by ``len(labels)`` → output
    ``(HEADER_HEIGHT + H, W, 3)`` float32 in ``[0, 1]``.
    """
    check_shape(grid, "H W 3", name="grid")
    if not labels or grid.shape[1] % len(labels):
        raise ValueError(f"{len(labels)} labels for a grid {grid.shape[1]} px wide")
    width = grid.shape[1] // len(labels)
    header = np.full((HEADER_HEIGHT, grid.shape[1], 3), 255, dtype=np.uint8)
    for index, label in enumerate(labels):
        lines = label.split("\n")
        if len(lines) > 2:
            raise ValueError(f"label {label!r} has more than two lines")
        widest = max(cv2.getTextSize(line, _FONT, 1.0, 1)[0][0] for line in lines)
        scale = min(_MAX_SCALE, (width - 6) / max(widest, 1))
        for row, line in enumerate(lines):
            origin = (index * width + 3, 14 + row * _LINE_HEIGHT)
            cv2.putText(header, line, origin, _FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([header.astype(np.float32) / 255.0, grid.astype(np.float32)], axis=0)


def caption(canvas: np.ndarray, text: str, origin: tuple[int, int]) -> None:
    """Draw ``text`` at ``origin`` (x, y of the baseline) in white outlined in black, legible on
    any photo. In place.

    Shape: ``canvas`` ``(H, W, 3)`` uint8.
    """
    for colour, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):
        cv2.putText(canvas, text, origin, _FONT, 0.35, colour, thickness)
